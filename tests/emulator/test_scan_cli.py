"""`lrf-emulator scan` through the real command line."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from emulator.scene import load_scene
from emulator.scene.sick_models import MODELS as SICK_MODELS
from emulator.sensors import create_sensor
from emulator.sensors.response import apply_model_override

SCENE = """
[scene]
name = "scan test"
seed = 3

[[objects]]
name = "wall"
box = { size = [0.2, 20.0, 3.0] }
position = [3.1, 0.0, 0.5]

[[smoke.regions]]
name = "fog"
box = { size = [2.0, 20.0, 3.0] }
position = [1.5, 0.0, 0.5]
density = { keyframes = [[0.0, 0.0], [10.0, 0.008]] }

[[smoke.plumes]]
name = "fire"
source = [2.0, -2.0, 0.0]
rate = 20.0
lifetime = 10.0
size = 0.3
velocity = [0.0, 0.3, 0.0]
spread = 0.3
density = 0.05

[[sensors]]
name = "urg"
model = "urg-04lx"
position = [0.0, 0.0, 0.5]
endpoints = ["tcp:127.0.0.1:10940"]

[[sensors]]
name = "lms"
model = "lms200"
position = [0.0, 0.0, 0.5]
endpoints = ["pty:ttyLMS0"]
angle_deg = 100
resolution_deg = 1
units = "cm"
"""


@pytest.fixture
def scene_file(tmp_path: Path) -> Path:
    path = tmp_path / "scan_test.toml"
    path.write_text(SCENE)
    return path


def lrf(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "emulator.cli", *args], capture_output=True, text=True, timeout=60)


def scan(*args: str) -> dict:
    result = lrf("scan", *args)
    assert result.returncode == 0, result.stderr
    return json.loads(result.stdout)


LASER_SCAN_FIELDS = {"angle_min", "angle_max", "angle_increment", "time_increment", "scan_time", "range_min", "range_max"}
FRONT = 384 - 44  # step 384 (straight ahead) among the measured steps 44..725


def test_urg_scan_json(scene_file):
    out = scan(str(scene_file), "--sensor", "urg", "--time", "1")
    assert set(out) == {"sensor", "model", "time_s", "unit", "angles_deg", "values", "ranges_m", "pose", "times_s"} | LASER_SCAN_FIELDS
    assert (out["sensor"], out["model"], out["time_s"], out["unit"]) == ("urg", "urg-04lx", 1.0, "mm")
    # the measured steps 44..725 only (PP: AMIN 44, AMAX 725), as urg_node publishes them
    assert len(out["angles_deg"]) == len(out["values"]) == len(out["ranges_m"]) == len(out["times_s"]) == 682
    assert out["times_s"][-1] == pytest.approx(1.0 - (768 - 725) * 0.1 / 1024, abs=1e-9)  # step 768 completes the scan
    assert out["times_s"][0] == pytest.approx(1.0 - (768 - 44) * 0.1 / 1024, abs=1e-9)
    assert out["angles_deg"][FRONT] == 0.0 and out["angles_deg"][0] == pytest.approx(-340 * 360 / 1024)
    assert out["angle_min"] == pytest.approx(math.radians(-340 * 360 / 1024))
    assert out["angle_max"] == pytest.approx(math.radians(341 * 360 / 1024))
    assert out["angle_increment"] == pytest.approx(2 * math.pi / 1024)
    assert (out["scan_time"], out["range_min"], out["range_max"]) == (0.1, 0.02, 5.6)
    assert out["time_increment"] == pytest.approx(0.1 / 1024)
    assert out["values"][FRONT] == 3000 and out["ranges_m"][FRONT] == 3.0


def test_time_moves_the_keyframed_smoke(scene_file):
    """0.008 d/10 s × 2 m of fog passes 0.007 d·m at t = 4.375 s."""
    assert scan(str(scene_file), "--sensor", "urg", "--time", "4.3")["values"][FRONT] == 3000
    late = scan(str(scene_file), "--sensor", "urg", "--time", "4.45")
    assert late["values"][FRONT] == 1 and late["ranges_m"][FRONT] is None


def test_lms_scan_uses_the_scene_window_and_unit(scene_file):
    out = scan(str(scene_file), "--sensor", "lms", "--time", "0")
    assert (out["model"], out["unit"]) == ("lms200", "cm")
    assert out["angles_deg"] == [float(a) for a in range(-50, 51)]  # 100° at 1°: device 40°..140°
    assert out["values"][50] == 300
    assert out["values"][30] == round(300 / math.cos(math.radians(20)))
    assert out["ranges_m"][50] == 3.0
    assert (out["angle_min"], out["angle_max"]) == pytest.approx((math.radians(-50), math.radians(50)))
    assert out["angle_increment"] == pytest.approx(math.radians(1))
    assert (out["scan_time"], out["range_min"], out["range_max"]) == pytest.approx((1 / 75, 0.0, 81.0))  # sicklms: cm


def test_seed_override_changes_only_the_plume(scene_file):
    args = (str(scene_file), "--sensor", "urg", "--time", "6")
    default, same, other = scan(*args), scan(*args, "--seed", "3"), scan(*args, "--seed", "4")
    assert default == same
    assert default["values"] != other["values"]
    assert default["values"][FRONT] == other["values"][FRONT]  # the straight-ahead beam never meets the plume


def test_bundled_scene_by_name():
    out = scan("railway", "--sensor", "urg", "--time", "5")
    assert out["sensor"] == "urg" and len(out["values"]) == 682


def test_unknown_sensor_is_one_line_exit_2(scene_file):
    result = lrf("scan", str(scene_file), "--sensor", "front")
    assert result.returncode == 2
    assert result.stdout == ""
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "front" in lines[0] and "urg, lms" in lines[0]
    assert "Traceback" not in result.stderr


def test_missing_sensor_option_is_a_usage_error(scene_file):
    result = lrf("scan", str(scene_file))
    assert result.returncode == 2 and "--sensor" in result.stderr and "Traceback" not in result.stderr


def test_model_override_selects_the_preset(scene_file):
    args = (str(scene_file), "--sensor", "urg", "--time", "1")
    paper, physical = scan(*args), scan(*args, "--model", "physical")
    scene = apply_model_override(load_scene(scene_file), "physical")
    assert physical["values"] == create_sensor(scene, "urg").scan(1.0).values[44:726].tolist()
    assert physical["values"] != paper["values"]  # datasheet noise in clear air


def test_unknown_model_is_one_line_exit_2(scene_file):
    result = lrf("scan", str(scene_file), "--sensor", "urg", "--model", "fog9000")
    assert result.returncode == 2 and result.stdout == ""
    assert result.stderr.count("\n") == 1 and "fog9000" in result.stderr and "physical" in result.stderr


def test_a_multi_echo_units_json_has_its_intensities_and_every_echo():
    """rescue's UTM-30LX-EW in its haze (`physical`): intensities, echoes (nearest first, -1 past a
    beam's last), their ranges and intensities, as the sensor computed them; the first echo slot is
    what ND sends, the values what GD sends."""
    out = scan("rescue", "--sensor", "utm", "--model", "physical", "--time", "20")
    expected = create_sensor(apply_model_override(load_scene("rescue"), "physical"), "utm").scan(20.0)
    assert out["intensities"] == expected.intensities.tolist() and len(out["intensities"]) == 1081
    assert out["echoes"] == expected.echoes.tolist() and out["echo_intensities"] == expected.echo_intensities.tolist()
    echoes = np.array(out["echoes"])
    assert (echoes[:, 1] >= 0).sum() > 100  # the smoke in the first echo, the wall behind in the next
    for row, ranges in zip(out["echoes"], out["echo_ranges_m"]):
        assert ranges == [value / 1000 if value >= 23 else None for value in row]
    assert "reflector" not in out


def test_the_lms200s_json_has_its_reflector_bits_and_a_urgs_nothing_it_lacks(scene_file):
    lms = scan(str(scene_file), "--sensor", "lms", "--time", "0")
    assert lms["reflector"] == [False] * 101  # no retro-reflector in the scene
    urg = scan(str(scene_file), "--sensor", "urg", "--time", "0")
    assert not {"intensities", "echoes", "echo_ranges_m", "echo_intensities", "reflector"} & set(urg)


def test_a_cola_units_echo_ranges_follow_its_distance_scale():
    """marulan's LMS511 (5 echoes, 2 mm a count): echoes with no return are -1 and null in metres."""
    out = scan("marulan", "--sensor", "lms5", "--model", "physical", "--time", "5")
    echoes = np.array(out["echoes"])
    assert echoes.shape[1] == 5 and (echoes == -1).any() and (echoes > 0).any()
    scale_mm = SICK_MODELS["lms511"].distance_scale
    for row, ranges in zip(out["echoes"], out["echo_ranges_m"]):
        assert ranges == [value * scale_mm / 1000 if value > 0 else None for value in row]
