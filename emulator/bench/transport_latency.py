"""Latency and jitter of the real daemon, as a driver sees them.

Starts `lrf-emulator serve` (emulator.bench.serve_process) on temporary pty and
TCP endpoints and measures, with plain blocking file descriptors and
sockets (no client library in the way):
- command → first reply byte latency for `VV`, p50 / p99 / max, in both URG
  timing modes: `real` (the unit's 100 ms command cycle: 0-100 ms by design;
  commands are sent at spread offsets after the previous reply, so the figures
  cover the whole cycle) and `fast` (answered at once; the scene is copied
  with `timing = "fast"` on its URG sensors);
- scan-to-scan period jitter of an unlimited `MD` stream: |Δt − 100 ms|
  between consecutive scans' arrival, p99 / max.
Targets (the performance issue): fast latency p99 ≤ 10 ms; real latency
max ≤ 100 ms + 10 ms; jitter p99 ≤ 2 ms.
"""

from __future__ import annotations

import os
import re
import select
import socket
import tempfile
import time
from pathlib import Path
from typing import Callable

import numpy as np

from emulator.bench.serve_process import ServeProcess
from emulator.scene import load_scene

LATENCY_TARGET_MS = 10.0
JITTER_TARGET_MS = 2.0
SCAN_PERIOD_S = 0.1
STREAM_COMMAND = b"MD0044072501000\n"  # urg_library's full scan, unlimited
COMMAND_CYCLE_S = 0.1  # a real-timing URG handles commands once per revolution
OFFSET_STEP_S = 0.037  # real timing: each command this much later in the cycle than the last (mod 100 ms)


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


def command_latency(uri: str, count: int = 1000, *, spread_s: float = 0.0) -> dict[str, float]:
    """`VV` sent `count` times on an open endpoint: time to the reply's first byte.
    One exchange first, untimed: a pty client is noticed within 15 ms of opening.
    `spread_s`: wait (i · 37 ms) mod `spread_s` after each reply, so commands fall
    at every point of a real-timing URG's command cycle."""
    line = _Line(uri)
    try:
        line.write(b"VV\n")
        line.read_message(bytearray())
        latencies = []
        for index in range(count):
            if spread_s:
                time.sleep((index * OFFSET_STEP_S) % spread_s)
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


def fast_timing_scene(scene: str, folder: Path) -> Path:
    """A copy of `scene` in `folder` whose URG sensors answer at once (`timing = "fast"`).
    Relative mesh paths would point into `folder`: the bench scenes use none."""
    source = load_scene(scene).path
    if source is None:
        raise ValueError(f"scene {scene!r} has no file to copy")
    text = re.sub(r'(?m)^(model\s*=\s*"urg-04lx".*)$', r'\1\ntiming = "fast"', source.read_text())
    copy = folder / f"{source.stem}-fast.toml"
    copy.write_text(text)
    return copy


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
    """The `bench` section: latency on pty and TCP in both URG timing modes, jitter on the
    pty, with the scene's URG (and its LMS200, idle) served. Returns (data for JSON, table lines)."""
    commands, real_commands, scans = (50, 10, 20) if quick else (1000, 100, 600)
    latency: dict[str, dict] = {}
    with tempfile.TemporaryDirectory(prefix="lrf-bench-") as folder:
        pty_uri = f"pty:{Path(folder) / 'ttyURG'}"
        endpoints = [f"urg={pty_uri}", "urg=tcp:127.0.0.1:0", f"lms=pty:{Path(folder) / 'ttyLMS'}"]
        with ServeProcess(fast_timing_scene(scene, Path(folder)), endpoints) as daemon:
            tcp_uri = daemon.endpoint("urg", "tcp").uri
            latency["fast"] = {"pty": command_latency(pty_uri, commands), "tcp": command_latency(tcp_uri, commands)}
        with ServeProcess(scene, endpoints) as daemon:
            tcp_uri = daemon.endpoint("urg", "tcp").uri
            latency["real"] = {
                "pty": command_latency(pty_uri, real_commands, spread_s=COMMAND_CYCLE_S),
                "tcp": command_latency(tcp_uri, real_commands, spread_s=COMMAND_CYCLE_S),
            }
            jitter = scan_jitter(pty_uri, scans)
    data = {"latency": latency, "jitter": jitter}
    lines = []
    for timing, target in (("fast", f"p99 ≤ {LATENCY_TARGET_MS:g} ms"), ("real", "max ≤ 110 ms: the 100 ms command cycle")):
        count = commands if timing == "fast" else real_commands
        lines.append(f"command → first reply byte (VV × {count}), timing = {timing!r}, target {target}")
        for transport, figures in latency[timing].items():
            lines.append(
                f"  {transport:<4} p50 {figures['p50_ms']:7.3f} ms   p99 {figures['p99_ms']:7.3f} ms"
                f"   max {figures['max_ms']:7.3f} ms"
            )
    lines.append(f"MD scan period jitter |Δt − 100 ms| over {scans} scans (pty), target p99 ≤ {JITTER_TARGET_MS:g} ms")
    lines.append(
        f"  mean period {jitter['mean_period_ms']:.3f} ms   p99 {jitter['p99_ms']:.3f} ms   max {jitter['max_ms']:.3f} ms"
    )
    return data, lines
