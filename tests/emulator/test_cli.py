"""The command line as a new user meets it: every subcommand refuses malformed arguments in one
line with exit status 2 (never a traceback), `--model` is the smoke preset everywhere, and the
commands that only talk to a daemon start without loading the simulation."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from emulator.cli import SUBCOMMANDS

CLI = [sys.executable, "-m", "emulator.cli"]


def run_cli(*args: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run([*CLI, *args], capture_output=True, text=True, timeout=120, cwd=cwd)


# subcommand → malformed invocations, each with a word its one error line must contain
MALFORMED: dict[str, list[tuple[list[str], str]]] = {
    "serve": [
        (["railway", "--speed", "fast"], "--speed"),
        (["railway", "--bogus"], "--bogus"),
        (["railway", "--endpoint", "urg=tcp:nowhere"], "tcp:nowhere"),
        (["railway", "--control", "nonsense"], "--control"),
        (["railway", "--epoch", "nan"], "--epoch"),  # NaN stopped every clock read: a traceback, no scans
        (["railway", "--epoch=-1e300"], "--epoch"),  # simulated time far past what a scan may take
        (["railway", "--epoch=--"], "--epoch"),  # argparse makes that [] for any type
        (["railway", "--control-token", ""], "--control-token"),
    ],
    "scan": [
        (["railway", "--sensor", "urg", "--time", "soon"], "--time"),
        (["railway"], "--sensor"),
        (["railway", "--sensor", "urg", "--seed", "x"], "--seed"),
        (["railway", "--sensor", "urg", "--time=--"], "--time"),
    ],
    "plot": [
        (["bocas", "--sensor", "urg", "--end", "1", "--out", "x.xyz"], ".xyz"),
        (["bocas", "--sensor", "urg", "--end", "1", "--out", "x.png", "--width", "wide"], "--width"),
        (["bocas", "--map", "--time", "later", "--out", "x.png"], "--time"),
        (["bocas", "--map", "--out", ""], "--out"),
    ],
    "record": [
        (["railway", "--sensor", "urg", "--end", "1", "--out", "x.log", "--format", "tape"], "--format"),
        (["railway", "--sensor", "urg", "--end", "1", "--out", "x.log", "--seed", "x"], "--seed"),
        (["railway", "--sensor", "urg", "--end", "1", "--out", "x.log", "--model", "lms200"], "lms200"),
        (["railway", "--sensor", "urg", "--end", "1", "--out", ""], "--out"),
        (["railway", "--sensor", "urg", "--end", "1", "--out", "/"], "a directory of that name exists"),
    ],
    "replay": [
        (["missing.log", "--device", "urg-04lx"], "missing.log"),
        (["missing.log", "--device", "hokuyo"], "--device"),
        (["missing.log", "--model", "urg-04lx"], "--device"),  # --model is the smoke preset, not the device
    ],
    "bench": [
        (["--section", "nope"], "--section"),
        (["--quick", "extra"], "extra"),
    ],
    "scenes": [
        (["extra"], "extra"),
    ],
    "ctl": [
        (["--url", "nonsense", "state"], "--url 'nonsense'"),
        (["--url", "http://127.0.0.1:99999", "state"], "--url"),
        (["--url", "http://127.0.0.1:1", "state"], "cannot reach the control API"),
        (["--url", "http://user:pw@127.0.0.1:1", "state"], "a user and password in the URL are not sent; give --token instead"),  # "Name or service not known"
        (["plume", "fire", "rate"], "expected 1 number"),
        (["pose", "robot", "one", "two"], "invalid float value"),
        (["frobnicate"], "frobnicate"),
        (["watch", "urg", "--count", "0"], "--count"),
    ],
}


def test_every_subcommand_is_tried() -> None:
    assert set(MALFORMED) == set(SUBCOMMANDS)


@pytest.mark.parametrize(
    ("args", "expected"),
    [([command, *args], expected) for command, cases in MALFORMED.items() for args, expected in cases]
    + [(["nosuchcommand"], "nosuchcommand"), ([], "COMMAND"), (["--debugging", "scenes"], "--debugging")],
    ids=lambda value: " ".join(value) if isinstance(value, list) else None,
)
def test_malformed_arguments_are_one_line_and_exit_2(tmp_path: Path, args: list[str], expected: str) -> None:
    result = run_cli(*args, cwd=tmp_path)
    assert "Traceback" not in result.stderr, result.stderr
    assert result.returncode == 2, result.stderr
    lines = result.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("lrf-emulator") and expected in lines[0], result.stderr
    assert list(tmp_path.iterdir()) == []  # nothing written


def imported_modules(tmp_path: Path, *args: str) -> set[str]:
    """The modules `lrf-emulator ARGS` has imported when it exits."""
    code = (
        "import sys, json\nfrom emulator.cli import main\n"
        f"try:\n    main({list(args)!r})\nexcept SystemExit:\n    pass\n"
        "print(json.dumps(sorted(sys.modules)))\n"
    )
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60, cwd=tmp_path)
    return set(json.loads(result.stdout.splitlines()[-1]))


SERVER_MODULES = ("numpy", "trimesh", "embreex", "aiohttp", "emulator.scene", "emulator.optics",
                  "emulator.sensors", "emulator.daemon", "emulator.transport", "emulator.control.server")


@pytest.mark.parametrize("args", [["--version"], ["ctl", "--url", "http://127.0.0.1:1", "state"], ["ctl", "--help"]])
def test_ctl_and_version_start_without_the_server(tmp_path: Path, args: list[str]) -> None:
    modules = imported_modules(tmp_path, *args)
    assert "emulator.cli" in modules
    assert not [name for name in modules if name.split(".")[0] in SERVER_MODULES or name.startswith(SERVER_MODULES)]


def test_version_prints_the_version(tmp_path: Path) -> None:
    result = run_cli("--version", cwd=tmp_path)
    assert result.returncode == 0 and result.stdout.startswith("lrf-emulator 0.") and result.stderr == ""


def test_record_takes_a_seed(tmp_path: Path) -> None:
    """The seed draws the plume's particles: another seed, other scans."""
    logs = {}
    for seed in ("1", "1", "2"):
        out = tmp_path / f"seed{seed}.log"
        result = run_cli("record", "marulan", "--sensor", "lms", "--start", "75", "--end", "75.1", "--seed", seed,
                         "--out", str(out), cwd=tmp_path)
        assert result.returncode == 0, result.stderr
        logs.setdefault(seed, []).append(out.read_text())
    assert logs["1"][0] == logs["1"][1]
    assert logs["1"][0] != logs["2"][0]


