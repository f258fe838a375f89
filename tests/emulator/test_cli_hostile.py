"""Hostile values for every subcommand's options (an empty name, a FIFO, a device, a link, absurd numbers,
characters no header carries): each refused in one line naming the option or file, exit status 2, no
traceback, nothing written, and never a hang, a daemon started, or a device or FIFO replaced.

Every case here failed before its fix: a hang (a FIFO opened for reading or writing), a file written
through a link or over a FIFO, a value taken that every other option refuses, or a message naming the
wrong thing (`.` for an empty name, `scene: sensors[0]` for a replay's --endpoint, "the answer is not
JSON" for a token HTTP cannot carry). Serve cases add `--idle-timeout 0`, refused after the scene loads:
a serve that let the hostile value through exits on that instead of starting a daemon."""

from __future__ import annotations

import os
import socket
import subprocess
from pathlib import Path

import pytest
from test_cli import CLI, run_cli
from test_cli_refusals import one_line_refusal

REFUSED_LATER = ["--idle-timeout", "0", "--view", "off", "--control", "off"]


def fifo(directory: Path, name: str) -> Path:
    path = directory / name
    os.mkfifo(path)
    return path


def unix_socket(directory: Path, name: str) -> Path:
    """A socket file: neither a regular file nor something open() can write."""
    path = directory / name
    server = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    server.bind(str(path))
    server.close()  # the file stays
    return path


def refusal(tmp_path: Path, *args: str) -> str:
    before = sorted(tmp_path.iterdir())
    line = one_line_refusal(run_cli(*args, cwd=tmp_path))
    assert sorted(tmp_path.iterdir()) == before, "a refusal wrote something"
    return line


# ---------------------------------------------------------------- names that are empty

@pytest.mark.parametrize(
    ("args", "expected"),
    [
        # Path('') is '.': ".: cannot read the event log: Is a directory"
        (["scan", "bocas", "--sensor", "urg", "--events-in", ""], "argument --events-in/--events: expected a file name, got ''"),
        (["record", "bocas", "--sensor", "urg", "--end", "0.2", "--out", "r.log", "--events", ""],
         "argument --events-in/--events: expected a file name, got ''"),
        # serve: "--events .: cannot write: Is a directory", "cannot write .: Is a directory (os error 21)"
        (["serve", "bocas", "--events", "", *REFUSED_LATER], "argument --events: expected a file name, got ''"),
        (["serve", "bocas", "--mcap", "", *REFUSED_LATER], "argument --mcap: expected a file name, got ''"),
        (["serve", "bocas", "--events-in", "", *REFUSED_LATER], "argument --events-in: expected a file name, got ''"),
        # replay: ".: is a directory, not a log file"
        (["replay", "", "--device", "urg-04lx"], "argument LOG: expected a log file, got ''"),
        # the blank name was shown as ''
        (["record", "bocas", "--sensor", "urg", "--end", "0.2", "--out", "   "], "expected a file name, got '   '"),
        # rosbag: "--sensor : name each sensor once"
        (["record", "bocas", "--sensor", "", "--end", "0.2", "--format", "rosbag2", "--out", "bag"],
         "--sensor '': a sensor name is empty"),
        (["record", "bocas", "--sensor", "urg,", "--end", "0.2", "--format", "rosbag1", "--out", "r.bag"],
         "--sensor 'urg,': a sensor name is empty"),
    ],
    ids=lambda value: " ".join(map(repr, value)) if isinstance(value, list) else None,
)
def test_an_empty_name_is_refused_as_empty(tmp_path: Path, args: list[str], expected: str) -> None:
    line = refusal(tmp_path, *args)
    assert expected in line, line


# ---------------------------------------------------------------- FIFOs, devices, sockets and links

def test_a_fifo_as_the_replayed_log_is_refused_not_waited_on(tmp_path: Path) -> None:
    """replay opened it for its magic bytes and blocked for good. `--device nonsense` is refused as
    argparse reaches it, after LOG: a replay that let the FIFO through names --device instead."""
    fifo(tmp_path, "scans.log")
    line = refusal(tmp_path, "replay", "scans.log", "--device", "nonsense")
    assert "argument LOG: scans.log: is not a regular file" in line, line


