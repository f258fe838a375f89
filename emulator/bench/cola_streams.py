"""`bench --section cola`: CoLa streams through the real daemon, every telegram timed on arrival.

Two cases (docs/cola.md "Speed"), each followed by its floor:

- `lms511-fine`: one LMS511 at 25 Hz, 0.1667° (1141 beams), under `physical`
  in a room with smoke, streamed over CoLa-B. Every scan must arrive (scan
  counters consecutive) and each gap between two arrivals lie within 5 % of
  the 40 ms period.
- `six-units`: one daemon serving 4 TiM571 (15 Hz) and 2 LMS111 (50 Hz,
  0.5°), each streamed to its own client. Every telegram on time: counters
  consecutive, and its jitter (arrival minus transmission time, less the
  client's median of that) within 1 ms at the 99th percentile.
- `floor`: the same telegram sizes, rates and phases from bare senders
  (`cola_floor`: a timerfd-woken loop that does nothing else), read by the
  same client: what this machine allows at the moment, to read the daemon's
  figures against. The load average is printed with the figures.

One thread reads every socket (selectors). A telegram's arrival is the
kernel's receive stamp of its last bytes (SO_TIMESTAMPNS, as `serve_load`
takes it), and reads stop at a telegram's end, so the figures are the
sender's, not this client's own scheduling; only the telegram's header
(counters, µs times) is read, at fixed CoLa-B offsets.
"""

from __future__ import annotations

import os
import selectors
import socket
import struct
import subprocess
import sys
import tempfile
import time
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Iterator

import numpy as np

from emulator.bench.serve_load import SCM_TIMESTAMPNS, stamp_received
from emulator.bench.serve_process import ServeProcess
from emulator.bench.steal import StealMeter, steal_percent
from emulator.scene import load_scene
from emulator.scene.sick_models import MODELS
from emulator.sensors.sick_cola import configured_request, power_on_phase_ms
from emulator.transport.timer import LATE_THRESHOLDS_MS
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
FIRST_TELEGRAM_TIMEOUT_S = 60.0
TIMESPEC = struct.Struct("@ll")
LENGTH = struct.Struct(">I")  # a CoLa-B telegram's payload length, after its four STX
JITTER_P99_LIMIT_MS = 1.0


@dataclass
class Stream:
    """One client's telegrams: scan counter, transmission time (µs), arrival (monotonic s)."""

    name: str
    period_s: float
    sock: socket.socket
    reader: ColaReader = field(default_factory=ColaReader)
    pending: int = 0  # bytes of the current telegram not read yet (0: its header is next)
    streaming: bool = False  # a LMDscandata telegram came
    counters: list[int] = field(default_factory=list)
    sent_us: list[int] = field(default_factory=list)
    arrived_s: list[float] = field(default_factory=list)

    def receive(self, realtime_to_monotonic: float, keep: bool) -> None:
        """Read up to the end of the current telegram (its 8 header bytes first, then the rest)."""
        wanted = self.pending or 8
        data, ancillary, _, _ = self.sock.recvmsg(wanted, socket.CMSG_SPACE(TIMESPEC.size))
        if not data:
            raise RuntimeError(f"{self.name}: the sender closed the stream")
        arrived = time.monotonic()
        for level, kind, payload in ancillary:
            if level == socket.SOL_SOCKET and kind == SCM_TIMESTAMPNS and len(payload) >= TIMESPEC.size:
                seconds, nanoseconds = TIMESPEC.unpack_from(payload)
                arrived = seconds + nanoseconds * 1e-9 - realtime_to_monotonic
        if self.pending:
            self.pending -= len(data)
        elif len(data) == 8 and data.startswith(b"\x02\x02\x02\x02"):
            self.pending = LENGTH.unpack_from(data, 4)[0] + 1  # the payload and its checksum
        for telegram in self.reader.feed(data):
            self.streaming |= telegram.payload.startswith(b"sSN LMDscandata ")
            if keep and telegram.payload.startswith(b"sSN LMDscandata "):
                fields = HEADER.unpack_from(telegram.payload, PAYLOAD_HEAD)
                self.counters.append(fields[6])
                self.sent_us.append(fields[8])
                self.arrived_s.append(arrived)

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


Address = tuple[str, int]


def _stream(sources: dict[str, tuple[Address, float]], duration_s: float, warm_up_s: float = 1.0,
            on_window: Callable[[], None] = lambda: None) -> list[Stream]:
    """Stream from every named source (address, period) to its own CoLa-B client for `duration_s`, from
    `warm_up_s` after every source has sent its first telegram; `on_window` is called as the measuring
    window opens and as it closes."""
    selector = selectors.DefaultSelector()
    streams = []
    for name, (address, period_s) in sources.items():
        sock = socket.create_connection(address, timeout=5)
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        stamp_received(sock)
        sock.sendall(frame(b"sEN LMDscandata \x01", Dialect.BINARY))
        sock.setblocking(False)
        stream = Stream(name, period_s, sock)
        streams.append(stream)
        selector.register(sock, selectors.EVENT_READ, stream)
    realtime_to_monotonic = time.time() - time.monotonic()  # the kernel stamps packets on CLOCK_REALTIME
    give_up = time.monotonic() + FIRST_TELEGRAM_TIMEOUT_S
    start = None  # once every stream has sent its first telegram (a worker's first scans may take seconds)
    window_open = False
    try:
        while start is None or time.monotonic() < start + warm_up_s + duration_s:
            for key, _ in selector.select(timeout=0.1):
                key.data.receive(realtime_to_monotonic, keep=start is not None and time.monotonic() >= start + warm_up_s)
            if not window_open and start is not None and time.monotonic() >= start + warm_up_s:
                window_open = True
                on_window()
            if start is None and all(stream.streaming for stream in streams):
                start = time.monotonic()
            elif start is None and time.monotonic() > give_up:
                raise RuntimeError(f"no telegram from {[s.name for s in streams if not s.streaming]}"
                                   f" in {FIRST_TELEGRAM_TIMEOUT_S:g} s")
        on_window()
    finally:
        for key in list(selector.get_map().values()):
            key.fileobj.close()
        selector.close()
    return streams


