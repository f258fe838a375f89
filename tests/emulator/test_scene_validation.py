"""Every rule of the scene format rejects bad input with one line naming file, table and key."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import pytest

from emulator.errors import SceneError
from emulator.scene import Material, bundled_scenes, load_scene

URG = '[[sensors]]\nname = "urg"\nmodel = "urg-04lx"\n'
LMS = '[[sensors]]\nname = "lms"\nmodel = "lms200"\n'
PLUME = '[[smoke.plumes]]\nname = "fire"\nsource = [0, 0, 0]\nrate = 1\nlifetime = 1\nsize = 0.1\ndensity = 0.05\n'
REGION = '[[smoke.regions]]\nname = "room"\nbox = { size = [1, 1, 1] }\n'
OBJECT = '[[objects]]\nname = "wall"\n'
MATERIAL_KEY_LIST = ", ".join(field.name for field in dataclasses.fields(Material))

CASES = [
    # top level and [scene]
    ("colour = 1", "colour: unknown key (expected one of: scene, materials, bodies, objects, smoke, sensors)"),
    ('[scene]\nnmae = "a"',
     "scene.nmae: unknown key (expected one of: name, description, seed, model, density_to_extinction, camera_reference)"),
    ("scene = 3", "scene: expected a table, got 3"),
    ("[scene]\nname = 3", "scene.name: expected a string, got 3"),
    ('[scene]\ndescription = """two\nlines"""', "scene.description: must be one line"),
    ("[scene]\nseed = true", "scene.seed: expected an integer, got true"),
    ("[scene]\nseed = 1.5", "scene.seed: expected an integer, got 1.5"),
    ("[scene]\nseed = -1", "scene.seed: must be >= 0, got -1"),
    ('[scene]\nmodel = "paper"', 'scene.model: must be one of "formsma2011", "physical", got "paper"'),
    ("[scene]\ndensity_to_extinction = 0", "scene.density_to_extinction: must be > 0, got 0"),
    ("[scene]\ndensity_to_extinction = nan", "scene.density_to_extinction: must be finite, got nan"),
    ("[scene]\ndensity_to_extinction = -inf", "scene.density_to_extinction: must be finite, got -inf"),
    ("[scene]\ndensity_to_extinction = false", "scene.density_to_extinction: expected a number, got false"),
    ('[scene]\ndensity_to_extinction = "250"', 'scene.density_to_extinction: expected a number, got "250"'),
    ("objects = 3", "objects: expected an array of tables ([[objects]]), got 3"),
    ("smoke = { clouds = [] }", "smoke.clouds: unknown key (expected one of: regions, plumes)"),
    # [[materials]]
    ('[[materials]]\nname = "blue"', "materials[0].reflectivity: missing required key"),
    ("[[materials]]\nreflectivity = 0.5", "materials[0].name: missing required key"),
    ('[[materials]]\nname = " "\nreflectivity = 0.5', "materials[0].name: must not be empty"),
    ('[[materials]]\nname = "blue"\nreflectivity = 1.5', "materials[0].reflectivity: must be <= 1, got 1.5"),
    ('[[materials]]\nname = "blue"\nreflectivity = -0.1', "materials[0].reflectivity: must be >= 0, got -0.1"),
    ('[[materials]]\nname = "blue"\nreflectivity = 0.5\ncolour = "blue"',
     f"materials[0].colour: unknown key (expected one of: {MATERIAL_KEY_LIST})"),
    ('[[materials]]\nname = "blue"\nreflectivity = 0.5\n[[materials]]\nname = "blue"\nreflectivity = 0.6',
     'materials[1].name: duplicate name "blue" (also materials[0])'),
    # [[objects]] and shapes
    (OBJECT, "objects[0]: needs exactly one shape key: box, sphere, cylinder, mesh"),
    (OBJECT + "box = { size = [1, 1, 1] }\nsphere = { radius = 1 }",
     "objects[0].sphere: only one shape key allowed, already has box"),
    (OBJECT + "box = { size = [1, 2] }", "objects[0].box.size: expected 3 numbers, got [1, 2]"),
    (OBJECT + 'box = { size = [1, "a", 2] }', 'objects[0].box.size: expected 3 numbers, got [1, "a", 2]'),
    (OBJECT + "box = { size = [1, true, 2] }", "objects[0].box.size: expected 3 numbers, got [1, true, 2]"),
    (OBJECT + "box = { size = [1, 0, 2] }", "objects[0].box.size[1]: must be > 0, got 0"),
    (OBJECT + "box = { size = [1, 1, nan] }", "objects[0].box.size[2]: must be finite, got nan"),
    (OBJECT + "box = [1, 1, 1]", "objects[0].box: expected a table, got [1, 1, 1]"),
    (OBJECT + "box = { size = [1, 1, 1], colour = 1 }", "objects[0].box.colour: unknown key (expected one of: size)"),
    (OBJECT + "box = {}", "objects[0].box.size: missing required key"),
    (OBJECT + "sphere = { radius = -1 }", "objects[0].sphere.radius: must be > 0, got -1"),
    (OBJECT + "cylinder = { radius = 1 }", "objects[0].cylinder.height: missing required key"),
    (OBJECT + "cylinder = { radius = 1, height = 0.0 }", "objects[0].cylinder.height: must be > 0, got 0.0"),
    (OBJECT + "mesh = 3", "objects[0].mesh: expected a string, got 3"),
    (OBJECT + 'mesh = "wall.txt"', "objects[0].mesh: unsupported mesh format '.txt' (use .glb, .gltf, .obj, .stl, .ply)"),
    (OBJECT + "sphere = { radius = 1 }\nposition = [0, 0, inf]", "objects[0].position[2]: must be finite, got inf"),
    (OBJECT + "sphere = { radius = 1 }\nposition = [true, 0, 0]",
     "objects[0].position: expected 3 numbers, got [true, 0, 0]"),
    (OBJECT + "sphere = { radius = 1 }\nrotation_deg = [0, 0]", "objects[0].rotation_deg: expected 3 numbers, got [0, 0]"),
    (OBJECT + 'sphere = { radius = 1 }\nrotation_deg = "north"',
     'objects[0].rotation_deg: expected 3 numbers, got "north"'),
    (OBJECT + 'sphere = { radius = 1 }\nmaterial = "gold"',
     'objects[0].material: unknown material "gold" (known: black_velvet, default, gold_paper, retro_reflector, rusty_steel, white_paper)'),
    (OBJECT + "sphere = { radius = 1 }\ncolour = 1",
     "objects[0].colour: unknown key (expected one of: name, box, sphere, cylinder, mesh, position, rotation_deg, material, body)"),
    ("[[objects]]\nsphere = { radius = 1 }", "objects[0].name: missing required key"),
    (OBJECT + "sphere = { radius = 1 }\n" + OBJECT + "sphere = { radius = 2 }",
     'objects[1].name: duplicate name "wall" (also objects[0])'),
    # [[smoke.regions]] and density
    (REGION, "smoke.regions[0].density: missing required key"),
    (REGION + "density = -0.1", "smoke.regions[0].density: must be >= 0, got -0.1"),
    (REGION + "density = true",
     "smoke.regions[0].density: expected a number or { keyframes = [[time, density], ...] }, got true"),
    (REGION + "density = inf", "smoke.regions[0].density: must be finite, got inf"),
    (REGION + "density = { frames = [] }", "smoke.regions[0].density.frames: unknown key (expected one of: keyframes)"),
    (REGION + "density = {}", "smoke.regions[0].density.keyframes: missing required key"),
    (REGION + "density = { keyframes = [] }",
     "smoke.regions[0].density.keyframes: expected a non-empty list of [time, density], got []"),
    (REGION + "density = { keyframes = [[0, 0.0], [5]] }",
     "smoke.regions[0].density.keyframes[1]: expected [time, density], got [5]"),
    (REGION + "density = { keyframes = [[0, 0.0], [10, 0.1], [5, 0.2]] }",
     "smoke.regions[0].density.keyframes[2][0]: keyframe times must not decrease, got 5 after 10"),
    (REGION + "density = { keyframes = [[0, -1]] }", "smoke.regions[0].density.keyframes[0][1]: must be >= 0, got -1"),
    (REGION + "density = { keyframes = [[nan, 0]] }", "smoke.regions[0].density.keyframes[0][0]: must be finite, got nan"),
    (REGION + 'density = { keyframes = [[0, "thick"]] }',
     'smoke.regions[0].density.keyframes[0][1]: expected a number, got "thick"'),
    (REGION + "density = 0.1\n" + REGION + "density = 0.2", 'smoke.regions[1].name: duplicate name "room" (also smoke.regions[0])'),
    ('[[smoke.regions]]\nname = "room"\ndensity = 0.1', "smoke.regions[0]: needs exactly one shape key: box, sphere, cylinder, mesh"),
    # [[smoke.plumes]]
    (PLUME + "colour = 1", "smoke.plumes[0].colour: unknown key (expected one of: name, source, rate, lifetime, size, growth, "
     "velocity, spread, wind, density, start, stop)"),
    (PLUME.replace("source = [0, 0, 0]\n", ""), "smoke.plumes[0].source: missing required key"),
    (PLUME.replace("rate = 1", "rate = 0"), "smoke.plumes[0].rate: must be > 0, got 0"),
    # a start or a rate whose particle numbers overflowed int64 (internal error, exit 1)
    ("[scene]\nname = 'a'\nseed = " + "9" * 5000, "line 3: an integer of more than 4300 digits"),  # tomllib's ValueError: exit 1
    (PLUME + "start = -1e20", "smoke.plumes[0].start: must be >= -1000000000.0, got -1e+20"),
    (PLUME.replace("rate = 1", "rate = 1e12").replace("lifetime = 1", "lifetime = 1e-9"),
     "smoke.plumes[0].rate: must be <= 1000000.0, got 1000000000000.0"),
    (PLUME.replace("lifetime = 1", "lifetime = -2.5"), "smoke.plumes[0].lifetime: must be > 0, got -2.5"),
    (PLUME.replace("size = 0.1", "size = 0"), "smoke.plumes[0].size: must be > 0, got 0"),
    (PLUME.replace("density = 0.05", "density = -0.05"), "smoke.plumes[0].density: must be >= 0, got -0.05"),
    (PLUME + "growth = -0.1", "smoke.plumes[0].growth: must be >= 0, got -0.1"),
    (PLUME + "spread = -1", "smoke.plumes[0].spread: must be >= 0, got -1"),
    (PLUME + "velocity = [0, 1]", "smoke.plumes[0].velocity: expected 3 numbers, got [0, 1]"),
    (PLUME + "wind = [0, 0, nan]", "smoke.plumes[0].wind[2]: must be finite, got nan"),
    (PLUME + "start = 10\nstop = 5", "smoke.plumes[0].stop: must be > start (10), got 5"),
    (PLUME + "start = 5e8\nstop = 1e8", "smoke.plumes[0].stop: must be > start (500000000.0), got 100000000.0"),
    (PLUME + "rate = true\n", "line 8: Cannot overwrite a value (column 12)"),
    (PLUME + PLUME, 'smoke.plumes[1].name: duplicate name "fire" (also smoke.plumes[0])'),
    ('[[materials]]\nname = "tape"\nreflectivity = 0.9\nretroreflective = 1', 'materials[0].retroreflective: expected true or false, got 1'),
    # [[sensors]]
    ('[[sensors]]\nname = "front"', "sensors[0].model: missing required key"),
    ('[[sensors]]\nname = "front"\nmodel = "uam-01lp"', 'sensors[0].model: must be one of "urg-04lx", "utm-30lx", "utm-30lx-ew", "ust-10lx", "ust-20lx", "lms200", "tim561", "tim571", "tim781", "lms111", "lms511", got "uam-01lp"'),
    (URG + "range = 4", "sensors[0].range: unknown key (expected one of: name, model, body, position, rotation_deg, endpoints, "
     "boot_protocol, serial, timing, baud, angle_deg, resolution_deg, units, type_string, firmware_profile, scan_frequency_hz, fog_filter)"),
    ('[[sensors]]\nname = "s"\nmodel = "lms511"\nscan_frequency_hz = 75\nresolution_deg = 0.25',
     "sensors[0].resolution_deg: must be one of 0.5, 1, got 0.25"),
    ('[[sensors]]\nname = "s"\nmodel = "tim571"\nscan_frequency_hz = 25', "sensors[0].scan_frequency_hz: must be one of 15, got 25"),
    ('[[sensors]]\nname = "s"\nmodel = "lms111"\nfog_filter = true',
     "sensors[0].fog_filter: must be true or false (true only on an LMS5xx), got true"),
    ('[[sensors]]\nname = "s"\nmodel = "lms111"\nserial = "12AB"', 'sensors[0].serial: must be up to 8 decimal digits, got "12AB"'),
    ('[[sensors]]\nname = "s"\nmodel = "lms111"\nbaud = 9600', "sensors[0].baud: is an option of lms200, not of lms111"),
    (URG + URG, 'sensors[1].name: duplicate name "urg" (also sensors[0])'),
    (URG + 'endpoints = "pty:ttyURG0"', 'sensors[0].endpoints: expected a list of endpoints, got "pty:ttyURG0"'),
    (URG + "endpoints = [10940]", "sensors[0].endpoints[0]: expected a string, got 10940"),
    *[  # `--endpoint fr=ont=tcp:…` and `--sensors a,b` could not name them, and a newline split every message
        (URG.replace('name = "urg"', f'name = "{bad}"'),
         f'sensors[0].name: "{shown}": a name holds no control character and none of = , / (it is named on the command '
         'line, SENSOR=URI and a,b lists, and in the control API\'s paths)')
        for bad, shown in (("fr=ont", "fr=ont"), ("a,b", "a,b"), ("up/down", "up/down"), ("two\\nlines", "two\\nlines"))
    ],
    (URG + 'endpoints = ["pty:a\\u0000b"]',  # scan took it, serve failed on it (ValueError: embedded null byte, exit 1)
     'sensors[0].endpoints[0]: expected "pty:PATH", "tcp:HOST:PORT" or "rfc2217:HOST:PORT" with PORT 0..65535, got "pty:a\\u0000b"'),
    *[
        (URG + f'endpoints = ["pty:ok", "{bad}"]',
         f'sensors[0].endpoints[1]: expected "pty:PATH", "tcp:HOST:PORT" or "rfc2217:HOST:PORT" with PORT 0..65535, '
         f'got "{bad}"')
        for bad in ("serial:/dev/ttyS0", "pty:", "tcp:127.0.0.1", "tcp::10940", "rfc2217:127.0.0.1",
                    "tcp:127.0.0.1:65536", "tcp:127.0.0.1:http", "tcp:127.0.0.1:-1", "ttyURG0",
                    "tcp:::0", "rfc2217:a:b:10940")  # host ":" (serve: "tcp:[:]:0: Name or service not known")
    ],
    (URG + 'endpoints = ["tcp:127.0.0.1:10940"]\n' + LMS + 'endpoints = ["tcp:127.0.0.1:10940"]',
     'sensors[1].endpoints[0]: endpoint "tcp:127.0.0.1:10940" already used by sensor "urg"'),
    (URG + 'endpoints = ["tcp:127.0.0.1:10940"]\n' + LMS + 'endpoints = ["rfc2217:127.0.0.1:10940"]',
     'sensors[1].endpoints[0]: endpoint "rfc2217:127.0.0.1:10940" already used by sensor "urg" as "tcp:127.0.0.1:10940"'),
    (URG + 'endpoints = ["pty:ttyA"]\n' + LMS + 'endpoints = ["pty:/dev/null", "pty:./ttyA"]',
     'sensors[1].endpoints[1]: endpoint "pty:./ttyA" already used by sensor "urg" as "pty:ttyA"'),
    (URG + 'endpoints = ["tcp:LocalHost:1", "tcp:localhost:1"]',
     'sensors[0].endpoints[1]: endpoint "tcp:localhost:1" already used by sensor "urg" as "tcp:LocalHost:1"'),
    # a wildcard host owns its port on every address; localhost is 127.0.0.1; [::1] is ::1
    *[
        (URG + f'endpoints = ["{first}"]\n' + LMS + f'endpoints = ["pty:ttyL", "{second}"]',
         f'sensors[1].endpoints[1]: endpoint "{second}" already used by sensor "urg"'
         + (f' as "{shown}"' if shown else ""))
        for first, second, shown in (
            ("tcp:0.0.0.0:10940", "tcp:127.0.0.1:10940", "tcp:0.0.0.0:10940"),
            ("tcp:127.0.0.2:10940", "tcp:0.0.0.0:10940", "tcp:127.0.0.2:10940"),
            ("tcp:[::]:10940", "tcp:localhost:10940", "tcp:[::]:10940"),
            ("tcp:*:10940", "tcp:[::1]:10940", "tcp:*:10940"),
            ("tcp:0.0.0.0:10940", "tcp:[0::0]:10940", "tcp:0.0.0.0:10940"),
            ("tcp:localhost:10940", "tcp:127.0.0.1:10940", "tcp:localhost:10940"),
            ("tcp:[::1]:10940", "tcp:::1:10940", ""),  # one spelling once parsed: nothing to add
        )
    ],
    # urg-04lx options
    (URG + 'boot_protocol = "scip3"', 'sensors[0].boot_protocol: must be one of "scip2", "scip1", got "scip3"'),
    (URG + 'timing = "slow"', 'sensors[0].timing: must be one of "real", "fast", got "slow"'),
    (URG + "timing = 1", "sensors[0].timing: expected a string, got 1"),
    (URG + 'serial = "H0706400H0706400X"', 'sensors[0].serial: must be 1 to 16 characters, got 17: "H0706400H0706400X"'),
    (URG + 'serial = ""', 'sensors[0].serial: must be 1 to 16 characters, got 0: ""'),
    (URG + 'serial = "H07;06"', 'sensors[0].serial: must be printable ASCII without ";", got "H07;06"'),
    (URG + 'serial = "H0706\\u00e9"', 'sensors[0].serial: must be printable ASCII without ";", got "H0706\\u00e9"'),
    (URG + "serial = 706400", "sensors[0].serial: expected a string, got 706400"),
    (URG + "baud = 9600", "sensors[0].baud: is an option of lms200, not of urg-04lx"),
    (URG + 'units = "mm"', "sensors[0].units: is an option of lms200, not of urg-04lx"),
    # SCIP 2.2 Hokuyo options
    ('[[sensors]]\nname = "u"\nmodel = "ust-10lx"\ntiming = "fast"', "sensors[0].timing: is an option of urg-04lx, not of ust-10lx"),
    ('[[sensors]]\nname = "u"\nmodel = "utm-30lx-ew"\nbaud = 9600', "sensors[0].baud: is an option of lms200, not of utm-30lx-ew"),
    ('[[sensors]]\nname = "u"\nmodel = "ust-20lx"\nserial = "H1;6"', 'sensors[0].serial: must be printable ASCII without ";", got "H1;6"'),
    ('[[sensors]]\nname = "u"\nmodel = "utm-30lx"\nendpoints = ["tcp:127.0.0.1"]',
     'sensors[0].endpoints[0]: expected "pty:PATH", "tcp:HOST:PORT" or "rfc2217:HOST:PORT" with PORT 0..65535, got "tcp:127.0.0.1"'),
    # lms200 options
    (LMS + 'serial = "H0706400"', "sensors[0].serial: is an option of urg-04lx, not of lms200"),
    (LMS + "baud = 115200", "sensors[0].baud: must be one of 9600, 19200, 38400, 500000, got 115200"),
    (LMS + "baud = 9600.0", "sensors[0].baud: expected an integer, got 9600.0"),
    (LMS + "angle_deg = 90", "sensors[0].angle_deg: must be one of 180, 100, got 90"),
    (LMS + "resolution_deg = 0.3", "sensors[0].resolution_deg: must be one of 1.0, 0.5, 0.25, got 0.3"),
    (LMS + "resolution_deg = 0.25", "sensors[0].resolution_deg: 0.25 needs angle_deg = 100 (no 180° scan at 0.25°)"),
    (LMS + 'units = "m"', 'sensors[0].units: must be one of "mm", "cm", got "m"'),
    (LMS + 'type_string = "LMS200;301063;V02.10"',
     'sensors[0].type_string: must be exactly 21 characters, got 20: "LMS200;301063;V02.10"'),
    (LMS + 'type_string = "LMS200;301063;V02.10\\n"',
     'sensors[0].type_string: must be printable ASCII, got "LMS200;301063;V02.10\\n"'),
    (LMS + 'firmware_profile = "v1.0"', 'sensors[0].firmware_profile: must be one of "v2.30", "32-byte-config", got "v1.0"'),
    # TOML syntax
    ("[scene]\nname = \nseed = 1", "line 2: Invalid value (column 8)"),
    ("[scene]\nname = [1,", "line 2: Invalid value (at the end of the file)"),
]


def write_scene(directory: Path, text: str, filename: str = "x.toml") -> Path:
    path = directory / filename
    path.write_text(text, encoding="utf-8")
    return path


@pytest.mark.parametrize(("text", "expected"), CASES, ids=[expected for _, expected in CASES])
def test_invalid_scene_is_rejected_with_one_line_naming_file_table_and_key(tmp_path: Path, text: str, expected: str) -> None:
    with pytest.raises(SceneError) as raised:
        load_scene(write_scene(tmp_path, text))
    assert str(raised.value) == f"x.toml: {expected}"



def test_a_byte_order_mark_before_the_first_table_is_no_statement(tmp_path: Path) -> None:
    """Some editors write one; tomllib read it as an invalid statement at line 1."""
    path = tmp_path / "bom.toml"
    path.write_text("\ufeff[scene]\nname = 'marked'\n" + PLUME, encoding="utf-8")
    assert load_scene(path).name == "marked"

def test_message_names_the_file_by_its_basename(tmp_path: Path) -> None:
    """The contract's own example, word for word."""
    text = PLUME + PLUME.replace('"fire"', '"embers"').replace("rate = 1", "rate = -3")
    with pytest.raises(SceneError, match=r"^railway\.toml: smoke\.plumes\[1\]\.rate: must be > 0, got -3$"):
        load_scene(write_scene(tmp_path, text, "railway.toml"))


