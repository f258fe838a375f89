"""Live changes held to the scene file's limits, against the real daemon.

A rate that would blow the particle budget, a density past the bound, a body
teleported faster than a body may move: each is refused with a 400 naming
the limit (HTTP, WebSocket and `ctl` alike), the world stays as it was and
the sensors keep streaming. A change up to the budget is accepted and scans
stay within a period. An event log that breaks a limit is refused at load,
one line, exit 2, by every command that reads one.
"""

from __future__ import annotations

import asyncio
import json
import os
import socket
import subprocess
import time
import urllib.error
import urllib.request
import multiprocessing
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import aiohttp
import numpy as np
import pytest

from emulator.bench.serve_process import ServeProcess, serve_command
from emulator.control.change_rate import CHANGE_BURST, CHANGE_RATE_HZ, FLOODING_REASON
from emulator.scene import load_scene
from emulator.scene.loader import MAX_BODY_SPEED_M_S, MAX_DENSITY, MAX_PARTICLES_ALIVE
from tests.robustness.conftest import SCALE

MD_UNLIMITED = b"MD0044072501000\n"
URG_PERIOD_S = 0.1


def request(url: str, method: str, path: str, body: object) -> tuple[int, dict]:
    data = json.dumps(body).encode()
    call = urllib.request.Request(url + path, data=data, method=method, headers={"Content-Type": "application/json"})
    try:
        with urllib.request.urlopen(call, timeout=10) as answer:
            return answer.status, json.loads(answer.read())
    except urllib.error.HTTPError as error:
        return error.code, json.loads(error.read())


class UrgStream:
    """An endless MD stream over TCP; the arrival time of each scan."""

    def __init__(self, address: tuple[str, int]) -> None:
        self.sock = socket.create_connection(address, timeout=5)
        self.sock.sendall(MD_UNLIMITED)
        self.buffer = b""
        self.arrivals: list[float] = []

    def read_for(self, seconds: float) -> list[float]:
        """Scans' arrival times over the next `seconds`."""
        start, end = len(self.arrivals), time.monotonic() + seconds
        self.sock.settimeout(0.05)
        while time.monotonic() < end:
            try:
                data = self.sock.recv(65536)
            except socket.timeout:
                continue
            assert data, "the daemon closed the stream"
            self.buffer += data
            while (cut := self.buffer.find(b"\n\n")) >= 0:
                message, self.buffer = self.buffer[:cut], self.buffer[cut + 2 :]
                if message.split(b"\n")[1:2] == [b"99b"]:
                    self.arrivals.append(time.monotonic())
        return self.arrivals[start:]

    def close(self) -> None:
        self.sock.close()


def longest_gap_s(arrivals: list[float]) -> float:
    return float(np.max(np.diff(arrivals))) if len(arrivals) > 1 else float("inf")


@pytest.mark.parametrize(
    "scene, plume, rate",
    [("rescue", "smoulder", 1e6), ("railway", "fire_debris", 100_000)],  # 1e6: the most a rate may be
)
def test_a_rate_over_the_particle_budget_is_refused_and_scans_go_on(scene: str, plume: str, rate: float) -> None:
    with ServeProcess(scene, ["urg=tcp:127.0.0.1:0"]) as served:
        stream = UrgStream(served.endpoint("urg", "tcp").address)
        try:
            stream.read_for(1.0)
            status, answer = request(served.control_url, "PATCH", f"/api/smoke/plumes/{plume}", {"rate": rate})
            after = stream.read_for(3.0)
        finally:
            stream.close()
        assert status == 400, answer
        assert f"particle budget allows at most {MAX_PARTICLES_ALIVE}" in answer["error"], answer
        assert answer["key"] == f"smoke.plumes[{plume}].rate"
        state = _state(served)
        assert state["plumes"][plume]["rate"] == next(p.rate for p in load_scene(scene).plumes if p.name == plume)
        assert len(after) >= 20 and longest_gap_s(after) < 1.0, "the sensor went silent"


def _state(served: ServeProcess) -> dict:
    with urllib.request.urlopen(served.control_url + "/api/state", timeout=10) as answer:
        return json.loads(answer.read())


