"""Sensor-like objects that serve the scans of a recorded log instead of the simulation.

They answer the same calls as the simulated sensors (`UrgSensor.scan(t)`,
`LmsSensor.scan(t, start_deg=…, step_deg=…, count=…, unit=…)`), so the daemon
and the protocol devices cannot tell them apart.

Timing: simulated time 0 is the log's first scan, and the scan served at time t
is the last one recorded at or before it, so the log plays at its recorded
rate. At the end the log loops: it starts over one recorded period after its
last scan, so a driver that stays connected keeps receiving scans.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from emulator.errors import UserError
from emulator.recording.textlog import Log
from emulator.scene.sick_models import ANGLE_TICKS_PER_DEG, FREQUENCY_TICKS_PER_HZ, SickModel
from emulator.scene.sick_models import MODELS as SICK_MODELS
from emulator.sensors.hokuyo_models import HOKUYO_MODELS, URG_04LX, HokuyoModel
from emulator.sensors.scan import Scan

URG_MODEL = "urg-04lx"
LMS_MODEL = "lms200"
MODELS = (*HOKUYO_MODELS, LMS_MODEL, *SICK_MODELS)

URG_STEPS = 769
URG_FRONT_STEP = 384
URG_STEP_RAD = 2.0 * np.pi / 1024.0
URG_PERIOD_S = 0.1
URG_NO_ECHO = 0  # a step the log does not cover: "no object in range"

LMS_REVOLUTION_S = 1.0 / 75.0
LMS_NO_ECHO = 8191  # a device angle the log does not cover
LMS_FIRST_CODE = 8183  # 8183..8191 are codes, not distances
ANGLE_TOLERANCE_RAD = 1e-4  # a log angle matches a beam within this (logs keep 6 decimals)


class ReplayClock:
    """Maps simulated time to a row of a recording (its scan times), looping at the end."""

    def __init__(self, times: np.ndarray, default_period_s: float) -> None:
        self._times = times - times[0]
        period = float(np.median(np.diff(times))) if len(times) > 1 else default_period_s
        self.period_s = period
        self._span = self._times[-1] + period

    def row_at(self, time_s: float) -> int:
        offset = float(np.mod(time_s, self._span))
        # A millisecond's slack: log timestamps are rounded to 1 ms.
        return max(0, int(np.searchsorted(self._times, offset + 5e-4, side="right")) - 1)


class HokuyoReplay:
    """A Hokuyo serving a log's scans: one value per step (a step the log lacks: "no object in range")."""

    def __init__(self, log: Log, name: str = "urg", model: HokuyoModel = URG_04LX) -> None:
        _check_model(log, model.name)
        steps = np.round(log.angles_rad / model.step_rad).astype(np.int64) + model.front_step
        off_grid = np.abs((steps - model.front_step) * model.step_rad - log.angles_rad) > ANGLE_TOLERANCE_RAD
        if np.any(off_grid) or np.any((steps < 0) | (steps >= model.steps)):
            raise UserError(
                f"log angles are not {model.name} steps (0..{model.steps - 1}, 2π/{model.steps_per_turn} rad apart,"
                f" 0 = step {model.front_step})"
            )
        self.name, self.model, self.period_s = name, model.name, model.period_s
        self._clock = ReplayClock(log.times_s, model.period_s)
        self._values = np.full((len(log.values), model.steps), model.no_echo, dtype=np.int64)
        np.put_along_axis(self._values, steps, log.values, axis=1)
        self._angles = model.step_angles_rad()

    def scan(self, time_s: float) -> Scan:
        values = self._values[self._clock.row_at(time_s)]
        return Scan(self.name, self.model, time_s, self._angles, values.copy(), "mm")

    def scans(self, times_s: Sequence[float]) -> list[Scan]:
        """`scan` at each of `times_s` (a table look-up each: nothing to share)."""
        return [self.scan(time_s) for time_s in times_s]


