"""`serve --view/--foxglove/--mcap` and `replay FILE.mcap` refuse bad input with one line and exit 2."""

from __future__ import annotations

import subprocess
from pathlib import Path

import pytest

from emulator.bench.serve_process import serve_command


def run(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run([*serve_command(), *args], capture_output=True, text=True, timeout=120, cwd=cwd)


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["serve", "railway", "--view", "0.0.0.0:8080"], "--view 0.0.0.0:8080: the view changes the world, so it listens on loopback only"),
        (["serve", "railway", "--view", "localhost"], "--view 'localhost': expected HOST:PORT or off"),
        (["serve", "railway", "--foxglove", "127.0.0.1:99999"], "--foxglove '127.0.0.1:99999': expected HOST:PORT or off"),
    ],
)
def test_bad_listen_options_are_one_line(tmp_path: Path, args: list[str], message: str) -> None:
    result = run(*args, cwd=tmp_path)
    assert result.returncode == 2
    assert result.stderr == f"lrf-emulator serve: {message}\n"


def test_replay_of_an_mcap_without_that_topic_is_one_line(tmp_path: Path) -> None:
    recording = tmp_path / "urg.mcap"
    assert run("record", "railway", "--sensor", "urg", "--start", "0", "--end", "0.2", "--out", str(recording),
               "--format", "mcap", cwd=tmp_path).returncode == 0
    result = run("replay", str(recording), "--device", "urg-04lx", "--topic", "/lms/scan", cwd=tmp_path)
    assert result.returncode == 2
    assert result.stderr == (
        "lrf-emulator replay: urg.mcap: --topic /lms/scan: not a LaserScan topic (LaserScan topics: /urg/scan)\n"
    )
    text = tmp_path / "urg.log"
    text.write_text("# lrf-emulator log sensor=urg model=urg-04lx unit=mm\n0.000 0.0 100\n")
    result = run("replay", str(text), "--device", "urg-04lx", "--topic", "/scan", cwd=tmp_path)
    assert result.returncode == 2 and "is not an MCAP file" in result.stderr