def test_a_density_past_the_bound_is_refused_live(tmp_path: Path) -> None:
    with ServeProcess("railway", ["urg=tcp:127.0.0.1:0"]) as served:
        region = load_scene("railway").regions[0].name
        status, answer = request(served.control_url, "PATCH", f"/api/smoke/regions/{region}", {"density": 1e300})
        assert status == 400 and f"must be <= {MAX_DENSITY:g}" in answer["error"], answer
        assert answer["key"] == f"smoke.regions[{region}].density"
        status, _ = request(served.control_url, "PATCH", f"/api/smoke/regions/{region}", {"density": MAX_DENSITY})
        assert status == 200
        ctl = subprocess.run(
            [*serve_command(), "ctl", "--url", served.control_url, "plume", "fire_debris", "rate", "1e6"],
            capture_output=True, text=True, timeout=60,
        )
        lines = ctl.stderr.strip().splitlines()
        assert ctl.returncode == 2 and len(lines) == 1 and "particle budget" in lines[0], ctl.stderr
        assert "RuntimeWarning" not in served.stderr and "overflow" not in served.stderr


LIVE_BODY_SCENE = """
[scene]
name = "yard"

[[bodies]]
name = "robot"
trajectory = "live"

[[objects]]
name = "wall"
box = { size = [0.2, 10.0, 2.0] }
position = [5.0, 0.0, 1.0]

[[sensors]]
name = "urg"
model = "urg-04lx"
body = "robot"
position = [0.0, 0.0, 0.5]
endpoints = ["tcp:127.0.0.1:0"]
"""


def test_a_body_moved_faster_than_a_body_may_is_refused(tmp_path: Path) -> None:
    scene = tmp_path / "yard.toml"
    scene.write_text(LIVE_BODY_SCENE)
    with ServeProcess(scene, ["urg=tcp:127.0.0.1:0"]) as served:
        status, answer = request(served.control_url, "PUT", "/api/bodies/robot/pose", {"position": [1.0, 0.0, 0.0]})
        assert status == 200, answer
        far = [1.0 + 10 * MAX_BODY_SPEED_M_S, 0.0, 0.0]  # ten seconds' worth at the limit, within one
        status, answer = request(served.control_url, "PUT", "/api/bodies/robot/pose", {"position": far})
        assert status == 400 and f"at most {MAX_BODY_SPEED_M_S:g} m/s" in answer["error"], answer
        assert answer["key"] == "bodies[robot].position"
        assert _state(served)["bodies"]["robot"]["position"] == [1.0, 0.0, 0.0]


def test_a_change_up_to_the_budget_keeps_scans_within_a_period() -> None:
    """railway under the costlier `physical` preset, its plume raised live to the whole budget:
    accepted, and the URG's scans keep coming at most one period late (no gap over two periods)."""
    scene = load_scene("railway")
    others = sum(plume.rate * plume.lifetime for plume in scene.plumes[1:])
    full = (MAX_PARTICLES_ALIVE - others) / scene.plumes[0].lifetime
    with ServeProcess("railway", ["urg=tcp:127.0.0.1:0"], extra_args=["--model", "physical"]) as served:
        stream = UrgStream(served.endpoint("urg", "tcp").address)
        try:
            stream.read_for(2.0)
            status, answer = request(served.control_url, "PATCH", f"/api/smoke/plumes/{scene.plumes[0].name}", {"rate": full})
            assert status == 200, answer
            stream.read_for(scene.plumes[0].lifetime)  # the plume fills to the budget
            after = stream.read_for(10.0)
        finally:
            stream.close()
    gaps, load = np.diff(after), os.getloadavg()[0]  # a machine with no core to spare makes any scan late
    assert len(after) >= 90, f"{len(after)} scans in 10 s (load average {load:.1f})"
    assert gaps.max() <= 2 * URG_PERIOD_S, f"a scan came {gaps.max() - URG_PERIOD_S:.3f} s late (load average {load:.1f})"


