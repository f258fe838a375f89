"""Signals at any moment and whatever lies at a pty path: the daemon never harms files it did not make."""

from __future__ import annotations

import os
import signal
import subprocess
import time
from pathlib import Path

import pytest

from emulator.bench.hostile import open_raw
from emulator.bench.serve_process import ServeProcess, serve_command
from tests.robustness.conftest import SCALE

# moments into start-up (imports, scene, world, binding) a stop signal lands; more in a soak
START_UP_DELAYS_S = [0.25, 0.8] if SCALE <= 1 else [0.1, 0.25, 0.4, 0.6, 0.8, 1.0, 1.2, 1.6, 2.0]


def serve_args(tmp_path: Path, *extra: str) -> list[str]:
    return [*serve_command(), "serve", "railway", "--endpoint", f"urg=pty:{tmp_path / 'ttyURG0'}",
            "--endpoint", f"lms=pty:{tmp_path / 'ttyLMS0'}", "--control", "off", "--view", "off", *extra]


@pytest.mark.parametrize("signum", [signal.SIGHUP, signal.SIGQUIT, signal.SIGTERM, signal.SIGINT])
def test_every_stop_signal_removes_the_symlinks_and_exits_0(tmp_path: Path, signum: int) -> None:
    daemon = ServeProcess("railway", [f"urg=pty:{tmp_path / 'ttyURG0'}", f"lms=pty:{tmp_path / 'ttyLMS0'}"])
    daemon.process.send_signal(signum)
    assert daemon.process.wait(10) == 0
    daemon.stop()
    assert not os.path.lexists(tmp_path / "ttyURG0") and not os.path.lexists(tmp_path / "ttyLMS0")
    assert "Traceback" not in daemon.stderr


@pytest.mark.parametrize("delay_s", START_UP_DELAYS_S)
@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM])
def test_a_stop_signal_during_start_up_exits_quietly_and_leaves_nothing(
    tmp_path: Path, delay_s: float, signum: int
) -> None:
    process = subprocess.Popen(serve_args(tmp_path), stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, text=True)
    time.sleep(delay_s)
    process.send_signal(signum)
    try:
        _, stderr = process.communicate(timeout=15)
    except subprocess.TimeoutExpired:
        process.kill()
        process.communicate()
        pytest.fail(f"serve kept running after {signal.Signals(signum).name} at {delay_s} s")
    assert "Traceback" not in stderr and stderr.strip() == "", stderr
    # -signum: it came while Python itself was starting, before any of our code (nothing made yet)
    assert process.returncode in (0, 128 + signum, -signum)
    assert not os.path.lexists(tmp_path / "ttyURG0") and not os.path.lexists(tmp_path / "ttyLMS0")


@pytest.mark.parametrize("kind", ["link to a file", "dangling link", "link to a live pty", "file", "directory"])
def test_serve_refuses_a_pty_path_that_exists_and_leaves_it_alone(tmp_path: Path, kind: str) -> None:
    precious = tmp_path / "hostname"
    precious.write_text("precious\n")
    path = tmp_path / "ttyURG0"
    master, slave = os.openpty()  # a pty in use, as another daemon's or a terminal's
    try:
        live = os.ttyname(slave)
        target = {"link to a file": str(precious), "dangling link": str(tmp_path / "gone"), "link to a live pty": live}
        if kind in target:
            path.symlink_to(target[kind])
        elif kind == "directory":
            path.mkdir()
        else:
            path.write_text("mine\n")
        result = subprocess.run(serve_args(tmp_path), stdin=subprocess.DEVNULL, capture_output=True, text=True,
                                timeout=60)
    finally:
        os.close(slave)
        os.close(master)
    assert result.returncode == 2
    assert len(result.stderr.strip().splitlines()) == 1 and "ttyURG0" in result.stderr, result.stderr
    assert "already exists" in result.stderr
    assert os.path.lexists(path) and precious.read_text() == "precious\n"
    if kind in target:
        assert os.readlink(path) == target[kind]
    elif kind == "directory":
        assert path.is_dir() and not path.is_symlink()
    else:
        assert path.read_text() == "mine\n"
    assert not os.path.lexists(tmp_path / "ttyLMS0")


def vanished_pty() -> str:
    """A /dev/pts/N no pty has: what a daemon killed with SIGKILL leaves its link pointing to."""
    number = max((int(name) for name in os.listdir("/dev/pts") if name.isdigit()), default=0) + 1000  # none open: 1000
    assert not os.path.lexists(f"/dev/pts/{number}")
    return f"/dev/pts/{number}"


def test_a_link_left_by_a_daemon_that_died_is_replaced(tmp_path: Path) -> None:
    first = ServeProcess("railway", [f"urg=pty:{tmp_path / 'ttyURG0'}", f"lms=pty:{tmp_path / 'ttyLMS0'}"],
                         extra_args=["--workers", "0", "--control", "off"])  # no child process outlives it
    first.process.kill()  # SIGKILL: no chance to remove its links
    first.process.wait(10)
    first.stop()
    assert os.path.islink(tmp_path / "ttyURG0")
    for link in ("ttyURG0", "ttyLMS0"):  # their ptys went with the daemon; pin the links to numbers surely gone
        os.unlink(tmp_path / link)
        os.symlink(vanished_pty(), tmp_path / link)
    with ServeProcess("railway", [f"urg=pty:{tmp_path / 'ttyURG0'}", f"lms=pty:{tmp_path / 'ttyLMS0'}"]) as second:
        link = os.readlink(tmp_path / "ttyURG0")
        assert os.path.exists(link) and link == second.endpoint("urg", "pty").device
        client = open_raw(f"pty:{tmp_path / 'ttyURG0'}")
        try:
            client.send(b"VV\n")
            reply = b""
            for _ in range(20):
                reply += client.drain(0.1)
                if reply.endswith(b"\n\n"):
                    break
            assert reply.startswith(b"VV\n00P\n")
        finally:
            client.close()
    assert not os.path.lexists(tmp_path / "ttyURG0") and not os.path.lexists(tmp_path / "ttyLMS0")


def test_a_second_daemon_on_the_same_path_is_refused_and_the_first_keeps_serving(tmp_path: Path) -> None:
    with ServeProcess("railway", [f"urg=pty:{tmp_path / 'ttyURG0'}", f"lms=pty:{tmp_path / 'ttyLMS0'}"]) as first:
        link = os.readlink(tmp_path / "ttyURG0")
        second = subprocess.run(serve_args(tmp_path), stdin=subprocess.DEVNULL, capture_output=True, text=True,
                                timeout=60)
        assert second.returncode == 2 and "already exists" in second.stderr, second.stderr
        assert os.readlink(tmp_path / "ttyURG0") == link
        client = open_raw(first.endpoint("urg", "pty").uri)
        try:
            client.send(b"VV\n")
            reply = b""
            for _ in range(20):
                reply += client.drain(0.1)
                if reply.endswith(b"\n\n"):
                    break
            assert reply.startswith(b"VV\n00P\n")
        finally:
            client.close()
    assert not os.path.lexists(tmp_path / "ttyURG0")
