"""The Hokuyo URG-04LX: beam geometry, timing, range limits and error codes.

Steps 0..768 at 2π/1024 rad each, step 384 straight ahead, positive to the
left (SCIP: ARES 1024, AFRT 384). Only steps 44..725 (AMIN..AMAX) are measured;
the others carry `OUTSIDE_VALID_AREA` so a client asking for them gets a
defined value. Error codes (< 20, SCIP spec): 0 no echo ("object possibly at
22 m"), 1 low reflected intensity (smoke), 19 non-measurable distance (closer
than DMIN = 20 mm).
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from emulator.optics import BeamHits, World
from emulator.scene.model import Scene, SensorSpec
from emulator.sensors.mount import SensorMount, cast_moving
from emulator.sensors.response import Beams, response_model, values_at_instants
from emulator.sensors.scan import Scan, simulated_instant

MODEL = "urg-04lx"
STEPS = 769
STEPS_PER_REVOLUTION = 1024
FRONT_STEP = 384
FIRST_VALID_STEP, LAST_VALID_STEP = 44, 725
PERIOD_S = 0.1  # 600 rpm
MAX_RANGE_M = 5.6  # DMAX 5600 mm
MIN_VALUE_MM = 20  # DMIN; values below 20 are error codes

NO_ECHO = 0
LOW_INTENSITY = 1
NON_MEASURABLE = 19
OUTSIDE_VALID_AREA = NO_ECHO


def step_offsets_s() -> np.ndarray:
    """When each step 0..768 is measured, relative to the scan's time stamp (read-only).

    The mirror turns 2π/1024 per step in 100 ms; the scan completes (its time
    stamp) when the last step, 768, is measured, so step s is measured
    (768 − s) · 100 ms / 1024 earlier.
    """
    offsets = (np.arange(STEPS) - (STEPS - 1)) * (PERIOD_S / STEPS_PER_REVOLUTION)
    offsets.flags.writeable = False
    return offsets


def angle_offsets_s(angles_rad: np.ndarray) -> np.ndarray:
    """`step_offsets_s` of the steps at sensor-frame `angles_rad` (a scan's angles, any window)."""
    steps = np.rint(np.asarray(angles_rad) / (2.0 * np.pi / STEPS_PER_REVOLUTION)) + FRONT_STEP
    return (steps - (STEPS - 1)) * (PERIOD_S / STEPS_PER_REVOLUTION)


def step_angles_rad() -> np.ndarray:
    """Sensor-frame angle of every step 0..768 (read-only: shared by every scan)."""
    angles = (np.arange(STEPS) - FRONT_STEP) * (2.0 * np.pi / STEPS_PER_REVOLUTION)
    angles.flags.writeable = False
    return angles


def revolution_phase_ms(scene: Scene, name: str) -> int:
    """When sensor `name`'s revolutions complete, past each 100 ms: the i-th of a scene's n URG-04LX
    turns i × 100 ms / n (whole ms) behind the first. Real units are not powered on in step; a daemon
    serving many then sends their scans spread over the period instead of all at once, and daemons of a
    fleet, given the same scene, agree on every sensor's instants."""
    urgs = [spec.name for spec in scene.sensors if spec.model == MODEL]
    return urgs.index(name) * int(PERIOD_S * 1000) // len(urgs)


class UrgSensor:
    """A simulated URG-04LX: `scan(time_s)` gives the 769 values of steps 0..768."""

    model = MODEL
    period_s = PERIOD_S

    def __init__(self, scene: Scene, spec: SensorSpec, world: World) -> None:
        self.scene, self.spec, self.world = scene, spec, world
        self.name = spec.name
        self.angles_rad = step_angles_rad()
        self._valid = slice(FIRST_VALID_STEP, LAST_VALID_STEP + 1)
        self._valid_angles = self.angles_rad[self._valid]
        self._valid_offsets = step_offsets_s()[self._valid]
        self.mount = SensorMount(scene, spec, world.bodies)
        self._fixed_spec = self.mount.fixed_spec
        self._prepared = None
        if not self.mount.moving:
            self._origins, self._directions = self.mount.fixed_rays(self._valid_angles)
            self._prepared = world.prepare(self._origins, self._directions, MAX_RANGE_M)  # fixed geometry never moves
        self._response = response_model(scene.model)
        self.configured_phase_s = revolution_phase_ms(scene, spec.name) / 1000

    def scan(self, time_s: float) -> Scan:
        """The scan completed at simulated time `time_s` (the world evaluated at that instant)."""
        return self.scans((time_s,))[0]

    def scans(self, times_s: Sequence[float]) -> list[Scan]:
        """`scan` at each of `times_s`, computed together: a preset that can (`physical`)
        shares each pass among them, which costs far less per scan."""
        instants = [simulated_instant(t) for t in times_s]
        casts = self._casts(instants)
        hits, beams = zip(*casts) if casts else ((), ())
        values = np.full((len(instants), STEPS), OUTSIDE_VALID_AREA, dtype=np.int64)
        values[:, self._valid] = values_at_instants(self._response, "urg_values", hits, beams)
        return [Scan(self.name, MODEL, t, self.angles_rad, row, "mm") for t, row in zip(times_s, values)]

    def _casts(self, instants: list[float]) -> list[tuple[BeamHits, Beams]]:
        """The valid steps' hits at each instant, each beam at the instant its step is measured."""
        if self._prepared is None:
            return cast_moving(self.world, self.scene, self.spec, self.mount, self._valid_angles, self._valid_offsets, instants, MAX_RANGE_M)
        casts = []
        for time_s in instants:
            beam_times = time_s + self._valid_offsets
            hits = self.world.cast_prepared(self._prepared, time_s, beam_times)
            beams = Beams(
                self.scene, self._fixed_spec, self.world, time_s, self._valid_angles, self._origins, self._directions,
                beam_times_s=beam_times if self.world.moving else None,  # sub-rays then meet moving solids at their instants
            )
            casts.append((hits, beams))
        return casts

    def configured_scan(self, time_s: float) -> Scan:
        """The same as `scan`: the URG-04LX has one scan (its window is chosen by the protocol)."""
        return self.scan(time_s)

    configured_period_s = PERIOD_S  # scans complete at configured_phase_s + k · period


def ranges_m(values: np.ndarray) -> np.ndarray:
    """Metres per value, NaN for error codes."""
    values = np.asarray(values)
    return np.where(values >= MIN_VALUE_MM, values / 1000.0, np.nan)
