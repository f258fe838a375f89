"""`bench --section cola`: CoLa streams through the real daemon, every telegram timed on arrival.

Two cases (docs/cola.md "Speed"):

- `lms511-fine`: one LMS511 at 25 Hz, 0.1667° (1141 beams), under `physical`
  in a room with smoke, streamed over CoLa-B. Every scan must arrive (scan
  counters consecutive) and each gap between two arrivals lie within 5 % of
  the 40 ms period.
- `six-units`: one daemon serving 4 TiM571 (15 Hz) and 2 LMS111 (50 Hz,
  0.5°), each streamed to its own client. Every telegram on time: counters
  consecutive, and its jitter (arrival minus transmission time, less the
  client's median of that) within 1 ms at the 99th percentile.

One thread reads every socket (selectors) and stamps each chunk as it
arrives; only the telegram's header (counters, µs times) is read, at fixed
CoLa-B offsets, so reading costs the clock nothing.
"""

from __future__ import annotations

import selectors
import socket
import struct
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from emulator.bench.serve_process import ServeProcess
from protocols.cola.framing import ColaReader, Dialect, frame

ROOM = """
[scene]
name = "cola-bench"
model = "{preset}"
seed = 3
[[objects]]
name = "north"
box = {{ size = [20.0, 0.2, 3.0] }}
position = [0.0, 6.0, 1.5]
[[objects]]
name = "south"
box = {{ size = [20.0, 0.2, 3.0] }}
position = [0.0, -6.0, 1.5]
[[objects]]
name = "east"
box = {{ size = [0.2, 12.0, 3.0] }}
position = [8.0, 0.0, 1.5]
[[smoke.regions]]
name = "haze"
box = {{ size = [4.0, 8.0, 2.5] }}
position = [4.0, 0.0, 1.25]
density = 0.002
{sensors}
"""
SENSOR = '[[sensors]]\nname = "{name}"\nmodel = "{model}"\nposition = [0.0, {y}, 0.5]\n{options}endpoints = []\n'
HEADER = struct.Struct(">HHIBBHHII")  # version … transmission time, after "sSN LMDscandata "
PAYLOAD_HEAD = len(b"sSN LMDscandata ")
PERIOD_TOLERANCE = 0.05
JITTER_P99_LIMIT_MS = 1.0


@dataclass
class Stream:
    """One client's telegrams: scan counter, transmission time (µs), arrival (monotonic s)."""

    name: str
    period_s: float
    reader: ColaReader = field(default_factory=ColaReader)
    counters: list[int] = field(default_factory=list)
    sent_us: list[int] = field(default_factory=list)
    arrived_s: list[float] = field(default_factory=list)

    def take(self, data: bytes, now: float) -> None:
        for telegram in self.reader.feed(data):
            if telegram.payload.startswith(b"sSN LMDscandata "):
                fields = HEADER.unpack_from(telegram.payload, PAYLOAD_HEAD)
                self.counters.append(fields[6])
                self.sent_us.append(fields[8])
                self.arrived_s.append(now)

    def summary(self) -> dict:
        counters = np.array(self.counters)
        arrived = np.array(self.arrived_s)
        offsets = arrived - np.array(self.sent_us) / 1e6
        jitter_ms = np.abs(offsets - np.median(offsets)) * 1000.0 if len(offsets) else np.zeros(1)
        gaps = np.diff(arrived)
        return {
            "client": self.name,
            "telegrams": len(counters),
            "missed": int(np.sum(np.diff(counters) - 1)) if len(counters) > 1 else 0,
            "gaps_within_5pct": float(np.mean(np.abs(gaps - self.period_s) <= PERIOD_TOLERANCE * self.period_s)) if len(gaps) else 0.0,
            "jitter_p99_ms": float(np.percentile(jitter_ms, 99)),
            "jitter_max_ms": float(jitter_ms.max()),
            "period_ms": self.period_s * 1000.0,
        }


def _stream(daemon: ServeProcess, names: dict[str, float], duration_s: float, warm_up_s: float = 1.0) -> list[Stream]:
    """Stream every named sensor to its own CoLa-B client for `duration_s` after `warm_up_s`."""
    selector = selectors.DefaultSelector()
    streams = []
    for name, period_s in names.items():
        sock = socket.create_connection(daemon.endpoint(name, "tcp").address, timeout=5)
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        sock.sendall(frame(b"sEN LMDscandata \x01", Dialect.BINARY))
        sock.setblocking(False)
        stream = Stream(name, period_s)
        streams.append(stream)
        selector.register(sock, selectors.EVENT_READ, stream)
    start = time.monotonic()
    try:
        while time.monotonic() < start + warm_up_s + duration_s:
            for key, _ in selector.select(timeout=0.1):
                now = time.monotonic()
                data = key.fileobj.recv(1 << 20)
                if data and now >= start + warm_up_s:
                    key.data.take(data, now)
    finally:
        for key in list(selector.get_map().values()):
            key.fileobj.close()
        selector.close()
    return streams


def _serve(folder: Path, sensors: list[tuple[str, str, str]], preset: str, workers: int) -> ServeProcess:
    text = "".join(SENSOR.format(name=name, model=model, y=0.3 * index, options=options)
                   for index, (name, model, options) in enumerate(sensors))
    scene = folder / f"cola-bench-{preset}.toml"
    scene.write_text(ROOM.format(sensors=text, preset=preset))
    return ServeProcess(scene, [f"{name}=tcp:127.0.0.1:0" for name, _, _ in sensors], extra_args=("--workers", str(workers)))


def bench_section(quick: bool) -> tuple[dict, list[str]]:
    duration_s = 3.0 if quick else 10.0
    rows = []
    with tempfile.TemporaryDirectory(prefix="cola-bench-") as folder:
        fine = [("lms511", "lms511", 'scan_frequency_hz = 25\nresolution_deg = 0.1667\n')]
        with _serve(Path(folder), fine, "physical", workers=1) as daemon:
            rows += [{"case": "lms511-fine", **s.summary()} for s in _stream(daemon, {"lms511": 0.04}, duration_s)]
        six = [(f"tim{i}", "tim571", "") for i in range(4)] + [(f"lms{i}", "lms111", "") for i in range(2)]
        with _serve(Path(folder), six, "formsma2011", workers=0) as daemon:
            periods = {name: (1 / 15 if model == "tim571" else 0.02) for name, model, _ in six}
            rows += [{"case": "six-units", **s.summary()} for s in _stream(daemon, periods, duration_s)]
    lines = ["cola: CoLa-B streams through the daemon (arrival-time jitter; gaps within 5 % of the period)",
             f"  {'case':<12} {'client':<7} {'period':>7} {'scans':>6} {'missed':>6} {'gaps±5%':>8} {'p99 ms':>7} {'max ms':>7}"]
    for row in rows:
        lines.append(f"  {row['case']:<12} {row['client']:<7} {row['period_ms']:>7.1f} {row['telegrams']:>6} {row['missed']:>6}"
                     f" {row['gaps_within_5pct']:>8.1%} {row['jitter_p99_ms']:>7.2f} {row['jitter_max_ms']:>7.2f}")
    return {"cola": rows}, lines
