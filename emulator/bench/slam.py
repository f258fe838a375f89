"""SLAM end to end with real tools: serve → rawlog-grabber → icp-slam → trajectory error.

`record` starts the real `serve` process, lets MRPT's `rawlog-grabber` record
a URG-04LX through its unmodified `CHokuyoURG` driver over a pty, and maps
every scan of the log to the simulated instant it was measured at; `slam`
runs MRPT's `icp-slam` on the log and compares its path with the sensor's
ground-truth pose at those instants (`trajectory.absolute_trajectory_error`).

Time stamps. CHokuyoURG stamps its first 10 scans with the wall clock on
arrival; from the 11th on it stamps `wall(11th) + (device_ms - device_ms(11th))`,
so later stamps differ exactly as the device's millisecond timer, which runs
on simulated time (protocols/scip: scan k completes at k / 10 s, timer 0 at
simulated 0). One constant remains: which scan the 11th was. The device's own
timer, read with `II` over the same sensor's TCP endpoint while the grabber
records (`read_device_clock`), maps wall time to simulated time to a fraction
of a millisecond. CHokuyoURG reads the serial port in 128-byte blocks with a
100 ms gap timeout, so it completes a scan's message, and stamps it, when the
next message starts to arrive (or the gap times out): one period after the scan
completed, plus the link's latency (measured: 1-3 ms). Each of the first 11
arrivals therefore bounds the 11th scan's index from above (the device streams
every scan: the 11th is the 1st + 10), and the tightest bound, less that one
period, is its index; a driver that starts behind and reads buffered scans late
only loosens the other bounds. tests/interop/test_mrpt_icp_slam.py checks the
rule scan by scan against a scene whose every scan differs from the next.
Scans before the 11th have no simulated time and are left out.
"""

from __future__ import annotations

import re
import socket
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from emulator.bench.mrpt import ExportedScans, MrptError, export_2d_scans, grab, icp_slam
from emulator.bench.serve_process import ServeProcess
from emulator.bench.trajectory import TrajectoryError, absolute_trajectory_error
from emulator.plots.map import sensor_poses_2d
from emulator.scene import Scene, load_scene

SCAN_PERIOD_S = 0.1  # URG-04LX: 600 rpm
SYNCED_FROM = 10  # CHokuyoURG's MINIMUM_PACKETS_TO_SET_TIMESTAMP_REFERENCE
ERROR_CODE_BELOW_M = 0.020  # URG values < 20 are error codes (docs/scip.md)
DRIVER_LAG_SCANS = 1  # CHokuyoURG stamps a scan when the next one starts to arrive (module docstring)
GRID_SLACK = 0.05  # of a period: a scan is never received before it completes, at most this early by the anchor's error


@dataclass(frozen=True)
class ClockAnchor:
    """Wall clock (Unix seconds) at simulated time 0, and simulated seconds per wall second."""

    wall_at_zero_s: float
    speed: float
    round_trip_s: float  # of the best II exchange: the anchor's uncertainty

    def simulated(self, wall_s: np.ndarray | float) -> np.ndarray | float:
        return (np.asarray(wall_s) - self.wall_at_zero_s) * self.speed


def read_device_clock(address: tuple[str, int], speed: float, samples: int = 7) -> ClockAnchor:
    """Anchor wall to simulated time with the device's timer (`II`'s TIME field, hex ms): the
    exchange with the shortest round trip wins, its timer read taken at the round trip's middle."""
    best: ClockAnchor | None = None
    with socket.create_connection(address, timeout=5.0) as link:
        for _ in range(samples):
            sent = time.time()
            link.sendall(b"II\n")
            reply = b""
            while not reply.endswith(b"\n\n"):
                chunk = link.recv(4096)
                if not chunk:
                    raise MrptError(f"{address}: connection closed during II")
                reply += chunk
            received = time.time()
            found = re.search(rb"TIME:([0-9A-Fa-f]{6});", reply)
            if found is None:
                raise MrptError(f"{address}: no TIME in the II reply {reply[:200]!r}")
            timer_s = int(found.group(1), 16) / 1000.0
            anchor = ClockAnchor((sent + received) / 2 - timer_s / speed, speed, received - sent)
            if best is None or anchor.round_trip_s < best.round_trip_s:
                best = anchor
            time.sleep(0.01)
    assert best is not None
    return best


