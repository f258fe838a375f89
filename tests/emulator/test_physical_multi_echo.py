"""The multi-echo receivers (`physical.multi_echo`): hand-computed echo lists, the smoke's returns,
scenes (a wall behind a slab, two surfaces in one footprint), batches, and properties of any list."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from emulator.optics import World
from emulator.scene.model import Box, Density, Plume, Pose, SmokeRegion
from emulator.sensors.physical.beams import Instants, SmokeEchoes, beam_physics_at, bin_fractions
from emulator.sensors.physical.echo import log_threshold, range_law
from emulator.sensors.physical.multi_echo import (
    FIRST,
    LAST,
    dynamic_range,
    echo_lists,
    echo_lists_at,
    intensity_of,
    nearest_first,
    select_echoes,
    smoke_returns,
)
from emulator.sensors.physical.params import DEFAULT_PARAMS, PULSED_RECEIVERS, PulsedReceiver
from emulator.validation.reference_scenes import cast_beams, panel, reference_scene

K = 250.0
QUIET = dataclasses.replace(DEFAULT_PARAMS, noise=False, fluctuation=False)
UTM = PULSED_RECEIVERS["utm-30lx-ew"]
LMS511 = PULSED_RECEIVERS["lms511"]
TH = 0.01  # a threshold for the hand-computed lists
RX3 = dataclasses.replace(UTM, max_echoes=3, separation_m=0.5)


def _lists(ranges, powers, receiver=RX3, threshold=TH, fog_filter=False):
    return select_echoes(np.array(ranges, dtype=float), np.array(powers, dtype=float), threshold, receiver, fog_filter=fog_filter)


def test_a_wall_behind_a_slab_gives_the_slab_first_and_the_wall_last():
    lists = _lists([[6.0, 2.0]], [[0.02, 0.015]])  # candidates in any order
    np.testing.assert_array_equal(lists.ranges_m[0, :2], [2.0, 6.0])
    np.testing.assert_array_equal(lists.powers[0], [0.015, 0.02, 0.0])
    assert np.isnan(lists.ranges_m[0, 2]) and lists.count[0] == 2
    assert lists.echo(FIRST)[0][0] == 2.0 and lists.echo(LAST)[0][0] == 6.0


def test_two_surfaces_in_one_footprint_give_two_echoes_apart_and_one_merged_when_closer_than_the_separation():
    apart = _lists([[3.0, 4.5, np.inf]], [[0.03, 0.01, 0.0]])
    np.testing.assert_array_equal(apart.ranges_m[0, :2], [3.0, 4.5])
    merged = _lists([[3.0, 3.3, np.inf]], [[0.03, 0.01, 0.0]])
    assert merged.count[0] == 1
    assert merged.ranges_m[0, 0] == pytest.approx((3.0 * 0.03 + 3.3 * 0.01) / 0.04)
    assert merged.powers[0, 0] == pytest.approx(0.04)


def test_returns_too_weak_alone_are_seen_once_merged_and_a_chain_merges_as_one():
    lists = _lists([[5.0, 5.2, 5.6, 9.0]], [[0.004, 0.004, 0.004, 0.009]])
    assert lists.count[0] == 1  # 5.0-5.2-5.6 chain (gaps 0.2, 0.4 < 0.5): 0.012 ≥ 0.01; 9.0 too weak
    assert lists.ranges_m[0, 0] == pytest.approx((5.0 + 5.2 + 5.6) / 3)
    assert lists.powers[0, 0] == pytest.approx(0.012)


def test_a_unit_with_fewer_slots_than_echoes_keeps_the_first_it_receives():
    lists = _lists([[5.0, 4.0, 3.0, 2.0, 1.0]], [[0.1] * 5])
    np.testing.assert_array_equal(lists.ranges_m[0], [1.0, 2.0, 3.0])
    assert lists.count[0] == 3
    one = _lists([[2.0, 3.0, 1.0]], [[0.1] * 3], receiver=dataclasses.replace(RX3, max_echoes=1))
    np.testing.assert_array_equal(one.ranges_m[0], [1.0])  # with one slot: the first echo (a TiM's DIST1)


def test_the_fog_filter_drops_near_echoes_weaker_than_its_raised_threshold():
    receiver = dataclasses.replace(RX3, fog_filter_m=16.0, fog_filter_gain=2.6)
    ranges, powers = [[3.0, 12.0, 20.0]], [[0.02, 0.03, 0.015]]
    off = _lists(ranges, powers, receiver)
    on = _lists(ranges, powers, receiver, fog_filter=True)
    np.testing.assert_array_equal(off.ranges_m[0], [3.0, 12.0, 20.0])
    np.testing.assert_array_equal(on.ranges_m[0, :2], [12.0, 20.0])  # 0.02 < 0.026 near; 0.015 ≥ 0.01 beyond 16 m


def test_no_echo_gives_nan_ranges_zero_powers_and_a_zero_count():
    lists = _lists([[np.inf, 3.0]], [[0.0, 0.001]])
    assert lists.count[0] == 0 and np.isnan(lists.ranges_m).all() and not lists.powers.any()
    assert np.isnan(lists.echo(LAST)[0][0])


def test_intensity_is_linear_in_power_and_saturates():
    assert intensity_of(np.array([1.0, 0.5, 0.0, 1e6]), UTM).tolist() == [6000, 3000, 0, 65535]


def _uniform_smoke(length_m: float, per_metre: float, start_m: float = 2.0) -> SmokeEchoes:
    """One beam's smoke with the same backscatter per metre everywhere (bins of the model's grid)."""
    fractions = bin_fractions(DEFAULT_PARAMS)
    edges = start_m + length_m * fractions
    amp = np.diff(edges) * per_metre
    return SmokeEchoes(np.array([0]), amp[None, :], (0.5 * (edges[1:] + edges[:-1]))[None, :], edges[None, :], fractions)


def test_uniform_smoke_returns_one_pulse_lengths_backscatter_from_where_it_first_holds_the_threshold():
    smoke = _uniform_smoke(4.0, per_metre=0.03)
    ranges, powers = smoke_returns(smoke, RX3, threshold=0.01)
    assert ranges.shape == (1, 1)
    assert ranges[0, 0] == pytest.approx(2.0 + 0.01 / 0.03)  # the last pulse length holds 0.03 per metre
    assert powers[0, 0] == pytest.approx(0.03 * RX3.separation_m)  # 0.015
    none, _ = smoke_returns(smoke, RX3, threshold=0.016)
    assert none.shape[1] == 0


def test_smoke_with_two_dense_stretches_gives_two_returns():
    fractions = bin_fractions(DEFAULT_PARAMS)
    edges = 1.0 + 10.0 * fractions
    mid = 0.5 * (edges[1:] + edges[:-1])
    per_metre = np.where((mid < 1.8) | ((mid > 6.0) & (mid < 8.0)), 0.05, 0.0)
    smoke = SmokeEchoes(np.array([0]), (np.diff(edges) * per_metre)[None, :], mid[None, :], edges[None, :], fractions)
    ranges, powers = smoke_returns(smoke, RX3, threshold=0.01)
    assert ranges.shape == (1, 2)
    assert ranges[0, 0] == pytest.approx(1.0 + 0.01 / 0.05)
    assert 5.0 < ranges[0, 1] < 6.5
    assert powers[0, 0] == pytest.approx(0.025) and powers[0, 1] == pytest.approx(0.025)


def _slab(density: float, near_m: float = 2.0, far_m: float = 5.5) -> SmokeRegion:
    return SmokeRegion("slab", Box((far_m - near_m, 4.0, 3.0)), Pose(((near_m + far_m) / 2, 0.0, 1.5)), Density(((0.0, density),)))


def _slab_scene(sigma: float, wall_m: float = 6.0):
    return reference_scene(objects=(panel("wall", wall_m, "white_paper", width_m=4.0),), regions=(_slab(sigma / K),))


def test_a_wall_behind_a_smoke_slab_in_a_scene_matches_the_hand_computed_echoes():
    """Wall at 6 m (white paper), slab 2–5.5 m: the wall's echo is its clear-air echo × exp(−2σL);
    the slab's is the backscatter of the pulse's first length in it, beta·V·(1+(σ/σ_ms)^3)·∫σ e^{−2σu} G."""
    sigma, length = 0.3, 3.5
    hits, beams = cast_beams(_slab_scene(sigma), "lms", np.array([0.0]), 0.0)
    lists = echo_lists(hits, beams, UTM, QUIET)
    assert lists.count[0] == 2
    clear = 0.9 / 0.9 * float(range_law(np.array(6.0), UTM, QUIET))
    assert lists.ranges_m[0, 1] == pytest.approx(6.0, abs=1e-9)
    assert lists.powers[0, 1] == pytest.approx(clear * np.exp(-2 * sigma * length), rel=1e-9)
    u = np.linspace(0.0, UTM.separation_m, 20001)
    share = UTM.volume_gain * QUIET.backscatter_ratio * (1 + (sigma / QUIET.multiple_scattering_extinction) ** 3)
    gathered = share * np.concatenate([[0.0], np.cumsum(np.diff(u) * (sigma * np.exp(-2 * sigma * u) * range_law(2.0 + u, UTM, QUIET))[1:])])
    threshold = np.exp(log_threshold(UTM, QUIET, K))
    assert lists.powers[0, 0] == pytest.approx(gathered[-1], rel=0.02)
    assert lists.ranges_m[0, 0] == pytest.approx(2.0 + np.interp(threshold, gathered, u), abs=0.01)


def test_clear_air_echoes_are_the_single_echo_physics_surfaces():
    """Continuity: without smoke every beam's one echo is the `physical` model's surface, range and power exactly."""
    scene = reference_scene(objects=(panel("wall", 6.0, "white_paper", width_m=4.0), panel("near", 3.0, "black_velvet", width_m=0.4)))
    angles = np.radians(np.linspace(-30, 30, 241))
    hits, beams = cast_beams(scene, "lms", angles, 0.0)
    for receiver in (PULSED_RECEIVERS["utm-30lx"], PULSED_RECEIVERS["tim571"]):
        lists = echo_lists(hits, beams, receiver, QUIET)
        surfaces = beam_physics_at(Instants.of([hits], [beams]), receiver, QUIET).surfaces
        single = surfaces.single & (surfaces.amp[:, 0] >= np.exp(log_threshold(receiver, QUIET, K)))
        assert single.sum() > 100
        np.testing.assert_array_equal(lists.ranges_m[single, 0], surfaces.range_m[single, 0])
        np.testing.assert_array_equal(lists.powers[single, 0], surfaces.amp[single, 0])


def test_a_footprint_over_two_surfaces_gives_two_echoes():
    """A narrow panel 3 m ahead of a wall at 6 m: beams grazing its edge see both (mixed pixels)."""
    scene = reference_scene(objects=(panel("wall", 6.0, "white_paper", width_m=6.0), panel("post", 3.0, "white_paper", width_m=0.4)))
    angles = np.radians(np.linspace(-8, 8, 641))
    hits, beams = cast_beams(scene, "lms", angles, 0.0)
    lists = echo_lists(hits, beams, UTM, QUIET)
    both = lists.count == 2
    assert 1 <= both.sum() <= 8
    np.testing.assert_allclose(lists.ranges_m[both, 0], 3.0, atol=0.01)
    np.testing.assert_allclose(lists.ranges_m[both, 1], 6.0, atol=0.03)  # a sub-ray meets the flat wall obliquely
    without = echo_lists(hits, beams, UTM, dataclasses.replace(QUIET, mixed_pixels=False))
    assert without.count.max() == 1


def test_a_plume_crossing_the_beam_gives_the_first_echo_on_the_puff_and_the_last_on_the_wall():
    plume = Plume("puff", source=(3.0, 0.0, 0.3), rate=1.0, lifetime=1.0, size=1.0, growth=0.0, velocity=(0.0, 0.0, 0.0),
                  spread=0.0, wind=(0.0, 0.0, 0.0), density=0.004)  # one puff at a time
    scene = reference_scene(objects=(panel("wall", 8.0, "white_paper", width_m=6.0),), plumes=(plume,))
    hits, beams = cast_beams(scene, "lms", np.array([0.0]), 5.5)
    lists = echo_lists(hits, beams, UTM, QUIET)
    assert lists.count[0] == 2
    assert 2.0 < lists.echo(FIRST)[0][0] < 4.0
    assert lists.echo(LAST)[0][0] == pytest.approx(8.0, abs=1e-6)


def test_a_batch_of_instants_equals_each_instant_alone():
    ramp = dataclasses.replace(_slab(0.0), density=Density(((0.0, 0.0), (1.0, 0.0), (2.0, 0.002))))
    scene = reference_scene(objects=(panel("wall", 6.0, "white_paper", width_m=4.0),), regions=(ramp,), seed=3)
    world = World(scene)
    angles = np.radians(np.linspace(-10, 10, 81))
    times = [0.5, 1.2, 1.5, 1.9, 2.5]
    casts = [cast_beams(scene, "lms", angles, t, world) for t in times]
    together = echo_lists_at([c[0] for c in casts], [c[1] for c in casts], UTM, DEFAULT_PARAMS)
    assert together.ranges_m.shape == (5, 81, 3)
    for k, (hits, beams) in enumerate(casts):
        alone = echo_lists(hits, beams, UTM, DEFAULT_PARAMS)
        np.testing.assert_array_equal(together.ranges_m[k], alone.ranges_m)
        np.testing.assert_array_equal(together.powers[k], alone.powers)
    assert together.count[0].max() == 1 and together.count[-1].max() == 2  # no smoke yet; slab and wall


def test_the_noise_is_seeded_by_scene_sensor_and_time():
    scene = _slab_scene(0.3)
    hits, beams = cast_beams(scene, "lms", np.array([0.0, 0.1]), 1.0)
    a, b = echo_lists(hits, beams, UTM), echo_lists(hits, beams, UTM)
    np.testing.assert_array_equal(a.ranges_m, b.ranges_m)
    quiet = echo_lists(hits, beams, UTM, dataclasses.replace(DEFAULT_PARAMS, noise=False))  # the same fluctuations
    assert not np.array_equal(a.ranges_m[:, :2], quiet.ranges_m[:, :2])
    assert np.nanmax(np.abs(a.ranges_m - quiet.ranges_m)) < 6 * UTM.range_sigma_m


def test_every_model_has_a_receiver_with_its_echo_count():
    counts = {name: receiver.max_echoes for name, receiver in PULSED_RECEIVERS.items()}
    assert counts == {"utm-30lx": 1, "utm-30lx-ew": 3, "ust-10lx": 3, "ust-20lx": 3,
                      "tim561": 1, "tim571": 1, "tim781": 1, "lms111": 2, "lms511": 5}
    assert all(dynamic_range(receiver) > 1 for receiver in PULSED_RECEIVERS.values())


_candidates = st.integers(1, 6).flatmap(
    lambda c: st.tuples(
        st.lists(st.lists(st.floats(0.05, 60.0), min_size=c, max_size=c), min_size=1, max_size=8),
        st.lists(st.lists(st.sampled_from([0.0, 0.002, 0.006, 0.011, 0.03, 0.5]), min_size=c, max_size=c), min_size=1, max_size=8),
    )
)


@settings(max_examples=200, deadline=None)
@given(_candidates, st.integers(1, 5), st.sampled_from([0.1, 0.6, 2.0]), st.booleans())
def test_any_echo_list_is_sorted_bounded_and_above_the_threshold(candidates, max_echoes, separation, fog_filter):
    ranges, powers = candidates
    rows = min(len(ranges), len(powers))
    ranges, powers = np.array(ranges[:rows]), np.array(powers[:rows])
    receiver = PulsedReceiver(overlap_m=0.05, footprint_rad=0.004, max_echoes=max_echoes, separation_m=separation,
                              fog_filter_m=10.0, fog_filter_gain=2.0)
    lists = select_echoes(ranges, powers, TH, receiver, fog_filter=fog_filter)
    assert lists.ranges_m.shape == (rows, max_echoes)
    for row in range(rows):
        count = lists.count[row]
        seen = lists.ranges_m[row, :count]
        assert count <= max_echoes and np.isnan(lists.ranges_m[row, count:]).all() and not lists.powers[row, count:].any()
        assert np.all(np.diff(seen) >= separation * (1 - 1e-9))  # sorted, and apart by at least the separation
        level = np.where(fog_filter & (seen < 10.0), 2.0 * TH, TH)
        assert np.all(lists.powers[row, :count] >= level * (1 - 1e-12))
        total = powers[row].sum()
        assert lists.powers[row, :count].sum() <= total * (1 + 1e-12)
        if count:  # the first and last echoes lie within the candidates' span
            assert ranges[row][powers[row] > 0].min() - 1e-9 <= seen[0] <= seen[-1] <= ranges[row][powers[row] > 0].max() + 1e-9


@settings(max_examples=100, deadline=None)
@given(st.floats(0.1, 59.0), st.floats(0.0, 2.0))
def test_a_single_return_is_reported_unchanged_or_not_at_all(range_m, power):
    lists = select_echoes(np.array([[range_m]]), np.array([[power]]), TH, RX3)
    if power >= TH:
        assert lists.count[0] == 1 and lists.ranges_m[0, 0] == range_m and lists.powers[0, 0] == power
    else:
        assert lists.count[0] == 0


def test_nearest_first_moves_the_seen_echoes_to_the_front_in_order_and_fills_with_minus_one():
    rng = np.random.default_rng(3)
    seen = rng.random((2, 50, 3)) < 0.5
    values, strengths = rng.integers(0, 60000, seen.shape), rng.integers(0, 9000, seen.shape)
    echoes, intensities = nearest_first(seen, values, strengths)
    for index in np.ndindex(seen.shape[:2]):
        kept = seen[index]
        expected = list(values[index][kept]) + [-1] * int((~kept).sum())
        assert list(echoes[index]) == expected
        assert list(intensities[index]) == list(strengths[index][kept]) + [-1] * int((~kept).sum())
