"""The Hokuyo scanners a scene may name, each described by its numbers (docs/scene-format.md, "The Hokuyo models").

Code that differs between them reads these attributes instead of testing a
model's name. Figures: PP replies and the SCIP 2.0 specification C-42-03320B
(step geometry, DMIN/DMAX, error codes: URG-04LX table 3, UTM-30LX table 4);
docs/scip.md cites the sources.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class HokuyoModel:
    """One model: steps 0..steps−1 at 2π/steps_per_turn each, `front_step` straight ahead.

    `stamp_step`: the step measured at the scan's time stamp. The URG-04LX
    stamps the completed revolution (its last step, 768, here); the SCIP 2.2
    units stamp step 0, the start of the sweep ("a timer value at 0th step").
    Values below `min_value_mm` are error codes: `no_echo` (nothing in range),
    `low_intensity` (the echo was too weak: smoke) and `non_measurable`
    (closer than DMIN).
    """

    name: str
    steps: int
    steps_per_turn: int
    front_step: int
    first_valid_step: int
    last_valid_step: int
    period_s: float
    stamp_step: int
    min_value_mm: int
    max_range_m: float
    no_echo: int
    low_intensity: int
    non_measurable: int
    max_echoes: int = 1
    has_intensity: bool = False
    interface: str = "usb"  # "usb": a pty like a USB CDC port; "ethernet": TCP
    default_port: int | None = None

    @property
    def step_rad(self) -> float:
        return 2.0 * math.pi / self.steps_per_turn

    @property
    def valid_steps(self) -> slice:
        return slice(self.first_valid_step, self.last_valid_step + 1)

    @property
    def max_value_mm(self) -> int:
        return int(round(self.max_range_m * 1000.0))

    @property
    def no_return_codes(self) -> tuple[int, ...]:
        """Codes meaning "nothing within range" (shaded as far, not as errors)."""
        return (self.no_echo,)

    def step_angles_rad(self) -> np.ndarray:
        """Sensor-frame angle of every step (read-only: shared by every scan)."""
        angles = (np.arange(self.steps) - self.front_step) * self.step_rad
        angles.flags.writeable = False
        return angles

    def step_offsets_s(self) -> np.ndarray:
        """When each step is measured relative to the scan's stamp (read-only)."""
        offsets = (np.arange(self.steps) - self.stamp_step) * (self.period_s / self.steps_per_turn)
        offsets.flags.writeable = False
        return offsets

    def angle_offsets_s(self, angles_rad: np.ndarray) -> np.ndarray:
        """`step_offsets_s` of the steps at sensor-frame `angles_rad` (any window of a scan)."""
        steps = np.rint(np.asarray(angles_rad) / self.step_rad) + self.front_step
        return (steps - self.stamp_step) * (self.period_s / self.steps_per_turn)

    def ranges_m(self, values: np.ndarray) -> np.ndarray:
        """Metres per value, NaN for error codes."""
        values = np.asarray(values)
        return np.where(values >= self.min_value_mm, values / 1000.0, np.nan)


URG_04LX = HokuyoModel(
    "urg-04lx", steps=769, steps_per_turn=1024, front_step=384, first_valid_step=44, last_valid_step=725,
    period_s=0.1, stamp_step=768, min_value_mm=20, max_range_m=5.6, no_echo=0, low_intensity=1, non_measurable=19,
)
# SCIP 2.2 units: 1081 steps of 0.25°, 25 ms a revolution; UTM-30LX error codes (spec table 4):
# 1 no object in range, 2 object too near, 3 measurement error (the weak echo of smoke).
_WIDE = dict(
    steps=1081, steps_per_turn=1440, front_step=540, first_valid_step=0, last_valid_step=1080,
    period_s=0.025, stamp_step=0, no_echo=1, low_intensity=3, non_measurable=2, has_intensity=True,
)
UTM_30LX = HokuyoModel("utm-30lx", **_WIDE, min_value_mm=23, max_range_m=60.0)
UTM_30LX_EW = HokuyoModel(
    "utm-30lx-ew", **_WIDE, min_value_mm=23, max_range_m=60.0, max_echoes=3, interface="ethernet", default_port=10940
)
UST_10LX = HokuyoModel(
    "ust-10lx", **_WIDE, min_value_mm=20, max_range_m=30.0, max_echoes=3, interface="ethernet", default_port=10940
)
UST_20LX = HokuyoModel(
    "ust-20lx", **_WIDE, min_value_mm=20, max_range_m=60.0, max_echoes=3, interface="ethernet", default_port=10940
)  # fmt: skip

HOKUYO_MODELS: dict[str, HokuyoModel] = {model.name: model for model in (URG_04LX, UTM_30LX, UTM_30LX_EW, UST_10LX, UST_20LX)}