def test_a_missing_scene_lists_the_bundled_ones(tmp_path: Path) -> None:
    bundled = ", ".join(scene.name for scene in bundled_scenes())
    assert "railway" in bundled
    with pytest.raises(SceneError) as by_name:
        load_scene("no_such_place")
    assert str(by_name.value) == f"no such scene: 'no_such_place' (bundled: {bundled})"
    missing_path = tmp_path / "gone.toml"
    with pytest.raises(SceneError) as by_path:
        load_scene(missing_path)
    assert str(by_path.value) == f"no such scene: '{missing_path}' (bundled: {bundled})"


def test_a_directory_is_not_a_scene(tmp_path: Path) -> None:
    (tmp_path / "dir.toml").mkdir()
    with pytest.raises(SceneError, match=r"^.*dir\.toml: is a directory, not a scene file \(give a scene's \.toml file"):
        load_scene(tmp_path / "dir.toml")


def test_a_file_that_is_not_utf8_is_rejected(tmp_path: Path) -> None:
    path = tmp_path / "x.toml"
    path.write_bytes(b'[scene]\nname = "\xff"\n')
    with pytest.raises(SceneError, match=r"^x\.toml: not UTF-8 text \(byte 16\)$"):
        load_scene(path)



def test_one_port_on_different_specific_hosts_is_allowed(tmp_path: Path) -> None:
    """Only the same host or a wildcard clashes: distinct addresses each bind the port."""
    endpoints = {
        "urg": ["tcp:127.0.0.1:10940", "tcp:0.0.0.0:10941"],
        "lms": ["tcp:127.0.0.2:10940", "tcp:[::1]:10940", "tcp:[::1]:10942"],
    }
    text = "".join(
        f'[[sensors]]\nname = "{name}"\nmodel = "{model}"\nendpoints = {json.dumps(endpoints[name])}\n'
        for name, model in (("urg", "urg-04lx"), ("lms", "lms200"))
    )
    scene = load_scene(write_scene(tmp_path, text))
    assert [list(sensor.endpoints) for sensor in scene.sensors] == [endpoints["urg"], endpoints["lms"]]
