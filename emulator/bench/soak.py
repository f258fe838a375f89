"""`lrf-emulator bench --section soak --minutes N`: the real daemon for a long while, under everything at once.

What a leak, a stuck descriptor or a slow drift needs hours to show, a soak
shows in one: every sensor model the bundled scenes carry streams on a pty and
on TCP to clients that stay, while other clients connect, start a stream and
vanish (half of the TCP ones with a reset), WebSocket clients subscribe to the
scans and vanish, a live change arrives every second through the control API,
and the browser view (with a watcher connected) and an MCAP recording run
throughout. The scenes are the fewest bundled ones that carry every model
among them (a model added to a bundled scene joins by itself); each gets its
own `serve`.

Every sample (once a minute; a tenth of a shorter run) notes, per daemon:
resident memory of the daemon and of its child processes (scan workers, the
view), open descriptors and threads (sampled while no churning client is
connected, so the count is the daemon's own), the daemon's counters (SIGUSR1:
timer wake-ups more than 5 ms late, stale scans dropped), the event log's and
the MCAP file's size; per stream: scans received and scans late, i.e. that
arrived more than one period after the previous one (a gap over twice the
stream's median gap). After the warm-up (the first sixth, at most ten
minutes) memory must stay within MEMORY_GROWTH_LIMIT of its first sample and
the descriptors must not grow (the fewest of the last FD_SETTLE_SAMPLES
samples no more than the fewest of the first FD_SETTLE_SAMPLES: one held
for a moment at either end is not a leak):
`passed` says whether they did.
"""

from __future__ import annotations

import asyncio
import os
import random
import re
import selectors
import socket
import struct
import sys
import tempfile
import threading
import time
import urllib.error
import urllib.request
import json
from contextlib import ExitStack
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from emulator.bench.hostile import RawClient, open_raw, rss_kib
from emulator.bench.lms_client import host_telegram
from emulator.bench.serve_load import child_pids
from emulator.bench.serve_process import ServeProcess
from emulator.daemon.service import build_device
from emulator.scene import bundled_scenes, load_scene
from emulator.scene.bodies import Live
from emulator.scene.model import Scene, SensorSpec

MEMORY_GROWTH_LIMIT = 0.05  # resident memory after warm-up stays within 5 % of its first sample
SAMPLE_EVERY_S = 60.0
MAX_WARM_UP_S = 600.0
CHANGE_EVERY_S = 1.0
CHURN_STREAM_S = (0.2, 4.0)  # a churning client streams this long (uniform) before it vanishes
QUIET_BEFORE_SAMPLE_S = 0.5  # churning clients gone this long before descriptors are counted
HANDSHAKE_TIMEOUT_S = 10.0
SEED = 24
FD_SETTLE_SAMPLES = 3  # descriptors grew if even the fewest of the last samples exceed the fewest of the first after warm-up


# --------------------------------------------------------------------------- what to serve


def soak_scenes() -> list[Scene]:
    """The fewest bundled scenes (greedily) whose sensors carry every model the bundled scenes have."""
    scenes = [load_scene(bundled.name) for bundled in bundled_scenes()]
    wanted = {spec.model for scene in scenes for spec in scene.sensors}
    chosen: list[Scene] = []
    while wanted:
        best = max(scenes, key=lambda scene: len(wanted & {spec.model for spec in scene.sensors}))
        chosen.append(best)
        wanted -= {spec.model for spec in best.sensors}
    return chosen


def protocol_of(spec: SensorSpec) -> str:
    """The protocol package (`scip`, `lms2xx`, ...) of the device the daemon builds for this sensor."""
    device = build_device(spec, _no_scans)
    return type(device).__module__.split(".")[1]


def _no_scans(*args: object, **kwargs: object) -> object:
    raise RuntimeError("the soak only asks which device a sensor gets")


# --------------------------------------------------------------------------- clients, per protocol


class _ScipFramer:
    """SCIP messages end in an empty line; a scan of MD is one whose status is 99."""

    def __init__(self) -> None:
        self._buffer = b""

    def scans(self, data: bytes) -> int:
        self._buffer += data
        parts = self._buffer.split(b"\n\n")
        self._buffer = parts.pop()
        return sum(1 for part in parts if part.split(b"\n")[1:2] and part.split(b"\n")[1].startswith(b"99"))


