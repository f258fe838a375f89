"""The Sick LMS200: beam geometry, timing, range limits and error codes.

Device angles run from 0 (right) through 90 (ahead) to 180 (left); the
sensor-frame angle is the device angle − 90°. The mirror turns at 75 Hz; a
0.5° scan interlaces two revolutions, 0.25° four. Values are distances in the
scan's unit (mm or cm); 8183 = value above the mode's maximum, 8191 = no
echo within the sensor's physical reach (80 m) (telegram listing §10.8).
"""

from __future__ import annotations

from typing import Any, Mapping, Sequence

import numpy as np

from emulator.optics import PreparedBeams, World
from emulator.scene.model import Scene, SensorSpec
from emulator.sensors.beam_geometry import scan_plane_rays
from emulator.sensors.response import Beams, response_model, values_at_instants
from emulator.sensors.scan import Scan, simulated_instant

MODEL = "lms200"
PERIOD_S = 1.0 / 75.0  # one mirror revolution
REACH_M = 80.0
UNITS_PER_M = {"mm": 1000.0, "cm": 100.0}
REVOLUTIONS_PER_SCAN = {1.0: 1, 0.5: 2, 0.25: 4}  # interlaced: each revolution measures a 1° grid
ABOVE_MAXIMUM = 8183
NO_ECHO = 8191


def device_angles_deg(start_deg: float, step_deg: float, count: int) -> np.ndarray:
    return start_deg + step_deg * np.arange(count)


def configured_window(options: Mapping[str, Any]) -> dict[str, Any]:
    """The `scan` keywords for the scan the scene's options select (angle_deg, resolution_deg,
    units): e.g. 100° at 1° → device angles 40°..140°, 101 values."""
    angle = float(options.get("angle_deg", 180))
    step = float(options.get("resolution_deg", 0.5))
    return {
        "start_deg": (180.0 - angle) / 2.0,
        "step_deg": step,
        "count": int(round(angle / step)) + 1,
        "unit": str(options.get("units", "mm")),
    }


class LmsSensor:
    """A simulated LMS200: `scan(time_s, ...)` gives values for any device-angle grid."""

    model = MODEL
    period_s = PERIOD_S

    def __init__(self, scene: Scene, spec: SensorSpec, world: World) -> None:
        self.scene, self.spec, self.world = scene, spec, world
        self.name = spec.name
        self._response = response_model(scene.model)
        self._rays: dict[tuple[float, float, int], tuple[np.ndarray, PreparedBeams]] = {}

    def _beams(self, start_deg: float, step_deg: float, count: int) -> tuple[np.ndarray, PreparedBeams]:
        """Sensor-frame angles of a window and its beams prepared against the fixed geometry
        (a device uses few windows, and objects never move: cached)."""
        key = (start_deg, step_deg, count)
        if key not in self._rays:
            angles_rad = np.radians(device_angles_deg(start_deg, step_deg, count) - 90.0)
            angles_rad.flags.writeable = False
            origins, directions = scan_plane_rays(self.spec.pose, angles_rad)
            self._rays[key] = (angles_rad, self.world.prepare(origins, directions, REACH_M))
        return self._rays[key]

    def scan(
        self, time_s: float, *, start_deg: float = 0.0, step_deg: float = 0.5, count: int = 361, unit: str = "mm"
    ) -> Scan:
        """Values at device angles start_deg + i·step_deg (i < count), in `unit`, at `time_s`."""
        return self.scans((time_s,), start_deg=start_deg, step_deg=step_deg, count=count, unit=unit)[0]

    def scans(
        self,
        times_s: Sequence[float],
        *,
        start_deg: float = 0.0,
        step_deg: float = 0.5,
        count: int = 361,
        unit: str = "mm",
    ) -> list[Scan]:
        """`scan` of one window at each of `times_s`, computed together: a preset that can
        (`physical`) shares each pass among them, which costs far less per scan."""
        if unit not in UNITS_PER_M:
            raise ValueError(f"unit must be one of {sorted(UNITS_PER_M)}, got {unit!r}")
        angles_rad, prepared = self._beams(start_deg, step_deg, count)
        instants = [simulated_instant(t) for t in times_s]
        hits = [self.world.cast_prepared(prepared, t) for t in instants]
        beams = [Beams(self.scene, self.spec, self.world, t, angles_rad, prepared.origins, prepared.directions) for t in instants]
        values = values_at_instants(self._response, "lms_values", hits, beams, unit).astype(np.int64, copy=False)
        return [Scan(self.name, MODEL, t, angles_rad, row, unit) for t, row in zip(times_s, values)]

    def configured_scan(self, time_s: float) -> Scan:
        """The scan the scene's options select (`configured_window`), at `time_s`."""
        return self.scan(time_s, **configured_window(self.spec.options))

    @property
    def configured_period_s(self) -> float:
        """Time the mirror needs for that scan: 1, 2 or 4 revolutions at 1°, 0.5°, 0.25°."""
        step = configured_window(self.spec.options)["step_deg"]
        return REVOLUTIONS_PER_SCAN[step] * PERIOD_S


def ranges_m(values: np.ndarray, unit: str) -> np.ndarray:
    """Metres per value, NaN for the codes 8183..8191."""
    values = np.asarray(values)
    return np.where(values < ABOVE_MAXIMUM, values / UNITS_PER_M[unit], np.nan)
