"""Live control through the real daemon, as a driver sees it (`bench --section control`).

Starts `lrf-emulator serve` on a small room (a URG-04LX facing a wall 2.9 m
away through a smoke region, and a crate on a live body beside the beam) and
streams `MD` over TCP, as a driver does, while the control API changes the
world:

- change → first scan showing it: the region's density is toggled between
  clear and 0.004 (the URG's straight-ahead beam turns to error 1 and back);
  for each change, the wall time from sending the PATCH to the arrival of the
  first scan that shows it, and the simulated time from the change's instant
  to that scan's time stamp (target: within one scan period, 100 ms). Any
  scan stamped at or after a change that still shows the old world counts as
  a violation (there must be none).
- a 100 Hz pose stream's cost: MD scan-to-scan jitter |Δt − 100 ms| (p99),
  alone and while a WebSocket client sends 100 poses a second that move the
  crate in and out of the beam plane (target: p99 still ≤ 2 ms), and the CPU
  the daemon and its workers use meanwhile (/proc/PID/stat);
- a flooding client's cost: the same jitter while another process sends region
  changes on one WebSocket as fast as it can (beyond 125 a second they are
  refused and paced: control/change_rate.py), with the changes sent and applied.
"""

from __future__ import annotations

import asyncio
import http.client
import json
import multiprocessing
import random
import tempfile
import threading
import time
import urllib.request
from pathlib import Path
from urllib.parse import urlsplit

import numpy as np

from emulator.bench.serve_load import cpu_seconds
from emulator.bench.serve_process import ServeProcess
from emulator.bench.transport_latency import JITTER_TARGET_MS, STREAM_COMMAND, _Line
from protocols.scip.encoding import decode_values, join_data_lines

SCAN_PERIOD_MS = 100.0
FRONT_INDEX = 384 - 44  # step 384 (straight ahead) in an MD 44..725 scan
DENSE = 0.004  # d·m: 2.9 m of it is 0.0116, past the URG's 0.007 budget

ROOM = """\
[scene]
name = "control bench room"
description = "a URG facing a wall through a smoke region; a crate on a live body"
seed = 3
model = "formsma2011"

[[objects]]
name = "front wall"
box = { size = [0.2, 10.0, 3.0] }
position = [3.0, 0.0, 1.5]

[[smoke.regions]]
name = "room"
box = { size = [5.8, 9.8, 2.9] }
position = [0.0, 0.0, 1.5]
density = 0.0

[[bodies]]
name = "robot"
position = [1.5, 2.0, 0.0]
trajectory = "live"

[[objects]]
name = "crate"
body = "robot"
box = { size = [0.3, 0.3, 1.0] }
position = [0.0, 0.0, 0.5]

[[sensors]]
name = "urg"
model = "urg-04lx"
position = [0.0, 0.0, 0.3]
"""


def _decode_md(message: bytes) -> tuple[int, np.ndarray]:
    """(time stamp ms, values) of one MD scan message (3-character encoding), checksums verified."""
    lines = [line for line in message.split(b"\n") if line]
    return int(decode_values(lines[2][:4], 4)[0]), decode_values(join_data_lines(b"\n".join(lines[3:]) + b"\n"), 3)


class _Api:
    """Keep-alive HTTP to the control API."""

    def __init__(self, url: str) -> None:
        parts = urlsplit(url)
        self._connection = http.client.HTTPConnection(parts.hostname, parts.port, timeout=10)

    def patch(self, path: str, body: dict) -> dict:
        self._connection.request("PATCH", path, json.dumps(body), {"Content-Type": "application/json"})
        answer = self._connection.getresponse()
        data = json.loads(answer.read())
        if answer.status != 200:
            raise RuntimeError(f"{path}: {answer.status} {data}")
        return data

    def close(self) -> None:
        self._connection.close()