def _scene(folder: Path, sensors: list[tuple[str, str, str]], preset: str) -> Path:
    text = "".join(SENSOR.format(name=name, model=model, y=0.3 * index, options=options)
                   for index, (name, model, options) in enumerate(sensors))
    scene = folder / f"cola-bench-{preset}.toml"
    scene.write_text(ROOM.format(sensors=text, preset=preset))
    return scene


@contextmanager
def _floor(scene_path: Path) -> Iterator[dict[str, Address]]:
    """Bare senders (`cola_floor`) of the scene's CoLa sensors' telegram sizes, rates and power-on phases."""
    scene = load_scene(scene_path)
    specs = []
    for spec in scene.sensors:
        request = configured_request(spec.options)
        beams = MODELS[spec.model].beam_count(request["resolution_ticks"])
        specs.append(f"{spec.name}:{100_000 / request['frequency_ticks']!r}:{power_on_phase_ms(scene, spec.name)}:{beams}")
    process = subprocess.Popen([sys.executable, "-m", "emulator.bench.cola_floor", *specs], stdout=subprocess.PIPE, text=True)
    try:
        addresses = {}
        for _ in specs:
            _, name, port = process.stdout.readline().split()  # type: ignore[union-attr]
            addresses[name] = ("127.0.0.1", int(port))
        yield addresses
    finally:
        process.terminate()
        process.wait(10)


def _rows(case: str, streams: list[Stream], steal: float, counters: list[dict[str, int]] | None = None) -> list[dict]:
    """A row per stream, with the load average and, for a daemon, its own count of timer wake-ups in the
    window and the share more than 1, 2, 5 ms late (SIGUSR1 stats: what its loop saw, whatever the client)."""
    load = os.getloadavg()[0]
    daemon: dict = {}
    if counters is not None and len(counters) == 2:
        before, after = counters
        wakes = after["wakes"] - before["wakes"]
        daemon = {"loop_wakes": wakes, **{f"loop_late_{ms}ms": (after[f"late_{ms}ms"] - before[f"late_{ms}ms"]) / wakes
                                          if wakes else float("nan") for ms in LATE_THRESHOLDS_MS}}
    return [{"case": case, **stream.summary(), "load": load, "steal": steal, **daemon} for stream in streams]


def _served(scene: Path, names: dict[str, float], workers: int, duration_s: float) -> list[dict]:
    """The scene's sensors streamed from a daemon, one row each."""
    with ServeProcess(scene, [f"{name}=tcp:127.0.0.1:0" for name in names], extra_args=("--workers", str(workers))) as daemon:
        counters: list[dict[str, int]] = []
        steal = StealMeter()
        streams = _stream({name: (daemon.endpoint(name, "tcp").address, period) for name, period in names.items()},
                          duration_s, on_window=lambda: (counters.append(daemon.stats()), steal.mark()))
        return _rows("lms511-fine" if "lms511" in names else "six-units", streams, steal.share, counters)


def _floored(scene: Path, names: dict[str, float], duration_s: float) -> list[dict]:
    """The same streams from bare senders, one row each."""
    steal = StealMeter()
    with _floor(scene) as addresses:
        streams = _stream({name: (addresses[name], period) for name, period in names.items()}, duration_s, on_window=steal.mark)
        return _rows("floor", streams, steal.share)


def bench_section(quick: bool) -> tuple[dict, list[str]]:
    duration_s = 3.0 if quick else 10.0
    rows = []
    with tempfile.TemporaryDirectory(prefix="cola-bench-") as folder:
        fine = _scene(Path(folder), [("lms511", "lms511", 'scan_frequency_hz = 25\nresolution_deg = 0.1667\n')], "physical")
        rows += _served(fine, {"lms511": 0.04}, 1, duration_s) + _floored(fine, {"lms511": 0.04}, duration_s)
        six = [(f"tim{i}", "tim571", "") for i in range(4)] + [(f"lms{i}", "lms111", "") for i in range(2)]
        periods = {name: (1 / 15 if model == "tim571" else 0.02) for name, model, _ in six}
        six_scene = _scene(Path(folder), six, "formsma2011")
        rows += _served(six_scene, periods, 0, duration_s) + _floored(six_scene, periods, duration_s)
    lines = ["cola: CoLa-B streams through the daemon, and from bare timerfd senders (floor): arrival-time jitter,"
             " gaps within 5 % of the period, load average, CPU time stolen by the hypervisor; the daemon's timer wake-ups more than 1 ms late",
             f"  {'case':<12} {'client':<7} {'period':>7} {'scans':>6} {'missed':>6} {'gaps±5%':>8} {'p99 ms':>7} {'max ms':>7}"
             f" {'load':>5} {'steal':>5} {'wake>1ms':>8}"]
    for row in rows:
        late = f"{row['loop_late_1ms']:>8.1%}" if "loop_late_1ms" in row else f"{'':>8}"
        lines.append(f"  {row['case']:<12} {row['client']:<7} {row['period_ms']:>7.1f} {row['telegrams']:>6} {row['missed']:>6}"
                     f" {row['gaps_within_5pct']:>8.1%} {row['jitter_p99_ms']:>7.2f} {row['jitter_max_ms']:>7.2f}"
                     f" {row['load']:>5.2f} {steal_percent(row['steal']):>5} {late}")
    return {"cola": rows}, lines