def _scip_start(client: RawClient) -> _ScipFramer:
    """PP for the device's measuring range (AMIN..AMAX: any SCIP 2 Hokuyo), then an endless MD stream."""
    client.send(b"PP\n")
    reply = _read_until(client, lambda data: b"\n\n" in data)
    found = re.search(rb"AMIN:(\d+);.*AMAX:(\d+);", reply, re.DOTALL)
    if found is None:
        raise RuntimeError(f"no AMIN/AMAX in the PP reply {reply[:200]!r}")
    first, last = int(found.group(1)), int(found.group(2))
    client.send(b"MD%04d%04d01000\n" % (first, last))
    return _ScipFramer()


class _LmsFramer:
    """LMS2xx telegrams by STX, address 0x80 and length (the interop tests check CRCs; this counts B0 scans)."""

    def __init__(self) -> None:
        self._buffer = bytearray()

    def scans(self, data: bytes) -> int:
        self._buffer += data
        count = 0
        while self._buffer:
            if self._buffer[:2] != b"\x02\x80":
                start = self._buffer.find(b"\x02\x80", 1)
                del self._buffer[: start if start >= 0 else max(len(self._buffer) - 1, 0)]
                if start < 0:
                    return count
                continue
            if len(self._buffer) < 5:
                return count
            total = 4 + int.from_bytes(self._buffer[2:4], "little") + 2
            if len(self._buffer) < total:
                return count
            count += self._buffer[4] == 0xB0
            del self._buffer[:total]
        return count


def _lms_start(client: RawClient) -> _LmsFramer:
    """Continuous output of every scan (20 24) at the line's power-on rate."""
    client.send(host_telegram(b"\x20\x24"))
    return _LmsFramer()


class _ColaFramer:
    """CoLa-A telegrams between STX and ETX; a scan is an `sSN LMDscandata` event."""

    def __init__(self) -> None:
        self._buffer = b""

    def scans(self, data: bytes) -> int:
        self._buffer += data
        parts = self._buffer.split(b"\x03")
        self._buffer = parts.pop()
        return sum(1 for part in parts if part.lstrip(b"\x02").startswith(b"sSN LMDscandata"))


def _cola_start(client: RawClient) -> _ColaFramer:
    """The scan data event stream (sEN LMDscandata 1) in CoLa-A, at the unit's configured scan."""
    client.send(b"\x02sEN LMDscandata 1\x03")
    return _ColaFramer()


Framer = _ScipFramer | _LmsFramer | _ColaFramer

# protocol package → (a client's first words, after which it counts scans); a new protocol adds one entry
STREAM_STARTS: dict[str, Callable[[RawClient], Framer]] = {
    "scip": _scip_start,
    "lms2xx": _lms_start,
    "cola": _cola_start,
}


def _read_until(client: RawClient, done: Callable[[bytes], bool]) -> bytes:
    data, deadline = b"", time.monotonic() + HANDSHAKE_TIMEOUT_S
    while not done(data):
        if time.monotonic() > deadline:
            raise RuntimeError(f"no answer within {HANDSHAKE_TIMEOUT_S} s (got {data[:200]!r})")
        data += client.drain(0.1)
    return data


@dataclass
class _Line:
    """One endpoint a client streams from: the sensor, its protocol, the URI and the line's baud."""

    daemon: int
    sensor: str
    protocol: str
    uri: str
    baud: int | None

    def open(self) -> tuple[RawClient, Framer]:
        client = open_raw(self.uri, self.baud)
        try:
            return client, STREAM_STARTS[self.protocol](client)
        except BaseException:
            client.close()
            raise


@dataclass
class _Stream:
    """A client that stays: its scans' arrival gaps, and what has been reported of them."""

    line: _Line
    client: RawClient
    framer: Framer
    last: float | None = None
    gaps: list[float] = field(default_factory=list)
    reported: int = 0

    def feed(self, data: bytes, now: float) -> None:
        for _ in range(self.framer.scans(data)):
            if self.last is not None:
                self.gaps.append(now - self.last)
            self.last = now

    def take(self) -> tuple[int, int, float]:
        """(scans, scans late, longest gap in s) since the last call."""
        new = np.asarray(self.gaps[self.reported :])
        self.reported = len(self.gaps)
        if not len(new):
            return 0, 0, 0.0
        period = float(np.median(self.gaps))
        return len(new), int(np.sum(new > 2.0 * period)), float(new.max())


# --------------------------------------------------------------------------- the soak


@dataclass
class _Daemon:
    scene: Scene
    serve: ServeProcess
    events_path: Path
    mcap_path: Path


