"""Scene files and options built to hurt: each refused with one line naming file, table and key, exit 2.

Every case runs both `scan` and `serve` through the command line's `main`
(in this process, for speed; a few also as the installed command): neither may
accept a scene the other refuses, grow without bound, hang or print a traceback.
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
from pathlib import Path

import pytest

from emulator import cli
from emulator.commands.stopping import STOP_SIGNALS
from emulator.bench.serve_process import serve_command
from emulator.scene.loader import MAX_BODY_SPEED_M_S, MAX_DENSITY, MAX_PARTICLES_ALIVE, MAX_PLUME_RATE

SENSOR = """
[[sensors]]
name = "urg"
model = "urg-04lx"
endpoints = ["pty:{tmp}/ttyURG0"]
"""
PLUME = """
[[smoke.plumes]]
name = "fire"
source = [1.0, 0.0, 0.0]
rate = {rate}
lifetime = {lifetime}
size = 0.2
density = {density}
"""
REGION = """
[[smoke.regions]]
name = "room"
box = {{ size = [4.0, 4.0, 3.0] }}
density = {density}
"""
BODY = """
[[bodies]]
name = "robot"
trajectory = {{ keyframes = [[0.0, 0.0, 0.0, 0.0], [{t}, 50.0, 0.0, 0.0]] }}
"""
BOX = """
[[objects]]
name = "wall"
box = {{ size = [{size}, 1.0, 1.0] }}
position = [3.0, 0.0, 0.0]
"""
MESH = """
[[objects]]
name = "thing"
mesh = "{mesh}"
"""

# name → (scene text, what the one error line must contain)
SCENES: dict[str, tuple[str, tuple[str, ...]]] = {
    "plume rate 1e9": (PLUME.format(rate=1e9, lifetime=2.0, density=1.0) + SENSOR,
                       ("smoke.plumes[0].rate", f"must be <= {MAX_PLUME_RATE}")),
    "plume rate 1e6": (PLUME.format(rate=1e6, lifetime=2.0, density=1.0) + SENSOR,
                       ("smoke.plumes[0].rate", f"particle budget allows at most {MAX_PARTICLES_ALIVE}")),
    "plume rate 1e5": (PLUME.format(rate=1e5, lifetime=2.0, density=1.0) + SENSOR, ("smoke.plumes[0].rate",)),
    "plume lifetime 1e12": (PLUME.format(rate=10, lifetime=1e12, density=1.0) + SENSOR, ("smoke.plumes[0].rate",)),
    "box of 1e308": (BOX.format(size="1e308") + SENSOR, ("objects[0].box.size[0]", "within")),
    "position 1e300": (BOX.format(size="1.0").replace("[3.0, 0.0, 0.0]", "[1e300, 0.0, 0.0]") + SENSOR,
                       ("objects[0].position[0]",)),
    "11 000 objects": ("".join(BOX.format(size=1.0).replace('"wall"', f'"w{i}"') for i in range(11_000)) + SENSOR,
                       ("objects", "at most 10000")),
    "5000-deep array": ("x = " + "[" * 5000 + "]" * 5000 + "\n" + SENSOR, ("nested too deeply",)),
    "garbage stl": (MESH.format(mesh="garbage.stl") + SENSOR, ("objects[0].mesh", "garbage.stl")),
    "garbage obj": (MESH.format(mesh="garbage.obj") + SENSOR, ("objects[0].mesh", "garbage.obj")),
    "garbage ply": (MESH.format(mesh="garbage.ply") + SENSOR, ("objects[0].mesh", "garbage.ply")),
    "garbage glb": (MESH.format(mesh="garbage.glb") + SENSOR, ("objects[0].mesh", "garbage.glb")),
    "fifo as mesh": (MESH.format(mesh="fifo.stl") + SENSOR, ("objects[0].mesh", "not a regular file")),
    "directory as mesh": (MESH.format(mesh="folder.obj") + SENSOR, ("objects[0].mesh", "not a regular file")),
    "257 sensors": ("".join(SENSOR.replace('"urg"', f'"u{i}"').replace("ttyURG0", f"ttyU{i}") for i in range(257)),
                    ("sensors[256]", "257 sensors; a scene may have at most 256")),
    "no sensors": (BOX.format(size=1.0), ("sensors",)),
    "empty file": ("", ("sensors",)),
}


# Limits added to the scene format later: on a daemon without them `serve` would run, so these go
# through the installed command with its timeout.
OVER_LIMITS: dict[str, tuple[str, tuple[str, ...]]] = {
    "plume density 1e300": (PLUME.format(rate=10, lifetime=2.0, density=1e300) + SENSOR,
                            ("smoke.plumes[0].density", f"must be <= {MAX_DENSITY:g}")),
    "region density 1e300": (REGION.format(density=1e300) + SENSOR, ("smoke.regions[0].density", f"must be <= {MAX_DENSITY:g}")),
    "keyframe density 1e300": (REGION.format(density="{ keyframes = [[0, 0.0], [10, 1e300]] }") + SENSOR,
                               ("smoke.regions[0].density.keyframes[1][1]", f"must be <= {MAX_DENSITY:g}")),
    "body at 50 km/s": (BODY.format(t=0.001) + SENSOR,
                        ("bodies[0].trajectory.keyframes[1]", f"at most {MAX_BODY_SPEED_M_S:g} m/s")),
}


def garbage_files(folder: Path) -> None:
    noise = bytes((i * 37 + 11) % 256 for i in range(3000))
    for name in ("garbage.stl", "garbage.ply", "garbage.glb"):
        (folder / name).write_bytes(noise)
    (folder / "garbage.obj").write_text("v 0 0 0\nv 1 0 0\nf 1 2 3\nf 1 2 9\n")
    os.mkfifo(folder / "fifo.stl")
    (folder / "folder.obj").mkdir()


def run(args: list[str], cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run([*serve_command(), *args], cwd=cwd, stdin=subprocess.DEVNULL, capture_output=True,
                          text=True, timeout=60)


def run_main(args: list[str], cwd: Path, capsys: pytest.CaptureFixture, monkeypatch: pytest.MonkeyPatch
             ) -> subprocess.CompletedProcess:
    """`lrf-emulator ARGS` through cli.main in this process (signal handlers put back after)."""
    monkeypatch.chdir(cwd)
    handlers = {signum: signal.getsignal(signum) for signum in STOP_SIGNALS}
    capsys.readouterr()
    try:
        code = cli.main(args)
    except SystemExit as exit_:
        code = exit_.code
    finally:
        for signum, handler in handlers.items():
            signal.signal(signum, handler)
    captured = capsys.readouterr()
    return subprocess.CompletedProcess(args, code, captured.out, captured.err)


def assert_one_line_exit_2(result: subprocess.CompletedProcess, *needles: str) -> None:
    lines = result.stderr.strip().splitlines()
    assert result.returncode == 2 and len(lines) == 1, result.stderr[-2000:]
    for needle in needles:
        assert needle in lines[0], lines[0]


INSTALLED_COMMAND_CASES = ("plume rate 1e9", "5000-deep array", "fifo as mesh", "empty file")


@pytest.mark.parametrize("case", sorted(SCENES))
@pytest.mark.parametrize("command", ["scan", "serve"])
def test_a_hostile_scene_is_one_line_exit_2(
    tmp_path: Path, case: str, command: str, capsys: pytest.CaptureFixture, monkeypatch: pytest.MonkeyPatch
) -> None:
    text, needles = SCENES[case]
    garbage_files(tmp_path)
    scene = tmp_path / "hostile.toml"
    scene.write_text(text.replace("{tmp}", str(tmp_path)))
    args = ["scan", str(scene), "--sensor", "urg"] if command == "scan" else ["serve", str(scene)]
    where = "hostile.toml"
    if command == "scan" and case in ("no sensors", "empty file"):
        where, needles = "scene 'hostile'", ("no sensor named 'urg'",)
    if case in INSTALLED_COMMAND_CASES:
        assert_one_line_exit_2(run(args, tmp_path), where, *needles)
    assert_one_line_exit_2(run_main(args, tmp_path, capsys, monkeypatch), where, *needles)
    assert not os.path.lexists(tmp_path / "ttyURG0")


@pytest.mark.parametrize("case", sorted(OVER_LIMITS))
@pytest.mark.parametrize("command", ["scan", "serve"])
def test_a_scene_over_a_limit_is_one_line_exit_2(tmp_path: Path, case: str, command: str) -> None:
    text, needles = OVER_LIMITS[case]
    scene = tmp_path / "hostile.toml"
    scene.write_text(text.replace("{tmp}", str(tmp_path)))
    args = ["scan", str(scene), "--sensor", "urg"] if command == "scan" else ["serve", str(scene)]
    try:
        result = run(args, tmp_path)
    except subprocess.TimeoutExpired:
        pytest.fail(f"{command} accepted a scene over a limit ({case}) and ran on")
    assert_one_line_exit_2(result, "hostile.toml", *needles)
    assert not os.path.lexists(tmp_path / "ttyURG0")


@pytest.mark.parametrize("time", ["nan", "inf", "-inf", "1e300", "-1", "soon"])
def test_scan_refuses_a_time_that_is_not_one(
    tmp_path: Path, time: str, capsys: pytest.CaptureFixture, monkeypatch: pytest.MonkeyPatch
) -> None:
    args = ["scan", "railway", "--sensor", "urg", "--time", time]
    assert_one_line_exit_2(run_main(args, tmp_path, capsys, monkeypatch), "--time")


@pytest.mark.parametrize("speed", ["inf", "0", "nan", "-1", "1e9"])
def test_serve_refuses_a_speed_that_is_not_one(
    tmp_path: Path, speed: str, capsys: pytest.CaptureFixture, monkeypatch: pytest.MonkeyPatch
) -> None:
    args = ["serve", "railway", "--speed", speed]
    assert_one_line_exit_2(run_main(args, tmp_path, capsys, monkeypatch), "--speed")


def test_version_and_debug_after_the_subcommand(
    tmp_path: Path, capsys: pytest.CaptureFixture, monkeypatch: pytest.MonkeyPatch
) -> None:
    version = run(["--version"], tmp_path)
    assert version.returncode == 0 and version.stdout.startswith("lrf-emulator ")
    result = run_main(["scan", "nowhere.toml", "--sensor", "urg", "--debug"], tmp_path, capsys, monkeypatch)
    assert result.returncode == 2 and "Traceback" in result.stderr
    for command in ("serve", "scan", "plot", "record", "replay", "bench", "scenes", None):
        help_text = run_main([command, "--help"] if command else ["--help"], tmp_path, capsys, monkeypatch).stdout
        assert "usage: lrf-emulator" in help_text and not re.search(r"\b[A-Z_0-9]+\.md\b", help_text)  # no design file
        if command == "replay":
            assert "--device" in help_text  # every other --model is the smoke preset