def change_to_scan(daemon: ServeProcess, changes: int) -> dict:
    """Toggle the density `changes` times while an MD stream runs; per change, wall and simulated latency."""
    line = _Line(daemon.endpoint("urg", "tcp").uri)
    api = _Api(daemon.control_url)
    buffer = bytearray()
    wall_ms, sim_ms, violations = [], [], 0
    try:
        line.write(STREAM_COMMAND)
        line.read_message(buffer)
        for _ in range(3):
            line.read_message(buffer)
        dense = False
        for _ in range(changes):
            time.sleep(random.uniform(0.05, 0.25))  # changes land at every phase of the scan period
            dense = not dense
            sent = time.perf_counter()
            applied = api.patch("/api/smoke/regions/room", {"density": DENSE if dense else 0.0})["applied"]
            change_ms = applied["t"] * 1000.0
            while True:
                message, arrived = line.read_message(buffer)
                stamp, values = _decode_md(message)
                shows = (values[FRONT_INDEX] == 1) == dense
                if stamp >= change_ms and not shows:
                    violations += 1
                if shows and stamp >= change_ms:
                    wall_ms.append((arrived - sent) * 1000.0)
                    sim_ms.append(stamp - change_ms)
                    break
        line.write(b"QT\n")
    finally:
        line.close()
        api.close()
    return {"changes": changes, "wall": _percentiles(wall_ms), "simulated": _percentiles(sim_ms), "violations": violations}


def _percentiles(values: list[float]) -> dict[str, float]:
    data = np.asarray(values)
    return {key: round(float(np.percentile(data, q)), 3) for key, q in (("p50_ms", 50), ("p99_ms", 99))} | {
        "max_ms": round(float(data.max()), 3)
    }


def _md_jitter(daemon: ServeProcess, scans: int) -> dict:
    """MD scan-to-scan jitter |Δt − 100 ms| over `scans` scans, and the CPU the daemon and its workers used."""
    line = _Line(daemon.endpoint("urg", "tcp").uri)
    buffer = bytearray()
    try:
        line.write(STREAM_COMMAND)
        line.read_message(buffer)
        cpu_before, wall_before = cpu_seconds(daemon.pid), time.monotonic()
        arrivals = [line.read_message(buffer)[1] for _ in range(scans + 1)]
        cpu_share = (cpu_seconds(daemon.pid) - cpu_before) / (time.monotonic() - wall_before)
        line.write(b"QT\n")
    finally:
        line.close()
    deviations = np.abs(np.diff(arrivals) * 1000 - SCAN_PERIOD_MS)
    return {
        "scans": scans,
        "cpu_share": round(cpu_share, 4),  # daemon + workers, CPU seconds per wall second
        "p99_ms": round(float(np.percentile(deviations, 99)), 3),
        "max_ms": round(float(deviations.max()), 3),
    }


def jitter_with_pose_stream(daemon: ServeProcess, scans: int, stream: bool) -> dict:
    """MD scan-to-scan jitter over `scans` scans, with or without a 100 Hz WebSocket pose stream."""
    stop = threading.Event()
    sent = [0]
    thread = threading.Thread(target=lambda: asyncio.run(_pose_stream(daemon.control_url, stop, sent)), daemon=True)
    if stream:
        thread.start()
        time.sleep(0.5)
    try:
        jitter = _md_jitter(daemon, scans)
    finally:
        stop.set()
        if stream:
            thread.join(5)
    return {**jitter, "poses_sent": sent[0]}


def jitter_with_change_flood(daemon: ServeProcess, scans: int) -> dict:
    """MD jitter while another process sends region changes on one WebSocket as fast as it can: what a
    flooding client costs its neighbours when every change beyond the per-thing rate is refused and paced
    (control/change_rate.py). Also the changes sent (written into the socket: most wait in its buffers)
    and applied while it flooded, and the applied rate."""
    context = multiprocessing.get_context("spawn")
    sent = context.Value("q", 0)
    flooder = context.Process(target=flood_changes, args=(daemon.control_url, sent), daemon=True)
    applied_before = _region_changes(daemon)
    flooder.start()
    try:
        while sent.value == 0 and flooder.is_alive():  # the flood is on before the scans are timed
            time.sleep(0.01)
        flood_start = time.monotonic()
        time.sleep(0.5)
        jitter = _md_jitter(daemon, scans)
        applied, changes_sent = _region_changes(daemon) - applied_before, sent.value
        flood_s = time.monotonic() - flood_start
    finally:  # no close handshake: the daemon reads its way to it at the paced rate, past this measurement
        flooder.kill()
        flooder.join()
    return {**jitter, "changes_sent": changes_sent, "changes_applied": applied, "applied_per_s": round(applied / flood_s, 1)}


