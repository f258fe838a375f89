"""Which values a scan holds and when it is complete: variants, the mirror's timeline, line time.

The mirror turns 75 times a second (TL: 13.32 ms) and measures in 1° steps
per revolution: revolution k is complete at k / 75 s of simulated time. A
0.5° scan needs two revolutions and a 0.25° scan four, so scan j of a
variant is complete at j · revolutions / 75 s (consecutive scans use disjoint
revolutions, TL Fig. 10-10).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

REVOLUTIONS_PER_SECOND = 75
BITS_PER_BYTE = 10  # 8N1
TIME_EPSILON_S = 1e-9

# (scanning angle °, resolution 1/100°) → number of values (TL §7.5.2); 180°/0.25° is not allowed.
_VALUE_COUNTS = {(180, 100): 181, (180, 50): 361, (100, 100): 101, (100, 50): 201, (100, 25): 401}
PARTIAL_SCANS = 4  # interlaced mode: offsets 0, .25, .5, .75°


@dataclass(frozen=True)
class Variant:
    """A scanning angle and angular resolution the LMS200 offers (command 3B)."""

    angle_deg: int
    resolution_cdeg: int

    @classmethod
    def of(cls, angle_deg: int, resolution_cdeg: int) -> Variant | None:
        """The variant, or None when the LMS200 does not offer it."""
        return cls(angle_deg, resolution_cdeg) if (angle_deg, resolution_cdeg) in _VALUE_COUNTS else None

    @property
    def count(self) -> int:
        return _VALUE_COUNTS[(self.angle_deg, self.resolution_cdeg)]

    @property
    def start_deg(self) -> float:
        """Device angle of the first value: 0° (right) for 180°, 40° for the 100° variant."""
        return (180 - self.angle_deg) / 2

    @property
    def step_deg(self) -> float:
        return self.resolution_cdeg / 100

    @property
    def revolutions(self) -> int:
        """Mirror revolutions one full scan takes."""
        return 100 // self.resolution_cdeg


def partial_scan_grid(revolution: int) -> tuple[int, float, int]:
    """Interlaced partial scan of a revolution: (partial index, start °, value count).

    The x.00° partial has 181 values (0°…180°), the others 180 (TL §7.5.2).
    """
    partial_index = revolution % PARTIAL_SCANS
    return partial_index, partial_index * 0.25, 181 if partial_index == 0 else 180


def completion_time(index: int, revolutions: int) -> float:
    """When scan `index` of scans `revolutions` long is complete."""
    return index * revolutions / REVOLUTIONS_PER_SECOND


def latest_complete(time_s: float, revolutions: int) -> int:
    """Index of the last scan of `revolutions` complete at `time_s`."""
    return math.floor(time_s * REVOLUTIONS_PER_SECOND / revolutions + TIME_EPSILON_S)


def transmit_seconds(n_bytes: int, baud: int) -> float:
    """How long `n_bytes` occupy a line at `baud`."""
    return n_bytes * BITS_PER_BYTE / baud