class LmsReplay:
    """An LMS200 serving a log's scans for any requested window of device angles.

    Device angle = sensor-frame angle + 90° (0° = right, 180° = left). A requested
    angle the log does not hold gets 8191 (no echo); distances are converted
    between the log's unit and the requested one, codes 8183..8191 pass unchanged.
    """

    model = LMS_MODEL
    period_s = LMS_REVOLUTION_S

    def __init__(self, log: Log, name: str = "lms") -> None:
        _check_model(log, LMS_MODEL)
        if log.header.unit not in ("mm", "cm"):
            raise UserError(f"log unit {log.header.unit!r}: an LMS200 log is in mm or cm")
        self.name = name
        self._clock = ReplayClock(log.times_s, 2 * LMS_REVOLUTION_S)
        self._unit = log.header.unit
        self._angles = log.angles_rad[0]
        if np.any(np.abs(log.angles_rad - self._angles) > ANGLE_TOLERANCE_RAD):
            raise UserError("an LMS200 log must use the same angles on every line")
        if len(self._angles) < 2 or np.any(np.diff(self._angles) <= 0):
            raise UserError("an LMS200 log needs at least two angles, increasing from right to left")
        self._values = log.values

    def scan(
        self, time_s: float, *, start_deg: float = 0.0, step_deg: float = 0.5,
        count: int = 361, unit: str = "mm", field_bits: int = 13,
    ) -> Scan:
        wanted = np.radians(start_deg + step_deg * np.arange(count) - 90.0)
        nearest = np.clip(np.searchsorted(self._angles, wanted), 1, len(self._angles) - 1)
        left_closer = np.abs(self._angles[nearest - 1] - wanted) <= np.abs(self._angles[nearest] - wanted)
        nearest = np.where(left_closer, nearest - 1, nearest)
        found = np.abs(self._angles[nearest] - wanted) <= ANGLE_TOLERANCE_RAD
        recorded = _convert_unit(self._values[self._clock.row_at(time_s)][nearest], self._unit, unit)
        values = np.where(found, recorded, LMS_NO_ECHO)
        # a wider measuring-mode field keeps the distances; its codes sit at its top
        values = np.where(values >= LMS_FIRST_CODE, values + (1 << field_bits) - (1 << 13), values)
        return Scan(self.name, self.model, time_s, wanted, values, unit)

    def scans(
        self, times_s: Sequence[float], *, start_deg: float = 0.0, step_deg: float = 0.5,
        count: int = 361, unit: str = "mm", field_bits: int = 13,
    ) -> list[Scan]:
        """`scan` of one window at each of `times_s` (a table look-up each: nothing to share)."""
        return [
            self.scan(t, start_deg=start_deg, step_deg=step_deg, count=count, unit=unit, field_bits=field_bits)
            for t in times_s
        ]


class ColaReplay:
    """A CoLa SICK serving a log's scans (first-echo distance counts, 0 = no echo) as its one echo.

    The log's angles are the unit's own grid at the recorded resolution; a client that asks for another
    scan configuration gets, per beam of its grid, the recorded beam at that angle (none within
    ANGLE_TOLERANCE_RAD: no echo).
    """

    def __init__(self, log: Log, name: str, model: SickModel) -> None:
        _check_model(log, model.name)
        self.name, self.model, self._sick = name, model.name, model
        self._angles = log.angles_rad[0]
        if np.any(np.abs(log.angles_rad - self._angles) > ANGLE_TOLERANCE_RAD):
            raise UserError(f"a {model.name} log must use the same angles on every line")
        if len(self._angles) < 2 or np.any(np.diff(self._angles) <= 0):
            raise UserError(f"a {model.name} log needs at least two angles, increasing from right to left")
        self._clock = ReplayClock(log.times_s, FREQUENCY_TICKS_PER_HZ / model.default[0])
        self.period_s = self._clock.period_s
        self._values = log.values

    def scan_configuration(self) -> dict[str, float]:
        """The scene options of the offered scan configuration nearest the log's rate and spacing."""
        return cola_scan_configuration(self._sick, self.period_s, float(np.median(np.diff(np.degrees(self._angles)))))

    def scan(self, time_s: float, *, frequency_ticks: int | None = None, resolution_ticks: int | None = None,
             fog_filter: bool = False) -> Scan:
        sick = self._sick
        count = sick.beam_count(resolution_ticks or sick.default[1])
        wanted = np.radians(np.linspace(sick.start_deg, sick.stop_deg, count) - 90.0)
        nearest = np.clip(np.searchsorted(self._angles, wanted), 1, len(self._angles) - 1)
        left_closer = np.abs(self._angles[nearest - 1] - wanted) <= np.abs(self._angles[nearest] - wanted)
        nearest = np.where(left_closer, nearest - 1, nearest)
        found = np.abs(self._angles[nearest] - wanted) <= ANGLE_TOLERANCE_RAD
        values = np.where(found, self._values[self._clock.row_at(time_s)][nearest], 0)
        return first_echo_scan(self.name, sick, time_s, wanted, values, np.zeros(count, np.int64))

    def scans(self, times_s: Sequence[float], **request: object) -> list[Scan]:
        """`scan` at each of `times_s` (a table look-up each: nothing to share)."""
        return [self.scan(t, **request) for t in times_s]


