"""The puffs' optical path per beam against the untruncated analytic integral over every puff.

Puffs are summed only out to their instant's reach (`reach_sigmas`); the ones left out may add
at most TRUNCATION_BUDGET to a beam, and the CDF table errs by at most CDF_ERROR per pair (in units
of its column): the bound promised in docs/physical-model.md ("Plumes at scale"), which is within 1e-4 d·m."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from emulator.optics.puff_kernels import CDF_ERROR
from emulator.optics.puffs import TRUNCATION_BUDGET, Puffs, cross_beams

_ERFC = np.frompyfunc(math.erfc, 1, 1)


def _cdf(z: np.ndarray) -> np.ndarray:
    return 0.5 * _ERFC(-z / math.sqrt(2.0)).astype(float)


def untruncated_path(puffs: Puffs, origins: np.ndarray, directions: np.ndarray, end: np.ndarray) -> np.ndarray:
    """Every puff against every beam, with the C library's erfc: the line integral of the Gaussians from each origin to its end."""
    offset = puffs.centers[None, :, :] - origins[:, None, :]
    along = np.einsum("npk,nk->np", offset, directions)
    miss_sq = np.maximum(np.einsum("npk,npk->np", offset, offset) - along * along, 0.0)
    sigma = puffs.sigma[None, :]
    column = puffs.central_column[None, :] * np.exp(-miss_sq / (2.0 * sigma * sigma))
    share = _cdf((end[:, None] - along) / sigma) - _cdf(-along / sigma)
    return (column * share).sum(axis=1)


@settings(max_examples=60, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    count=st.integers(1, 1500),
    size=st.floats(0.05, 1.2),
    density=st.floats(0.001, 1.0),
    spread=st.floats(0.2, 6.0),
    fan=st.booleans(),
)
def test_the_optical_path_per_beam_is_within_the_bound_of_the_untruncated_integral(seed, count, size, density, spread, fan):
    rng = np.random.default_rng(seed)
    centres = np.array([2.0, 0.0, 0.4]) + rng.normal(size=(count, 3)) * [spread, spread, 0.3 * spread]
    puffs = Puffs(centres, rng.uniform(0.2, 1.0, count) * size, rng.uniform(0.1, 1.0, count) * density)
    angles = np.radians(np.linspace(-135.0, 135.0, 181))
    directions = np.stack([np.cos(angles), np.sin(angles), np.zeros_like(angles)], axis=1)
    origins = np.tile([0.0, 0.0, 0.4], (len(angles), 1))
    if not fan:  # beams with their own origins: the path for moving sensors
        origins = origins + rng.normal(size=origins.shape) * 0.05
    end = rng.uniform(0.5, 12.0, len(angles))
    got = cross_beams(puffs, origins, directions, end).optical_path_to(end)
    exact = untruncated_path(puffs, origins, directions, end)
    pairs_column = puffs.central_column.sum()  # bounds the columns of any beam's pairs
    bound = TRUNCATION_BUDGET + 2.0 * CDF_ERROR * pairs_column + 1e-12 * (1.0 + exact)
    assert np.all(np.abs(got - exact) <= bound), np.abs(got - exact).max()
    assert np.all(np.abs(got - exact) <= np.maximum(1e-4, 0.01 * exact))
