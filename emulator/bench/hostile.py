"""Hostile clients against the real daemon, and what a well-behaved neighbour sees meanwhile.

Used by the robustness suite (tests/robustness) and by `bench`'s fairness
section. `RAW_CLIENTS` opens any endpoint kind as a plain byte pipe (adding a
kind is one entry); `Flood` runs an attack on a thread; `LmsWatcher` streams
an LMS200 at 500 kBd on another endpoint and measures its scan rate, and
`lms_command_latencies` its replies to commands.
"""

from __future__ import annotations

import os
import random
import re
import select
import socket
import subprocess
import sys
import termios
import time
import tty
from collections.abc import Callable
from pathlib import Path

import numpy as np

from emulator.bench.lms_client import LmsSerialClient, Telegram
from emulator.bench.lms_rates import line_rate_limit

GD_FLOOD = b"GD0000076801\n" * (65536 // 13)  # 64 KiB of full-scan requests
WATCH_BAUD = 500_000
WATCH_RESOLUTION_DEG = 0.5
NOMINAL_SCANS_PER_S = line_rate_limit(WATCH_BAUD, WATCH_RESOLUTION_DEG)  # 37.5: the mirror's rate


class RawClient:
    """A client's end of one endpoint as a non-blocking byte pipe."""

    def __init__(self, fd: int, close: Callable[[], None]) -> None:
        self.fd = fd
        self._close = close
        self.received = 0

    def send(self, data: bytes, timeout_s: float = 5.0) -> int:
        """Write what the endpoint takes within `timeout_s` (a flooder does not wait forever)."""
        view, deadline = memoryview(data), time.monotonic() + timeout_s
        while view and time.monotonic() < deadline:
            if not select.select([], [self.fd], [], max(0.0, deadline - time.monotonic()))[1]:
                break
            try:
                view = view[os.write(self.fd, view) :]
            except BlockingIOError:
                continue
            except OSError:
                break
        return len(data) - len(view)

    def drain(self, timeout_s: float = 0.0) -> bytes:
        """Whatever has arrived (waiting up to `timeout_s` for the first byte)."""
        chunks = []
        while select.select([self.fd], [], [], timeout_s)[0]:
            try:
                chunk = os.read(self.fd, 65536)
            except (BlockingIOError, OSError):
                break
            if not chunk:
                break
            chunks.append(chunk)
            timeout_s = 0.0
        data = b"".join(chunks)
        self.received += len(data)
        return data

    def close(self) -> None:
        self._close()


def open_pty(path: str, baud: int | None = None) -> RawClient:
    fd = os.open(path, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
    tty.setraw(fd)
    if baud is not None:
        attributes = termios.tcgetattr(fd)
        attributes[4] = attributes[5] = getattr(termios, f"B{baud}")
        termios.tcsetattr(fd, termios.TCSANOW, attributes)
    return RawClient(fd, lambda: os.close(fd))


def open_tcp(address: str, baud: int | None = None) -> RawClient:
    host, _, port = address.rpartition(":")
    sock = socket.create_connection((host.strip("[]"), int(port)), timeout=5)
    sock.setblocking(False)
    return RawClient(sock.fileno(), sock.close)


# endpoint scheme → how a client opens it (the URI without its scheme; the baud for a serial line)
RAW_CLIENTS: dict[str, Callable[[str, int | None], RawClient]] = {
    "pty": open_pty,
    "tcp": open_tcp,
}


def open_raw(uri: str, baud: int | None = None) -> RawClient:
    scheme, _, rest = uri.partition(":")
    return RAW_CLIENTS[scheme](rest, baud)


BURSTS = {"gd": lambda: GD_FLOOD, "junk": lambda: junk(65536), "bad-lines": lambda: b"X\n" * 32768}


class Flood:
    """Writes a burst ("gd", "junk", "bad-lines") to `uri` every `period_s` (0: back to back)
    until stopped, reading whatever comes back unless `reads` is False. It runs in its own
    process, so that its busy loop takes no interpreter time from the client measuring."""

    def __init__(self, uri: str, burst: str, *, period_s: float = 0.0, reads: bool = True,
                 baud: int | None = None) -> None:
        self.args = [sys.executable, "-m", "emulator.bench.hostile", uri, burst, str(period_s),
                     "1" if reads else "0", str(baud or 0)]
        self.process: subprocess.Popen | None = None
        self.sent = self.received = 0

    def start(self) -> None:
        self.process = subprocess.Popen(self.args, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
        if self.process.stdout.readline().strip() != "flooding":
            raise RuntimeError(f"flood {self.args} did not start")

    def stop(self) -> None:
        """End the flood; `sent` and `received` count its bytes."""
        assert self.process is not None
        output, _ = self.process.communicate("stop\n", timeout=10)
        self.sent, self.received = (int(word) for word in output.split()[:2])

    def __enter__(self) -> Flood:
        self.start()
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.stop()


def _flood(uri: str, burst_name: str, period_s: float, reads: bool, baud: int | None) -> None:
    """The flooding process: until a line arrives on stdin; prints 'SENT RECEIVED' at the end."""
    client, burst, sent = open_raw(uri, baud), BURSTS[burst_name](), 0
    print("flooding", flush=True)
    while not select.select([sys.stdin], [], [], 0)[0]:
        started = time.monotonic()
        sent += client.send(burst, timeout_s=0.2)
        while True:
            if reads:
                client.drain(0.01)
            left = period_s - (time.monotonic() - started)
            if left <= 0:
                break
            if not reads:
                time.sleep(min(left, 0.01))
    print(sent, client.received, flush=True)
    client.close()


def junk(size: int, seed: int = 17) -> bytes:
    """Reproducible random bytes."""
    return random.Random(seed).randbytes(size)


def attach_lms(path: str) -> LmsSerialClient:
    """An LMS200 host on the pty at `path`, switched to 500 kBd at 180°/0.5°, in mode 25."""
    client = LmsSerialClient(path)
    client.find_device_baud()
    if client.baud != WATCH_BAUD:
        client.switch_baud(WATCH_BAUD)
    client.request(bytes([0x3B, 180, 0, round(WATCH_RESOLUTION_DEG * 100), 0]))
    client.discard_input()
    return client


def lms_scan_rate(client: LmsSerialClient, duration_s: float) -> float:
    """Full B0 scans per second streamed in mode 24 over `duration_s` (the line kept at 500 kBd)."""
    client.request(b"\x20\x24")
    expected = round(180 / WATCH_RESOLUTION_DEG) + 1
    arrivals = [
        event.arrived for event in client.events(duration_s)
        if isinstance(event, Telegram) and event.command == 0xB0 and event.b0_values()[0] & 0x3FF == expected
    ]
    client.request(b"\x20\x25")
    client.discard_input()
    if len(arrivals) < 2:
        return 0.0
    return (len(arrivals) - 1) / (arrivals[-1] - arrivals[0])


def lms_command_latencies(client: LmsSerialClient, count: int, timeout_s: float = 5.0) -> np.ndarray:
    """Seconds from sending a status request (31) to its whole B1 reply, `count` times."""
    latencies = []
    for _ in range(count):
        started = time.monotonic()
        _, reply = client.request(b"\x31", timeout_s)
        latencies.append(reply.arrived - started)
    return np.asarray(latencies)


def rss_kib(pid: int) -> int:
    """Resident set size of a process (kB), from /proc."""
    status = Path(f"/proc/{pid}/status").read_text()
    return int(re.search(r"^VmRSS:\s+(\d+)", status, re.MULTILINE).group(1))


if __name__ == "__main__":
    _flood(sys.argv[1], sys.argv[2], float(sys.argv[3]), sys.argv[4] == "1", int(sys.argv[5]) or None)