def test_record_names_the_ground_truth_after_its_output_file(tmp_path: Path) -> None:
    """`run.log` and `run.mcap` from the same place keep apart ground truths: one per file."""
    spans = {"run.log": ("0", "0.3", "text"), "run.mcap": ("0", "0.5", "mcap")}
    for name, (start, end, fmt) in spans.items():
        result = run_cli("record", "railway", "--sensor", "urg", "--start", start, "--end", end, "--format", fmt,
                         "--out", name, cwd=tmp_path)
        assert result.returncode == 0, result.stderr
        assert f"ground truth to {name}.tum" in result.stdout
    assert sorted(path.name for path in tmp_path.iterdir()) == ["run.log", "run.log.tum", "run.mcap", "run.mcap.tum"]
    for name, poses in (("run.log.tum", 4), ("run.mcap.tum", 6)):
        lines = (tmp_path / name).read_text().splitlines()
        assert len([line for line in lines if not line.startswith("#")]) == poses


def test_record_does_not_write_through_a_symbolic_link(tmp_path: Path) -> None:
    """A link at --out (or at its ground truth's path) is refused, and what it points to is left alone."""
    target = tmp_path / "elsewhere.txt"
    target.write_text("keep me")
    for linked in ("run.log", "run.log.tum"):
        (tmp_path / linked).symlink_to(target)
        result = run_cli("record", "railway", "--sensor", "urg", "--end", "0.2", "--out", "run.log", cwd=tmp_path)
        assert result.returncode == 2 and "symbolic link" in result.stderr and "Traceback" not in result.stderr, result.stderr
        assert target.read_text() == "keep me"
        (tmp_path / linked).unlink()
