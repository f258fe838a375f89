"""Beam-puff crossings of a fan against brute force, where the fan's shortcuts are delicate:
a full circle of beams (angular intervals wrapping around ±pi), puffs around the origin,
above or below the plane, behind it and past the beams' ends; and the per-beam reductions."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from emulator.optics.puffs import REACH_SIGMAS, BeamPuffCrossings, Puffs, cross_beams
from emulator.scene.plumes import Particles

COUNT = 400


def _full_circle_fan(count: int = 720) -> tuple[np.ndarray, np.ndarray]:
    angles = np.linspace(-np.pi, np.pi, count, endpoint=False) + 1e-3
    directions = np.stack([np.cos(angles), np.sin(angles), np.zeros_like(angles)], axis=1)
    return np.tile([0.5, -0.2, 0.4], (count, 1)), directions


@pytest.fixture(scope="module")
def puffs() -> Puffs:
    rng = np.random.default_rng(11)
    centres = rng.uniform([-6.0, -6.0, -0.4], [6.0, 6.0, 1.2], (COUNT, 3))
    centres[:20] = [0.5, -0.2, 0.4] + rng.uniform(-0.3, 0.3, (20, 3))  # around the origin
    centres[20:40, 0] = rng.uniform(-6.0, -3.0, 20)  # behind the middle beam, where the fan's angles wrap
    centres[20:40, 1] = -0.2 + rng.uniform(-0.2, 0.2, 20)
    particles = Particles(centres, rng.uniform(0.1, 0.6, COUNT), rng.uniform(0.01, 0.1, COUNT), np.arange(COUNT))
    return Puffs.from_particles(particles)


def _sorted(crossings: BeamPuffCrossings) -> tuple[np.ndarray, np.ndarray]:
    order = np.lexsort((crossings.along_m, crossings.beam))
    fields = (crossings.along_m, crossings.sigma, crossings.column, crossings.before_origin)
    return crossings.beam[order], np.stack([field[order] for field in fields])


def _fan_and_brute(puffs: Puffs, end: np.ndarray) -> tuple[BeamPuffCrossings, BeamPuffCrossings]:
    origins, directions = _full_circle_fan(len(end))
    jittered = origins.copy()
    jittered[0, 0] += 1e-12  # no longer one origin: the brute-force path over every beam x puff
    return cross_beams(puffs, origins, directions, end), cross_beams(puffs, jittered, directions, end)


def test_a_full_circle_fan_finds_the_same_pairs_as_brute_force(puffs):
    end = np.random.default_rng(5).uniform(0.5, 5.0, 720)  # ends short of many puffs
    fan, brute = _fan_and_brute(puffs, end)
    # the fan keeps its pairs within BINS_SIGMAS and sums what the fainter ones add up to each beam's end;
    # brute force keeps them all
    def keys(crossings):
        return {(int(b), round(float(a), 9), round(float(s), 12)) for b, a, s in zip(crossings.beam, crossings.along_m, crossings.sigma)}

    fan_keys, brute_keys = keys(fan), keys(brute)
    near_keys = keys(BeamPuffCrossings(*(getattr(brute, name)[brute.near] for name in ("beam", "along_m", "sigma", "column", "before_origin", "near"))))
    assert near_keys <= fan_keys <= brute_keys
    assert len(near_keys) < len(fan_keys) < len(brute_keys)  # some kept beyond 3 sigma for the bins, some summed
    assert len(fan) > 2000
    assert len(np.unique(fan.beam)) > 600  # beams on every side, across the wrap at ±pi
    summed = np.unique(fan.beam)
    assert np.all(fan.pooled_end_m[fan.pooled_column > 0] == end[fan.pooled_column > 0])
    np.testing.assert_allclose(fan.optical_path_to(end), brute.optical_path_to(end), rtol=1e-9, atol=1e-15)
    assert len(summed) > 600


def test_puffs_far_from_every_beam_cross_nothing():
    particles = Particles(np.array([[0.0, 0.0, 5.0], [40.0, 0.0, 0.4]]), np.array([0.2, 0.2]), np.array([0.05, 0.05]), np.arange(2))
    origins, directions = _full_circle_fan()
    assert len(cross_beams(Puffs.from_particles(particles), origins, directions, np.full(720, 10.0))) == 0


def test_extent_spans_every_near_puffs_reach_and_nothing_else(puffs):
    some = Puffs(puffs.centers[20:80], puffs.sigma[20:80], puffs.peak_density[20:80])  # none around the origin
    fan, crossings = _fan_and_brute(some, np.full(720, 4.0))  # brute force keeps its faint pairs too
    start, end = crossings.extent_m(720)
    for mine, theirs in zip(fan.extent_m(720), (start, end)):  # the fan keeps only the near ones: the same extent
        np.testing.assert_allclose(mine, theirs, rtol=1e-12, atol=1e-9)  # brute force's first origin is 1e-12 off
    near = crossings.beam[crossings.near]
    assert 0 < len(near) < len(crossings)  # the faint tails beyond REACH_SIGMAS are summed, not spanned
    for beam in np.unique(near)[[0, 1, 7, 50, -2, -1]]:
        mine = (crossings.beam == beam) & crossings.near
        reach = REACH_SIGMAS * crossings.sigma[mine]
        assert mine.any()
        assert start[beam] == np.maximum(crossings.along_m[mine] - reach, 0.0).min()
        assert end[beam] == (crossings.along_m[mine] + reach).max()
    without = np.setdiff1d(np.arange(720), near)
    assert len(without) > 0
    assert np.all(start[without] == np.inf) and np.all(end[without] == -np.inf)


def test_optical_path_to_some_rows_and_unbounded_limits(puffs):
    crossings, _ = _fan_and_brute(puffs, np.full(720, 6.0))
    limits = np.random.default_rng(2).uniform(0.0, 6.0, (720, 3))
    limits[::7, 1] = np.inf
    limits[::11, 2] = np.nan  # no limit: the whole way, as inf
    whole = crossings.optical_path_to(limits)
    rows = np.array([719, 3, 360, 1, 500])  # in any order
    np.testing.assert_array_equal(crossings.optical_path_to(limits[rows], rows), whole[rows])
    np.testing.assert_array_equal(whole[::11, 2], crossings.optical_path_to(np.full(720, np.inf))[::11])
    single = crossings.optical_path_to(limits[:, 0])
    assert single.shape == (720,)
    np.testing.assert_array_equal(single, whole[:, 0])


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), columns=st.integers(2, 5), zero=st.floats(0.0, 1.0), same=st.floats(0.0, 1.0))
def test_later_limits_equal_to_the_first_or_zero_give_every_limit_its_own_sum_bit_for_bit(puffs, seed, columns, zero, same):
    """optical_path_to evaluates a later limit only where it is neither 0 nor the first limit again
    (a footprint's sub-rays mostly are): each column must still equal that column evaluated alone, to the bit."""
    rng = np.random.default_rng(seed)
    crossings, _ = _fan_and_brute(puffs, np.full(720, 6.0))
    limits = rng.uniform(0.0, 6.0, (720, columns))
    limits[rng.random((720, columns)) < same] = np.inf
    limits[:, 1:] = np.where(rng.random((720, columns - 1)) < same, limits[:, :1], limits[:, 1:])
    limits[:, 1:][rng.random((720, columns - 1)) < zero] = 0.0
    whole = crossings.optical_path_to(limits)
    for column in range(columns):
        np.testing.assert_array_equal(whole[:, column], crossings.optical_path_to(limits[:, column]))
    rows = rng.permutation(720)[: rng.integers(1, 720)]
    np.testing.assert_array_equal(crossings.optical_path_to(limits[rows], rows), whole[rows])


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), rows=st.integers(1, 720))
def test_the_smoke_grid_of_some_rows_sums_exactly_as_that_of_every_row(puffs, seed, rows):
    """Each row's grid sums run over its own pairs only: asking for some rows, in any order, must give
    those rows of the grid of every row, to the bit."""
    rng = np.random.default_rng(seed)
    crossings, _ = _fan_and_brute(puffs, np.full(720, 6.0))
    start = rng.uniform(0.0, 2.0, 720)
    length = rng.uniform(0.1, 5.0, 720)
    fractions = np.concatenate([[0.0], np.cumsum(1.3 ** np.arange(16)) / np.sum(1.3 ** np.arange(16))])
    whole = crossings.optical_path_on_grid(np.arange(720), start, length, fractions)
    picked = rng.permutation(720)[:rows]
    some = crossings.optical_path_on_grid(picked, start[picked], length[picked], fractions)
    np.testing.assert_array_equal(some, whole[picked])
    assert np.count_nonzero(whole) > 1000


