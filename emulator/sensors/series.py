"""A sensor's scans over a span of simulated time, for `record`, `plot` and the validation report."""

from __future__ import annotations

import math
from typing import Iterator

import numpy as np

from emulator.errors import UserError
from emulator.sensors import Sensor
from emulator.sensors.scan import Scan


CHUNK_SCANS = 4096  # span_times makes this many times at once: its memory does not grow with the span


def _scan_range(period_s: float, start_s: float, end_s: float, phase_s: float) -> tuple[int, int]:
    """(first, last) k of the scans phase_s + k · period_s within [start_s, end_s] (last < first: none)."""
    if not (math.isfinite(start_s) and math.isfinite(end_s)) or start_s < 0 or end_s < start_s:
        raise UserError(f"need 0 <= --start <= --end, got {start_s} and {end_s}")
    first = max(0, math.ceil((start_s - phase_s) / period_s - 1e-9))
    last = math.floor((end_s - phase_s) / period_s + 1e-9)
    return first, last


def _times(first: int, stop: int, period_s: float, phase_s: float) -> np.ndarray:
    times = np.arange(first, stop) * period_s
    return times if phase_s == 0 else np.round((times + phase_s) * 1e6) / 1e6


def scan_times(period_s: float, start_s: float, end_s: float, phase_s: float = 0.0) -> np.ndarray:
    """The scan completion times phase_s + k · period_s within [start_s, end_s] (k ≥ 0),
    on the µs grid the device's times lie on."""
    first, last = _scan_range(period_s, start_s, end_s, phase_s)
    return _times(first, last + 1, period_s, phase_s)


def scan_count(period_s: float, start_s: float, end_s: float, phase_s: float = 0.0) -> int:
    """How many times `scan_times` gives for that span, without making them (a huge span is refused
    before any work: one line, not gigabytes)."""
    first, last = _scan_range(period_s, start_s, end_s, phase_s)
    return max(0, last - first + 1)


def span_times(period_s: float, start_s: float, end_s: float, phase_s: float = 0.0) -> Iterator[float]:
    """`scan_times`' times one at a time, CHUNK_SCANS made at once."""
    first, last = _scan_range(period_s, start_s, end_s, phase_s)
    for low in range(first, last + 1, CHUNK_SCANS):
        yield from _times(low, min(low + CHUNK_SCANS, last + 1), period_s, phase_s).tolist()


def scan_series(sensor: Sensor, times_s: np.ndarray) -> Iterator[Scan]:
    """The sensor's configured scans at `times_s`, as the device would put them on the wire."""
    for time_s in times_s:
        yield sensor.configured_scan(float(time_s))
