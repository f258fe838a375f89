"""The smoke regions' optical path on each smoky beam's range grid (`physical.beams._region_path_to`):
rows that enter a region only past their last grid point are skipped, which must change no bit of
any row, whether few or most rows reach the region, for convex (one interval) and mesh regions."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from emulator.optics.hits import RegionCrossing
from emulator.sensors.physical.beams import _region_path_to


def _every_row(regions: list[tuple[RegionCrossing, np.ndarray]], rows: np.ndarray, limits: np.ndarray) -> np.ndarray:
    """Every region summed over every row, the way it was before rows were skipped."""
    total = np.zeros(limits.shape)
    for region, density in regions:
        limit = limits[:, :, None]
        entry, exit_ = region.entry_m[rows], region.exit_m[rows]
        inside = (np.minimum(exit_[:, None, :], limit) - np.minimum(entry[:, None, :], limit)).sum(axis=2)
        total += inside * density[rows][:, None]
    return total


@pytest.mark.parametrize("intervals", [1, 3])
@pytest.mark.parametrize("reaching", [0.0, 0.1, 0.9])
def test_skipping_rows_that_enter_past_their_grid_changes_no_bit(intervals: int, reaching: float) -> None:
    rng = np.random.default_rng(int(reaching * 10) + intervals)
    beams, grid = 3000, 17
    rows = np.sort(rng.choice(beams, 900, replace=False))
    start = rng.uniform(0.0, 5.0, len(rows))
    limits = start[:, None] + rng.uniform(0.1, 4.0, len(rows))[:, None] * np.linspace(0.0, 1.0, grid)
    regions = []
    for _ in range(2):
        entry = np.sort(rng.uniform(0.0, 20.0, (beams, intervals)), axis=1)
        entry[rng.random(beams) >= reaching] += 100.0  # these beams enter past every grid point
        entry[rng.random((beams, intervals)) < 0.2] = np.inf  # missing intervals
        exit_ = entry + rng.uniform(0.0, 3.0, (beams, intervals))
        regions.append((RegionCrossing(len(regions), 0.002, entry, exit_), rng.uniform(0.0, 0.01, beams)))
    instants = SimpleNamespace(beam_rows=lambda rows: rows, smoky_regions=lambda: iter(regions))
    mine = _region_path_to(instants, rows, limits)
    np.testing.assert_array_equal(mine, _every_row(regions, rows, limits))
    assert (np.count_nonzero(mine) > 0) == (reaching > 0)