def test_block_cut_of_beams_with_own_origins_keeps_exactly_the_all_pairs_crossings(monkeypatch: pytest.MonkeyPatch) -> None:
    """A moving sensor's beams each start elsewhere: the 16-beam block boxes may only drop pairs the exact
    tests drop too, so every crossing (and its order, which sums depend on) equals the all-pairs one."""
    import emulator.optics.puffs as puffs_module

    rng = np.random.default_rng(12)
    cases = []
    for _ in range(200):
        n_beams, n_puffs = int(rng.integers(1, 200)), int(rng.integers(0, 300))
        origins = rng.normal(size=(n_beams, 3)) * 0.05 + rng.normal(size=3)
        directions = rng.normal(size=(n_beams, 3))
        directions /= np.linalg.norm(directions, axis=1)[:, None]
        puffs = Puffs(rng.uniform(-8, 8, (n_puffs, 3)), rng.uniform(0.05, 1.5, n_puffs), rng.uniform(0, 3, n_puffs))
        cases.append((puffs, origins, directions, rng.uniform(0.1, 10, n_beams)))
    blocked = [cross_beams(*case) for case in cases]
    monkeypatch.setattr(puffs_module, "_block_pairs", lambda o, d, e, centers, r: puffs_module._all_pairs(len(o), len(centers)))
    assert sum(len(c) for c in blocked) > 1000  # the cases do cross
    for case, fast in zip(cases, blocked):
        slow = cross_beams(*case)
        for name in ("beam", "along_m", "sigma", "column", "before_origin"):
            np.testing.assert_array_equal(getattr(fast, name), getattr(slow, name))