class Soak:
    """Daemons, the clients that stay, the churn, the live changes and the samples, for `duration_s`."""

    def __init__(self, duration_s: float, folder: Path, sample_s: float | None = None, out: Callable[[str], None] = print):
        self.duration_s = duration_s
        self.sample_s = sample_s or min(SAMPLE_EVERY_S, duration_s / 10.0)
        self.warm_up_s = min(MAX_WARM_UP_S, duration_s / 6.0)
        self.folder = folder
        self.out = out
        self.random = random.Random(SEED)
        self.daemons: list[_Daemon] = []
        self.steady: list[_Stream] = []
        self.churn_lines: list[_Line] = []
        self.samples: list[dict] = []
        self.churned = {"serial": 0, "websocket": 0, "failed": 0, "view_reconnects": 0}
        self.changes = {"accepted": 0, "refused": 0}
        self._quiet = threading.Lock()  # held by the sampler: no churning client connects meanwhile
        self._sampling = threading.Event()  # the sampler waits for the lock: churn lets it have it
        self._counters: dict[int, dict[str, int]] = {}
        self._stop = threading.Event()

    def run(self) -> dict:
        with ExitStack() as stack:
            for index, scene in enumerate(soak_scenes()):
                self.daemons.append(self._start(index, scene, stack))
            self._open_steady(stack)
            threads = [threading.Thread(target=target, daemon=True, name=name) for name, target in (
                ("soak-read", self._read), ("soak-churn", self._churn), ("soak-view", self._watch_views))]
            for thread in threads:
                thread.start()
            try:
                self._drive()
            finally:
                self._stop.set()
                for thread in threads:
                    thread.join(30.0)
            for daemon in self.daemons:
                status = daemon.serve.stop()
                if status != 0:
                    raise RuntimeError(f"serve {daemon.scene.name} exited with {status}\n{daemon.serve.stderr[-2000:]}")
        return self.report()

    def _start(self, index: int, scene: Scene, stack: ExitStack) -> _Daemon:
        endpoints = []
        for spec in scene.sensors:
            for role in ("steady", "churn"):
                endpoints += [f"{spec.name}=pty:{self.folder / f'{index}-{spec.name}-{role}'}", f"{spec.name}=tcp:127.0.0.1:0"]
        events, mcap = self.folder / f"{index}-events.jsonl", self.folder / f"{index}.mcap"
        extra = ["--view", "127.0.0.1:0", "--mcap", str(mcap), "--events", str(events)]
        serve = stack.enter_context(ServeProcess(scene.path, endpoints, extra_args=extra, timeout_s=300.0))
        serve.service("view", timeout_s=180.0)
        return _Daemon(scene, serve, events, mcap)

    def _open_steady(self, stack: ExitStack) -> None:
        for index, daemon in enumerate(self.daemons):
            for spec in daemon.scene.sensors:
                protocol = protocol_of(spec)
                if protocol not in STREAM_STARTS:
                    raise RuntimeError(f"sensor {spec.name} ({spec.model}): no soak client for protocol {protocol!r}")
                baud = spec.options.get("baud")
                ready = [ready for ready in daemon.serve.ready if ready.sensor == spec.name]
                for position, endpoint in enumerate(ready):
                    line = _Line(index, spec.name, protocol, endpoint.uri, baud)
                    if position < 2:  # the first pty and TCP endpoint: clients that stay
                        client, framer = line.open()
                        stack.callback(client.close)
                        self.steady.append(_Stream(line, client, framer))
                    else:
                        self.churn_lines.append(line)

    def _read(self) -> None:
        selector = selectors.DefaultSelector()
        for stream in self.steady:
            selector.register(stream.client.fd, selectors.EVENT_READ, stream)
        try:
            while not self._stop.is_set():
                for key, _ in selector.select(0.1):
                    stream = key.data
                    stream.feed(stream.client.drain(), time.monotonic())
        finally:
            selector.close()

    def _churn(self) -> None:
        while not self._stop.is_set():
            while self._sampling.is_set():
                time.sleep(0.05)
            with self._quiet:
                if self.random.random() < 0.8:
                    self._churn_serial(self.random.choice(self.churn_lines))
                else:
                    self._churn_websocket(self.random.choice(self.daemons))

    def _churn_serial(self, line: _Line) -> None:
        try:
            client, framer = line.open()
        except (OSError, RuntimeError):
            self.churned["failed"] += 1
            return
        try:
            deadline = time.monotonic() + self.random.uniform(*CHURN_STREAM_S)
            while time.monotonic() < deadline and not self._stop.is_set():
                framer.scans(client.drain(0.05))
            if line.uri.startswith("tcp:") and self.random.random() < 0.5:  # vanish with a reset
                sock = socket.socket(fileno=os.dup(client.fd))
                sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
                sock.close()
        finally:
            client.close()
        self.churned["serial"] += 1

    def _churn_websocket(self, daemon: _Daemon) -> None:
        sensors = [spec.name for spec in daemon.scene.sensors]
        try:
            asyncio.run(_subscribe_briefly(daemon.serve.control_url, sensors, self.random.uniform(*CHURN_STREAM_S)))
            self.churned["websocket"] += 1
        except (OSError, RuntimeError, asyncio.TimeoutError):
            self.churned["failed"] += 1

    def _watch_views(self) -> None:
        """A browser's part: a WebSocket open on each daemon's view, read, reopened every few minutes
        (and at once if the view closed it: `view_reconnects` counts those)."""
        urls = [daemon.serve.service("view") for daemon in self.daemons]
        while not self._stop.is_set():
            try:
                asyncio.run(_watch(urls, min(300.0, self.duration_s / 4), self._stop))
            except (OSError, RuntimeError, asyncio.TimeoutError):
                self.churned["view_reconnects"] += 1
                time.sleep(1.0)

    def _drive(self) -> None:
        started = time.monotonic()
        next_change, next_sample = started, started + self.sample_s
        end = started + self.duration_s
        while (now := time.monotonic()) < end:
            if now >= next_sample:
                self._sample(now - started)
                next_sample += self.sample_s
            if now >= next_change:
                self._change()
                next_change += CHANGE_EVERY_S
            time.sleep(max(0.0, min(next_change, next_sample, end) - time.monotonic()))
        self._sample(time.monotonic() - started)

    def _change(self) -> None:
        daemon = self.random.choice(self.daemons)
        method, path, body = live_change(daemon.scene, self.random)
        request = urllib.request.Request(
            daemon.serve.control_url + path, data=json.dumps(body).encode(), method=method,
            headers={"Content-Type": "application/json"},
        )
        try:
            with urllib.request.urlopen(request, timeout=10.0) as answer:
                answer.read()
            self.changes["accepted"] += 1
        except urllib.error.HTTPError:
            self.changes["refused"] += 1

    def _sample(self, elapsed_s: float) -> None:
        self._sampling.set()
        with self._quiet:
            self._sampling.clear()
            time.sleep(QUIET_BEFORE_SAMPLE_S)
            daemons = [self._daemon_sample(daemon) for daemon in self.daemons]
        streams = [stream.take() for stream in self.steady]
        interval_s = elapsed_s - (self.samples[-1]["minute"] * 60.0 if self.samples else 0.0)
        sample = {
            "minute": round(elapsed_s / 60.0, 2),
            "rss_mb": sum(daemon["rss_mb"] for daemon in daemons),
            "fds": sum(daemon["fds"] for daemon in daemons),
            "threads": sum(daemon["threads"] for daemon in daemons),
            "scans": sum(scans for scans, _, _ in streams),
            "scans_per_s": sum(scans for scans, _, _ in streams) / interval_s,
            "scans_late": sum(late for _, late, _ in streams),
            "longest_gap_s": max((gap for _, _, gap in streams), default=0.0),
            "event_log_kb": sum(daemon["event_log_kb"] for daemon in daemons),
            "mcap_mb": sum(daemon["mcap_mb"] for daemon in daemons),
            "late_5ms": sum(daemon["late_5ms"] for daemon in daemons),
            "dropped": sum(daemon["dropped"] for daemon in daemons),
            "load_average": [round(value, 2) for value in os.getloadavg()],
            "daemons": daemons,
        }
        self.samples.append(sample)
        self.out(sample_line(sample))

    def _daemon_sample(self, daemon: _Daemon) -> dict:
        pids = [daemon.serve.pid, *child_pids(daemon.serve.pid)]
        stats = daemon.serve.stats()
        before = self._counters.get(daemon.serve.pid, {})
        self._counters[daemon.serve.pid] = stats
        return {
            "scene": daemon.scene.name,
            "rss_mb": sum(_alive(rss_kib, pid) for pid in pids) / 1024.0,
            "daemon_rss_mb": _alive(rss_kib, daemon.serve.pid) / 1024.0,
            "processes": len(pids),
            "fds": sum(_alive(_fd_count, pid) for pid in pids),
            "threads": sum(_alive(_thread_count, pid) for pid in pids),
            "late_5ms": stats.get("late_5ms", 0) - before.get("late_5ms", 0),  # since the last sample
            "dropped": stats.get("dropped", 0),  # stale scans dropped for the clients connected now
            "clients": stats.get("clients", 0),
            "event_log_kb": _size(daemon.events_path) / 1024.0,
            "mcap_mb": _size(daemon.mcap_path) / 2**20,
        }

    def report(self) -> dict:
        after = [sample for sample in self.samples if sample["minute"] * 60.0 >= self.warm_up_s] or self.samples[-1:]
        first = after[0]
        growth = max(sample["rss_mb"] for sample in after) / first["rss_mb"] - 1.0
        # a descriptor held for a moment (a client the daemon is still closing) is no leak, at either end:
        # one that stays is (the fewest of the first settled samples against the fewest of the last)
        fd_growth = _fewest_fds(after[-FD_SETTLE_SAMPLES:]) - _fewest_fds(after[:FD_SETTLE_SAMPLES])
        return {
            "soak": {
                "minutes": self.duration_s / 60.0,
                "warm_up_minutes": self.warm_up_s / 60.0,
                "scenes": [daemon.scene.name for daemon in self.daemons],
                "models": sorted({spec.model for daemon in self.daemons for spec in daemon.scene.sensors}),
                "streams": [f"{stream.line.sensor} {stream.line.uri.split(':')[0]}" for stream in self.steady],
                "samples": self.samples,
                "memory_growth": growth,
                "fd_growth": fd_growth,
                "fd_range": [min(sample["fds"] for sample in after), max(sample["fds"] for sample in after)],
                "thread_growth": max(sample["threads"] for sample in after) - first["threads"],
                "scans_late": sum(sample["scans_late"] for sample in self.samples),
                "scans": sum(sample["scans"] for sample in self.samples),
                "changes": dict(self.changes),
                "churned": dict(self.churned),
                "passed": growth <= MEMORY_GROWTH_LIMIT and fd_growth <= 0,
            }
        }


