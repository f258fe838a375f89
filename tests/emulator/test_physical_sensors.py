"""The `physical` model as the sensors serve it: determinism from the seed, the model override."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from emulator.errors import UserError
from emulator.optics import World
from emulator.scene import load_scene
from emulator.scene.model import Density, Plume
from emulator.sensors import create_sensor
from emulator.sensors.response import apply_model_override
from emulator.validation.reference_scenes import panel, reference_scene, room


def _scans(scene, time_s):
    world = World(scene)
    return create_sensor(scene, "urg", world).scan(time_s).values, create_sensor(scene, "lms", world).scan(time_s).values


def test_scans_are_a_function_of_seed_and_time():
    scene = reference_scene(objects=(panel("wall", 3.0, "white_paper", width_m=6.0),), regions=(room(0.002),), seed=11)
    first = _scans(scene, 4.2)
    again = _scans(scene, 4.2)
    for a, b in zip(first, again):
        np.testing.assert_array_equal(a, b)
    for other in (_scans(dataclasses.replace(scene, seed=12), 4.2), _scans(scene, 4.3)):
        for a, b in zip(first, other):
            assert not np.array_equal(a, b)


def test_apply_model_override():
    scene = load_scene("marulan")
    assert apply_model_override(scene, None) is scene
    physical_scene = apply_model_override(scene, "physical")
    assert physical_scene.model == "physical" and physical_scene.objects == scene.objects
    with pytest.raises(UserError, match="unknown smoke model 'bogus' .*formsma2011.*physical"):
        apply_model_override(scene, "bogus")


def test_bundled_scenes_scan_under_the_physical_model():
    for name in ("railway", "marulan", "bocas"):
        scene = apply_model_override(load_scene(name), "physical")
        world = World(scene)
        for spec in scene.sensors:
            values = create_sensor(scene, spec.name, world).scan(30.0).values
            assert values.dtype.kind == "i" and values.min() >= 0
            if spec.model == "lms200":
                assert values.max() <= 8191


@pytest.mark.parametrize("preset", ["formsma2011", "physical"])
def test_what_sensors_keep_between_scans_changes_no_value(preset):
    """Prepared beams, surfaces, fan geometry and the last instant's particles are kept across scans
    (objects never move): two sensors sharing a world, scanning interleaved instants in any order,
    give exactly the values of a fresh world and sensor per scan."""
    scene = apply_model_override(load_scene("railway"), preset)
    world = World(scene)
    kept = {name: create_sensor(scene, name, world) for name in ("urg", "lms")}
    for time_s in (20.0, 3.5, 20.0, 41.25, 3.5):
        for name in ("lms", "urg"):
            fresh = create_sensor(scene, name, World(scene)).configured_scan(time_s).values
            np.testing.assert_array_equal(kept[name].configured_scan(time_s).values, fresh)


def _smoke_that_comes_and_goes():
    """A plume starting at 0.95 s and a room whose smoke starts at 1.3 s (density 0 before): a batch spanning
    those instants mixes rows with no smoke, plume smoke only, and both."""
    ramp = dataclasses.replace(room(0.0), density=Density(((0.0, 0.0), (1.3, 0.0), (1.6, 0.004), (3.0, 0.001))))
    plume = Plume("puffs", (2.0, 0.3, 0.3), 10.0, 2.0, 0.3, 0.1, (0.4, 0.0, 0.0), 0.2, (0.0, 0.2, 0.0), 0.4, start=0.95)
    objects = (panel("wall", 3.5, "white_paper", width_m=6.0), panel("steel", 1.8, "rusty_steel", yaw_deg=35.0))
    return reference_scene(objects=objects, regions=(ramp,), plumes=(plume,), seed=5)


@pytest.mark.parametrize("sensor", ["urg", "lms"])
def test_scans_computed_together_equal_each_scan_computed_alone(sensor):
    scene = _smoke_that_comes_and_goes()
    together_sensor, alone_sensor = create_sensor(scene, sensor, World(scene)), create_sensor(scene, sensor, World(scene))
    times = [0.9 + k * 0.08 for k in range(9)] + [2.5, 7.0]  # smoke absent, arriving, thick, leaving; uneven steps
    together = together_sensor.scans(times)
    assert [scan.time_s for scan in together] == times
    for scan in together:
        np.testing.assert_array_equal(scan.values, alone_sensor.scan(scan.time_s).values)
    assert len({scan.values.tobytes() for scan in together}) == len(times)  # the instants really differ


@pytest.mark.parametrize("sensor", ["urg", "lms"])
@pytest.mark.parametrize("puffs_per_pass", [1, 45])
def test_a_batch_split_into_passes_by_its_puffs_equals_one_pass(sensor, puffs_per_pass, monkeypatch):
    """A dense plume's batch is computed a few instants at a time (`PUFFS_PER_PASS`): the values must be
    those of one pass over every instant, whichever instants each pass takes."""
    import emulator.sensors.physical.preset as preset

    scene = _smoke_that_comes_and_goes()
    times = [0.9 + k * 0.08 for k in range(9)] + [2.5, 7.0]
    one_pass = create_sensor(scene, sensor, World(scene)).scans(times)
    monkeypatch.setattr(preset, "PUFFS_PER_PASS", puffs_per_pass)
    world = World(scene)
    split = create_sensor(scene, sensor, world).scans(times)
    beams = [type("Instant", (), {"world": world, "time_s": t}) for t in times]
    assert 3 <= len(preset._passes(beams)) < len(times) or puffs_per_pass == 1  # passes of several instants
    for together, apart in zip(one_pass, split):
        np.testing.assert_array_equal(apart.values, together.values)
    assert len({scan.values.tobytes() for scan in split}) == len(times)


def test_a_scan_is_evaluated_on_the_microsecond_grid():
    scene = _smoke_that_comes_and_goes()
    lms = create_sensor(scene, "lms", World(scene))
    np.testing.assert_array_equal(lms.scan(1.3 + 1e-9).values, lms.scan(1.3).values)
    assert lms.scan(1.3 + 1e-9).time_s == 1.3 + 1e-9  # the scan keeps the time asked for
