"""Live changes (scene/live.py): the world at t is a pure function of (scene, seed, events, t).

A change alters nothing before its instant; plume particles already alive
keep their birth parameters; scan caches drop what they computed at or
after a change; the wall clock stays continuous when its speed or pause changes.
"""

from __future__ import annotations

import dataclasses
import threading
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from emulator.daemon.clock import WallClock
from emulator.daemon.scan_cache import ScanCache
from emulator.optics import World
from emulator.scene import load_scene
from emulator.scene.live import PlumeChange, RegionChange, emission_segments
from emulator.scene.model import Density, Plume
from emulator.scene.plumes import particles_at
from emulator.sensors import create_sensor


def plume(**changes) -> Plume:
    fields = dict(
        name="fire", source=(1.0, 2.0, 0.5), rate=20.0, lifetime=5.0, size=0.4, growth=0.1,
        velocity=(0.0, 0.0, 0.6), spread=0.2, wind=(0.8, 0.3, 0.0), density=0.05, start=0.0, stop=1e9,
    )
    fields.update(changes)
    return Plume(**fields)


def particles(p: Plume, changes: list[PlumeChange], time_s: float):
    return particles_at(p, 3, 0, time_s, emission_segments(p, changes))


def test_a_plume_without_changes_is_bit_identical_to_the_scene_emission() -> None:
    p = plume(start=1.0, stop=9.0)
    for time_s in (0.5, 1.0, 3.3, 9.5, 13.9, 14.1):
        plain, split = particles_at(p, 3, 0, time_s), particles(p, [], time_s)
        np.testing.assert_array_equal(plain.index, split.index)
        np.testing.assert_array_equal(plain.centers, split.centers)
        np.testing.assert_array_equal(plain.half_sizes, split.half_sizes)


def test_switching_a_plume_off_stops_births_and_alive_particles_live_on() -> None:
    p = plume()
    off = [PlumeChange(2.0, "fire", emitting=False)]
    before = particles_at(p, 3, 0, 1.999)
    np.testing.assert_array_equal(particles(p, off, 1.999).centers, before.centers)  # nothing changes before
    later = particles(p, off, 4.0)
    unchanged = particles_at(p, 3, 0, 4.0)
    born_before = unchanged.index < 40  # births at i / 20 < 2.0
    np.testing.assert_array_equal(later.index, unchanged.index[born_before])
    np.testing.assert_array_equal(later.centers, unchanged.centers[born_before])
    assert len(particles(p, off, 7.01)) == 0  # all dead one lifetime after the last birth


def test_a_wind_change_reaches_only_particles_born_after_it() -> None:
    p = plume()
    gust = [PlumeChange(2.0, "fire", wind=(0.0, -3.0, 0.0))]
    now = particles(p, gust, 3.0)
    unchanged = particles_at(p, 3, 0, 3.0)
    old = now.index < 40
    np.testing.assert_array_equal(now.centers[old], unchanged.centers[unchanged.index < 40])
    assert len(np.unique(now.index)) == len(now.index)
    ages = 3.0 - (2.0 + (now.index[~old] - 40 + 1) / 20.0) + 1 / 20.0
    assert np.all(ages >= 0)
    # the young ones drift along -y: their mean y is below the source
    assert now.centers[~old, 1].mean() < p.source[1] - 0.5 * 3.0 * ages.mean()


def test_switching_on_overrides_the_scene_schedule_and_rate_changes_the_cadence() -> None:
    p = plume(start=50.0)
    on = [PlumeChange(1.0, "fire", emitting=True, rate=10.0)]
    assert len(particles(p, [], 2.0)) == 0
    alive = particles(p, on, 2.0)
    assert len(alive) == 11  # births at 1.0, 1.1, ..., 2.0


@settings(max_examples=60, deadline=None)
@given(
    times=st.lists(st.floats(0.0, 20.0), min_size=1, max_size=5).map(sorted),
    flags=st.lists(st.sampled_from([None, True, False]), min_size=5, max_size=5),
    rates=st.lists(st.sampled_from([None, 2.0, 15.0, 40.0]), min_size=5, max_size=5),
    time_s=st.floats(0.0, 30.0),
)
def test_particles_are_unique_and_alive_whatever_the_changes(times, flags, rates, time_s) -> None:
    p = plume(lifetime=2.0)
    changes = [PlumeChange(t, "fire", emitting=flags[i], rate=rates[i]) for i, t in enumerate(times)]
    alive = particles(p, changes, time_s)
    assert len(np.unique(alive.index)) == len(alive.index)
    assert np.all(alive.half_sizes >= 0.5 * p.size)
    assert np.all(alive.half_sizes < 0.5 * (p.size + p.growth * p.lifetime) + 1e-9)


@pytest.fixture(scope="module")
def railway():
    return load_scene("railway")


