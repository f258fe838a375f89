"""A LaserScan topic of an MCAP file or ROS bag served as a Hokuyo, an LMS200 or a CoLa SICK
(`replay FILE --topic T`).

Reads `foxglove.LaserScan` (protobuf, as `record --format mcap` and Foxglove's
SDKs write it, or JSON) and ROS 2 `sensor_msgs/msg/LaserScan` (CDR, as a ROS 2
bag in MCAP holds it). Each scan's ranges are resampled onto the device's own
beams (the nearest recorded beam within half a recorded step; beams the scan
does not cover get "no echo") and turned into device values by the device's
conventions (`laserscan.py`), in whatever unit the client asks for. A Hokuyo
that reports intensity (UTM, UST) serves the scans' intensities, resampled
alike (0 where a scan has none). A CoLa SICK serves them as its first echo and
its RSSI, on the grid of whichever scan configuration its client sets.

Time: simulated time 0 is the first message; each scan is stamped with its
header time (the log time when a message has none); the recording loops as a
text log's replay does (`replay_sources.ReplayClock`).

A file is not trusted: at most MAX_MESSAGES scans of at most MAX_BEAMS ranges
each are read; anything else is a one-line error naming the file and topic.
"""

from __future__ import annotations

import functools
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterable, Optional, Sequence

import numpy as np
from mcap.decoder import DecoderFactory
from mcap.exceptions import McapError
from mcap.reader import make_reader
from mcap.records import Schema
from mcap_protobuf.decoder import DecoderFactory as ProtobufDecoderFactory
from mcap_ros2.decoder import DecoderFactory as Ros2DecoderFactory

from emulator.errors import UserError
from emulator.recording.laserscan import ranges_to_values
from emulator.recording.replay_sources import (
    LMS_MODEL,
    LMS_NO_ECHO,
    LMS_REVOLUTION_S,
    ReplayClock,
    cola_scan_configuration,
    first_echo_scan,
)
from emulator.scene.sick_models import FREQUENCY_TICKS_PER_HZ
from emulator.scene.sick_models import MODELS as SICK_MODELS
from emulator.sensors import hokuyo_model, lms200
from emulator.sensors.physical.params import PULSED_RECEIVERS
from emulator.sensors.scan import Scan

MAX_MESSAGES = 500_000
MAX_BEAMS = 20_000
LASERSCAN_SCHEMAS = ("foxglove.LaserScan", "sensor_msgs/msg/LaserScan")
LMS_GRID_STEP_DEG = 0.25  # the finest LMS200 resolution: every window a client can ask for lies on it
INTENSITY_MAX = (1 << 18) - 1  # the most a SCIP intensity field (3 characters) holds
ROWS_KEPT = 64  # resampled scans kept: the few a replay's clients read around now


class _JsonDecoderFactory(DecoderFactory):
    """`foxglove.LaserScan` messages in JSON encoding."""

    def decoder_for(self, message_encoding: str, schema: Optional[Schema]) -> Optional[Callable[[bytes], Any]]:
        if message_encoding == "json":
            return lambda data: json.loads(data)
        return None


@dataclass(frozen=True)
class LaserScans:
    """A topic's scans: times (n,) from 0, and per scan its first angle, step, ranges (metres) and
    intensities (None where a scan has none, one per range otherwise)."""

    topic: str
    times_s: np.ndarray
    start_angles_rad: np.ndarray
    steps_rad: np.ndarray
    ranges_m: list[np.ndarray]
    range_limits_m: list[tuple[float, float]]
    intensities: list[np.ndarray | None]


def _field(message: Any, name: str, default: Any = None) -> Any:
    if isinstance(message, dict):
        return message.get(name, default)
    return getattr(message, name, default)


def _stamp_s(message: Any, log_time_ns: int) -> float:
    header = _field(message, "header")
    stamp = _field(header, "stamp") if header is not None else _field(message, "timestamp")
    if stamp is not None:
        seconds = _field(stamp, "sec", None)
        seconds = _field(stamp, "seconds", 0) if seconds is None else seconds  # protobuf's Timestamp
        nanoseconds = next((n for n in (_field(stamp, key) for key in ("nanosec", "nsec", "nanos")) if n is not None), 0)
        if seconds or nanoseconds:
            return float(seconds) + float(nanoseconds or 0) * 1e-9
    return log_time_ns * 1e-9


def _scan_geometry(message: Any, count: int) -> tuple[float, float, tuple[float, float]]:
    """(first angle, step, (range_min, range_max)) of a ROS or Foxglove LaserScan."""
    if _field(message, "angle_min") is not None or _field(message, "angle_increment") is not None:
        start, step = float(_field(message, "angle_min", 0.0)), float(_field(message, "angle_increment", 0.0))
        limits = (float(_field(message, "range_min", 0.0) or 0.0), float(_field(message, "range_max", 0.0) or np.inf))
        return start, step, limits
    start, end = float(_field(message, "start_angle", 0.0)), float(_field(message, "end_angle", 0.0))
    return start, (end - start) / (count - 1) if count > 1 else 0.0, (0.0, np.inf)


