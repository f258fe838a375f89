"""The SICK scanners that speak CoLa over TCP, as their datasheets describe them (docs/cola.md).

One table serves the scene loader (which models and scan configurations a
scene may name), the sensors (field of view, range, echoes, mirror timing)
and the daemon (what it tells a CoLa device about its unit). Angles are the
units' own: 90° straight ahead, counter-clockwise; resolutions and
frequencies in the wire's units (1/10 000 °, 1/100 Hz).
"""

from __future__ import annotations

from dataclasses import dataclass
from types import MappingProxyType
from typing import Mapping

ANGLE_TICKS_PER_DEG = 10_000
FREQUENCY_TICKS_PER_HZ = 100


@dataclass(frozen=True)
class SickModel:
    """One model: `scan_configs` maps a scan frequency (1/100 Hz) to the resolutions
    (1/10 000 °) it offers; `default` is the (frequency, resolution) at power-on."""

    name: str
    family: str  # TiM5xx, TiM7xx, LMS1xx, LMS5xx
    device_ident: str
    firmware_version: str
    start_deg: float
    stop_deg: float
    min_range_m: float
    max_range_m: float
    echoes: int
    distance_scale: float  # mm per distance count on the wire (LMS5xx: 2, its range exceeds 65.5 m)
    scan_configs: Mapping[int, tuple[int, ...]]
    default: tuple[int, int]

    @property
    def field_of_view_deg(self) -> float:
        return self.stop_deg - self.start_deg

    def beam_count(self, resolution_ticks: int) -> int:
        """Points over the whole field at a resolution: 270° at 0.3333° → 811 (the grid is 1/3°)."""
        return int(round(self.field_of_view_deg * ANGLE_TICKS_PER_DEG / resolution_ticks)) + 1

    def offers(self, frequency_ticks: int, resolution_ticks: int) -> bool:
        return resolution_ticks in self.scan_configs.get(frequency_ticks, ())


def _configs(table: dict[int, tuple[int, ...]]) -> Mapping[int, tuple[int, ...]]:
    return MappingProxyType(table)


_TIM_CONFIGS = _configs({1500: (3333,)})  # 15 Hz at 0.33°
MODELS: Mapping[str, SickModel] = MappingProxyType({
    "tim561": SickModel("tim561", "TiM5xx", "TiM5xx", "V3.10", -45.0, 225.0, 0.05, 10.0, 1, 1.0,
                        _TIM_CONFIGS, (1500, 3333)),
    "tim571": SickModel("tim571", "TiM5xx", "TiM5xx", "V3.10", -45.0, 225.0, 0.05, 25.0, 1, 1.0,
                        _TIM_CONFIGS, (1500, 3333)),
    "tim781": SickModel("tim781", "TiM7xx", "TiM7xx", "V1.60", -45.0, 225.0, 0.05, 25.0, 1, 1.0,
                        _TIM_CONFIGS, (1500, 3333)),
    "lms111": SickModel("lms111", "LMS1xx", "LMS1xx", "V1.80", -45.0, 225.0, 0.5, 20.0, 2, 1.0,
                        _configs({2500: (2500,), 5000: (5000,)}), (5000, 5000)),
    "lms511": SickModel("lms511", "LMS5xx", "LMS5xx", "V1.90", -5.0, 185.0, 0.7, 80.0, 5, 2.0,
                        _configs({2500: (1667, 2500, 3333, 5000, 6667, 10000), 3500: (2500, 5000),
                                  5000: (3333, 5000, 6667, 10000), 7500: (5000, 10000), 10000: (6667, 10000)}),
                        (2500, 5000)),
})
NAMES = tuple(MODELS)
