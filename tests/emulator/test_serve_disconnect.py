"""Clients killed in the middle of an unlimited MD, against the real daemon: the next
client's handshake completes at once, and 100 such cycles leak nothing."""

from __future__ import annotations

import re
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from emulator.bench.serve_process import ServeProcess
from emulator.bench.transport_latency import _Line

# A driver that opens the endpoint, starts an unlimited MD, reads the first scan,
# then hangs without reading (scans pile up in the pty / socket) until SIGKILLed.
KILLED_CLIENT = r"""
import os, socket, sys, time
uri = sys.argv[1]
scheme, _, rest = uri.partition(":")
if scheme == "pty":
    fd = os.open(rest, os.O_RDWR | os.O_NOCTTY)
    write, read = (lambda data: os.write(fd, data)), (lambda: os.read(fd, 65536))
else:
    host, _, port = rest.rpartition(":")
    sock = socket.create_connection((host, int(port)))
    write, read = sock.sendall, (lambda: sock.recv(65536))
write(b"MD0044072501000\n")
received = b""
while received.count(b"\n\n") < 2:
    received += read()
time.sleep(0.15)
print("streaming", flush=True)
time.sleep(60)
"""

STATS = re.compile(r"^stats (.*)$", re.MULTILINE)


def stats(daemon: ServeProcess) -> dict[str, int]:
    """The daemon's own counters (SIGUSR1 → one `stats` line on stderr)."""
    seen = len(STATS.findall(daemon.stderr))
    daemon.process.send_signal(signal.SIGUSR1)
    deadline = time.monotonic() + 5
    while len(STATS.findall(daemon.stderr)) == seen:
        assert time.monotonic() < deadline, "no stats line after SIGUSR1"
        time.sleep(0.002)
    fields = STATS.findall(daemon.stderr)[-1].split()
    return {key: int(value) for key, value in (field.split("=") for field in fields)}


def process_resources(pid: int) -> tuple[int, int]:
    """(open file descriptors, threads) of a process, from /proc."""
    fds = len(list(Path(f"/proc/{pid}/fd").iterdir()))
    threads = int(re.search(r"^Threads:\s+(\d+)", Path(f"/proc/{pid}/status").read_text(), re.MULTILINE).group(1))
    return fds, threads


def kill_streaming_client(uri: str) -> None:
    client = subprocess.Popen([sys.executable, "-c", KILLED_CLIENT, uri], stdout=subprocess.PIPE, text=True)
    try:
        assert client.stdout.readline() == "streaming\n"
    finally:
        client.kill()
        client.wait()


def wait_until_no_client(daemon: ServeProcess) -> None:
    """The daemon has noticed the killed client (a driver restarting takes far longer)."""
    deadline = time.monotonic() + 2
    while stats(daemon)["clients"] != 0:
        assert time.monotonic() < deadline, "the daemon did not notice the client went away"


def handshake(uri: str) -> float:
    """QT as urg_library's open sends it; the reply must be the first bytes the client sees."""
    started = time.monotonic()
    line = _Line(uri)
    try:
        line.write(b"QT\n")
        message, _ = line.read_message(bytearray(), timeout_s=1.0)
    finally:
        line.close()
    assert message == b"QT\n00P\n\n", f"stale or wrong bytes: {message[:80]!r}"
    return time.monotonic() - started


@pytest.fixture
def daemon(tmp_path: Path):
    with ServeProcess(
        "railway", [f"urg=pty:{tmp_path / 'ttyURG0'}", "urg=tcp:127.0.0.1:0", f"lms=pty:{tmp_path / 'ttyLMS0'}"]
    ) as served:
        yield served


@pytest.mark.parametrize("scheme", ["pty", "tcp"])
def test_the_next_client_after_a_killed_one_gets_its_reply_within_1_s(daemon: ServeProcess, scheme: str) -> None:
    uri = daemon.endpoint("urg", scheme).uri
    kill_streaming_client(uri)
    wait_until_no_client(daemon)
    assert handshake(uri) < 1.0


def test_a_killed_tcp_client_does_not_lock_out_its_immediate_successor(daemon: ServeProcess) -> None:
    """The successor connects before the daemon has seen the old client go (the daemon
    is stopped meanwhile): the one-client policy must not refuse a restarting driver."""
    uri = daemon.endpoint("urg", "tcp").uri
    client = subprocess.Popen([sys.executable, "-c", KILLED_CLIENT, uri], stdout=subprocess.PIPE, text=True)
    assert client.stdout.readline() == "streaming\n"
    daemon.process.send_signal(signal.SIGSTOP)
    try:
        successor = socket.create_connection(daemon.endpoint("urg", "tcp").address, timeout=2)
        client.kill()
        client.wait()
    finally:
        daemon.process.send_signal(signal.SIGCONT)
    with successor:
        successor.sendall(b"QT\n")
        assert successor.recv(100) == b"QT\n00P\n\n"


def test_100_killed_clients_leak_no_descriptors_threads_or_tasks(daemon: ServeProcess) -> None:
    uris = [daemon.endpoint("urg", "pty").uri, daemon.endpoint("urg", "tcp").uri]
    for uri in uris:  # one warm-up cycle each: lazily created resources are not leaks
        kill_streaming_client(uri)
        wait_until_no_client(daemon)
        handshake(uri)
    wait_until_no_client(daemon)
    before_fds, before_threads = process_resources(daemon.pid)
    before = stats(daemon)
    slowest = 0.0
    for cycle in range(100):
        uri = uris[cycle % 2]
        kill_streaming_client(uri)
        wait_until_no_client(daemon)
        slowest = max(slowest, handshake(uri))
    wait_until_no_client(daemon)
    after_fds, after_threads = process_resources(daemon.pid)
    after = stats(daemon)
    assert (after_fds, after_threads) == (before_fds, before_threads)
    assert after["tasks"] == before["tasks"] and after["fds"] == before["fds"]
    assert after["served"] == before["served"] + 200  # each cycle: the killed client and the handshake
    assert slowest < 1.0
