"""The bundled `rescue` scene: a robot's closed 60 s loop through a smoky building, with its sensors on board."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from emulator.optics import World
from emulator.scene import load_scene
from emulator.scene.bodies import matrix_euler_deg
from emulator.sensors import create_sensor, ranges_m, urg04lx

LOOP_S = 60.0


@pytest.fixture(scope="module")
def rescue():
    return load_scene("rescue")


def test_the_robot_carries_its_sensors_with_their_endpoints(rescue) -> None:
    assert {(s.name, s.model, s.body) for s in rescue.sensors} == {
        ("urg", "urg-04lx", "robot"), ("utm", "utm-30lx-ew", "robot"), ("lms", "lms200", "robot"),
    }
    assert rescue.sensor("urg").endpoints == ("pty:ttyURG0", "tcp:127.0.0.1:10940")
    assert rescue.sensor("utm").endpoints == ("tcp:127.0.0.1:10941",)
    assert rescue.sensor("utm").pose == rescue.sensor("urg").pose  # the multi-echo unit on the URG's mount


def test_the_loop_closes_in_about_a_minute_at_speeds_a_real_robot_has(rescue) -> None:
    times = np.arange(0.0, LOOP_S + 1e-9, 0.05)
    frames = World(rescue).bodies.frames("robot", times)
    np.testing.assert_allclose(frames.positions[0], frames.positions[-1], atol=1e-9)
    yaw = np.unwrap(np.radians([matrix_euler_deg(r)[2] for r in frames.rotations]))
    assert np.degrees(yaw[-1] - yaw[0]) == pytest.approx(360.0)  # once round, counter-clockwise
    assert np.degrees(np.abs(np.diff(yaw))).max() / 0.05 <= 45.0  # yaw rate, deg/s
    speed = np.linalg.norm(np.diff(frames.positions, axis=0), axis=1) / 0.05
    assert speed.max() <= 1.0 and np.sum(speed * 0.05) > 30.0  # metres driven


def test_the_path_is_clear_and_structure_is_always_in_reach(rescue) -> None:
    """Nothing solid within 0.4 m of the URG-04LX anywhere on the loop, and at every instant a good share
    of its beams see a surface (what scan matching needs), in clear air before the smoke starts."""
    sensor = create_sensor(dataclasses.replace(rescue, regions=(), plumes=()), "urg")
    for time_s in np.arange(0.1, LOOP_S, 1.0):
        ranges = ranges_m(sensor.scan(float(time_s)))[urg04lx.FIRST_VALID_STEP : urg04lx.LAST_VALID_STEP + 1]
        assert np.nanmin(ranges) > 0.4, time_s
        assert np.mean(np.isfinite(ranges)) > 0.6, time_s


def test_smoke_fills_part_of_the_building_during_the_run(rescue) -> None:
    densities = {region.name: [region.density.at(t) for t in (0.0, 31.9, 32.0, 45.0)] for region in rescue.regions}
    assert densities["east_room"][0] == 0.0 and densities["east_room"][3] > 0.002
    assert densities["corridor_haze"][1] == 0.0 and densities["corridor_haze"][2] > 0.001  # a step at 32 s
    urg = create_sensor(rescue, "urg")
    in_smoke = urg.scan(20.0).values[urg04lx.FIRST_VALID_STEP : urg04lx.LAST_VALID_STEP + 1]
    clear = urg.scan(5.0).values[urg04lx.FIRST_VALID_STEP : urg04lx.LAST_VALID_STEP + 1]
    assert np.mean(in_smoke == urg04lx.LOW_INTENSITY) > 0.1 > np.mean(clear == urg04lx.LOW_INTENSITY)


def test_the_slam_bench_uses_rescues_own_utm(rescue) -> None:
    from emulator.bench.slam_echoes import with_utm_on_the_urgs_mount

    assert with_utm_on_the_urgs_mount(rescue) is rescue
    others = dataclasses.replace(rescue, sensors=tuple(spec for spec in rescue.sensors if spec.name != "utm"))
    added = with_utm_on_the_urgs_mount(others).sensor("utm")
    assert (added.model, added.body, added.pose) == ("utm-30lx-ew", "robot", rescue.sensor("urg").pose)