def test_a_density_change_holds_from_its_instant_and_drops_later_keyframes(railway) -> None:
    scene = dataclasses.replace(
        railway, regions=(dataclasses.replace(railway.regions[0], density=Density(((0.0, 0.0), (10.0, 1.0)))),)
    )
    world = World(scene)
    world.apply(RegionChange(4.0, scene.regions[0].name, 0.25))
    assert world.live.region_density(0, 3.999999) == pytest.approx(0.3999999)
    assert world.live.region_density(0, 4.0) == 0.25
    assert world.live.region_density(0, 20.0) == 0.25
    world.apply(RegionChange(2.0, scene.regions[0].name, 0.5))  # an earlier change replaces the later one
    assert world.live.region_density(0, 4.0) == 0.5


def test_a_sensor_sees_a_change_from_its_instant_on(railway) -> None:
    world = World(railway)
    urg = create_sensor(railway, "urg", world=world)
    before = urg.scan(1.0).values
    world.apply(RegionChange(1.05, "haze", 0.05))
    np.testing.assert_array_equal(urg.scan(1.0).values, before)
    assert np.sum(urg.scan(1.1).values < 20) > np.sum(before < 20) + 100


class CountingSensor:
    """A URG of the world, counting the instants it computes."""

    def __init__(self, scene, world) -> None:
        self.sensor = create_sensor(scene, "urg", world=world)
        self.instants: list[float] = []
        self.lock = threading.Lock()

    def scan(self, time_s, **request):
        return self.scans([time_s])[0]

    def scans(self, times_s, **request):
        with self.lock:
            self.instants += list(times_s)
        return self.sensor.scans(times_s)


def test_the_scan_cache_recomputes_what_it_foresaw_at_or_after_a_change(railway) -> None:
    world = World(railway)
    counting = CountingSensor(railway, world)
    with ThreadPoolExecutor(max_workers=1) as executor:
        cache = ScanCache(counting, executor)
        for index in range(1, 4):
            cache(index / 10)  # a steady stream: the next SCAN_BATCH scans are foreseen
        ahead = cache.request(0.6)
        ahead.result()
        stale = ahead.result().values
        world.apply(RegionChange(0.55, "haze", 0.05))
        cache.invalidate_from(0.55)
        assert not cache.holds(0.6, ahead)
        fresh = cache(0.6).values
        assert np.sum(fresh < 20) > np.sum(stale < 20) + 100
        np.testing.assert_array_equal(fresh, create_sensor(railway, "urg", world=world).scan(0.6).values)
        assert cache.holds(0.5, cache.request(0.5))  # before the change: kept
        ticks = [round(t * 1e6) for t in counting.instants]
        assert ticks.count(500_000) == 1 and ticks.count(600_000) == 2  # 0.6 again after the change


def test_the_wall_clock_is_continuous_when_its_speed_or_pause_changes() -> None:
    wall = [100.0]
    clock = WallClock(2.0, wall=lambda: wall[0])
    wall[0] += 1.0
    assert clock.now() == 2.0
    clock.set(speed=0.5)
    assert clock.now() == 2.0
    wall[0] += 2.0
    assert clock.now() == 3.0
    assert clock.wall_delay(1.0) == 2.0
    clock.set(paused=True)
    wall[0] += 5.0
    assert clock.now() == 3.0 and clock.wall_delay(0.1) == float("inf")
    clock.set(paused=False)
    wall[0] += 2.0
    assert clock.now() == 4.0
    with pytest.raises(ValueError):
        clock.set(speed=0.0)
    with pytest.raises(ValueError, match="speed must be >= 0.001"):
        clock.set(speed=1e-320)


def test_a_stream_of_changes_keeps_one_job_per_scan_under_way(railway) -> None:
    """Ten changes while the next scan computes start it again once, when it is asked for, not ten times."""
    world = World(railway)
    counting = CountingSensor(railway, world)
    gate = threading.Event()
    plain_scans = counting.scans

    def gated_scans(times_s, **request):
        gate.wait(10)
        return plain_scans(times_s, **request)

    counting.scans = gated_scans
    with ThreadPoolExecutor(max_workers=1) as executor:
        cache = ScanCache(counting, executor)
        gate.set()
        cache(0.1)  # one scan computed, the gate open
        gate.clear()
        cache.prefetch(0.2)  # the device's next scan: its job waits at the gate
        for change in range(10):
            time_s = 0.1 + (change + 1) * 0.005
            world.apply(RegionChange(time_s, "haze", 0.001 * change))
            cache.invalidate_from(time_s)
        waiting = cache.pending(0.2)
        assert waiting is not None and not waiting.done()  # the outdated job: wait for it, then ask again
        gate.set()
        waiting.result(10)
        fresh = cache.pending(0.2)
        assert fresh is not waiting
        np.testing.assert_array_equal(fresh.result(10).values, create_sensor(railway, "urg", world=world).scan(0.2).values)
        ticks = [round(t * 1e6) for t in counting.instants]
        assert ticks.count(200_000) == 2, ticks  # the outdated job and one fresh one
