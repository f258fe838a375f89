"""The Hokuyo URG-04LX: beam geometry, timing, range limits and error codes.

Steps 0..768 at 2π/1024 rad each, step 384 straight ahead, positive to the
left (SCIP: ARES 1024, AFRT 384). Only steps 44..725 (AMIN..AMAX) are measured;
the others carry `OUTSIDE_VALID_AREA` so a client asking for them gets a
defined value. Error codes (< 20, SCIP spec): 0 no echo ("object possibly at
22 m"), 1 low reflected intensity (smoke), 19 non-measurable distance (closer
than DMIN = 20 mm). The numbers live in `hokuyo_models.URG_04LX`; the sensor is
`hokuyo.HokuyoSensor`.
"""

from __future__ import annotations

import numpy as np

from emulator.optics import World
from emulator.scene.model import Scene, SensorSpec
from emulator.sensors import hokuyo
from emulator.sensors.hokuyo_models import URG_04LX

MODEL = URG_04LX.name
STEPS = URG_04LX.steps
STEPS_PER_REVOLUTION = URG_04LX.steps_per_turn
FRONT_STEP = URG_04LX.front_step
FIRST_VALID_STEP, LAST_VALID_STEP = URG_04LX.first_valid_step, URG_04LX.last_valid_step
PERIOD_S = URG_04LX.period_s  # 600 rpm
MAX_RANGE_M = URG_04LX.max_range_m  # DMAX 5600 mm
MIN_VALUE_MM = URG_04LX.min_value_mm  # DMIN; values below 20 are error codes

NO_ECHO = URG_04LX.no_echo
LOW_INTENSITY = URG_04LX.low_intensity
NON_MEASURABLE = URG_04LX.non_measurable
OUTSIDE_VALID_AREA = NO_ECHO


def step_offsets_s() -> np.ndarray:
    """When each step 0..768 is measured, relative to the scan's time stamp (read-only).

    The mirror turns 2π/1024 per step in 100 ms; the scan completes (its time
    stamp) when the last step, 768, is measured, so step s is measured
    (768 − s) · 100 ms / 1024 earlier.
    """
    return URG_04LX.step_offsets_s()


def angle_offsets_s(angles_rad: np.ndarray) -> np.ndarray:
    """`step_offsets_s` of the steps at sensor-frame `angles_rad` (a scan's angles, any window)."""
    return URG_04LX.angle_offsets_s(angles_rad)


def step_angles_rad() -> np.ndarray:
    """Sensor-frame angle of every step 0..768 (read-only: shared by every scan)."""
    return URG_04LX.step_angles_rad()


def revolution_phase_ms(scene: Scene, name: str) -> int:
    """The i-th of a scene's n URG-04LX turns i × 100 ms / n (whole ms) behind the first."""
    return hokuyo.revolution_phase_ms(scene, name, URG_04LX)


class UrgSensor(hokuyo.HokuyoSensor):
    """A simulated URG-04LX: `scan(time_s)` gives the 769 values of steps 0..768."""

    model = MODEL
    period_s = PERIOD_S
    configured_period_s = PERIOD_S  # scans complete at configured_phase_s + k · period

    def __init__(self, scene: Scene, spec: SensorSpec, world: World) -> None:
        super().__init__(scene, spec, world, URG_04LX)


def ranges_m(values: np.ndarray) -> np.ndarray:
    """Metres per value, NaN for error codes."""
    return URG_04LX.ranges_m(values)