def test_an_event_log_over_a_limit_is_refused_at_load(tmp_path: Path) -> None:
    log = tmp_path / "session.jsonl"
    lines = [
        {"t": 1.0, "op": "plume", "name": "fire_debris", "rate": 8.0},
        {"t": 2.0, "op": "plume", "name": "fire_debris", "rate": 100000.0},
    ]
    log.write_text("".join(json.dumps(line) + "\n" for line in lines))
    commands = {
        "serve": ["serve", "railway", "--endpoint", "urg=tcp:127.0.0.1:0", "--control", "off", "--view", "off"],
        "record": ["record", "railway", "--sensor", "urg", "--end", "3", "--out", str(tmp_path / "x.log")],
        "scan": ["scan", "railway", "--sensor", "urg", "--time", "3"],
    }
    for name, args in commands.items():
        try:
            result = subprocess.run([*serve_command(), *args, "--events-in", str(log)], cwd=tmp_path,
                                    capture_output=True, text=True, timeout=60)
        except subprocess.TimeoutExpired:
            pytest.fail(f"{name} accepted an event log over the particle budget and ran on")
        errors = result.stderr.strip().splitlines()
        assert result.returncode == 2 and len(errors) == 1, (name, result.stderr[-2000:])
        assert "session.jsonl: line 2" in errors[0] and "particle budget" in errors[0], (name, errors[0])


TWIST = {"vx": 1.0, "wz": 0.0}  # at the body's max_speed: soon pushing into a wall
# what each flood sends: (the WebSocket message, the HTTP method, path and body)
FLOODS = {
    "twist": ({"op": "twist", "name": "robot", **TWIST}, ("PUT", "/api/bodies/robot/twist", TWIST)),
    "smoke": (
        {"op": "region", "name": "east_room", "density": 0.002},
        ("PATCH", "/api/smoke/plumes/smoulder", {"wind": [0.1, 0.0, 0.0]}),
    ),
}


async def _flood_websocket(url: str, flood_s: float, change: str) -> tuple[int, list[dict]]:
    """Changes at up to 5 kHz (40 times the rate), reading the answers meanwhile, until `flood_s` is over
    or the daemon closes the connection (past its refusal budget); the close handshake is not waited for."""
    sent, errors = 0, []
    message = FLOODS[change][0]
    close = aiohttp.ClientWSTimeout(ws_close=0.5)
    async with aiohttp.ClientSession() as http, http.ws_connect(url + "/api/ws", timeout=close) as ws:
        async def read() -> None:
            async for answer in ws:
                data = json.loads(answer.data)
                if data["type"] == "error":
                    errors.append(data)

        reader = asyncio.create_task(read())
        end = time.monotonic() + flood_s
        while time.monotonic() < end and not ws.closed:  # past its refusal budget the daemon closes it
            try:
                await ws.send_json(message)
            except ConnectionError:
                break
            sent += 1
            if sent % 50 == 0:
                await asyncio.sleep(0.01)  # and let the reader keep up
        reader.cancel()
    return sent, errors


async def _flood_http(url: str, flood_s: float, change: str) -> tuple[int, list[dict]]:
    """Changes over HTTP, one after another on a keep-alive connection."""
    sent, refusals = 0, []
    method, path, body = FLOODS[change][1]
    async with aiohttp.ClientSession() as http:
        end = time.monotonic() + flood_s
        while time.monotonic() < end:
            async with http.request(method, url + path, json=body) as answer:
                sent += 1
                if answer.status == 429:
                    refusals.append(await answer.json())
                else:
                    assert answer.status == 200, await answer.text()
    return sent, refusals


def _started(pause_s: float) -> int:
    """A client process up, this module imported in it: its pid."""
    time.sleep(pause_s)
    return os.getpid()


def flood(client: str, url: str, flood_s: float, change: str) -> tuple[int, list[dict]]:
    """One flooding client, run in a process of its own (as a client is): its CPU is the machine's,
    but it does not hold the reading test's interpreter lock."""
    return asyncio.run({"websocket": _flood_websocket, "http": _flood_http}[client](url, flood_s, change))


def _flooded(change: str, flood_s: float) -> tuple[list[float], list[tuple[int, list[dict]]], list[dict]]:
    """rescue-live with its URG streamed while a WebSocket client and an HTTP client flood `change`: the
    scans' arrivals during the flood, each client's (sent, refusals), and the event log. Leaving the
    `with` stops the daemon by SIGTERM, and fails if it did not stop within ServeProcess's timeout."""
    spawn = multiprocessing.get_context("spawn")
    with ServeProcess("rescue-live", ["urg=tcp:127.0.0.1:0"]) as served, ProcessPoolExecutor(2, mp_context=spawn) as clients:
        started = [clients.submit(_started, 0.3) for _ in range(2)]  # both up before the flood
        assert len({future.result() for future in started}) == 2
        url = served.control_url
        stream = UrgStream(served.endpoint("urg", "tcp").address)
        try:
            stream.read_for(1.0)
            sent = [clients.submit(flood, client, url, flood_s, change) for client in ("websocket", "http")]
            during = stream.read_for(flood_s)
            answers = [future.result() for future in sent]
        finally:
            stream.close()
        with urllib.request.urlopen(url + "/api/events", timeout=10) as answer:
            events = json.loads(answer.read())
    return during, answers, events


