"""A valid scene file becomes exactly the dataclasses it describes; bundled scenes are found by name or path."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from emulator.scene import (
    Box,
    Cylinder,
    Density,
    Material,
    Plume,
    Pose,
    SceneObject,
    SensorSpec,
    SmokeRegion,
    Sphere,
    bundled_scenes,
    load_scene,
)
from emulator.scene.materials import BUILTIN_MATERIALS

EVERY_KEY = """
[scene]
name = "BOCAS training room"
description = "every key of the format"
seed = 7
model = "physical"
density_to_extinction = 180.5

[[materials]]
name = "blue_paper"
reflectivity = 0.7

[[materials]]
name = "white_paper"          # overrides the built-in
reflectivity = 0.85

[[objects]]
name = "target"
box = { size = [0.05, 1.2, 1.0] }
position = [2.5, 0.0, 0.5]
rotation_deg = [1, 2, 3]
material = "blue_paper"

[[objects]]
name = "bollard"
cylinder = { radius = 0.05, height = 0.4 }
position = [0.6, -0.3, 0.2]
material = "white_paper"

[[objects]]
name = "ball"
sphere = { radius = 0.25 }

[[smoke.regions]]
name = "room"
box = { size = [8, 6, 3] }
position = [2, 0, 1.5]
rotation_deg = [0, 0, 90]
density = 0.002

[[smoke.regions]]
name = "machine"
sphere = { radius = 1.5 }
density = { keyframes = [[0, 0.0], [10, 0.004], [60, 0.004], [300, 0.0]] }

[[smoke.plumes]]
name = "fire"
source = [10.0, 3.0, 0.2]
rate = 20.0
lifetime = 25.0
size = 0.4
growth = 0.05
velocity = [0.0, 0.0, 0.6]
spread = 0.2
wind = [0.8, 0.3, 0.0]
density = 0.05
start = 5.0
stop = 100

[[sensors]]
name = "front"
model = "urg-04lx"
position = [0.0, 0.0, 0.3]
rotation_deg = [0, 0, 45]
endpoints = ["pty:ttyURG0", "tcp:127.0.0.1:10940"]
boot_protocol = "scip1"
timing = "fast"
serial = "H1234567"

[[sensors]]
name = "sick"
model = "lms200"
position = [0.1, 0.0, 0.4]
endpoints = ["pty:ttyLMS0", "tcp:[::1]:2111"]
baud = 38400
angle_deg = 100
resolution_deg = 0.25
units = "cm"
type_string = "LMS200;30106;V02.30  "
firmware_profile = "32-byte-config"
"""


def write_scene(directory: Path, text: str, filename: str = "x.toml") -> Path:
    path = directory / filename
    path.write_text(text, encoding="utf-8")
    return path


def test_every_key_lands_in_the_dataclasses(tmp_path: Path) -> None:
    path = write_scene(tmp_path, EVERY_KEY, "room.toml")
    scene = load_scene(path)

    assert scene.path == path.resolve()
    assert (scene.name, scene.description, scene.seed) == ("BOCAS training room", "every key of the format", 7)
    assert (scene.model, scene.density_to_extinction) == ("physical", 180.5)

    assert scene.materials["blue_paper"] == Material("blue_paper", reflectivity=0.7)
    assert scene.materials["white_paper"] == Material("white_paper", reflectivity=0.85)
    assert scene.materials["black_velvet"] == BUILTIN_MATERIALS["black_velvet"]

    assert scene.objects == (
        SceneObject("target", Box((0.05, 1.2, 1.0)), Pose((2.5, 0.0, 0.5), (1.0, 2.0, 3.0)), "blue_paper"),
        SceneObject("bollard", Cylinder(0.05, 0.4), Pose((0.6, -0.3, 0.2)), "white_paper"),
        SceneObject("ball", Sphere(0.25), Pose(), "default"),
    )
    assert scene.regions == (
        SmokeRegion("room", Box((8.0, 6.0, 3.0)), Pose((2.0, 0.0, 1.5), (0.0, 0.0, 90.0)), Density(((0.0, 0.002),))),
        SmokeRegion(
            "machine", Sphere(1.5), Pose(),
            Density(((0.0, 0.0), (10.0, 0.004), (60.0, 0.004), (300.0, 0.0))),
        ),
    )
    assert scene.plumes == (
        Plume(
            name="fire", source=(10.0, 3.0, 0.2), rate=20.0, lifetime=25.0, size=0.4, growth=0.05,
            velocity=(0.0, 0.0, 0.6), spread=0.2, wind=(0.8, 0.3, 0.0), density=0.05, start=5.0, stop=100.0,
        ),
    )
    assert scene.sensors == (
        SensorSpec(
            "front", "urg-04lx", Pose((0.0, 0.0, 0.3), (0.0, 0.0, 45.0)), ("pty:ttyURG0", "tcp:127.0.0.1:10940"),
            {"boot_protocol": "scip1", "serial": "H1234567", "timing": "fast"},
        ),
        SensorSpec(
            "sick", "lms200", Pose((0.1, 0.0, 0.4)), ("pty:ttyLMS0", "tcp:[::1]:2111"),
            {
                "baud": 38400, "angle_deg": 100, "resolution_deg": 0.25, "units": "cm",
                "type_string": "LMS200;30106;V02.30  ", "firmware_profile": "32-byte-config",
            },
        ),
    )
    assert scene.sensor("sick").options["units"] == "cm"


def test_omitted_keys_take_their_documented_defaults(tmp_path: Path) -> None:
    scene = load_scene(write_scene(tmp_path, """
