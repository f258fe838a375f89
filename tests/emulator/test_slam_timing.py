"""Mapping CHokuyoURG's rawlog stamps to simulated time (emulator/bench/slam.py `simulated_times`).

Synthetic stamps built the way the driver makes them: the first 10 scans
stamped with the wall clock when the next message starts to arrive, the rest
`wall(11th) + device time since the 11th`. The real driver's stamps are
checked scan by scan in tests/interop/test_mrpt_icp_slam.py.
"""

from __future__ import annotations

import numpy as np
import pytest

from emulator.bench.slam import ClockAnchor, simulated_times

WALL_AT_ZERO = 1_800_000_000.0


def driver_stamps(first_index: int, count: int, speed: float, lags_s: np.ndarray) -> np.ndarray:
    """Stamps of scans first_index, first_index + 1, ... (scan k completes at k / 10 s simulated);
    `lags_s` (wall seconds) is how long after the next scan's completion each of the first 11 was stamped."""
    completes = (first_index + np.arange(count)) / 10.0
    arrivals = WALL_AT_ZERO + (completes + 0.1) / speed + np.resize(lags_s, count)
    stamps = arrivals.copy()
    stamps[10:] = arrivals[10] + (completes[10:] - completes[10])  # device ms differences, simulated
    return stamps


@pytest.mark.parametrize("speed", [1.0, 2.0, 3.0])
def test_prompt_arrivals_give_each_scan_its_completion_time(speed: float) -> None:
    lags = np.full(11, 0.002)
    stamps = driver_stamps(57, 40, speed, lags)
    times = simulated_times(stamps, ClockAnchor(WALL_AT_ZERO, speed, 0.0002))
    assert np.isnan(times[:10]).all()
    np.testing.assert_allclose(times[10:], (57 + np.arange(10, 40)) / 10.0, atol=1e-9)


def test_a_driver_that_starts_behind_needs_one_prompt_arrival() -> None:
    lags = np.array([0.4, 0.35, 0.3, 0.25, 0.2, 0.15, 0.1, 0.002, 0.06, 0.09, 0.12])  # reading a backlog
    times = simulated_times(driver_stamps(30, 20, 2.0, lags), ClockAnchor(WALL_AT_ZERO, 2.0, 0.0002))
    assert times[10] == pytest.approx(4.0)


def test_too_few_scans_have_no_time() -> None:
    stamps = driver_stamps(5, 11, 1.0, np.zeros(11))[:10]
    assert np.isnan(simulated_times(stamps, ClockAnchor(WALL_AT_ZERO, 1.0, 0.0))).all()