def _busiest_second(stamps: list[float]) -> int:
    """The most changes stamped within any 1 s of the simulated clock."""
    times = np.sort(np.array(stamps))
    return int((np.searchsorted(times, times + 1.0) - np.arange(len(times))).max()) if len(times) else 0


def test_a_twist_flood_is_held_to_the_rate_and_another_clients_scans_stay_on_time() -> None:
    """rescue-live's robot driven by a WebSocket client sending twists as fast as it can and an HTTP client
    doing the same (each applied twist costs the loop 0.3–1.5 ms, more pushing into a wall; unpaced,
    40 000 refused WebSocket messages a second took a core and the URG fell silent for 0.9 s): beyond the
    per-body rate they are refused (429, an error message naming the limit), no second of simulated time
    gets more twists than the rate plus the burst, and the URG's MD stream, another client's, keeps coming."""
    flood_s = 3.0 * SCALE
    during, ((ws_sent, errors), (put_sent, refusals)), events = _flooded("twist", flood_s)
    load = os.getloadavg()[0]
    stamps = [event["t"] for event in events if event["op"] == "twist"]
    assert refusals and errors, (len(refusals), len(errors))
    for refusal in [*refusals[:3], *errors[:3]]:
        assert refusal["key"] == "bodies[robot].twist", refusal
        assert f"more than {CHANGE_RATE_HZ:g} twist commands a second" in refusal["error"], refusal
    assert ws_sent + put_sent > 2 * len(stamps), (ws_sent, put_sent, len(stamps))  # the flood outran the rate
    assert _busiest_second(stamps) <= CHANGE_RATE_HZ + CHANGE_BURST, _busiest_second(stamps)
    expected = flood_s / URG_PERIOD_S

    assert len(during) >= 0.7 * expected, f"{len(during)} scans of {expected:.0f} (load average {load:.1f})"
    assert longest_gap_s(during) < 1.0, f"the sensor went silent for {longest_gap_s(during):.2f} s (load average {load:.1f})"


def test_a_flood_of_smoke_changes_is_held_to_the_rate_and_the_daemon_stays_responsive() -> None:
    """A WebSocket client changing a region's density and an HTTP client changing a plume's wind, each as
    fast as it can. Unlimited, 18 000 region changes a second took the loop (the URG beside them got
    2 scans in 10 s) and, before the workers had sender threads, froze the daemon for good (SIGTERM
    ignored). Now each is refused beyond the per-thing rate, naming the limit; no second of simulated
    time gets more of either than the rate plus the burst; the URG keeps streaming; SIGTERM stops it."""
    flood_s = 3.0 * SCALE
    during, ((ws_sent, errors), (http_sent, refusals)), events = _flooded("smoke", flood_s)
    load = os.getloadavg()[0]
    assert errors and refusals, (len(errors), len(refusals))
    for error in errors[:3]:
        assert error["key"] == "smoke.regions[east_room]", error
        assert f"more than {CHANGE_RATE_HZ:g} region commands a second for one region" in error["error"], error
    for refusal in refusals[:3]:
        assert refusal["key"] == "smoke.plumes[smoulder]", refusal
        assert f"more than {CHANGE_RATE_HZ:g} plume commands a second for one plume" in refusal["error"], refusal
    for op, sent in (("region", ws_sent), ("plume", http_sent)):
        stamps = [event["t"] for event in events if event["op"] == op]
        assert sent > len(stamps), (op, sent, len(stamps))  # some were refused, none applied twice
        assert _busiest_second(stamps) <= CHANGE_RATE_HZ + CHANGE_BURST, (op, _busiest_second(stamps))
    expected = flood_s / URG_PERIOD_S
    assert len(during) >= 0.7 * expected, f"{len(during)} scans of {expected:.0f} (load average {load:.1f})"
    assert longest_gap_s(during) < 1.0, f"the sensor went silent for {longest_gap_s(during):.2f} s (load average {load:.1f})"