def _fewest_fds(samples: list[dict]) -> int:
    return min(sample["fds"] for sample in samples)


def live_change(scene: Scene, rng: random.Random) -> tuple[str, str, dict]:
    """One live change a user might make to `scene`, within its limits: (method, path, body)."""
    choices: list[Callable[[], tuple[str, str, dict]]] = []
    for region in scene.regions:
        top = max(density for _, density in region.density.keyframes) or 0.01
        choices.append(lambda region=region, top=top: (
            "PATCH", f"/api/smoke/regions/{region.name}", {"density": round(rng.uniform(0.0, 1.5 * top), 6)}))
    for plume in scene.plumes:
        choices.append(lambda plume=plume: ("PATCH", f"/api/smoke/plumes/{plume.name}", rng.choice([
            {"rate": round(plume.rate * rng.uniform(0.5, 1.5), 3)},
            {"wind": [round(rng.uniform(-1.0, 1.0), 3), round(rng.uniform(-1.0, 1.0), 3), 0.0]},
            {"emitting": rng.random() < 0.7},
        ])))
    for body in scene.bodies:
        if isinstance(body.trajectory, Live):
            choices.append(lambda body=body: ("PUT", f"/api/bodies/{body.name}/pose", {
                "position": [round(body.pose.position[0] + rng.uniform(-0.5, 0.5), 3),
                             round(body.pose.position[1] + rng.uniform(-0.5, 0.5), 3), body.pose.position[2]],
                "yaw_deg": round(rng.uniform(-180.0, 180.0), 1)}))
    if not choices:
        return "PATCH", "/api/clock", {"paused": False}
    return rng.choice(choices)()