@pytest.mark.parametrize("name", ["scene.toml", "./scene"])
def test_a_fifo_as_the_scene_is_named_not_a_regular_file(tmp_path: Path, name: str) -> None:
    """It was `no such scene: 'scene.toml'`, though it is there."""
    fifo(tmp_path, name.removeprefix("./"))
    line = refusal(tmp_path, "scan", name, "--sensor", "urg")
    assert f"{name}: is not a regular file" in line, line


def test_plot_does_not_replace_a_fifo_named_as_its_output(tmp_path: Path) -> None:
    """plot renames its image over --out: a FIFO (or, as root, /dev/null itself) became a PNG file."""
    path = fifo(tmp_path, "map.png")
    line = refusal(tmp_path, "plot", "bocas", "--map", "--out", "map.png")
    assert "argument --out: map.png: exists and is not a regular file" in line, line
    assert path.is_fifo()


@pytest.mark.parametrize("fmt", ["text", "mcap"])
def test_record_does_not_write_to_a_socket_or_fifo(tmp_path: Path, fmt: str) -> None:
    """A FIFO blocked record for good (mcap); a socket failed only after the scene and the first scan."""
    unix_socket(tmp_path, "run.log")
    line = refusal(tmp_path, "record", "bocas", "--sensor", "urg", "--end", "0.2", "--format", fmt, "--out", "run.log")
    assert "argument --out: run.log: exists and is not a regular file" in line, line


@pytest.mark.parametrize("kind", ["fifo", "symlink"])
def test_serve_mcap_is_never_a_fifo_or_a_link(tmp_path: Path, kind: str) -> None:
    """A FIFO blocked serve before it served; a link had its target overwritten with MCAP data."""
    if kind == "fifo":
        fifo(tmp_path, "live.mcap")
    else:
        (tmp_path / "keep.toml").write_text("keep me")
        (tmp_path / "live.mcap").symlink_to(tmp_path / "keep.toml")
    line = refusal(tmp_path, "serve", "bocas", "--mcap", "live.mcap", *REFUSED_LATER)
    assert line.startswith("lrf-emulator serve: argument --mcap: live.mcap"), line
    if kind == "symlink":
        assert (tmp_path / "keep.toml").read_text() == "keep me"