def cola_scan_configuration(sick: SickModel, period_s: float, step_deg: float) -> dict[str, float]:
    """The scene options of the scan configuration `sick` offers nearest a recording's period and beam spacing."""
    resolution_ticks = step_deg * ANGLE_TICKS_PER_DEG
    pairs = [(f, r) for f, resolutions in sick.scan_configs.items() for r in resolutions]
    frequency, resolution = min(pairs, key=lambda pair: (abs(FREQUENCY_TICKS_PER_HZ / pair[0] - period_s),
                                                        abs(pair[1] - resolution_ticks)))
    return {"scan_frequency_hz": frequency / FREQUENCY_TICKS_PER_HZ, "resolution_deg": resolution / ANGLE_TICKS_PER_DEG}


def first_echo_scan(name: str, sick: SickModel, time_s: float, angles: np.ndarray, values: np.ndarray,
                    strengths: np.ndarray) -> Scan:
    """A CoLa SICK's scan of recorded distance counts (0: no echo): each its beam's one echo, with its RSSI."""
    strengths = np.where(values > 0, strengths, 0)
    echoes = np.full((len(values), sick.echoes), -1, np.int64)
    echoes[:, 0] = np.where(values > 0, values, -1)
    powers = np.where(echoes >= 0, 0, -1)
    powers[:, 0] = np.where(values > 0, strengths, -1)
    return Scan(name, sick.name, time_s, angles, values, "mm", None, strengths, echoes, powers)


def _convert_unit(values: np.ndarray, from_unit: str, to_unit: str) -> np.ndarray:
    if from_unit == to_unit:
        return values
    is_code = values >= LMS_FIRST_CODE
    if to_unit == "cm":
        converted = np.round(values / 10.0).astype(np.int64)
    else:
        converted = np.minimum(values * 10, LMS_FIRST_CODE)
    return np.where(is_code, values, converted)


def _check_model(log: Log, model: str) -> None:
    if log.header.model and log.header.model != model:
        raise UserError(f"the log was recorded from a {log.header.model}, not a {model}")


def replay_sensor(log: Log, model: str, name: str) -> HokuyoReplay | LmsReplay | ColaReplay:
    """The replaying sensor for `model` (a Hokuyo's, "lms200" or a CoLa SICK's)."""
    if model in SICK_MODELS:
        _check_wire_values(log, model, COLA_MAX_VALUE)
        return ColaReplay(log, name, SICK_MODELS[model])
    if model in HOKUYO_MODELS:
        _check_wire_values(log, model, SCIP_MAX_VALUE)
        return HokuyoReplay(log, name, HOKUYO_MODELS[model])
    if model == LMS_MODEL:
        _check_wire_values(log, model, LMS_MAX_VALUE)
        return LmsReplay(log, name)
    raise UserError(f"unknown model {model!r} (use {' or '.join(MODELS)})")


# The largest value each protocol's scans carry: a SCIP 3-character value (18 bits), the LMS200's
# 13-bit distance field (codes 8183..8191 on top), a CoLa 16-bit DIST channel. A log holding more was
# clamped or masked on the wire without a word.
SCIP_MAX_VALUE = (1 << 18) - 1
LMS_MAX_VALUE = (1 << 13) - 1
COLA_MAX_VALUE = 0xFFFF


def _check_wire_values(log: Log, model: str, most: int) -> None:
    too_large = log.values > most
    if too_large.any():
        row = int(too_large.any(axis=1).argmax())
        value = int(log.values[row][too_large[row]][0])
        raise UserError(f"the log's scan at {log.times_s[row]:g} s holds the value {value}; a {model} sends at most {most}")