async def _subscribe_briefly(url: str, sensors: list[str], seconds: float) -> None:
    import aiohttp

    async with aiohttp.ClientSession() as session:
        async with session.ws_connect(url + "/api/ws", max_msg_size=0, timeout=10.0) as socket_:
            await socket_.send_json({"subscribe": sensors})
            end = time.monotonic() + seconds
            while (left := end - time.monotonic()) > 0:
                try:
                    await asyncio.wait_for(socket_.receive(), left)
                except asyncio.TimeoutError:
                    break


async def _watch(urls: list[str], seconds: float, stop: threading.Event) -> None:
    import aiohttp

    async with aiohttp.ClientSession() as session:
        sockets = [await session.ws_connect(url.replace("http://", "ws://", 1), max_msg_size=0, timeout=30.0) for url in urls]
        try:
            end = time.monotonic() + seconds
            while time.monotonic() < end and not stop.is_set():
                outcomes = await asyncio.gather(*(_drain(socket_, 0.5) for socket_ in sockets), return_exceptions=True)
                for outcome in outcomes:
                    if isinstance(outcome, BaseException):
                        raise outcome
        finally:
            for socket_ in sockets:
                await socket_.close()


async def _drain(socket_, seconds: float) -> None:
    end = time.monotonic() + seconds
    while (left := end - time.monotonic()) > 0:
        try:
            message = await asyncio.wait_for(socket_.receive(), left)
        except asyncio.TimeoutError:
            return
        if message.type.name in ("CLOSE", "CLOSED", "ERROR"):
            raise RuntimeError("the view closed its WebSocket")


