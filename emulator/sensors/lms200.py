"""The Sick LMS200: beam geometry, timing, range limits and error codes.

Device angles run from 0 (right) through 90 (ahead) to 180 (left); the
sensor-frame angle is the device angle − 90°. The mirror turns at 75 Hz; a
0.5° scan interlaces two revolutions, 0.25° four. Values are distances in the
scan's unit (mm or cm); 8183 = value above the mode's maximum, 8191 = no
echo within the sensor's physical reach (80 m) (telegram listing §10.8).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Mapping, Sequence

import numpy as np

from emulator.optics import BeamHits, PreparedBeams, World
from emulator.scene.model import Scene, SensorSpec
from emulator.sensors.mount import SensorMount, cast_moving
from emulator.sensors.response import Beams, response_model, values_at_instants
from emulator.sensors.scan import Scan, simulated_instant

MODEL = "lms200"
PERIOD_S = 1.0 / 75.0  # one mirror revolution
REACH_M = 80.0
UNITS_PER_M = {"mm": 1000.0, "cm": 100.0}
REVOLUTIONS_PER_SCAN = {1.0: 1, 0.5: 2, 0.25: 4}  # interlaced: each revolution measures a 1° grid
ABOVE_MAXIMUM = 8183
NO_ECHO = 8191
# A measuring mode's distance field: 13 bits (8 m in mm, 80 m in cm), 14 (16 m) or 15 (32 m);
# its error codes are the 13-bit ones moved to the top of the field (TL Table 3-7: 1FF7h,
# 3FF7h, 7FF7h = "value above maximum").
FIELD_BITS = (13, 14, 15)
# A value within this of the solid surface's range is that surface's echo (not smoke's):
# a retro-reflective surface there makes it a reflector echo.
REFLECTOR_MATCH_M = 0.1


def field_code(code: int, field_bits: int) -> int:
    """The 13-bit error code `code` (8183..8191) in a `field_bits` wide distance field."""
    return code + (1 << field_bits) - (1 << 13)


def retroreflective_objects(scene: Scene) -> np.ndarray:
    """Per scene object, whether its material is retro-reflective, plus a last False for "nothing hit"."""
    return np.array([scene.materials[obj.material].retroreflective for obj in scene.objects] + [False])


def reflector_echoes(
    retroreflective: np.ndarray, hits: Sequence[BeamHits], values: np.ndarray, unit: str, field_bits: int
) -> np.ndarray:
    """Per scan (one per `hits`, rows of `values` (K, N)) and beam: its value is a distance measured on a
    retro-reflective material (`retroreflective_objects`; the LMS200's reflector bits: the protocol only
    encodes them)."""
    objects = np.concatenate([hit.object_index for hit in hits]).reshape(values.shape)
    solid_range_m = np.concatenate([hit.solid_range_m for hit in hits]).reshape(values.shape)
    index = np.where((objects >= 0) & (objects < len(retroreflective) - 1), objects, -1)
    distance = values < field_code(ABOVE_MAXIMUM, field_bits)
    at_surface = np.abs(values / UNITS_PER_M[unit] - solid_range_m) <= REFLECTOR_MATCH_M
    return retroreflective[index] & distance & at_surface


def device_angles_deg(start_deg: float, step_deg: float, count: int) -> np.ndarray:
    return start_deg + step_deg * np.arange(count)


def beam_offsets_s(device_angles: np.ndarray, step_deg: float) -> np.ndarray:
    """When each device angle of a window is measured, relative to the scan's time stamp (≤ 0).

    The mirror sweeps 360° per revolution (PERIOD_S), the field 0°..180° in its
    first half; an interlaced scan measures the 1° grid shifted by r · step in
    revolution r (0.5°: integer angles first, then the half degrees; 0.25°:
    .0, .25, .5, .75; telegram listing §10.10). The scan completes (its time
    stamp) when the mirror reaches 180° in its last revolution.
    """
    revolutions = REVOLUTIONS_PER_SCAN.get(step_deg, 1)
    revolution = np.rint(np.mod(device_angles, 1.0) / step_deg).astype(np.int64) % revolutions if revolutions > 1 else 0
    offsets = -(revolutions - 1 - revolution) * PERIOD_S - (180.0 - device_angles) / 360.0 * PERIOD_S
    offsets = np.asarray(offsets, dtype=float) * np.ones(len(device_angles))
    offsets.flags.writeable = False
    return offsets


def angle_offsets_s(angles_rad: np.ndarray) -> np.ndarray:
    """`beam_offsets_s` of a scan's sensor-frame `angles_rad` (its resolution read off their spacing)."""
    device_angles = np.round(np.degrees(np.asarray(angles_rad)) + 90.0, 6)
    step = float(np.round(np.min(np.diff(device_angles)), 6)) if len(device_angles) > 1 else 1.0
    return beam_offsets_s(device_angles, step)


