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
    beam, cube, _ = candidate_pairs(origins, directions, beam_end, centers, half * np.sqrt(3.0))
    assert _exact_pairs(origins, directions, beam_end, centers, half) <= set(zip(beam.tolist(), cube.tolist()))


def test_beams_from_several_origins_are_no_fan_and_still_find_their_pairs():
    origins, directions = _fan(50, -45.0, 90.0, np.zeros(3))
    origins = origins + np.linspace(0.0, 1.0, 50)[:, None] * np.array([0.0, 0.0, 0.01])
    beam_end = np.full(50, 10.0)
    centers = np.array([[3.0, 0.0, 0.0], [2.6, 1.5, 0.0], [-3.0, 0.0, 0.0]])
    half = np.full(3, 0.3)
    assert beam_segments(origins, directions, beam_end).fan is None
    beam, cube, _ = candidate_pairs(origins, directions, beam_end, centers, half * np.sqrt(3.0))
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


def _fan_pairs_of_every_sphere(fan, offset, radius, skip):
    """fan_pairs as it was before it cut spheres the plane misses first: angles for every sphere."""
    from emulator.optics.fans import _TINIEST

    beam_angle, axes = fan.beam_angle, fan.axes_by_row
    height, x, y = offset[0] * axes[0] + offset[1] * axes[1] + offset[2] * axes[2]
    in_plane = np.sqrt(np.maximum(radius * radius - height * height, 0.0))
    distance = np.hypot(x, y)
    around_origin = distance <= in_plane
    half_width = np.arcsin(np.minimum(in_plane, distance) / np.maximum(distance, _TINIEST))
    centre = np.arctan2(y, x)
    skipped = (np.abs(height) >= radius) | skip
    lower_edge, upper_edge = centre - half_width, centre + half_width
    wraps = upper_edge.max() > beam_angle[0] + (2.0 * np.pi - 1e-9) or lower_edge.min() < beam_angle[-1] - (2.0 * np.pi - 1e-9)
    beams, sphere_of = [], []
    for turn in (-2.0 * np.pi, 0.0, 2.0 * np.pi) if wraps else (0.0,):
        low = beam_angle.searchsorted(centre + turn - half_width if turn else lower_edge, side="left")
        high = beam_angle.searchsorted(centre + turn + half_width if turn else upper_edge, side="right")
        if turn:
            high[around_origin] = low[around_origin]
        else:
            low[around_origin], high[around_origin] = 0, len(beam_angle)
        counts = high - low
        counts[skipped] = 0
        sphere_of.append(np.arange(len(counts)).repeat(counts))
        beams.append((low + counts - counts.cumsum()).repeat(counts) + np.arange(len(sphere_of[-1])))
    return np.concatenate(beams), np.concatenate(sphere_of)


@settings(max_examples=80, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    span=st.sampled_from([90.0, 240.0, 359.0, 359.9]),
    start=st.floats(-180.0, 180.0),
    tilt=st.floats(-60.0, 60.0),
    spheres=st.integers(1, 300),
)
def test_fan_pairs_cut_spheres_the_plane_misses_first_yet_give_the_same_pairs_in_order(seed, span, start, tilt, spheres):
    """fan_pairs computes angles only for spheres the fan's plane cuts: the pairs, their order (sums
    depend on it) and the wrap-around turns must be those of angles for every sphere."""
    from emulator.optics.fans import fan_pairs

    rng = np.random.default_rng(seed)
    origin = rng.uniform(-2.0, 2.0, 3)
    origins, directions = _fan(361, start, span, origin)
    c, s = np.cos(np.radians(tilt)), np.sin(np.radians(tilt))
    directions = directions @ np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]]).T  # a tilted plane
    fan = beam_segments(origins, directions, np.full(361, 8.0)).fan
    assert fan is not None
    centers = origin + rng.uniform(-6.0, 6.0, (spheres, 3)) * np.array([1.0, 1.0, 0.3])
    centers[: spheres // 10] = origin + rng.uniform(-0.3, 0.3, (spheres // 10, 3))  # around the origin
    radius = rng.uniform(0.01, 1.0, spheres)
    skip = rng.random(spheres) < 0.2
    offset = np.subtract(centers.T, origin[:, None], order="C")
    got = fan_pairs(fan, offset, radius, skip)
    expected = _fan_pairs_of_every_sphere(fan, offset, radius, skip)
    np.testing.assert_array_equal(got[0], expected[0])
    np.testing.assert_array_equal(got[1], expected[1])