def _alive(measure: Callable[[int], float], pid: int) -> float:
    try:
        return measure(pid)
    except (OSError, AttributeError):
        return 0  # a process that exited between listing and reading


def _fd_count(pid: int) -> int:
    return len(os.listdir(f"/proc/{pid}/fd"))


def _thread_count(pid: int) -> int:
    return int(re.search(r"^Threads:\s+(\d+)", Path(f"/proc/{pid}/status").read_text(), re.MULTILINE).group(1))


def _size(path: Path) -> int:
    try:
        return path.stat().st_size
    except OSError:
        return 0


def sample_line(sample: dict) -> str:
    return (
        f"  {sample['minute']:>7.2f} {sample['rss_mb']:>8.1f} {sample['fds']:>5} {sample['threads']:>7}"
        f" {sample['scans_per_s']:>7.1f} {sample['scans_late']:>5} {sample['longest_gap_s']:>7.2f}"
        f" {sample['event_log_kb']:>9.1f} {sample['mcap_mb']:>8.1f} {sample['late_5ms']:>8} {sample['dropped']:>7}"
        f"  {' '.join(f'{value:g}' for value in sample['load_average'])}"
    )


SAMPLE_HEADER = (
    f"  {'minute':>7} {'RSS MB':>8} {'fds':>5} {'threads':>7} {'scans/s':>7} {'late':>5} {'gap s':>7}"
    f" {'events kB':>9} {'MCAP MB':>8} {'late5ms':>8} {'dropped':>7}  load avg"
)


def soak_section(quick: bool, minutes: float | None = None) -> tuple[dict, list[str]]:
    """The soak for `minutes` (default 60; quick: 1)."""
    duration_s = 60.0 * (minutes if minutes is not None else (1.0 if quick else 60.0))
    with tempfile.TemporaryDirectory(prefix="lrf-soak-") as folder:
        soak = Soak(duration_s, Path(folder), out=lambda line: print(line, flush=True, file=sys.stderr))
        print(f"soak: {duration_s / 60:g} min; a sample every {soak.sample_s:g} s\n{SAMPLE_HEADER}", file=sys.stderr, flush=True)
        report = soak.run()
    data = report["soak"]
    lines = [
        f"soak: {data['minutes']:g} min of {', '.join(data['scenes'])} ({', '.join(data['models'])}); streams that stay:"
        f" {', '.join(data['streams'])}; churn: {data['churned']['serial']} serial and {data['churned']['websocket']}"
        f" WebSocket clients came and vanished ({data['churned']['failed']} failed to connect); the view's watcher"
        f" reconnected {data['churned']['view_reconnects']} times after the view closed it; live changes:"
        f" {data['changes']['accepted']} accepted, {data['changes']['refused']} refused; view watched, MCAP on",
        SAMPLE_HEADER,
        *(sample_line(sample) for sample in data["samples"]),
        f"  after {data['warm_up_minutes']:.1f} min of warm-up: memory {data['memory_growth']:+.1%}"
        f" (limit {MEMORY_GROWTH_LIMIT:.0%}), descriptors {data['fd_growth']:+d} ({data['fd_range'][0]}–{data['fd_range'][1]}), threads {data['thread_growth']:+d};"
        f" scans late {data['scans_late']} of {data['scans']}: {'passed' if data['passed'] else 'FAILED'}",
    ]
    return report, lines