@dataclass(frozen=True)
class _Window:
    """A window's sensor-frame angles and measuring offsets (N,); a fixed sensor's beams prepared
    against the fixed geometry (None when the sensor moves: its beams are cast per scan)."""

    angles_rad: np.ndarray
    offsets_s: np.ndarray
    prepared: PreparedBeams | None


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
        self.mount = SensorMount(scene, spec, world.bodies)
        self._fixed_spec = self.mount.fixed_spec
        self._rays: dict[tuple[float, float, int], _Window] = {}
        self._retroreflective = retroreflective_objects(scene)

    def _beams(self, start_deg: float, step_deg: float, count: int) -> _Window:
        """A window's angles, offsets and (fixed sensor) beams prepared against the fixed geometry
        (a device uses few windows, and fixed objects never move: cached)."""
        key = (start_deg, step_deg, count)
        if key not in self._rays:
            device_angles = device_angles_deg(start_deg, step_deg, count)
            angles_rad = np.radians(device_angles - 90.0)
            angles_rad.flags.writeable = False
            prepared = None
            if not self.mount.moving:
                origins, directions = self.mount.fixed_rays(angles_rad)
                prepared = self.world.prepare(origins, directions, REACH_M)
            self._rays[key] = _Window(angles_rad, beam_offsets_s(device_angles, step_deg), prepared)
        return self._rays[key]

    def _casts(self, window: _Window, instants: list[float]) -> list[tuple[BeamHits, Beams]]:
        """The window's hits at each instant, each beam at the instant the mirror measures it."""
        prepared = window.prepared
        if prepared is None:
            return cast_moving(self.world, self.scene, self.spec, self.mount, window.angles_rad, window.offsets_s, instants, REACH_M)
        casts = []
        for time_s in instants:
            beam_times = time_s + window.offsets_s
            hits = self.world.cast_prepared(prepared, time_s, beam_times)
            beams = Beams(
                self.scene, self._fixed_spec, self.world, time_s, window.angles_rad, prepared.origins, prepared.directions,
                beam_times_s=beam_times if self.world.moving else None,  # sub-rays then meet moving solids at their instants
            )
            casts.append((hits, beams))
        return casts

    def scan(
        self, time_s: float, *, start_deg: float = 0.0, step_deg: float = 0.5, count: int = 361, unit: str = "mm",
        field_bits: int = 13,
    ) -> Scan:
        """Values at device angles start_deg + i·step_deg (i < count), in `unit`, at `time_s`."""
        return self.scans(
            (time_s,), start_deg=start_deg, step_deg=step_deg, count=count, unit=unit, field_bits=field_bits
        )[0]

    def scans(
        self,
        times_s: Sequence[float],
        *,
        start_deg: float = 0.0,
        step_deg: float = 0.5,
        count: int = 361,
        unit: str = "mm",
        field_bits: int = 13,
    ) -> list[Scan]:
        """`scan` of one window at each of `times_s`, computed together: a preset that can
        (`physical`) shares each pass among them, which costs far less per scan. `field_bits`:
        the measuring mode's distance field (codes at its top); each scan says which of its
        values are reflector echoes."""
        if unit not in UNITS_PER_M:
            raise ValueError(f"unit must be one of {sorted(UNITS_PER_M)}, got {unit!r}")
        if field_bits not in FIELD_BITS:
            raise ValueError(f"field_bits must be one of {FIELD_BITS}, got {field_bits!r}")
        window = self._beams(start_deg, step_deg, count)
        instants = [simulated_instant(t) for t in times_s]
        casts = self._casts(window, instants)
        hits, beams = zip(*casts) if casts else ((), ())
        values = values_at_instants(self._response, "lms_values", hits, beams, unit, field_bits=field_bits)
        values = values.astype(np.int64, copy=False)
        reflector = reflector_echoes(self._retroreflective, hits, values, unit, field_bits) if hits else values.astype(bool)
        return [Scan(self.name, MODEL, t, window.angles_rad, row, unit, echo) for t, row, echo in zip(times_s, values, reflector)]

    def configured_scan(self, time_s: float) -> Scan:
        """The scan the scene's options select (`configured_window`), at `time_s`."""
        return self.scan(time_s, **configured_window(self.spec.options))

    configured_phase_s = 0.0  # scans complete at k · period

    @property
    def configured_period_s(self) -> float:
        """Time the mirror needs for that scan: 1, 2 or 4 revolutions at 1°, 0.5°, 0.25°."""
        step = configured_window(self.spec.options)["step_deg"]
        return REVOLUTIONS_PER_SCAN[step] * PERIOD_S


def ranges_m(values: np.ndarray, unit: str) -> np.ndarray:
    """Metres per value, NaN for the codes 8183..8191."""
    values = np.asarray(values)
    return np.where(values < ABOVE_MAXIMUM, values / UNITS_PER_M[unit], np.nan)