@pytest.mark.parametrize("then", ["stays", "closes"])
def test_a_websocket_client_with_a_backlog_of_twists_does_not_hold_the_daemon_at_shutdown(then: str) -> None:
    """A client that sent 5000 twists at once (the daemon reads them at the rate, one every 8 ms: 40 s of
    them) and then stays without reading, or closes its socket without a close handshake. SIGTERM still
    ends the daemon within its stop timeout: stopping waits at most CLOSE_TIMEOUT_S for a client's
    handshake, then resets the connection."""
    with ServeProcess("rescue-live", ["urg=tcp:127.0.0.1:0"]) as served:
        port = int(served.control_url.rsplit(":", 1)[1])
        flooder = socket.create_connection(("127.0.0.1", port))
        flooder.sendall(
            b"GET /api/ws HTTP/1.1\r\nHost: x\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
            b"Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n\r\n"
        )
        twist = json.dumps({"op": "twist", "name": "robot", "vx": 0.1, "wz": 0.0}).encode()
        frame = bytes([0x81, 0x80 | len(twist)]) + b"\x00\x00\x00\x00" + twist  # masked text frames
        flooder.sendall(frame * 5000)
        if then == "closes":
            flooder.close()
        time.sleep(0.5)  # some of them refused and paced meanwhile
        try:
            assert served.stop(timeout_s=10.0) == 0, served.stderr
        finally:
            flooder.close()


def _websocket_frames(data: bytes) -> list[tuple[int, bytes]]:
    """(opcode, payload) of the server's unmasked frames in `data`, a torn last one left out."""
    frames, at = [], 0
    while at + 2 <= len(data):
        opcode, length, at = data[at] & 0x0F, data[at + 1] & 0x7F, at + 2
        if length >= 126:
            size = 2 if length == 126 else 8
            length, at = int.from_bytes(data[at:at + size], "big"), at + size
        if at + length > len(data):
            break
        frames.append((opcode, data[at:at + length]))
        at += length
    return frames


def test_a_flooders_backlog_is_not_applied_once_it_is_closed() -> None:
    """A client writes 20 000 region changes as fast as the socket takes them and never reads. Paced to
    the rate alone, the daemon went on applying its backlog (held in the kernel's buffers) for as long as
    it took to read: 7 s after a 5 s flood's client was killed. Now, refused past its budget
    (REFUSALS_BURST, about 4 s of flooding), the connection is closed with 1008 and the reason, and no
    change is applied after: the log holds at most the burst and 6 s of the rate, and stops growing."""
    with ServeProcess("rescue-live", ["urg=tcp:127.0.0.1:0"]) as served:
        url = served.control_url
        flooder = socket.create_connection(("127.0.0.1", int(url.rsplit(":", 1)[1])))
        flooder.sendall(
            b"GET /api/ws HTTP/1.1\r\nHost: x\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
            b"Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n\r\n"
        )
        change = json.dumps({"op": "region", "name": "east_room", "density": 0.5}).encode()
        backlog = (bytes([0x81, 0x80 | len(change)]) + b"\x00\x00\x00\x00" + change) * 20_000
        flooder.setblocking(False)
        began = time.monotonic()
        written = 0
        while written < len(backlog) and time.monotonic() - began < 2.0:  # what the buffers hold, 2 s at most
            try:
                written += flooder.send(backlog[written:written + 65536])
            except BlockingIOError:
                time.sleep(0.005)
        time.sleep(max(0.0, began + 7.0 - time.monotonic()))
        received = b""
        flooder.settimeout(5.0)
        try:
            while chunk := flooder.recv(1 << 16):
                received += chunk
        except (ConnectionResetError, socket.timeout):
            pass
        flooder.close()
        counts = []
        for _ in range(2):
            with urllib.request.urlopen(url + "/api/events", timeout=10) as answer:
                counts.append(sum(1 for event in json.loads(answer.read()) if event["op"] == "region"))
            time.sleep(1.0)
    frames = _websocket_frames(received.split(b"\r\n\r\n", 1)[1])
    closes = [payload for opcode, payload in frames if opcode == 0x8]
    written_changes = written // (len(backlog) // 20_000)
    assert closes and int.from_bytes(closes[0][:2], "big") == 1008, (written_changes, frames[-3:])
    assert closes[0][2:].decode() == FLOODING_REASON
    assert counts[0] == counts[1], f"changes still applied after the close: {counts}"
    assert counts[0] <= CHANGE_BURST + 6.0 * CHANGE_RATE_HZ < written_changes, (counts, written_changes)