def simulated_times(stamps_s: np.ndarray, anchor: ClockAnchor) -> np.ndarray:
    """Each scan's simulated completion time (NaN before CHokuyoURG synchronises its stamps).

    Scan j <= 10 was stamped (wall clock) at least a period after it completed,
    so the 11th scan's index is at most the last grid instant before j's stamp,
    less one, plus 10 - j; the tightest of these bounds is its index. Later scans
    follow by the device's own timer differences."""
    stamps_s = np.asarray(stamps_s, dtype=float)
    times = np.full(len(stamps_s), np.nan)
    if len(stamps_s) <= SYNCED_FROM:
        return times
    synced = stamps_s[SYNCED_FROM]
    arrivals = np.asarray(anchor.simulated(stamps_s[: SYNCED_FROM + 1]))
    bounds = np.floor(arrivals / SCAN_PERIOD_S + GRID_SLACK) + (SYNCED_FROM - np.arange(SYNCED_FROM + 1))
    index = int(bounds.min()) - DRIVER_LAG_SCANS
    offsets = np.rint((stamps_s[SYNCED_FROM:] - synced) * 1000.0) / 1000.0  # whole device milliseconds
    times[SYNCED_FROM:] = index * SCAN_PERIOD_S + offsets
    return times


@dataclass(frozen=True)
class Recording:
    """A rawlog of one sensor and each of its scans' simulated time."""

    rawlog: Path
    scans: ExportedScans
    times_s: np.ndarray  # NaN for the scans before the driver synchronised
    anchor: ClockAnchor

    @property
    def error_share(self) -> float:
        """Share of the synchronised scans' beams that carry an error code."""
        kept = ~np.isnan(self.times_s)
        return float(np.mean(self.scans.ranges_m[kept] < ERROR_CODE_BELOW_M))


def record(
    scene: str | Path, sensor: str, folder: Path, *, until_s: float, speed: float = 1.0,
    serve_args: tuple[str, ...] = (),
) -> Recording:
    """Serve `scene` at `speed`, record `sensor` (a URG-04LX) with rawlog-grabber over a pty until
    simulated time `until_s`, and time every scan."""
    folder.mkdir(parents=True, exist_ok=True)
    others = [f"{spec.name}=pty:{folder / spec.name}" for spec in load_scene(scene).sensors if spec.name != sensor]
    endpoints = [f"{sensor}=pty:{folder / 'ttyURG'}", f"{sensor}=tcp:127.0.0.1:0", *others]
    with ServeProcess(scene, endpoints, extra_args=("--speed", repr(speed), *serve_args)) as daemon:
        anchor = read_device_clock(daemon.endpoint(sensor, "tcp").address, speed)
        section = (
            "[URG]\ndriver = CHokuyoURG\nprocess_rate = 90\nsensorLabel = URG\n"
            f"COM_port_LIN = {daemon.endpoint(sensor, 'pty').path}\n"
        )
        wall_end = anchor.wall_at_zero_s + until_s / speed
        grabbed = grab(folder / "grab", section, until=lambda _saved: time.time() >= wall_end,
                       timeout_s=until_s / speed + 30.0)
    if grabbed.returncode != 0 or grabbed.rawlog is None:
        raise MrptError(f"rawlog-grabber failed ({grabbed.returncode}):\n{grabbed.output[-3000:]}")
    scans = export_2d_scans(grabbed.rawlog, "URG")
    return Recording(grabbed.rawlog, scans, simulated_times(scans.times_s, anchor), anchor)


@dataclass(frozen=True)
class SlamRun:
    """icp-slam's path beside the truth, over the synchronised scans."""

    recording: Recording
    times_s: np.ndarray  # (n,) simulated
    truth: np.ndarray  # (n, 3)
    estimate: np.ndarray  # (n, 3) icp-slam's, in its own frame
    error: TrajectoryError
    map_points: np.ndarray  # (m, 2) icp-slam's final map, moved into the world frame


def slam(recording: Recording, scene: Scene, sensor: str, folder: Path, *, start_s: float | None = None) -> SlamRun:
    """icp-slam on the recording (from its first scan at or after simulated `start_s`, if given:
    the same input however long the driver took to start); its path aligned onto the ground truth."""
    timed = ~np.isnan(recording.times_s)
    if timed.sum() < 2:
        raise MrptError(f"only {timed.sum()} synchronised scans in {recording.rawlog}")
    skip = 0
    if start_s is not None:
        later = np.flatnonzero(timed & (np.nan_to_num(recording.times_s, nan=-np.inf) >= start_s - 1e-6))
        if len(later) < 2 or recording.times_s[later[0]] > start_s + SCAN_PERIOD_S / 2:
            first = recording.times_s[timed][0]
            raise MrptError(f"the recording's first timed scan is at {first:.1f} s, after the start asked ({start_s} s)")
        skip = int(later[0])
    result = icp_slam(recording.rawlog, folder / "icp-slam", skip=skip)
    times_s = recording.times_s[skip:]
    if len(result.path) != len(times_s):
        raise MrptError(f"icp-slam wrote {len(result.path)} poses for {len(times_s)} scans")
    kept = ~np.isnan(times_s)
    times = times_s[kept]
    truth = sensor_poses_2d(scene, sensor, times)
    error = absolute_trajectory_error(result.path[kept], truth)
    transform = error.transform
    map_points = result.map_points @ transform.rotation.T + transform.translation
    return SlamRun(recording, times, truth, result.path[kept], error, map_points)