def _region_changes(daemon: ServeProcess) -> int:
    with urllib.request.urlopen(daemon.control_url + "/api/events", timeout=10) as answer:
        return sum(event["op"] == "region" for event in json.loads(answer.read()))


def flood_changes(url: str, sent) -> None:
    """A flooding client (a process of its own, killed when done): region changes toggling the room between
    clear and DENSE, as fast as its WebSocket takes them; `sent` counts them."""
    asyncio.run(_flood_changes(url, sent))


async def _flood_changes(url: str, sent) -> None:
    import aiohttp

    async with aiohttp.ClientSession() as session:
        async with session.ws_connect(url + "/api/ws") as ws:
            asyncio.ensure_future(_drain(ws))
            while True:
                for _ in range(50):
                    await ws.send_str(json.dumps({"op": "region", "name": "room", "density": DENSE * (sent.value % 2)}))
                    sent.value += 1
                await asyncio.sleep(0)  # the reader drains the refusals meanwhile


async def _pose_stream(url: str, stop: threading.Event, sent: list[int]) -> None:
    """100 poses a second on one WebSocket: the crate sweeps across the URG's field of view."""
    import aiohttp

    async with aiohttp.ClientSession() as session:
        async with session.ws_connect(url + "/api/ws") as ws:
            reader = asyncio.ensure_future(_drain(ws))
            start = time.monotonic()
            while not stop.is_set():
                y = 1.5 * np.sin(2 * np.pi * 0.5 * sent[0] / 100.0)
                await ws.send_str(json.dumps({"op": "pose", "name": "robot", "position": [1.5, float(y), 0.0], "yaw_deg": 0}))
                sent[0] += 1
                await asyncio.sleep(max(0.0, start + sent[0] / 100.0 - time.monotonic()))
            reader.cancel()


async def _drain(ws) -> None:
    async for _ in ws:  # state messages: read and forget, as a live view would
        pass


def control_bench(quick: bool = False) -> tuple[dict, list[str]]:
    """The `bench` section. Returns (data for JSON, table lines)."""
    changes, scans = (6, 20) if quick else (60, 300)
    with tempfile.TemporaryDirectory(prefix="lrf-bench-control-") as folder:
        scene = Path(folder) / "room.toml"
        scene.write_text(ROOM)
        with ServeProcess(scene, ["urg=tcp:127.0.0.1:0"]) as daemon:
            latency = change_to_scan(daemon, changes)
            alone = jitter_with_pose_stream(daemon, scans, stream=False)
            streamed = jitter_with_pose_stream(daemon, scans, stream=True)
            flooded = jitter_with_change_flood(daemon, scans)
    data = {
        "change_to_scan": latency,
        "control_jitter": {"alone": alone, "pose_stream_100hz": streamed, "change_flood": flooded},
    }
    wall, sim = latency["wall"], latency["simulated"]
    lines = [
        f"change → first MD scan showing it ({changes} density changes), target: within one scan period (100 ms)",
        f"  simulated (scan stamp − change instant) p50 {sim['p50_ms']:.1f} ms   p99 {sim['p99_ms']:.1f} ms"
        f"   max {sim['max_ms']:.1f} ms   scans after a change showing the old world: {latency['violations']}",
        f"  wall (PATCH sent → scan received)       p50 {wall['p50_ms']:.1f} ms   p99 {wall['p99_ms']:.1f} ms"
        f"   max {wall['max_ms']:.1f} ms",
        f"MD jitter |Δt − 100 ms| over {scans} scans, target p99 ≤ {JITTER_TARGET_MS:g} ms",
        f"  alone                     p99 {alone['p99_ms']:.3f} ms   max {alone['max_ms']:.3f} ms"
        f"   CPU (daemon + workers) {alone['cpu_share']:.1%} of a core",
        f"  with a 100 Hz pose stream p99 {streamed['p99_ms']:.3f} ms   max {streamed['max_ms']:.3f} ms"
        f"   CPU {streamed['cpu_share']:.1%} of a core ({streamed['poses_sent']} poses sent)",
        f"  with a change flood       p99 {flooded['p99_ms']:.3f} ms   max {flooded['max_ms']:.3f} ms"
        f"   CPU {flooded['cpu_share']:.1%} of a core ({flooded['changes_sent']} region changes sent,"
        f" {flooded['changes_applied']} applied: {flooded['applied_per_s']:g} a second)",
    ]
    return data, lines