def test_replay_names_its_endpoint_option_when_the_endpoint_cannot_serve(tmp_path: Path) -> None:
    """It was `scene: sensors[0].endpoints[0]: pty:...`: the user gave no scene, but --endpoint."""
    log = tmp_path / "run.log"
    result = run_cli("record", "bocas", "--sensor", "urg", "--end", "0.2", "--out", str(log), cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    (tmp_path / "taken").mkdir()
    line = refusal(tmp_path, "replay", "run.log", "--device", "urg-04lx", "--endpoint", "pty:taken")
    assert line.startswith("lrf-emulator replay: --endpoint urg: pty:taken: "), line


# ---------------------------------------------------------------- values out of range

def test_plot_map_time_takes_the_range_of_every_other_time(tmp_path: Path) -> None:
    """`plot --map --time 1e308` drew a map "at 1e+308 s"; --start, --end and scan --time refuse it."""
    for value in ("1e308", "99999999999999999999", "10000000.5"):
        line = refusal(tmp_path, "plot", "bocas", "--map", "--time", value, "--out", "map.png")
        assert line.startswith("lrf-emulator plot: argument --time: must be a time in 0..1e+07 s"), line


@pytest.mark.parametrize("value", ["1e308", "-1e300", "99999999999999999999"])
def test_serve_refuses_an_absurd_epoch_in_one_short_line(tmp_path: Path, value: str) -> None:
    """The refusal printed the epoch's distance to now in some 300 digits."""
    line = refusal(tmp_path, "serve", "bocas", f"--epoch={value}", *REFUSED_LATER)
    assert line.startswith("lrf-emulator serve: argument --epoch: expected a UNIX time within") and len(line) < 200, line


@pytest.mark.parametrize("token", ["a b", "é", "☃", "tab\there", "new\nline"], ids=repr)
def test_a_token_http_cannot_carry_is_refused_up_front(tmp_path: Path, token: str) -> None:
    """ctl sent it and reported "the answer is not JSON"; serve took it, and no client could then authenticate."""
    line = refusal(tmp_path, "ctl", "--url", "http://127.0.0.1:1", "--token", token, "state")
    assert line.startswith("lrf-emulator ctl: argument --token: expected visible ASCII"), line
    line = refusal(tmp_path, "serve", "bocas", "--control-token", token, *REFUSED_LATER)
    assert line.startswith("lrf-emulator serve: argument --control-token: expected visible ASCII"), line


@pytest.mark.parametrize("value", ["1e-320", "0.0009", "0"])
def test_serve_refuses_a_speed_that_all_but_stops_the_clock(tmp_path: Path, value: str) -> None:
    """`--speed 1e-320` was taken: simulated time then crept so slowly that no scan ever came due."""
    line = refusal(tmp_path, "serve", "bocas", "--speed", value, *REFUSED_LATER)
    assert line.startswith("lrf-emulator serve: --speed must be >= 0.001 and <= 1000, got"), line


@pytest.mark.parametrize("time_text", [str(10**400), "1e300"])
def test_an_event_time_no_float_holds_to_the_microsecond_is_refused_naming_its_line(tmp_path: Path, time_text: str) -> None:
    """A JSON integer of 400 digits was taken as a time and then overflowed the float (internal error, exit 1)."""
    log = tmp_path / "events.jsonl"
    log.write_text('{"t": 1.0, "op": "clock", "speed": 2}\n{"t": ' + time_text + ', "op": "clock", "speed": 1}\n')
    line = refusal(tmp_path, "scan", "bocas", "--sensor", "urg", "--events-in", str(log))
    assert line.startswith("lrf-emulator scan: events.jsonl: line 2: t: expected a time in seconds, 0 <= t < 1e+09, got"), line
    assert len(line) < 200, line


def test_a_live_pose_out_of_order_in_an_event_log_is_refused_naming_its_line(tmp_path: Path) -> None:
    """It was refused as the world took it, naming neither the line nor the body."""
    pose = '{"t": %s, "op": "pose", "name": "robot", "position": [0, 0, 0], "rotation_deg": [0, 0, 0]}\n'
    log = tmp_path / "back.jsonl"
    log.write_text(pose % 5.0 + pose % 1.0)
    line = refusal(tmp_path, "scan", "rescue-live", "--sensor", "urg", "--events-in", str(log))
    assert line == "lrf-emulator scan: back.jsonl: line 2: bodies[robot]: a live pose at 1 s, earlier than the body's last one (5 s)"


@pytest.mark.parametrize("args", [["scenes"], ["scan", "bocas", "--sensor", "urg"]])
def test_an_output_that_cannot_be_written_is_said_in_one_line_not_as_an_internal_error(tmp_path: Path, args: list[str]) -> None:
    """Standard output on a full disk (/dev/full) read "internal error (OSError: …)"."""
    with open("/dev/full", "w") as full:
        result = subprocess.run([*CLI, *args], stdout=full, stderr=subprocess.PIPE, text=True, timeout=120, cwd=tmp_path)
    assert result.returncode == 1
    assert result.stderr == f"lrf-emulator {args[0]}: cannot write: No space left on device\n"


def test_serve_refuses_one_file_for_both_the_event_log_and_the_mcap_recording(tmp_path: Path) -> None:
    line = refusal(tmp_path, "serve", "bocas", "--events", "same", "--mcap", "./same", *REFUSED_LATER)
    assert line == "lrf-emulator serve: --events same and --mcap same: one file each (both wrote it)", line  # ./same