def read_laser_scans(path: Path, topic: str | None) -> LaserScans:
    """The scans of `topic` (default: the file's only LaserScan topic)."""
    try:
        with open(path, "rb") as file:
            reader = make_reader(file, decoder_factories=[ProtobufDecoderFactory(), Ros2DecoderFactory(), _JsonDecoderFactory()])
            topic = _choose_topic(path, reader, topic)
            messages = ((decoded, message.log_time) for _, _, message, decoded
                        in reader.iter_decoded_messages(topics=[topic], log_time_order=True))
            return laser_scans(path, topic, messages)
    except FileNotFoundError:
        raise UserError(f"no such MCAP file: {path}") from None
    except (McapError, OSError, ValueError, KeyError, TypeError, RuntimeError) as error:
        raise UserError(f"{path.name}: cannot read MCAP: {error}") from None


def laser_scans(path: Path, topic: str, messages: Iterable[tuple[Any, int]]) -> LaserScans:
    """The decoded LaserScans of `topic` (each with its log time in ns), checked and ordered by stamp."""
    times, starts, steps, ranges, limits, intensities = [], [], [], [], [], []
    for decoded, log_time_ns in messages:
        if len(times) >= MAX_MESSAGES:
            raise UserError(f"{path.name}: topic {topic}: more than {MAX_MESSAGES} scans")
        values = np.asarray(_field(decoded, "ranges", ()), dtype=float)
        if not 0 < values.size <= MAX_BEAMS:
            raise UserError(f"{path.name}: topic {topic}: a scan with {values.size} ranges (need 1..{MAX_BEAMS})")
        start, step, limit = _scan_geometry(decoded, values.size)
        if not (np.isfinite(start) and np.isfinite(step)) or (values.size > 1 and step == 0.0):
            raise UserError(f"{path.name}: topic {topic}: a scan without a usable angle step")
        strengths = np.asarray(_field(decoded, "intensities", ()), dtype=float).ravel()
        times.append(_stamp_s(decoded, log_time_ns))
        starts.append(start), steps.append(step), ranges.append(values), limits.append(limit)
        intensities.append(strengths if strengths.size == values.size else None)  # ROS: empty or one per range
    if not times:
        raise UserError(f"{path.name}: topic {topic}: no scans")
    order = np.argsort(np.asarray(times), kind="stable")
    times_s = np.asarray(times)[order]
    return LaserScans(
        topic, times_s - times_s[0], np.asarray(starts)[order], np.asarray(steps)[order],
        [ranges[i] for i in order], [limits[i] for i in order], [intensities[i] for i in order],
    )


def _choose_topic(path: Path, reader: Any, topic: str | None) -> str:
    summary = reader.get_summary()
    if summary is None:
        raise UserError(f"{path.name}: no summary section (an unfinished recording?)")
    scans = sorted(
        channel.topic for channel in summary.channels.values()
        if channel.schema_id in summary.schemas and summary.schemas[channel.schema_id].name in LASERSCAN_SCHEMAS
    )
    if topic is None:
        if len(scans) != 1:
            raise UserError(f"{path.name}: --topic: choose one of the LaserScan topics: {', '.join(scans) or 'none'}")
        return scans[0]
    if topic not in scans:
        raise UserError(f"{path.name}: --topic {topic}: not a LaserScan topic (LaserScan topics: {', '.join(scans) or 'none'})")
    return topic