@pytest.mark.filterwarnings("error")
def test_an_endless_beam_among_beams_with_own_origins_crosses_without_nan_and_as_all_pairs(monkeypatch: pytest.MonkeyPatch) -> None:
    """A beam that meets nothing (end inf) whose direction has a zero component (a level beam: z = 0):
    no end point exists (0 × inf would be NaN), so no block box either; the pairs are all pairs', with no warning."""
    import emulator.optics.puffs as puffs_module

    rng = np.random.default_rng(3)
    angles = np.linspace(-1.0, 1.0, 40)
    directions = np.stack([np.cos(angles), np.sin(angles), np.zeros(40)], axis=1)
    origins = np.tile([0.0, 0.0, 0.4], (40, 1))
    origins[:, 0] += np.arange(40) * 1e-3  # a moving sensor: an origin per beam, no fan
    end = np.full(40, 1.5)
    end[3] = np.inf
    centres = rng.uniform([0.0, -3.0, 0.2], [8.0, 3.0, 0.6], (30, 3))
    centres[0] = origins[3] + 1.0 * directions[3]  # on the endless beam
    puffs = Puffs(centres, rng.uniform(0.1, 0.4, 30), rng.uniform(0.1, 1.0, 30))
    crossed = cross_beams(puffs, origins, directions, end)
    assert (crossed.beam == 3).any() and len(crossed) > 100
    monkeypatch.setattr(puffs_module, "_block_pairs", lambda o, d, e, centers, r: puffs_module._all_pairs(len(o), len(centers)))
    slow = cross_beams(puffs, origins, directions, end)
    for name in ("beam", "along_m", "sigma", "column", "before_origin"):
        np.testing.assert_array_equal(getattr(crossed, name), getattr(slow, name))
