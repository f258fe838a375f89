"""The browser view's own process (emulator/view/process.py) as the real daemon runs it.

The view runs in a spawned child of `serve`; with `--workers 0` it is the only
child running `multiprocessing.spawn` (workers would be others). Killing it
must not stop the daemon: scans keep coming and SIGTERM still exits 0. A
normal stop ends it too: no view process outlives its daemon.
"""

from __future__ import annotations

import os
import signal
import socket
from pathlib import Path

from support.interop import write_room

from emulator.bench.serve_load import child_pids
from emulator.bench.serve_process import ServeProcess

GD = b"GD0044072501\n"


def view_processes(daemon_pid: int) -> list[int]:
    return [pid for pid in child_pids(daemon_pid)
            if b"multiprocessing.spawn" in Path(f"/proc/{pid}/cmdline").read_bytes()]


def alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state not in ("Z", "X")  # a zombie has ended (an init that does not reap leaves them)


def reply_to(connection: socket.socket, command: bytes) -> bytes:
    """A SCIP command's whole reply, up to its blank line."""
    connection.sendall(command)
    reply = b""
    while not reply.endswith(b"\n\n"):
        chunk = connection.recv(65536)
        assert chunk, f"the daemon closed the connection after {reply!r}"
        reply += chunk
    return reply


def one_scan(address: tuple[str, int]) -> bytes:
    """Laser on (BM), then one GD scan's reply."""
    with socket.create_connection(address, timeout=20) as connection:
        assert reply_to(connection, b"BM\n").startswith(b"BM\n0")
        return reply_to(connection, GD)


def test_the_daemon_serves_on_when_its_view_process_dies(tmp_path: Path) -> None:
    room = write_room(tmp_path, "urg")
    daemon = ServeProcess(room, ["urg=tcp:127.0.0.1:0"], extra_args=["--view", "127.0.0.1:0", "--workers", "0"])
    try:
        daemon.service("view")
        views = view_processes(daemon.pid)
        assert len(views) == 1, views
        os.kill(views[0], signal.SIGKILL)
        address = daemon.endpoint("urg", "tcp").address
        for _ in range(3):
            assert one_scan(address).startswith(GD + b"00"), "no scan after the view's process died"
    finally:
        status = daemon.stop()
    assert status == 0, daemon.stderr
    assert "Traceback" not in daemon.stderr, daemon.stderr  # the view's end is expected, not a crash


def test_stopping_the_daemon_ends_its_view_process(tmp_path: Path) -> None:
    room = write_room(tmp_path, "urg")
    daemon = ServeProcess(room, ["urg=tcp:127.0.0.1:0"], extra_args=["--view", "127.0.0.1:0", "--workers", "0"])
    try:
        daemon.service("view")
        views = view_processes(daemon.pid)
        assert len(views) == 1, views
        assert one_scan(daemon.endpoint("urg", "tcp").address).startswith(GD + b"00")
    finally:
        status = daemon.stop()
    assert status == 0, daemon.stderr
    assert not alive(views[0]), "the view's process outlived its daemon"
