"""Interop fixtures: the REAL `lrf-emulator serve` process on temporary endpoints.

Every test here starts the installed daemon as a child process (`serve`
fixture), waits for its `ready` lines, drives it with an unmodified
third-party client (hokuyolx, MRPT's rawlog-grabber) or a driver-like pyserial
client, and SIGTERMs it at the end, checking that it exits 0.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
from support.interop import write_room
from support.ports import free_tcp_port

from emulator.bench.serve_process import ServeProcess


@pytest.fixture
def urg_room(tmp_path: Path) -> Path:
    """The room with a URG-04LX named `urg` at the origin, 0.3 m up, looking along +x."""
    return write_room(tmp_path, "urg")


@pytest.fixture
def lms_room(tmp_path: Path) -> Path:
    """The room with an LMS200 named `lms` at the origin, 0.45 m up, looking along +x."""
    return write_room(tmp_path, "lms")


@pytest.fixture
def ust_room(tmp_path: Path) -> Path:
    """The room with a UST-10LX named `ust` at the origin, 0.3 m up, looking along +x."""
    return write_room(tmp_path, "ust")


@pytest.fixture
def utm_room(tmp_path: Path) -> Path:
    """The room with a UTM-30LX-EW named `utm` at the origin, 0.3 m up, looking along +x."""
    return write_room(tmp_path, "utm")


@pytest.fixture
def serve() -> Iterator[Callable[..., ServeProcess]]:
    """`serve(scene, "urg=tcp:127.0.0.1:PORT", ...)` → a running daemon; SIGTERMed afterwards."""
    started: list[ServeProcess] = []

    def start(scene: str | Path, *endpoints: str, extra_args: tuple[str, ...] = ()) -> ServeProcess:
        daemon = ServeProcess(scene, endpoints, extra_args=extra_args)
        started.append(daemon)
        return daemon

    yield start
    failures = []
    for daemon in started:
        status = daemon.stop()
        if status != 0:
            failures.append(f"{' '.join(daemon.args)} exited {status} on SIGTERM\n{daemon.stderr}")
    assert not failures, "\n".join(failures)


@pytest.fixture
def tcp_port() -> int:
    return free_tcp_port()
