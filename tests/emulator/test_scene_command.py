"""The installed `lrf-emulator` command: `scenes` lists the bundled scenes; a bad scene is one stderr line, status 2."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from emulator.scene import bundled_scenes

LRF_EMULATOR = Path(sys.executable).with_name("lrf-emulator")


def run_cli(*args: str, cwd: Path | None = None) -> subprocess.CompletedProcess[str]:
    return subprocess.run([str(LRF_EMULATOR), *args], capture_output=True, text=True, timeout=60, cwd=cwd)


def test_scenes_prints_one_aligned_line_per_bundled_scene(tmp_path: Path) -> None:
    result = run_cli("scenes", cwd=tmp_path)  # found from any directory: scenes ship inside the package
    assert result.returncode == 0 and result.stderr == ""
    lines = result.stdout.splitlines()
    scenes = bundled_scenes()
    assert len(lines) == len(scenes) >= 1
    column = max(len(scene.name) for scene in scenes) + 2
    for line, scene in zip(lines, scenes):
        assert line == f"{scene.name:<{column}}{scene.description}"
    railway = next(line for line in lines if line.startswith("railway "))
    assert railway.split(None, 1)[1].startswith("RoboCup Rescue 2009 outdoor challenge")


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("[[sensors]]\nname = \"urg\"\nmodel = \"urg-04lx\"\nserial = 7\n",
         "x.toml: sensors[0].serial: expected a string, got 7"),
        ("[[sensors]]\nname = \"urg\"\nmodel = \n", "x.toml: line 3: Invalid value (column 9)"),
    ],
)
def test_a_scene_error_is_one_stderr_line_and_status_2(tmp_path: Path, text: str, message: str) -> None:
    (tmp_path / "x.toml").write_text(text)
    result = run_cli("scan", str(tmp_path / "x.toml"), "--sensor", "urg")
    assert result.returncode == 2
    assert result.stdout == ""
    assert result.stderr == f"lrf-emulator scan: {message}\n"


def test_an_unknown_scene_name_lists_the_bundled_ones() -> None:
    result = run_cli("scan", "atlantis", "--sensor", "urg")
    bundled = ", ".join(scene.name for scene in bundled_scenes())
    assert (result.returncode, result.stdout) == (2, "")
    assert result.stderr == f"lrf-emulator scan: no such scene: 'atlantis' (bundled: {bundled})\n"