def _resample(scans: LaserScans, row: int, grid_rad: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
    """Scan `row`'s ranges and (if it has them) intensities on the device's beams: the nearest recorded
    beam within half a recorded step (a beam halfway takes the next one); where the scan does not reach,
    +inf (no echo) and intensity 0."""
    ranges, start, step = scans.ranges_m[row], scans.start_angles_rad[row], scans.steps_rad[row]
    if ranges.size == 1:
        index = np.zeros(len(grid_rad), dtype=np.int64)
        near = np.abs(grid_rad - start) <= 1e-4
    else:
        index = np.floor((grid_rad - start) / step + 0.5).astype(np.int64)  # halves go up
        near = (index >= 0) & (index < ranges.size) & (np.abs(start + index * step - grid_rad) <= abs(step) / 2 + 1e-9)
    resampled = np.full(len(grid_rad), np.inf)
    resampled[near] = ranges[index[near]]
    recorded = scans.intensities[row]
    if recorded is None:
        return resampled, None
    strengths = np.zeros(len(grid_rad))
    strengths[near] = recorded[index[near]]
    return resampled, strengths


def _on_scale(strengths: np.ndarray, largest: int) -> np.ndarray:
    """Recorded intensities on a unit's scale: whole, 0..its largest (a recording holds floats, maybe of
    another unit's scale)."""
    return np.clip(np.rint(np.nan_to_num(strengths)), 0, largest).astype(np.int64)


class LaserScanReplay:
    """A Hokuyo, an LMS200 or a CoLa SICK serving a LaserScan topic (module docstring); answers the
    same calls as the simulated sensors."""

    def __init__(self, scans: LaserScans, model: str, name: str) -> None:
        self.model, self.name = model, name
        self._scans = scans
        self._grids: dict[int, np.ndarray] = {}  # beams → their angles (a CoLa SICK's, per resolution its client sets)
        # a scan resampled as it is first asked for (a long recording is not resampled whole, up front)
        self._on_grid = functools.lru_cache(maxsize=ROWS_KEPT)(self._resampled)
        hokuyo = hokuyo_model(model)
        if model in SICK_MODELS:
            sick = SICK_MODELS[model]
            self._intensity_max = PULSED_RECEIVERS[model].intensity_max
            self._clock = ReplayClock(scans.times_s, FREQUENCY_TICKS_PER_HZ / sick.default[0])
            self.period_s = self._clock.period_s
            self._limits = scans.range_limits_m
            return
        self._intensity_max = INTENSITY_MAX if hokuyo is not None and hokuyo.has_intensity else None
        if hokuyo is not None:
            self._grid = hokuyo.step_angles_rad()
            self.period_s = hokuyo.period_s
        elif model == LMS_MODEL:
            self._grid = np.radians(np.arange(0.0, 180.0 + LMS_GRID_STEP_DEG / 2, LMS_GRID_STEP_DEG) - 90.0)
            self.period_s = LMS_REVOLUTION_S
        else:
            raise UserError(f"unknown model {model!r}")
        self._grids[len(self._grid)] = self._grid
        self._clock = ReplayClock(scans.times_s, self.period_s)
        self._limits = scans.range_limits_m

    def _resampled(self, row: int, beams: int) -> tuple[np.ndarray, np.ndarray | None]:
        """Scan `row` on the grid of `beams` beams: ranges, and intensities on the unit's scale (None: none)."""
        ranges, strengths = _resample(self._scans, row, self._grids[beams])
        return ranges, None if strengths is None or self._intensity_max is None else _on_scale(strengths, self._intensity_max)

    def _row(self, time_s: float, unit: str) -> tuple[np.ndarray, np.ndarray | None]:
        """The device values and intensities of the scan recorded at or before `time_s`, on the device's grid."""
        row = self._clock.row_at(time_s)
        ranges, strengths = self._on_grid(row, len(self._grid))
        return ranges_to_values(ranges, self.model, unit, *self._limits[row]), strengths

    def scan_configuration(self) -> dict[str, float]:
        """A CoLa SICK's scene options: the offered scan configuration nearest the recording's rate and spacing."""
        return cola_scan_configuration(SICK_MODELS[self.model], self.period_s, abs(float(np.degrees(np.median(self._scans.steps_rad)))))

    def scan(self, time_s: float, *, start_deg: float = 0.0, step_deg: float = 0.5, count: int = 361, unit: str = "mm",
             frequency_ticks: int | None = None, resolution_ticks: int | None = None, fog_filter: bool = False) -> Scan:
        if self.model in SICK_MODELS:
            return self._cola_scan(time_s, resolution_ticks)
        if hokuyo_model(self.model) is not None:
            values, intensities = self._row(time_s, "mm")
            return Scan(self.name, self.model, time_s, self._grid, values, "mm", intensities=intensities)
        wanted = np.radians(lms200.device_angles_deg(start_deg, step_deg, count) - 90.0)
        columns = np.clip(np.round((wanted - self._grid[0]) / np.radians(LMS_GRID_STEP_DEG)).astype(np.int64), 0, len(self._grid) - 1)
        values = self._row(time_s, unit)[0][columns]
        values = np.where(np.abs(self._grid[columns] - wanted) <= 1e-6, values, LMS_NO_ECHO)
        return Scan(self.name, self.model, time_s, wanted, values, unit)

    def _cola_scan(self, time_s: float, resolution_ticks: int | None) -> Scan:
        """The whole field at the client's resolution: the recorded range as echo 1 (0 and -1: none), its RSSI."""
        sick = SICK_MODELS[self.model]
        count = sick.beam_count(resolution_ticks or sick.default[1])
        if count not in self._grids:
            self._grids[count] = np.radians(np.linspace(sick.start_deg, sick.stop_deg, count) - 90.0)
        angles = self._grids[count]
        row = self._clock.row_at(time_s)
        ranges, rssi = self._on_grid(row, count)
        values = ranges_to_values(ranges, self.model, "mm", *self._limits[row])
        return first_echo_scan(self.name, sick, time_s, angles, values, rssi if rssi is not None else np.zeros(count, np.int64))

    def scans(self, times_s: Sequence[float], **request: Any) -> list[Scan]:
        return [self.scan(time_s, **request) for time_s in times_s]
