"""The first particle box per beam (`optics/first_boxes.py`): exact tests only on the candidates that can
come first must give the ranges and densities of testing every candidate, ties included, to the bit."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import emulator.optics.first_boxes as first_boxes_module
from emulator.optics.candidates import candidate_pairs
from emulator.optics.chords import paired_cube_intervals
from emulator.optics.first_boxes import first_boxes


def _every_candidate(origins, directions, beam_end, centers, half, density, beam, box):
    """The first box as it was found before: every candidate tested, the minimum entry, a tie to the last listed."""
    first_range, first_density = np.full(len(origins), np.inf), np.zeros(len(origins))
    entry, exit_ = paired_cube_intervals(origins[beam], directions[beam], centers[box], half[box])
    entry = np.maximum(entry, 0.0)
    met = (exit_ >= entry) & (entry < beam_end[beam])
    beam, box, entry = beam[met], box[met], entry[met]
    np.minimum.at(first_range, beam, entry)
    first = entry == first_range[beam]
    first_density[beam[first]] = density[box[first]]
    return first_range, first_density


@settings(max_examples=60, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    one_origin=st.booleans(),
    boxes=st.integers(1, 400),
    depth=st.sampled_from([0.0, 0.05, 0.2, 1.0, np.inf]),
)
def test_testing_only_the_boxes_that_can_come_first_finds_what_testing_every_candidate_does(seed, one_origin, boxes, depth):
    rng = np.random.default_rng(seed)
    angles = np.radians(np.linspace(-60.0, 60.0, 121))
    directions = np.stack([np.cos(angles), np.sin(angles), np.zeros_like(angles)], axis=1)
    origins = np.zeros((121, 3)) if one_origin else rng.uniform(-0.2, 0.2, (121, 3))
    beam_end = rng.uniform(1.0, 6.0, 121)
    centers = rng.uniform([0.5, -3.0, -0.3], [5.0, 3.0, 0.3], (boxes, 3))
    half = rng.uniform(0.02, 0.5, boxes)
    density = rng.uniform(0.01, 0.1, boxes)
    twins = rng.integers(0, boxes, boxes // 5)  # the same box again with another density: exact ties
    centers, half = np.concatenate([centers, centers[twins]]), np.concatenate([half, half[twins]])
    density = np.concatenate([density, rng.uniform(0.2, 0.3, len(twins))])
    centers[: boxes // 20] = rng.uniform(-0.1, 0.1, (boxes // 20, 3))  # around the origin: ties at 0
    radius = half * np.sqrt(3.0)
    beam, box, along = candidate_pairs(origins, directions, beam_end, centers, radius)
    expected = _every_candidate(origins, directions, beam_end, centers, half, density, beam, box)

    def intervals(pairs):
        return paired_cube_intervals(origins[beam[pairs]], directions[beam[pairs]], centers[box[pairs]], half[box[pairs]])

    kept_depth = first_boxes_module.FRONT_DEPTH_M
    try:
        first_boxes_module.FRONT_DEPTH_M = depth
        got = first_boxes(beam, box, along - radius[box], intervals, beam_end, density)
    finally:
        first_boxes_module.FRONT_DEPTH_M = kept_depth
    np.testing.assert_array_equal(got[0], expected[0])
    np.testing.assert_array_equal(got[1], expected[1])
    if boxes > 200:
        assert np.isfinite(expected[0]).sum() > 10  # beams that meet boxes, not only open air


def test_a_dense_plume_tests_fewer_boxes_than_it_has_candidates(monkeypatch: pytest.MonkeyPatch):
    """The point of it: behind each beam's first boxes, the candidates are never tested exactly."""
    rng = np.random.default_rng(3)
    angles = np.radians(np.linspace(-30.0, 30.0, 61))
    directions = np.stack([np.cos(angles), np.sin(angles), np.zeros_like(angles)], axis=1)
    origins, beam_end = np.zeros((61, 3)), np.full(61, 20.0)
    centers = rng.uniform([2.0, -4.0, -0.2], [12.0, 4.0, 0.2], (3000, 3))
    half, density = np.full(3000, 0.2), np.full(3000, 0.05)
    radius = half * np.sqrt(3.0)
    beam, box, along = candidate_pairs(origins, directions, beam_end, centers, radius)
    tested = []

    def intervals(pairs):
        tested.append(len(pairs))
        return paired_cube_intervals(origins[beam[pairs]], directions[beam[pairs]], centers[box[pairs]], half[box[pairs]])

    got = first_boxes(beam, box, along - radius[box], intervals, beam_end, density)
    assert np.isfinite(got[0]).all()
    assert sum(tested) < len(beam) / 4


def test_a_box_entered_at_its_corner_just_before_the_first_box_found_is_still_found(monkeypatch: pytest.MonkeyPatch):
    """A beam along a cube's diagonal enters it at its corner, exactly at the bound `along - radius`: a small
    box entered so 0.5 mm before the box pass 1 found (face entry at 1 m, a nearer bound) must win."""
    monkeypatch.setattr(first_boxes_module, "FRONT_DEPTH_M", 0.0)  # pass 1: only each beam's nearest bound
    direction = np.full((1, 3), 1.0 / np.sqrt(3.0))
    origins, beam_end = np.zeros((1, 3)), np.array([5.0])
    small, large, sideways = 0.01, 0.3, 0.1
    on_beam = (0.9995 + small * np.sqrt(3.0)) * direction[0]  # corner entry at 0.9995 m
    face = np.full(3, (1.0 / np.sqrt(3.0) + large - sideways)) + np.array([sideways, -sideways, 0.0])  # face entry at 1 m
    centers, half, density = np.array([face, on_beam]), np.array([large, small]), np.array([0.05, 0.07])
    radius = half * np.sqrt(3.0)
    beam, box, along = candidate_pairs(origins, direction, beam_end, centers, radius)
    expected = _every_candidate(origins, direction, beam_end, centers, half, density, beam, box)
    assert expected[0][0] == pytest.approx(0.9995, abs=1e-9) and expected[1][0] == 0.07

    def intervals(pairs):
        return paired_cube_intervals(origins[beam[pairs]], direction[beam[pairs]], centers[box[pairs]], half[box[pairs]])

    got = first_boxes(beam, box, along - radius[box], intervals, beam_end, density)
    assert got[0][0] == expected[0][0] and got[1][0] == expected[1][0]
