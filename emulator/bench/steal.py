"""How much of the machine's CPU time its hypervisor took for others during a measuring window.

On a virtual machine the host may run other guests on the same physical cores; the time this
guest's vCPUs were ready but not running is counted in /proc/stat as `steal`. A timing figure
taken while steal was high measures the host, not the daemon (on the build machine a quiet load
average has come with 15-37 % steal), so each bench row that times a stream reports the share of
CPU time stolen over its window beside the load average.
"""

from __future__ import annotations

import math
from pathlib import Path

PROC_STAT = Path("/proc/stat")
# /proc/stat's aggregate "cpu" line: user nice system idle iowait irq softirq steal guest guest_nice
# (guest time is already counted in user and nice, so it is left out of the total).
STEAL_FIELD = 7
COUNTED_FIELDS = 8


def cpu_ticks(stat_text: str) -> tuple[int, int]:
    """(all ticks, stolen ticks) of the aggregate `cpu` line of a /proc/stat text; (0, 0) if it has none
    (not Linux, or a kernel without the steal field)."""
    for line in stat_text.splitlines():
        words = line.split()
        if words and words[0] == "cpu":
            ticks = [int(word) for word in words[1 : 1 + COUNTED_FIELDS]]
            if len(ticks) <= STEAL_FIELD:
                return 0, 0
            return sum(ticks), ticks[STEAL_FIELD]
    return 0, 0


def read_cpu_ticks() -> tuple[int, int]:
    try:
        return cpu_ticks(PROC_STAT.read_text())
    except OSError:
        return 0, 0


def steal_share(before: tuple[int, int], after: tuple[int, int]) -> float:
    """The share of all CPU time between two `cpu_ticks` readings that was stolen (NaN if none passed)."""
    total, stolen = after[0] - before[0], after[1] - before[1]
    return stolen / total if total > 0 else math.nan


class StealMeter:
    """Marked as a window opens and as it closes (a stream's `on_window` callback); `share` is the
    steal over the span from the first mark to the last."""

    def __init__(self) -> None:
        self._marks: list[tuple[int, int]] = []

    def mark(self) -> None:
        self._marks.append(read_cpu_ticks())

    @property
    def share(self) -> float:
        return steal_share(self._marks[0], self._marks[-1]) if len(self._marks) >= 2 else math.nan


def steal_percent(share: float) -> str:
    """A table cell: "12%", or "n/a" where the machine does not count steal."""
    return "n/a" if math.isnan(share) else f"{share:.0%}"


def steal_text(share: float) -> str:
    return f"steal {steal_percent(share)}"
