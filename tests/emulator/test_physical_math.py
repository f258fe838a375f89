"""The `physical` model's building blocks on plain arrays: puffs, echo law, threshold, receivers."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from emulator.optics.puff_kernels import CDF_ERROR, WINDOW_ERROR, normal_cdf
from emulator.optics.puffs import TRUNCATION_BUDGET, BeamPuffCrossings, Puffs, cross_beams
from emulator.scene.material_optics import BUILTIN_OPTICS, patch_values
from emulator.scene.materials import BUILTIN_MATERIALS
from emulator.scene.plumes import Particles
from emulator.sensors.physical import echo_kernels
from emulator.sensors.physical.echo import (
    lms_first_echo,
    log_target_echo,
    log_threshold,
    range_law,
    reference_spreading,
    smoke_bin_echo,
)
from emulator.sensors.physical.noise import (
    edge_strength,
    fluctuation_factor,
    fluctuation_field,
)
from emulator.sensors.physical.params import DEFAULT_PARAMS, LmsReceiver

K = 250.0  # density_to_extinction, 1/m per density unit


def test_normal_cdf_matches_the_standard_library():
    x = np.concatenate([np.linspace(-9.0, 9.0, 20001), np.random.default_rng(4).uniform(-9.0, 9.0, 20000)])
    expected = [0.5 * math.erfc(-v / math.sqrt(2.0)) for v in x]
    assert np.max(np.abs(normal_cdf(x) - expected)) < CDF_ERROR


def test_a_puff_keeps_the_boxs_peak_density_mass_and_central_column():
    edge, density = 0.6, 0.05
    particles = Particles(np.array([[3.0, 0.0, 0.3]]), np.array([edge / 2]), np.array([density]), np.array([0]))
    puffs = Puffs.from_particles(particles)
    sigma = puffs.sigma[0]
    assert density * (2 * np.pi) ** 1.5 * sigma**3 == pytest.approx(density * edge**3)
    origins, directions = np.array([[0.0, 0.0, 0.3]]), np.array([[1.0, 0.0, 0.0]])
    crossings = cross_beams(puffs, origins, directions, np.array([10.0]))
    assert crossings.optical_path_to(np.array([10.0]))[0] == pytest.approx(density * edge, rel=1e-6)
    assert crossings.optical_path_to(np.array([3.0]))[0] == pytest.approx(density * edge / 2, rel=1e-6)


@settings(max_examples=40, deadline=None)
@given(
    centre=st.tuples(st.floats(-1.0, 6.0), st.floats(-1.0, 1.0), st.floats(0.0, 0.6)),
    edge=st.floats(0.1, 1.0),
    limit=st.floats(0.0, 8.0),
    angle=st.floats(-0.5, 0.5),
)
def test_puff_optical_path_equals_numerical_integration_of_the_gaussian(centre, edge, limit, angle):
    """The analytic (erf) line integral against a fine Riemann sum of the 3-D Gaussian density."""
    particles = Particles(np.array([centre]), np.array([edge / 2]), np.array([0.05]), np.array([0]))
    puffs = Puffs.from_particles(particles)
    origin = np.array([0.0, 0.0, 0.3])
    direction = np.array([math.cos(angle), math.sin(angle), 0.0])
    analytic = cross_beams(puffs, origin[None], direction[None], np.array([limit])).optical_path_to(np.array([limit]))[0]
    s = np.linspace(0.0, limit, 40001)
    points = origin + s[:, None] * direction
    density = 0.05 * np.exp(-np.sum((points - np.array(centre)) ** 2, axis=1) / (2 * puffs.sigma[0] ** 2))
    numeric = float(np.sum((density[1:] + density[:-1]) * 0.5 * np.diff(s)))
    # only puffs whose share is within the truncation budget are left out (the Riemann sum: < 1e-9)
    assert analytic == pytest.approx(numeric, abs=TRUNCATION_BUDGET + 1e-9)


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), growth=st.floats(1.0, 1.6), bins=st.integers(1, 24))
def test_puff_path_on_a_grid_equals_the_path_to_each_grid_point(seed, growth, bins):
    """The range bins' shortcut (the kept pairs, CDF only within WINDOW sigmas of each puff)
    against `optical_path_to` at the same distances, on beams that start inside, before and past puffs."""
    rng = np.random.default_rng(seed)
    count = 200
    particles = Particles(
        rng.uniform([-1, -4, 0], [6, 4, 0.8], (count, 3)), rng.uniform(0.02, 0.4, count), rng.uniform(0.01, 0.1, count), np.arange(count)
    )
    angles = np.radians(np.linspace(-100, 100, 161))
    directions = np.stack([np.cos(angles), np.sin(angles), np.zeros_like(angles)], axis=1)
    origins = np.tile([0.0, 0.0, 0.4], (len(angles), 1))
    crossings = cross_beams(Puffs.from_particles(particles), origins, directions, np.full(len(angles), 7.0))
    rows = np.unique(crossings.beam)[::2]
    assert len(rows) > 10
    start = rng.uniform(0.0, 3.0, len(rows))
    length = rng.uniform(0.01, 5.0, len(rows))
    widths = growth ** np.arange(bins)
    fractions = np.concatenate([[0.0], np.cumsum(widths) / widths.sum()])
    grid = start[:, None] + length[:, None] * fractions
    fields = ("beam", "along_m", "sigma", "column", "before_origin", "near")
    kept_only = BeamPuffCrossings(*(getattr(crossings, name) for name in fields))  # without the faint pairs' sums
    expected = kept_only.optical_path_to(grid, rows)
    assert np.count_nonzero(expected) > 10
    on_grid = crossings.optical_path_on_grid(rows, start, length, fractions)
    column_per_row = np.bincount(crossings.beam, weights=crossings.column, minlength=len(angles))[rows]
    # the CDF taken as 0 or 1 beyond WINDOW sigmas: at most WINDOW_ERROR of each column, besides the table's own error
    assert np.all(np.abs(on_grid - expected) < (WINDOW_ERROR + 2 * CDF_ERROR) * column_per_row[:, None] + 1e-15)
    # the faint pairs (beyond BINS_SIGMAS) count to the beam's end, not in the bins
    slack = (WINDOW_ERROR + 2 * CDF_ERROR) * column_per_row[:, None] + 1e-15
    assert np.all(crossings.optical_path_to(grid, rows) - on_grid <= crossings.pooled_column[rows][:, None] + slack)


def test_fan_culling_finds_the_same_pairs_as_brute_force():
    rng = np.random.default_rng(3)
    particles = Particles(
        rng.uniform([-2, -6, 0], [8, 6, 1], (300, 3)), rng.uniform(0.1, 0.5, 300), rng.uniform(0.01, 0.1, 300), np.arange(300)
    )
    puffs = Puffs.from_particles(particles)
    angles = np.radians(np.linspace(-120, 120, 682))
    directions = np.stack([np.cos(angles), np.sin(angles), np.zeros_like(angles)], axis=1)
    fan_origins = np.tile([0.0, 0.0, 0.4], (682, 1))
    jittered = fan_origins.copy()
    jittered[0, 0] += 1e-12  # no longer one origin: the brute-force path
    end = np.full(682, 9.0)
    fan = cross_beams(puffs, fan_origins, directions, end).optical_path_to(end)
    brute = cross_beams(puffs, jittered, directions, end).optical_path_to(end)
    assert np.count_nonzero(fan) > 100
    np.testing.assert_allclose(fan, brute, rtol=1e-9, atol=1e-12)


def test_threshold_is_derived_from_the_penetration_power():
    urg = DEFAULT_PARAMS.urg
    threshold = log_threshold(urg, DEFAULT_PARAMS, K)
    assert threshold == -2.0 * K * 0.007
    reference = log_target_echo(np.array([0.9]), np.array([1.0]), np.array([2.5]), np.array([0.007]), K, urg, DEFAULT_PARAMS)
    assert reference[0] == threshold
    assert range_law(np.array([2.5]), urg, DEFAULT_PARAMS)[0] == 1.0


def test_darker_farther_more_oblique_targets_echo_less():
    urg = DEFAULT_PARAMS.urg
    echo = lambda rho, cos, r: log_target_echo(np.array([rho]), np.array([cos]), np.array([r]), np.array([0.003]), K, urg, DEFAULT_PARAMS)[0]
    assert echo(0.9, 1.0, 2.5) > echo(0.6, 1.0, 2.5) > echo(0.02, 1.0, 2.5)
    assert echo(0.9, 1.0, 2.0) > echo(0.9, 1.0, 2.5) > echo(0.9, 1.0, 4.0)
    assert echo(0.9, 1.0, 2.5) > echo(0.9, 0.7, 2.5)
    assert log_target_echo(np.array([0.9]), np.array([1.0]), np.array([np.inf]), np.array([0.0]), K, urg, DEFAULT_PARAMS)[0] == -np.inf


def test_the_lms_receivers_clear_air_detection_matches_its_datasheet_point():
    """The LMS200 sees a 10 % target at 10 m in clear air, just: its threshold is that echo."""
    lms = DEFAULT_PARAMS.lms
    threshold = log_threshold(lms, DEFAULT_PARAMS, K)
    at_10m = log_target_echo(np.array([0.1]), np.array([1.0]), np.array([10.0]), np.array([0.0]), K, lms, DEFAULT_PARAMS)[0]
    assert at_10m == pytest.approx(threshold, abs=1e-12)


def _homogeneous_lms(sigma_per_m: float, receiver: LmsReceiver, length_m: float = 6.0, bins: int = 600) -> float:
    edges = np.linspace(0.0, length_m, bins + 1)[None]
    path = sigma_per_m / K * edges
    transmission = np.exp(-2.0 * K * path)
    mid = 0.5 * (edges[:, 1:] + edges[:, :-1])
    smoke = smoke_bin_echo(transmission, np.full(mid.shape, 0.05), mid, receiver, DEFAULT_PARAMS)
    echo_m, from_smoke, clean = lms_first_echo(np.zeros((1, 1)), np.full((1, 1), np.inf), smoke, edges, log_threshold(receiver, DEFAULT_PARAMS, K), receiver)
    assert from_smoke[0] and clean[0]
    return float(echo_m[0])


def test_lms_first_echo_in_homogeneous_smoke_is_inversely_proportional_to_density():
    """With the gain ramp flattening the range law, the integrated echo reaches the threshold near a fixed optical depth."""
    receiver = DEFAULT_PARAMS.lms
    extinction = np.array([0.3, 0.4, 0.6, 0.8])
    ranges = np.array([_homogeneous_lms(s, receiver) for s in extinction])
    assert np.all(np.diff(ranges) < 0)
    slope = np.polyfit(np.log(extinction), np.log(ranges), 1)[0]
    assert -1.1 < slope < -0.6  # close to 1/density; the finite window and sharpness test bend it a little


def test_lms_sharpness_rejects_a_slow_rise_and_accepts_a_surface():
    receiver = DEFAULT_PARAMS.lms
    threshold = log_threshold(receiver, DEFAULT_PARAMS, K)
    edges = np.linspace(0.0, 4.0, 41)[None]
    slow = np.full((1, 40), np.exp(threshold) / 25.0)  # reaches the threshold after 2.5 m of thin smoke
    echo_m, from_smoke, clean = lms_first_echo(np.zeros((1, 1)), np.full((1, 1), np.inf), slow, edges, threshold, receiver)
    assert from_smoke[0] and not clean[0] and echo_m[0] == pytest.approx(2.5)
    surface = np.array([[np.exp(threshold) * 2.0]])
    echo_m, from_smoke, clean = lms_first_echo(surface, np.array([[3.5]]), slow * 0.01, edges, threshold, receiver)
    assert echo_m[0] == 3.5 and not from_smoke[0] and clean[0]


def test_material_optics_cover_the_paper_surfaces_and_patches_are_fixed():
    assert set(BUILTIN_OPTICS) <= set(BUILTIN_MATERIALS)
    assert BUILTIN_OPTICS["gold_paper"].range_stretch > 0 and BUILTIN_OPTICS["white_paper"].range_stretch == 0
    points = np.random.default_rng(1).uniform(-3, 3, (4000, 3))
    values = patch_values(points, seed=5)
    np.testing.assert_array_equal(values, patch_values(points, seed=5))
    assert not np.array_equal(values, patch_values(points, seed=6))
    assert abs(values.mean()) < 0.1 and values.std() == pytest.approx(1.0, abs=0.1)


def test_fluctuations_are_strongest_on_smoke_edges_and_have_median_one():
    angles = np.radians(np.linspace(-30, 30, 121))
    lateral = 3.0 * np.tan(angles)  # a plume 3 m ahead, its column Gaussian across the beams
    column = 0.03 * np.exp(-(lateral**2) / (2 * 0.3**2)) + 1e-12
    edges = edge_strength(column, angles, np.full(len(angles), 3.0), DEFAULT_PARAMS.fluctuation_length_m)
    assert edges[60] < 0.05 and edges[np.argmin(np.abs(lateral - 0.45))] > 0.9
    assert np.all(edge_strength(np.full(121, 0.01), angles, np.full(121, 3.0), 0.3) == 0.0)
    field = fluctuation_field(9, "lms", angles, np.arange(0.0, 600.0, 3.0), DEFAULT_PARAMS)
    assert abs(np.median(field)) < 0.1 and field.std() == pytest.approx(1.0, abs=0.15)
    off = fluctuation_factor(9, "lms", angles, (1.0,), column, np.full(121, 3.0), dataclasses.replace(DEFAULT_PARAMS, fluctuation=False))
    assert np.all(off == 1.0)


def test_the_compiled_smoke_bins_are_the_formulas_bit_for_bit():
    """`echo_kernels.smoke_bin_powers` (what `beam_physics_at` runs) against `smoke_bin_echo` and the
    share's formula in numpy, with and without a gain ramp."""
    rng = np.random.default_rng(5)
    rows, edges = 40, 9
    path = np.cumsum(rng.exponential(0.002, (rows, edges)), axis=1)
    low, length = rng.uniform(0.1, 5.0, rows), rng.uniform(0.5, 20.0, rows)
    middles = np.sort(rng.uniform(0.0, 1.0, edges - 1))
    per_path = rng.uniform(1.0, 50.0, edges - 1)
    for receiver in (DEFAULT_PARAMS.urg, DEFAULT_PARAMS.lms):
        transmission = np.exp(path * -500.0)
        amp, mid = echo_kernels.smoke_bin_powers(
            path, transmission, low, length, per_path, middles, 3.0, receiver.overlap_m**2, receiver.gain_ramp_m,
            reference_spreading(DEFAULT_PARAMS.reference_range_m, receiver.overlap_m, receiver.gain_ramp_m),
        )
        scattering = (path[:, 1:] - path[:, :-1]) * per_path * (1.0 / length)[:, None]
        share = (scattering * scattering * scattering + 1.0) * 3.0
        expected_mid = low[:, None] + length[:, None] * middles
        np.testing.assert_array_equal(mid, expected_mid)
        np.testing.assert_array_equal(amp, smoke_bin_echo(transmission, share, expected_mid, receiver, DEFAULT_PARAMS))
