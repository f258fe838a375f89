"""The shared culling (`optics/fans.py`): a superset of every beam–cube pair the exact slab test finds."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from emulator.optics.candidates import candidate_pairs
from emulator.optics.chords import paired_cube_intervals
from emulator.optics.fans import beam_segments


def _fan(count: int, start_deg: float, span_deg: float, origin: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    angles = np.radians(start_deg + np.linspace(0.0, span_deg, count))
    directions = np.stack([np.cos(angles), np.sin(angles), np.zeros(count)], axis=1)
    return np.repeat(origin[None, :], count, axis=0), directions


def _exact_pairs(origins, directions, beam_end, centers, half) -> set[tuple[int, int]]:
    beam, cube = np.meshgrid(np.arange(len(origins)), np.arange(len(centers)), indexing="ij")
    beam, cube = beam.ravel(), cube.ravel()
    entry, exit_ = paired_cube_intervals(origins[beam], directions[beam], centers[cube], half[cube])
    entry = np.maximum(entry, 0.0)
    met = (exit_ >= entry) & (entry < beam_end[beam])
    return set(zip(beam[met].tolist(), cube[met].tolist()))


@settings(max_examples=60, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    span=st.sampled_from([90.0, 180.0, 240.0, 359.0]),
    start=st.floats(-180.0, 180.0),
    cubes=st.integers(1, 60),
)
def test_fan_candidates_hold_every_pair_the_slab_test_finds(seed, span, start, cubes):
    rng = np.random.default_rng(seed)
    origin = rng.uniform(-2.0, 2.0, 3)
    origins, directions = _fan(181, start, span, origin)
    beam_end = rng.uniform(0.5, 8.0, len(origins))
    centers = origin + rng.uniform(-6.0, 6.0, (cubes, 3)) * np.array([1.0, 1.0, 0.1])
    half = rng.uniform(0.01, 0.8, cubes)
    assert beam_segments(origins, directions, beam_end).fan is not None  # the fan path is what is tested
    beam, cube = candidate_pairs(origins, directions, beam_end, centers, half * np.sqrt(3.0))
    assert _exact_pairs(origins, directions, beam_end, centers, half) <= set(zip(beam.tolist(), cube.tolist()))


def test_beams_from_several_origins_are_no_fan_and_still_find_their_pairs():
    origins, directions = _fan(50, -45.0, 90.0, np.zeros(3))
    origins = origins + np.linspace(0.0, 1.0, 50)[:, None] * np.array([0.0, 0.0, 0.01])
    beam_end = np.full(50, 10.0)
    centers = np.array([[3.0, 0.0, 0.0], [2.6, 1.5, 0.0], [-3.0, 0.0, 0.0]])
    half = np.full(3, 0.3)
    assert beam_segments(origins, directions, beam_end).fan is None
    beam, cube = candidate_pairs(origins, directions, beam_end, centers, half * np.sqrt(3.0))
    found = set(zip(beam.tolist(), cube.tolist()))
    assert _exact_pairs(origins, directions, beam_end, centers, half) <= found
    assert {c for _, c in found} == {0, 1}  # the cube behind the fan is culled


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), axis_aligned=st.booleans(), pairs=st.integers(0, 400))
def test_the_slab_test_from_per_ray_and_per_cube_values_gives_the_same_bits(seed, axis_aligned, pairs):
    """A fan's slab test takes 1/direction per beam and centre − origin per box (gathered_cube_intervals):
    every pair's entry and exit must be those of the per-pair test, to the bit, also for beams along an
    axis (1/0 = inf) and origins inside boxes."""
    from emulator.optics.chords import gathered_cube_intervals, paired_cube_intervals_by_axis

    rng = np.random.default_rng(seed)
    origin = rng.uniform(-2.0, 2.0, 3)
    directions = rng.normal(size=(90, 3))
    if axis_aligned:
        directions[rng.random((90, 3)) < 0.3] = 0.0
        directions[np.all(directions == 0.0, axis=1), 0] = 1.0
    directions /= np.linalg.norm(directions, axis=1)[:, None]
    centers = origin + rng.uniform(-3.0, 3.0, (40, 3))
    centers[:5] = origin + rng.uniform(-0.1, 0.1, (5, 3))  # around the origin
    half = rng.uniform(0.01, 0.8, 40)
    ray, cube = rng.integers(0, 90, pairs), rng.integers(0, 40, pairs)
    with np.errstate(divide="ignore"):
        inverse = np.divide(1.0, np.ascontiguousarray(directions.T))
    offsets = np.subtract(centers.T, origin[:, None], order="C")
    gathered = gathered_cube_intervals(inverse, offsets, half, ray, cube)
    paired = paired_cube_intervals_by_axis(
        np.tile(origin[:, None], (1, pairs)), directions.T[:, ray], centers.T[:, cube], half[cube]
    )
    np.testing.assert_array_equal(gathered[0], paired[0])
    np.testing.assert_array_equal(gathered[1], paired[1])
    if pairs > 100:
        assert np.isfinite(paired[0]).any()  # some pairs meet