[[smoke.plumes]]
name = "fire"
source = [1, 2, 3]
rate = 2
lifetime = 3
size = 0.5
density = 0.1

[[sensors]]
name = "urg"
model = "urg-04lx"

[[sensors]]
name = "lms"
model = "lms200"
""", "bare.toml"))
    assert (scene.name, scene.description, scene.seed) == ("bare", "", 0)
    assert (scene.model, scene.density_to_extinction) == ("formsma2011", 250.0)
    assert dict(scene.materials) == dict(BUILTIN_MATERIALS)
    assert scene.objects == () and scene.regions == ()
    plume = scene.plumes[0]
    assert (plume.growth, plume.velocity, plume.spread, plume.wind) == (0.0, (0.0, 0.0, 0.0), 0.0, (0.0, 0.0, 0.0))
    assert (plume.start, plume.stop) == (0.0, 1e9)
    urg, lms = scene.sensors
    assert urg.pose == Pose((0.0, 0.0, 0.0), (0.0, 0.0, 0.0)) and urg.endpoints == ()
    assert dict(urg.options) == {"boot_protocol": "scip2", "serial": "H0706400", "timing": "real"}
    assert dict(lms.options) == {
        "baud": 9600, "angle_deg": 180, "resolution_deg": 0.5, "units": "mm",
        "type_string": "LMS200;301063;V02.10 ", "firmware_profile": "v2.30",
    }


def test_loaded_scene_cannot_be_changed(tmp_path: Path) -> None:
    scene = load_scene(write_scene(tmp_path, '[[sensors]]\nname = "urg"\nmodel = "urg-04lx"\n'))
    with pytest.raises(TypeError):
        scene.sensors[0].options["serial"] = "X"  # type: ignore[index]
    with pytest.raises(TypeError):
        scene.materials["default"] = Material("default", 1.0)  # type: ignore[index]


def test_builtin_materials_are_the_documented_ones() -> None:
    assert {name: material.reflectivity for name, material in BUILTIN_MATERIALS.items()} == {
        "default": 0.5, "white_paper": 0.9, "gold_paper": 0.6, "rusty_steel": 0.25, "black_velvet": 0.02,
        "retro_reflector": 1.0,
    }
    assert [name for name, material in BUILTIN_MATERIALS.items() if material.retroreflective] == ["retro_reflector"]


def test_a_scene_material_may_be_retroreflective(tmp_path: Path) -> None:
    scene = load_scene(write_scene(tmp_path, '[[materials]]\nname = "tape"\nreflectivity = 0.9\nretroreflective = true\n'))
    assert scene.materials["tape"].retroreflective and not scene.materials["default"].retroreflective


def test_overriding_a_builtin_may_omit_the_reflectivity(tmp_path: Path) -> None:
    scene = load_scene(write_scene(tmp_path, '[[materials]]\nname = "gold_paper"\n'))
    assert scene.materials["gold_paper"] == BUILTIN_MATERIALS["gold_paper"]


KISMET = Density(((0.0, 0.0), (10.0, 0.004), (60.0, 0.004), (300.0, 0.0)))


@pytest.mark.parametrize(
    ("time_s", "density"),
    [
        (-5.0, 0.0),      # before the first keyframe: holds its value
        (0.0, 0.0),
        (2.5, 0.001),     # a quarter of the way up
        (10.0, 0.004),
        (35.0, 0.004),    # on the plateau
        (60.0, 0.004),
        (120.0, 0.003),   # a quarter of the way down
        (300.0, 0.0),
        (1e6, 0.0),       # after the last keyframe: holds its value
    ],
)
def test_density_is_piecewise_linear_between_keyframes(time_s: float, density: float) -> None:
    assert KISMET.at(time_s) == pytest.approx(density, abs=1e-15)


def test_density_of_many_times_at_once_and_a_constant(tmp_path: Path) -> None:
    np.testing.assert_allclose(KISMET.at(np.array([5.0, 180.0, 400.0])), [0.002, 0.002, 0.0], atol=1e-15)
    scene = load_scene(write_scene(tmp_path, '[[smoke.regions]]\nname = "r"\nbox = { size = [1, 1, 1] }\ndensity = 3\n'))
    constant = scene.regions[0].density
    assert constant == Density(((0.0, 3.0),))
    assert [constant.at(t) for t in (-10.0, 0.0, 1e9)] == [3.0, 3.0, 3.0]


def test_keyframe_loaded_from_a_file_interpolates(tmp_path: Path) -> None:
    scene = load_scene(write_scene(tmp_path, """
