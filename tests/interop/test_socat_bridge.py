"""The Docker user's path: TCP endpoints bridged back to a device file with socat.

A container cannot export a pty, so the image serves both sensors on TCP and
docs/interop.md tells host users to run
`socat pty,raw,echo=0,link=/tmp/ttyURG0 tcp:127.0.0.1:10940`. This checks that
bridge against the real daemon with serial clients on the socat pty.
"""

from __future__ import annotations

import subprocess
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
import serial
from support.interop import require_program
from support.ports import free_tcp_port

from emulator.bench.lms_client import ACK, LmsSerialClient, Telegram


@pytest.fixture
def bridge(tmp_path: Path) -> Iterator:
    """`bridge(link, port)` starts socat between a pty at `link` and 127.0.0.1:`port`."""
    socat = require_program("socat", "apt-get install socat")
    started: list[subprocess.Popen] = []

    def start(link: Path, port: int) -> Path:
        process = subprocess.Popen([socat, f"pty,raw,echo=0,link={link}", f"tcp:127.0.0.1:{port}"],
                                   stderr=subprocess.PIPE, text=True)
        started.append(process)
        deadline = time.monotonic() + 5.0
        while not link.exists():
            if process.poll() is not None or time.monotonic() > deadline:
                pytest.fail(f"socat gave no pty: {process.stderr.read() if process.poll() is not None else ''}")
            time.sleep(0.02)
        return link

    yield start
    for process in started:
        process.terminate()
        process.wait(5)


def read_reply(port: serial.Serial, timeout_s: float = 2.0) -> bytes:
    """One SCIP reply: up to and including its empty line."""
    reply = b""
    deadline = time.monotonic() + timeout_s
    while not reply.endswith(b"\n\n") and time.monotonic() < deadline:
        reply += port.read(max(1, port.in_waiting))
    return reply


def test_urg_through_socat(serve, urg_room: Path, tmp_path: Path, bridge) -> None:
    port = free_tcp_port()
    serve(urg_room, f"urg=tcp:127.0.0.1:{port}")
    link = bridge(tmp_path / "ttyURG0", port)
    with serial.Serial(str(link), 19200, timeout=0.05) as urg:
        urg.write(b"VV\n")
        assert read_reply(urg).startswith(b"VV\n00P\nVEND:Hokuyo Automatic Co.,Ltd.;[\n")
        urg.write(b"BM\n")
        assert read_reply(urg) in (b"BM\n00P\n\n", b"BM\n02R\n\n")
        urg.write(b"GD0044072501\n")
        reply = read_reply(urg)
        assert reply.startswith(b"GD0044072501\n00P\n") and len(reply) == 2134


def test_lms_through_socat(serve, lms_room: Path, tmp_path: Path, bridge) -> None:
    port = free_tcp_port()
    serve(lms_room, f"lms=tcp:127.0.0.1:{port}")
    link = bridge(tmp_path / "ttyLMS0", port)
    with LmsSerialClient(str(link), baud=38400) as lms:
        lms.discard_input()
        # Over TCP the device follows 20 40 logically; the pty's own rate does not reach it.
        assert lms.switch_baud(38400).data == b"\x00"
        lms.send(b"\x20\x24")
        events = list(lms.events(1.0))
        assert events[0] == ACK
        scans = [event for event in events if isinstance(event, Telegram) and event.command == 0xB0]
        assert len(scans) >= 3 and all(scan.b0_values()[0] & 0x3FF == 361 for scan in scans)
