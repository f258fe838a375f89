"""URG-04LX and LMS200 sensors: beam geometry, error codes, windows, units, determinism."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from emulator.errors import UserError
from emulator.optics import World
from emulator.scene.model import (
    Box,
    Density,
    Material,
    Plume,
    Pose,
    Scene,
    SceneObject,
    SensorSpec,
    SmokeRegion,
)
from emulator.sensors import LmsSensor, UrgSensor, create_sensor, ranges_m

MATERIALS = {"default": Material("default", 0.5)}


def wall(x: float, width: float = 20.0, y: float = 0.0) -> SceneObject:
    """A wall whose near face is at x (it faces the sensor at the origin)."""
    return SceneObject("wall", Box((0.2, width, 4.0)), Pose((x + 0.1, y, 0.0)), "default")


def scene(objects=(), regions=(), plumes=(), seed=1, yaw=0.0, position=(0.0, 0.0, 0.0)) -> Scene:
    sensors = (
        SensorSpec("urg", "urg-04lx", Pose(position, (0.0, 0.0, yaw)), ()),
        SensorSpec("lms", "lms200", Pose(position, (0.0, 0.0, yaw)), ()),
    )
    return Scene(None, "test", "", seed, "formsma2011", 250.0, MATERIALS, tuple(objects), tuple(regions), tuple(plumes), sensors)


def smoke(density: float | Density, size=(20.0, 20.0, 4.0), position=(0.0, 0.0, 0.0)) -> SmokeRegion:
    keyframes = density if isinstance(density, Density) else Density(((0.0, density),))
    return SmokeRegion("smoke", Box(size), Pose(position), keyframes)


def parked(center, edge=0.3) -> Plume:
    return Plume("parked", tuple(center), 1.0, 1e6, edge, 0.0, (0, 0, 0), 0.0, (0, 0, 0), 0.05)


FRONT = 384


# --- URG-04LX ---------------------------------------------------------------------------------------


def test_urg_steps_angles_and_timing():
    urg = create_sensor(scene([wall(3.0)]), "urg")
    assert isinstance(urg, UrgSensor) and urg.model == "urg-04lx" and urg.period_s == 0.1
    scan = urg.scan(0.5)
    assert len(scan.values) == len(scan.angles_rad) == 769
    assert scan.angles_rad[FRONT] == 0.0
    assert scan.angles_rad[FRONT + 256] == pytest.approx(math.pi / 2)  # 1024 steps per turn, positive left
    assert scan.angles_rad[0] == pytest.approx(-384 * 2 * math.pi / 1024)
    assert scan.time_s == 0.5 and scan.timestamp_ms == 500 and scan.unit == "mm"
    assert scan.values.dtype.kind == "i"


def test_urg_range_to_a_wall_in_millimetres():
    values = create_sensor(scene([wall(3.0)]), "urg").scan(0.0).values
    assert values[FRONT] == 3000
    angle = 10 * 2 * math.pi / 1024
    assert values[FRONT + 10] == round(3000 / math.cos(angle))
    assert values[FRONT - 10] == round(3000 / math.cos(angle))


def test_urg_steps_outside_the_valid_area_carry_code_0():
    room = SceneObject("room", Box((3.0, 3.0, 4.0)), Pose((0.0, 0.0, 0.0)), "default")  # seen from inside
    values = create_sensor(scene([room]), "urg").scan(0.0).values
    assert np.all(values[:44] == 0) and np.all(values[726:] == 0)
    assert np.all(values[44:726] >= 1500)  # every valid step measures a wall


def test_urg_nothing_within_5600_mm_returns_0():
    values = create_sensor(scene([wall(5.65)]), "urg").scan(0.0).values
    assert values[FRONT] == 0
    assert create_sensor(scene([wall(5.55)]), "urg").scan(0.0).values[FRONT] == 5550


def test_urg_closer_than_20_mm_returns_19():
    values = create_sensor(scene([wall(0.015)]), "urg").scan(0.0).values
    assert values[FRONT] == 19
    assert create_sensor(scene([wall(0.025)]), "urg").scan(0.0).values[FRONT] == 25


def test_urg_smoke_above_the_penetration_power_returns_1():
    """2.5 m of smoke in front of the target: the threshold is density 0.0028 (0.007 d·m)."""
    target = wall(2.5)
    below = create_sensor(scene([target], [smoke(0.00279)]), "urg").scan(0.0).values
    above = create_sensor(scene([target], [smoke(0.00281)]), "urg").scan(0.0).values
    assert below[FRONT] == 2500 and above[FRONT] == 1


def test_urg_smoke_behind_the_target_does_not_count():
    behind = smoke(0.1, size=(5.0, 20.0, 4.0), position=(5.2, 0.0, 0.0))
    assert create_sensor(scene([wall(2.5)], [behind]), "urg").scan(0.0).values[FRONT] == 2500


def test_urg_keyframed_smoke_switches_at_the_interpolated_time():
    """Density ramps 0 → 0.004 over 10 s; it passes 0.0028 (2.5 m × 0.0028 = 0.007) at t = 7 s."""
    ramp = Density(((0.0, 0.0), (10.0, 0.004)))
    urg = create_sensor(scene([wall(2.5)], [smoke(ramp)]), "urg")
    assert urg.scan(6.99).values[FRONT] == 2500
    assert urg.scan(7.01).values[FRONT] == 1


def test_urg_plume_particle_before_the_wall_returns_1_behind_it_nothing():
    urg = create_sensor(scene([wall(3.0)], plumes=[parked((1.5, 0.0, 0.0)), parked((4.0, 0.5, 0.0))]), "urg")
    values = urg.scan(1.0).values
    assert values[FRONT] == 1
    step_to_hidden = FRONT + round(math.atan2(0.5, 4.0) / (2 * math.pi / 1024))
    assert values[step_to_hidden] == round(3000 / math.cos((step_to_hidden - FRONT) * 2 * math.pi / 1024))


def test_urg_ranges_m():
    scan = create_sensor(scene([wall(2.0)]), "urg").scan(0.0)
    ranges = ranges_m(scan)
    assert ranges[FRONT] == 2.0
    assert np.all(np.isnan(ranges[:44]))


def test_sensor_pose_turns_and_moves_the_beams():
    moved = create_sensor(scene([wall(3.0)], yaw=90.0, position=(0.0, -1.0, 0.0)), "urg").scan(0.0).values
    assert moved[FRONT - 256] == 3000  # looking along +y, its right points at the wall along +x
    assert moved[FRONT] == 0


# --- LMS200 --------------------------------------------------------------------------------------------


def test_lms_device_angles_map_to_the_sensor_frame():
    lms = create_sensor(scene([wall(3.0)]), "lms")
    assert isinstance(lms, LmsSensor) and lms.model == "lms200" and lms.period_s == pytest.approx(1 / 75)
    scan = lms.scan(0.0)
    assert len(scan.values) == 361
    assert scan.angles_rad[0] == pytest.approx(-math.pi / 2) and scan.angles_rad[-1] == pytest.approx(math.pi / 2)
    assert scan.values[180] == 3000  # device 90° = straight ahead


@pytest.mark.parametrize(
    "start, step, count",
    [(0.0, 1.0, 181), (0.0, 0.5, 361), (0.0, 0.25, 401), (40.0, 1.0, 101), (40.0, 0.5, 201), (40.0, 0.25, 401), (0.25, 1.0, 180)],
)
def test_lms_windows(start, step, count):
    scan = create_sensor(scene([wall(3.0)]), "lms").scan(0.0, start_deg=start, step_deg=step, count=count)
    expected_deg = start + step * np.arange(count) - 90.0
    np.testing.assert_allclose(np.degrees(scan.angles_rad), expected_deg, atol=1e-9)
    expected = np.rint(3000.0 / np.cos(np.radians(expected_deg)))
    ahead = np.abs(expected_deg) < 60
    np.testing.assert_array_equal(scan.values[ahead], expected[ahead])


def test_lms_units_and_codes():
    lms = create_sensor(scene([wall(9.0, width=4.0)]), "lms")
    mm = lms.scan(0.0, unit="mm")
    cm = lms.scan(0.0, unit="cm")
    assert mm.values[180] == 8183  # 9 m is beyond 8183 mm
    assert cm.values[180] == 900 and cm.unit == "cm"
    assert mm.values[0] == 8191 and cm.values[0] == 8191  # nothing within 80 m to the right
    assert np.isnan(ranges_m(mm)[180]) and ranges_m(cm)[180] == 9.0
    far = create_sensor(scene([wall(79.0, width=4.0)]), "lms").scan(0.0, unit="cm").values[180]
    beyond = create_sensor(scene([wall(81.0, width=4.0)]), "lms").scan(0.0, unit="cm").values[180]
    assert far == 7900 and beyond == 8191
    with pytest.raises(ValueError):
        lms.scan(0.0, unit="m")


def test_lms_sees_a_particle_as_a_solid_and_smoke_regions_not_at_all():
    lms = create_sensor(scene([wall(3.0)], [smoke(0.05)], [parked((1.5, 0.0, 0.0))]), "lms")
    values = lms.scan(1.0).values
    assert values[180] == 1350  # the particle's near face
    assert values[120] == round(3000 / math.cos(math.radians(30)))  # device 60°: dense smoke region, transparent


# --- determinism, creation ------------------------------------------------------------------------------


def drifting_plume() -> Plume:
    return Plume("fire", (2.0, 0.0, -0.5), 20.0, 10.0, 0.2, 0.05, (0.0, 0.0, 0.1), 0.4, (0.0, 0.2, 0.0), 0.05)


def test_same_seed_same_scans_other_seed_other_plume():
    base = scene([wall(4.0)], plumes=[drifting_plume()], seed=7)
    first = create_sensor(base, "urg").scan(6.0).values
    again = create_sensor(base, "urg").scan(6.0).values
    other = create_sensor(dataclasses.replace(base, seed=8), "urg").scan(6.0).values
    np.testing.assert_array_equal(first, again)
    assert np.count_nonzero(first == 1) > 5
    assert not np.array_equal(first, other)
    lms_first = create_sensor(base, "lms").scan(6.0).values
    np.testing.assert_array_equal(lms_first, create_sensor(base, "lms").scan(6.0).values)


def test_sensors_share_a_world():
    base = scene([wall(4.0)])
    world = World(base)
    assert create_sensor(base, "urg", world).world is world
    assert create_sensor(base, "lms", world).world is world


def test_unknown_sensor_names_the_known_ones():
    with pytest.raises(UserError, match=r"no sensor named 'front'.*known: urg, lms"):
        create_sensor(scene(), "front")


def test_unknown_response_model_is_a_user_error():
    with pytest.raises(UserError, match="unknown smoke model 'fancy'"):
        create_sensor(dataclasses.replace(scene(), model="fancy"), "urg")


def test_configured_scan_follows_the_scene_options():
    base = scene([wall(3.0)])
    narrow = dataclasses.replace(
        base, sensors=(SensorSpec("lms", "lms200", Pose(), (), {"angle_deg": 100, "resolution_deg": 0.25, "units": "cm"}),)
    )
    lms = create_sensor(narrow, "lms")
    scan = lms.configured_scan(0.0)
    assert len(scan.values) == 401 and scan.unit == "cm" and scan.values[200] == 300
    assert np.degrees(scan.angles_rad[0]) == pytest.approx(-50.0) and np.degrees(scan.angles_rad[-1]) == pytest.approx(50.0)
    assert lms.configured_period_s == pytest.approx(4 / 75)
    urg = create_sensor(base, "urg")
    np.testing.assert_array_equal(urg.configured_scan(0.0).values, urg.scan(0.0).values)
    assert urg.configured_period_s == 0.1


@pytest.mark.parametrize("preset", ["formsma2011", "physical"])
def test_lms_reflector_echoes_come_from_retroreflective_materials(preset: str) -> None:
    """The sensor decides per beam whether its echo is a reflector's; the protocol only encodes it."""
    tape = SceneObject("tape", Box((0.1, 0.4, 4.0)), Pose((3.05, 0.0, 0.0)), "tape")
    far = SceneObject("far", Box((0.2, 60.0, 4.0)), Pose((20.1, 0.0, 0.0)), "default")
    materials = {**MATERIALS, "tape": Material("tape", 1.0, retroreflective=True)}
    full = dataclasses.replace(scene([tape, far]), materials=materials, model=preset)
    lms = LmsSensor(full, full.sensors[1], World(full))
    narrow = lms.scan(1.0, start_deg=70.0, step_deg=1.0, count=41, unit="mm")
    ahead = np.abs(narrow.angles_rad) < math.radians(2)
    assert narrow.reflector is not None and narrow.reflector[ahead].all()
    assert not narrow.reflector[np.abs(narrow.angles_rad) > math.radians(10)].any()
    assert np.all(np.abs(narrow.values[ahead] - 3000) < 100)


def test_lms_field_bits_widen_the_range_and_move_the_codes() -> None:
    lms = create_sensor(scene([wall(20.0, width=60.0)]), "lms")
    ahead = slice(88, 93)
    assert np.all(lms.scan(1.0, start_deg=0.0, step_deg=1.0, count=181, field_bits=13).values[ahead] == 8183)
    assert np.all(lms.scan(1.0, start_deg=0.0, step_deg=1.0, count=181, field_bits=14).values[ahead] == 16375)
    assert np.all(np.abs(lms.scan(1.0, start_deg=0.0, step_deg=1.0, count=181, field_bits=15).values[ahead] - 20000) < 50)
    nothing = create_sensor(scene([]), "lms").scan(1.0, start_deg=0.0, step_deg=1.0, count=181, field_bits=15)
    assert np.all(nothing.values == 0x7FFF) and not nothing.reflector.any()
