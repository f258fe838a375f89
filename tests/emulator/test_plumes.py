"""Plume particles: analytic in time, deterministic from the seed (docs/scene-format.md)."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from emulator.scene.model import Plume
from emulator.scene.plumes import particles_at, uniforms


def plume(**changes) -> Plume:
    fields = dict(
        name="fire", source=(1.0, 2.0, 0.5), rate=20.0, lifetime=5.0, size=0.4, growth=0.1,
        velocity=(0.0, 0.0, 0.6), spread=0.2, wind=(0.8, 0.3, 0.0), density=0.05, start=0.0, stop=1e9,
    )
    fields.update(changes)
    return Plume(**fields)


@settings(max_examples=200, deadline=None)
@given(
    rate=st.floats(0.5, 50.0),
    lifetime=st.floats(0.05, 30.0),
    start=st.floats(-10.0, 10.0),
    window=st.floats(0.01, 60.0),
    time_s=st.floats(-20.0, 80.0),
)
def test_alive_particles_are_exactly_those_born_and_not_yet_dead(rate, lifetime, start, window, time_s):
    p = plume(rate=rate, lifetime=lifetime, start=start, stop=start + window)
    got = particles_at(p, 1, 0, time_s).index
    expected = []
    i = 0
    while start + i / rate <= time_s:  # independent reference: walk the births
        birth = start + i / rate
        if birth < p.stop and time_s < birth + lifetime:
            expected.append(i)
        i += 1
    assert got.tolist() == expected


def test_positions_follow_velocity_wind_and_growth_exactly_without_spread():
    p = plume(spread=0.0)
    particles = particles_at(p, 3, 0, 2.0)
    age = 2.0 - particles.index / p.rate
    expected = np.array(p.source) + np.outer(age, np.add(p.velocity, p.wind))
    np.testing.assert_allclose(particles.centers, expected, rtol=0, atol=1e-12)
    np.testing.assert_allclose(particles.half_sizes, (p.size + p.growth * age) / 2, rtol=0, atol=1e-12)
    assert np.all(particles.density == p.density)


def test_same_seed_gives_identical_particles_in_any_evaluation_order():
    p = plume()
    late_first = particles_at(p, 7, 2, 9.0)
    particles_at(p, 7, 2, 1.0)
    again = particles_at(p, 7, 2, 9.0)
    np.testing.assert_array_equal(late_first.centers, again.centers)
    np.testing.assert_array_equal(late_first.index, again.index)


def test_a_particle_keeps_its_velocity_offset_over_its_life():
    p = plume(wind=(0.0, 0.0, 0.0), velocity=(0.0, 0.0, 0.0), growth=0.0)
    early, late = particles_at(p, 5, 0, 3.0), particles_at(p, 5, 0, 4.0)
    shared, at_early, at_late = np.intersect1d(early.index[:-1], late.index, return_indices=True)  # not the newborn
    assert len(shared) > 10
    velocity_early = (early.centers[at_early] - p.source) / (3.0 - shared / p.rate)[:, None]
    velocity_late = (late.centers[at_late] - p.source) / (4.0 - shared / p.rate)[:, None]
    np.testing.assert_allclose(velocity_early, velocity_late, rtol=1e-9, atol=1e-12)


def test_other_seed_or_plume_index_gives_a_different_plume():
    p = plume()
    base = particles_at(p, 7, 0, 4.0).centers
    assert not np.allclose(base, particles_at(p, 8, 0, 4.0).centers)
    assert not np.allclose(base, particles_at(p, 7, 1, 4.0).centers)


def test_velocity_offsets_are_normal_with_the_spread_as_standard_deviation():
    p = plume(rate=20000.0, lifetime=1.0, velocity=(0.0, 0.0, 0.0), wind=(0.0, 0.0, 0.0), source=(0.0, 0.0, 0.0), spread=0.3)
    particles = particles_at(p, 11, 0, 0.999)
    age = 0.999 - particles.index / p.rate
    keep = age > 0.01
    velocities = particles.centers[keep] / age[keep, None]
    n = keep.sum()
    assert n > 15000
    assert np.all(np.abs(velocities.mean(axis=0)) < 4 * 0.3 / math.sqrt(n))
    np.testing.assert_allclose(velocities.std(axis=0), 0.3, rtol=0.03)
    correlation = np.corrcoef(velocities.T)
    assert np.all(np.abs(correlation[np.triu_indices(3, 1)]) < 0.05)


def test_uniforms_cover_the_unit_interval_evenly():
    draws = uniforms(42, 0, np.arange(50000), 4).ravel()
    assert draws.min() >= 0.0 and draws.max() < 1.0
    counts, _ = np.histogram(draws, bins=20, range=(0.0, 1.0))
    expected = len(draws) / 20
    chi_squared = ((counts - expected) ** 2 / expected).sum()
    assert chi_squared < 45.0  # 19 degrees of freedom: p ≈ 0.0007


def test_a_hundred_thousand_live_particles_draw_their_offsets_once():
    # 10 000 particles/s for 10 s: about 98 blocks of offsets alive at once; each instant after the first
    # must find them all kept (a smaller cache drew every block again, at every instant)
    from emulator.scene.plumes import _offset_block

    p = plume(rate=10_000.0, lifetime=10.0)
    first = particles_at(p, 7, 0, 30.0)
    before = _offset_block.cache_info().misses
    again = particles_at(p, 7, 0, 30.05)
    assert _offset_block.cache_info().misses - before <= 1  # at most the block of the newest births
    shared = np.intersect1d(first.index, again.index)
    assert len(shared) > 99_000
