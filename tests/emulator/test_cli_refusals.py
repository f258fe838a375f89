"""Refusals from a first hour with the command line: each one line on stderr naming what to fix,
under the prog of the (sub)command that refused it, exit status 2 and no traceback."""

from __future__ import annotations

import subprocess
from pathlib import Path

import pytest
from test_cli import run_cli


def one_line_refusal(result: subprocess.CompletedProcess[str]) -> str:
    """The single stderr line of a refusal (exit status 2, no traceback)."""
    assert "Traceback" not in result.stderr, result.stderr
    assert result.returncode == 2, result.stderr
    lines = result.stderr.splitlines()
    assert len(lines) == 1, result.stderr
    return lines[0]


@pytest.mark.parametrize(
    ("args", "prog"),
    [
        (["ctl", "state", "extra"], "lrf-emulator ctl state: "),
        (["ctl", "--url", "http://127.0.0.1:1", "state", "extra"], "lrf-emulator ctl state: "),
        (["ctl", "set", "region", "room", "density", "0.1", "extra"], "lrf-emulator ctl set: "),
        (["ctl", "clock", "--pause", "extra"], "lrf-emulator ctl clock: "),
        (["scenes", "extra"], "lrf-emulator scenes: "),
        (["scan", "railway", "--sensor", "urg", "extra"], "lrf-emulator scan: "),
    ],
    ids=lambda value: " ".join(value) if isinstance(value, list) else None,
)
def test_an_unexpected_argument_is_refused_by_the_subcommand_it_follows(
    tmp_path: Path, args: list[str], prog: str
) -> None:
    """Argparse left extra arguments of a subcommand to the top-level parser, which named itself
    (`lrf-emulator: unrecognized arguments`): the user could not tell which command refused them."""
    line = one_line_refusal(run_cli(*args, cwd=tmp_path))
    assert line.startswith(prog) and "unrecognized arguments: extra" in line, line


def test_an_unknown_top_level_option_is_still_refused_by_the_top_level_parser(tmp_path: Path) -> None:
    line = one_line_refusal(run_cli("--bogus", "scenes", cwd=tmp_path))
    assert line == "lrf-emulator: unrecognized arguments: --bogus", line


@pytest.mark.parametrize("seed", [["--seed=-1"], ["--seed", "-1"], ["--seed", "-9999999999999999999999"]], ids=" ".join)
@pytest.mark.parametrize("command", [["scan", "railway", "--sensor", "urg"], ["serve", "railway"]], ids=" ".join)
def test_a_negative_seed_is_refused_up_front(tmp_path: Path, command: list[str], seed: list[str]) -> None:
    """A scene file's seed must be >= 0; `--seed -1` went into the scene unchecked (scan printed a scan,
    serve served). The option's type refuses it before the scene loads: with --endpoint broken too,
    a serve that let the seed through would refuse that instead, never start a daemon."""
    line = one_line_refusal(run_cli(*command, *seed, "--endpoint", "broken", cwd=tmp_path))
    assert line.startswith(f"lrf-emulator {command[0]}: argument --seed: ") and ">= 0" in line, line


def test_the_seed_option_takes_the_range_a_scene_file_takes(tmp_path: Path) -> None:
    (tmp_path / "negative.toml").write_text("[scene]\nseed = -1\n")
    line = one_line_refusal(run_cli("scan", "negative.toml", "--sensor", "urg", cwd=tmp_path))
    assert "scene.seed: must be >= 0, got -1" in line, line
    for seed in ("0", "99999999999999999999999"):  # no upper bound in a scene file either
        result = run_cli("scan", "railway", "--sensor", "urg", "--seed", seed, cwd=tmp_path)
        assert result.returncode == 0 and result.stderr == "", result.stderr


@pytest.mark.parametrize(("listed", "twice"), [("urg,urg", "urg"), ("lms,urg,lms", "lms"), ("urg, urg", "urg")])
def test_a_sensor_listed_twice_is_refused(tmp_path: Path, listed: str, twice: str) -> None:
    """`--sensors urg,urg` was accepted. `--idle-timeout 0` is refused right after --sensors is
    checked: a serve that let the duplicate through exits 2 on that instead of starting a daemon."""
    result = run_cli("serve", "railway", "--sensors", listed, "--idle-timeout", "0", cwd=tmp_path)
    line = one_line_refusal(result)
    assert line.startswith("lrf-emulator serve: --sensors") and f"sensor {twice!r} named more than once" in line, line


@pytest.mark.parametrize("relative", [False, True], ids=["absolute", "relative"])
def test_a_directory_given_as_the_scene_is_named_a_directory(tmp_path: Path, relative: bool) -> None:
    """It was `no such scene: '/tmp/somedir'`, though the directory is there."""
    (tmp_path / "somedir").mkdir()
    scene = "somedir" if relative else str(tmp_path / "somedir")
    line = one_line_refusal(run_cli("scan", scene, "--sensor", "urg", cwd=tmp_path))
    assert line.startswith(f"lrf-emulator scan: {scene}: is a directory, not a scene file"), line


def test_a_directory_named_as_a_bundled_scene_leaves_the_bundled_scene(tmp_path: Path) -> None:
    (tmp_path / "railway").mkdir()
    result = run_cli("scan", "railway", "--sensor", "urg", cwd=tmp_path)
    assert result.returncode == 0 and result.stderr == "", result.stderr
    line = one_line_refusal(run_cli("scan", "railway/", "--sensor", "urg", cwd=tmp_path))
    assert "railway/: is a directory, not a scene file" in line, line


def test_a_directory_given_as_the_log_is_named_a_directory(tmp_path: Path) -> None:
    """It was `cannot read log: [Errno 21] Is a directory`."""
    (tmp_path / "logs").mkdir()
    line = one_line_refusal(run_cli("replay", "logs", "--device", "urg-04lx", cwd=tmp_path))
    assert line.startswith("lrf-emulator replay: logs: is a directory, not a log file"), line
    assert "Errno" not in line, line