[[smoke.regions]]
name = "r"
box = { size = [1, 1, 1] }
density = { keyframes = [[-2, 0.5], [2, 1.5]] }
"""))
    assert [scene.regions[0].density.at(t) for t in (-3.0, -2.0, 0.0, 1.0, 2.0, 3.0)] == [0.5, 0.5, 1.0, 1.25, 1.5, 1.5]


def test_bundled_scenes_are_listed_sorted_with_descriptions() -> None:
    scenes = bundled_scenes()
    names = [scene.name for scene in scenes]
    assert names == sorted(names) and "railway" in names
    for scene in scenes:
        assert scene.path.is_file() and scene.path.name == f"{scene.name}.toml"
        assert scene.description and "\n" not in scene.description


def test_a_bundled_scene_loads_by_name_and_by_path_alike() -> None:
    railway = next(scene for scene in bundled_scenes() if scene.name == "railway")
    by_name = load_scene("railway")
    by_path = load_scene(railway.path)
    by_text = load_scene(str(railway.path))
    assert by_name == by_path == by_text
    assert by_name.path == railway.path.resolve()


def test_a_relative_path_is_relative_to_the_working_directory(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    (tmp_path / "here").mkdir()
    write_scene(tmp_path / "here", '[scene]\nname = "local"\n', "railway.toml")
    monkeypatch.chdir(tmp_path)
    assert load_scene("here/railway.toml").name == "local"
    assert load_scene(os.path.join(".", "here", "railway.toml")).path == (tmp_path / "here" / "railway.toml").resolve()
    assert load_scene("railway").name != "local"   # a bare name is always the bundled scene


def test_railway_has_the_sensors_other_parts_rely_on() -> None:
    scene = load_scene("railway")
    urg, lms = scene.sensor("urg"), scene.sensor("lms")
    assert (urg.model, urg.endpoints) == ("urg-04lx", ("pty:ttyURG0", "tcp:127.0.0.1:10940"))
    assert (lms.model, lms.endpoints) == ("lms200", ("pty:ttyLMS0",))
    assert urg.pose.position[2] == pytest.approx(0.3, abs=0.05)
    assert lms.pose.position[2] == pytest.approx(0.4, abs=0.05)
    assert scene.plumes and sum(plume.rate * plume.lifetime for plume in scene.plumes) <= 400
    assert all(isinstance(item.shape, (Box, Cylinder)) for item in (*scene.objects, *scene.regions))


def test_ethernet_hokuyos_default_to_port_10940(tmp_path):
    from emulator.scene import load_scene

    path = tmp_path / "ust.toml"
    path.write_text(
        '[scene]\nname = "ust"\n\n[[sensors]]\nname = "a"\nmodel = "ust-10lx"\nendpoints = ["tcp:127.0.0.1", "tcp:[::1]"]\n\n'
        '[[sensors]]\nname = "b"\nmodel = "ust-20lx"\nserial = "H1234567"\nendpoints = ["tcp:127.0.0.2:2000"]\n'
    )
    scene = load_scene(path)
    assert scene.sensor("a").endpoints == ("tcp:127.0.0.1:10940", "tcp:[::1]:10940")
    assert scene.sensor("b").endpoints == ("tcp:127.0.0.2:2000",)
    assert scene.sensor("b").options["serial"] == "H1234567" and "serial" not in scene.sensor("a").options
