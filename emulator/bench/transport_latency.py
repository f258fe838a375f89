"""Latency and jitter of the real daemon, as a driver sees them.

Starts `lrf-emulator serve` (emulator.bench.serve_process) on temporary pty and
TCP endpoints and measures, with plain blocking file descriptors and
sockets (no client library in the way):
- command → first reply byte latency for `VV`, p50 / p99 / max;
- scan-to-scan period jitter of an unlimited `MD` stream: |Δt − 100 ms|
  between consecutive scans' arrival, p99 / max.
Targets (the performance issue): latency p99 ≤ 10 ms, jitter p99 ≤ 2 ms.
"""

from __future__ import annotations

import os
import select
import socket
import tempfile
import time
from pathlib import Path
from typing import Callable

import numpy as np

from emulator.bench.serve_process import ServeProcess

LATENCY_TARGET_MS = 10.0
JITTER_TARGET_MS = 2.0
SCAN_PERIOD_S = 0.1
STREAM_COMMAND = b"MD0044072501000\n"  # urg_library's full scan, unlimited


class _Line:
    """A blocking byte pipe to one endpoint: a pty opened like a driver does, or a TCP socket."""

    def __init__(self, uri: str) -> None:
        scheme, _, rest = uri.partition(":")
        if scheme == "pty":
            fd = os.open(rest, os.O_RDWR | os.O_NOCTTY)
            self._fd = fd
            self.write: Callable[[bytes], object] = lambda data: os.write(fd, data)
            self.read: Callable[[], bytes] = lambda: os.read(fd, 65536)
            self.close: Callable[[], None] = lambda: os.close(fd)
        else:
            host, _, port = rest.rpartition(":")
            sock = socket.create_connection((host.strip("[]"), int(port)))
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            self._fd = sock.fileno()
            self.write = sock.sendall
            self.read = lambda: sock.recv(65536)
            self.close = sock.close

    def wait_readable(self, timeout_s: float) -> bool:
        return bool(select.select([self._fd], [], [], timeout_s)[0])

    def read_message(self, buffer: bytearray, timeout_s: float = 2.0) -> tuple[bytes, float]:
        """The next SCIP message (up to its empty line) and when its last byte arrived."""
        deadline = time.monotonic() + timeout_s
        while b"\n\n" not in buffer:
            if not self.wait_readable(deadline - time.monotonic()):
                raise TimeoutError(f"no complete message within {timeout_s} s")
            buffer += self.read()
        arrived = time.perf_counter()
        end = buffer.index(b"\n\n") + 2
        message = bytes(buffer[:end])
        del buffer[:end]
        return message, arrived


def _percentiles(values_ms: list[float]) -> dict[str, float]:
    data = np.asarray(values_ms)
    return {
        "p50_ms": round(float(np.percentile(data, 50)), 3),
        "p99_ms": round(float(np.percentile(data, 99)), 3),
        "max_ms": round(float(data.max()), 3),
    }


def command_latency(uri: str, count: int = 1000) -> dict[str, float]:
    """`VV` sent `count` times on an open endpoint: time to the reply's first byte.
    One exchange first, untimed: a pty client is noticed within 15 ms of opening."""
    line = _Line(uri)
    try:
        line.write(b"VV\n")
        line.read_message(bytearray())
        latencies = []
        for _ in range(count):
            started = time.perf_counter()
            line.write(b"VV\n")
            if not line.wait_readable(2.0):
                raise TimeoutError(f"{uri}: no reply to VV within 2 s")
            first = time.perf_counter()
            buffer = bytearray(line.read())
            line.read_message(buffer)
            latencies.append((first - started) * 1000)
        return {"count": count, **_percentiles(latencies)}
    finally:
        line.close()


def scan_jitter(uri: str, scans: int = 600) -> dict[str, float]:
    """An unlimited MD stream: |Δt − 100 ms| between consecutive scans' arrival."""
    line = _Line(uri)
    try:
        buffer = bytearray()
        line.write(STREAM_COMMAND)
        line.read_message(buffer)  # the acknowledgement
        arrivals = [line.read_message(buffer)[1] for _ in range(scans + 1)]
        line.write(b"QT\n")
    finally:
        line.close()
    periods_ms = np.diff(arrivals) * 1000
    deviations = np.abs(periods_ms - SCAN_PERIOD_S * 1000)
    return {
        "scans": scans,
        "mean_period_ms": round(float(periods_ms.mean()), 3),
        **{key: value for key, value in _percentiles(list(deviations)).items() if key != "p50_ms"},
    }


def transport_bench(quick: bool = False, scene: str = "railway") -> tuple[dict, list[str]]:
    """The `bench` section: latency on pty and TCP, jitter on the pty, with the
    scene's URG (and its LMS200, idle) served. Returns (data for JSON, table lines)."""
    commands, scans = (50, 20) if quick else (1000, 600)
    with tempfile.TemporaryDirectory(prefix="lrf-bench-") as folder:
        pty_uri = f"pty:{Path(folder) / 'ttyURG'}"
        endpoints = [f"urg={pty_uri}", "urg=tcp:127.0.0.1:0", f"lms=pty:{Path(folder) / 'ttyLMS'}"]
        with ServeProcess(scene, endpoints) as daemon:
            tcp_uri = daemon.endpoint("urg", "tcp").uri
            data = {
                "latency": {
                    "pty": command_latency(pty_uri, commands),
                    "tcp": command_latency(tcp_uri, commands),
                },
                "jitter": scan_jitter(pty_uri, scans),
            }
    lines = [f"command → first reply byte (VV × {commands}), target p99 ≤ {LATENCY_TARGET_MS:g} ms"]
    for transport, figures in data["latency"].items():
        lines.append(
            f"  {transport:<4} p50 {figures['p50_ms']:7.3f} ms   p99 {figures['p99_ms']:7.3f} ms"
            f"   max {figures['max_ms']:7.3f} ms"
        )
    jitter = data["jitter"]
    lines.append(f"MD scan period jitter |Δt − 100 ms| over {scans} scans (pty), target p99 ≤ {JITTER_TARGET_MS:g} ms")
    lines.append(
        f"  mean period {jitter['mean_period_ms']:.3f} ms   p99 {jitter['p99_ms']:.3f} ms   max {jitter['max_ms']:.3f} ms"
    )
    return data, lines
