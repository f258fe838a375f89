"""The control API against the real `serve` process (docs/control.md).

Answers are JSON with the scene loader's words; nothing a client sends gets a
500; a plume switched on shows up in the LMS200's scans; the clock pauses;
the token rule holds; a WebSocket client that stops reading is dropped while
others keep their scans; and a live session replayed from its event log
gives the same scans.
"""

from __future__ import annotations

import asyncio
import json
import math
import shlex
import signal
import socket
import subprocess
import time
from pathlib import Path

from urllib.parse import quote

import aiohttp
import numpy as np
import pytest
from control_support import ENDPOINTS, call, write_live_body_room, write_live_room
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from emulator.bench.serve_process import ServeProcess, serve_command
from emulator.commands.options import world_from_args
from emulator.scene import load_scene
from emulator.sensors import create_sensor
from emulator.sensors.published import published


@pytest.fixture
def room(tmp_path: Path) -> Path:
    return write_live_room(tmp_path)


@pytest.fixture
def daemon(room: Path):
    with ServeProcess(room, ENDPOINTS) as process:
        yield process
        assert process.process.poll() is None, process.stderr


def test_errors_are_json_in_the_scene_loaders_words(daemon: ServeProcess) -> None:
    url = daemon.control_url
    assert call(url, "PATCH", "/api/smoke/regions/room", {"density": -1}) == (
        400, {"error": "smoke.regions[room].density: must be >= 0, got -1", "key": "smoke.regions[room].density"}
    )
    status, answer = call(url, "PATCH", "/api/smoke/regions/nowhere", {"density": 1})
    assert status == 404 and answer["key"] == "smoke.regions[nowhere]" and "known: room" in answer["error"]
    status, answer = call(url, "PATCH", "/api/smoke/plumes/fire", {"rate": 0})
    assert (status, answer["error"]) == (400, "smoke.plumes[fire].rate: must be > 0, got 0")
    status, answer = call(url, "PATCH", "/api/smoke/plumes/fire", {"colour": "red"})
    assert status == 400 and answer["error"].startswith("smoke.plumes[fire].colour: unknown key")
    assert call(url, "PATCH", "/api/smoke/regions/room", raw=b"{nope")[0] == 400
    assert call(url, "PATCH", "/api/smoke/regions/room", raw=b"[" * 5000 + b"]" * 5000)[0] == 400
    assert call(url, "PATCH", "/api/smoke/regions/room", {"density": 10**400})[0] == 400
    assert call(url, "PATCH", "/api/smoke/regions/room", raw=b" " * (65 * 1024))[0] == 413
    status, answer = call(url, "PUT", "/api/bodies/robot/pose", {"position": [0, 0, 0]})
    assert status == 404 and "no body named" in answer["error"]
    assert call(url, "DELETE", "/api/state")[0] == 405
    assert call(url, "GET", "/api/nothing/here")[0] == 404
    assert call(url, "GET", "/api/sensors/none/scan")[0] == 404


def test_a_plume_switched_on_shows_up_as_lms200_obstacles(daemon: ServeProcess) -> None:
    url = daemon.control_url
    status, before = call(url, "GET", "/api/sensors/lms/scan")
    assert status == 200 and before["model"] == "lms200" and len(before["values"]) == 361
    assert before["scan_time"] == pytest.approx(2 / 75) and before["angle_min"] == pytest.approx(-math.pi / 2)  # 180° at 0.5°
    ahead = np.abs(np.asarray(before["angles_deg"])) <= 3
    assert np.all(np.asarray(before["values"])[ahead] > 2800)  # the wall, 2.9 m away
    status, answer = call(url, "PATCH", "/api/smoke/plumes/fire", {"emitting": True})
    assert status == 200 and answer["applied"]["emitting"] is True
    assert answer["state"]["plumes"]["fire"]["emitting"] is True
    time.sleep(1.5)  # the particles rise through the scan plane
    status, after = call(url, "GET", "/api/sensors/lms/scan")
    assert after["time_s"] > answer["applied"]["t"]
    values = np.asarray(after["values"])[ahead]
    assert np.any((values > 1000) & (values < 2000)), values  # particles 1.5 m ahead, not the wall
    status, events = call(url, "GET", "/api/events")
    assert events == [answer["applied"]]


def test_the_clock_pauses_and_changes_speed_continuously(daemon: ServeProcess) -> None:
    url = daemon.control_url
    status, answer = call(url, "PATCH", "/api/clock", {"paused": True})
    assert status == 200 and answer["state"]["paused"] is True
    frozen = answer["state"]["time_s"]
    time.sleep(0.3)
    assert call(url, "GET", "/api/state")[1]["time_s"] == frozen
    status, answer = call(url, "PATCH", "/api/clock", {"paused": False, "speed": 0.5})
    assert answer["state"]["speed"] == 0.5 and abs(answer["state"]["time_s"] - frozen) < 0.05
    assert call(url, "PATCH", "/api/clock", {"speed": 0})[1]["error"] == "clock.speed: must be >= 0.001, got 0"


def test_a_slow_websocket_client_is_dropped_and_others_keep_their_scans(daemon: ServeProcess) -> None:
    url = daemon.control_url
    port = int(url.rsplit(":", 1)[1])
    stuck = socket.create_connection(("127.0.0.1", port))
    stuck.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    stuck.sendall(
        b"GET /api/ws HTTP/1.1\r\nHost: x\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
        b"Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n\r\n"
    )
    subscribe = json.dumps({"subscribe": ["lms", "urg"]}).encode()
    mask = b"\x00\x00\x00\x00"
    stuck.sendall(bytes([0x81, 0x80 | len(subscribe)]) + mask + subscribe)  # a masked text frame

    async def watch() -> list[float]:
        async with aiohttp.ClientSession() as session:
            async with session.ws_connect(url + "/api/ws") as ws:
                await ws.send_json({"subscribe": ["urg"]})
                times = []
                while len(times) < 40:
                    message = json.loads((await ws.receive(timeout=10)).data)
                    if message["type"] == "scan":
                        times.append(message["time_s"])
                return times

    times = asyncio.run(watch())  # 4 s: the stuck client fills its queue meanwhile
    assert np.allclose(np.diff(times), 0.1), times
    time.sleep(2.0)
    ended, received = False, 0
    stuck.settimeout(1.0)
    deadline = time.monotonic() + 10.0
    try:
        while time.monotonic() < deadline:
            try:
                chunk = stuck.recv(1 << 16)
            except socket.timeout:
                continue
            if not chunk:
                ended = True
                break
            received += len(chunk)
    except ConnectionResetError:
        ended = True
    stuck.close()
    assert ended, f"the daemon kept a client that stopped reading ({received} bytes read afterwards)"
    assert received < 20_000_000
    assert call(url, "GET", "/api/state")[0] == 200


def test_state_messages_come_at_most_20_a_second_and_carry_the_latest_change(daemon: ServeProcess) -> None:
    """200 region changes over 2 s on one connection (100 a second, within the change rate; each answered
    in a state message, they would cost the loop a state each): the client gets at most 20 state messages
    in any second, and the last one it gets holds the last change."""
    url = daemon.control_url

    async def change() -> tuple[list[float], dict]:
        async with aiohttp.ClientSession() as http, http.ws_connect(url + "/api/ws") as ws:
            assert json.loads((await ws.receive(timeout=5)).data)["type"] == "state"  # the one on connecting
            arrivals, last = [], {}
            start = time.monotonic()
            for sent in range(1, 201):
                await ws.send_json({"op": "region", "name": "room", "density": sent / 10_000})
                while (wait := start + sent / 100 - time.monotonic()) > 0 or sent == 200:
                    try:
                        message = await ws.receive(timeout=max(wait, 0.3 if sent == 200 else 0.0))
                    except asyncio.TimeoutError:
                        break
                    data = json.loads(message.data)
                    assert data["type"] == "state", data
                    arrivals.append(time.monotonic() - start)
                    last = data
            return arrivals, last

    arrivals, last = asyncio.run(change())
    assert last["regions"]["room"]["density"] == 0.02, last["regions"]
    spans = np.array(arrivals)
    busiest = int((np.searchsorted(spans, spans + 1.0) - np.arange(len(spans))).max())  # in any 1 s
    assert 2 <= busiest <= 20 + 1, (busiest, len(arrivals))  # +1: a client may read two in one wake-up


def test_the_token_rule(room: Path) -> None:
    result = subprocess.run(
        [*serve_command(), "serve", str(room), "--endpoint", ENDPOINTS[0], "--control", "0.0.0.0:0"],
        capture_output=True, text=True, timeout=60,
    )
    assert result.returncode == 2
    assert result.stderr.count("\n") == 1 and "--control-token" in result.stderr
    with ServeProcess(room, ENDPOINTS[:1], extra_args=("--control", "127.0.0.1:0", "--control-token", "s3cret")) as d:
        assert call(d.control_url, "GET", "/api/state")[0] == 401
        assert call(d.control_url, "GET", "/api/state", headers={"Authorization": "Bearer wrong"})[0] == 401
        assert call(d.control_url, "GET", "/api/state", headers={"Authorization": "Bearer s3cret"})[0] == 200


def test_a_live_session_and_its_replay_give_identical_scans(room: Path, tmp_path: Path) -> None:
    log = tmp_path / "events.jsonl"
    scans: list[dict] = []
    with ServeProcess(room, ENDPOINTS, extra_args=("--control", "127.0.0.1:0", "--events", str(log))) as daemon:
        url = daemon.control_url

        async def session() -> None:
            async with aiohttp.ClientSession() as http:
                async with http.ws_connect(url + "/api/ws") as ws:
                    await ws.send_json({"subscribe": ["urg"]})
                    changes = [
                        {"op": "region", "name": "room", "density": 0.003},
                        {"op": "plume", "name": "fire", "emitting": True, "rate": 25},
                        {"op": "plume", "name": "fire", "wind": [0.0, 0.5, 0.0]},
                        {"op": "region", "name": "room", "density": 0.0},
                    ]
                    while len(scans) < 16:
                        message = json.loads((await ws.receive(timeout=10)).data)
                        if message["type"] == "scan":
                            scans.append(message)
                            if len(scans) % 3 == 0 and changes:
                                await ws.send_json(changes.pop(0))
                        assert message["type"] != "error", message

        asyncio.run(session())
    events = [json.loads(line) for line in log.read_text().splitlines()]
    assert [event["op"] for event in events] == ["region", "plume", "plume", "region"]
    scene = load_scene(room)

    class Args:
        events_in = log

    urg = create_sensor(scene, "urg", world_from_args(scene, Args()))
    changed = 0
    plain = create_sensor(scene, "urg")
    for scan in scans:
        replayed = published(urg.scan(scan["time_s"])).values
        np.testing.assert_array_equal(replayed, scan["values"], err_msg=f"at {scan['time_s']}")
        changed += not np.array_equal(replayed, published(plain.scan(scan["time_s"])).values)
    assert changed >= 6, "the changes should have shown in the scans"
    result = subprocess.run(
        [*serve_command(), "scan", str(room), "--sensor", "urg", "--time", repr(scans[-1]["time_s"]),
         "--events-in", str(log)], capture_output=True, text=True, timeout=60,
    )
    assert json.loads(result.stdout)["values"] == scans[-1]["values"]
    with ServeProcess(room, ENDPOINTS[:1], extra_args=("--control", "127.0.0.1:0", "--events-in", str(log))) as again:
        assert call(again.control_url, "GET", "/api/events")[1] == events


METHODS = st.sampled_from(["GET", "PUT", "PATCH", "POST", "DELETE", "HEAD", "OPTIONS", "TRACE", "FOO"])
PATHS = st.one_of(
    st.sampled_from(
        ["/api/scene", "/api/state", "/api/events", "/api/clock", "/api/ws", "/api/smoke/regions/room",
         "/api/smoke/plumes/fire", "/api/bodies/robot/pose", "/api/sensors/urg/scan", "/api/sensors/lms/scan", "/"]
    ),
    st.builds(
        lambda kind, name: f"/api/{kind}/{quote(name, safe='%')}",
        st.sampled_from(["smoke/regions", "smoke/plumes", "bodies", "sensors"]),
        st.text("abcdefgh%2F._-~ü", min_size=0, max_size=12),
    ),
)
JSON = st.recursive(
    st.none() | st.booleans() | st.floats(allow_nan=True) | st.integers() | st.text(max_size=8),
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(
        st.sampled_from(["density", "emitting", "rate", "wind", "speed", "paused", "position", "yaw_deg", "x"]), inner,
        max_size=4,
    ),
    max_leaves=12,
)


@pytest.fixture(scope="module")
def shared_daemon(tmp_path_factory):
    room = write_live_room(tmp_path_factory.mktemp("fuzz"))
    with ServeProcess(room, ENDPOINTS) as process:
        yield process


@settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(method=METHODS, path=PATHS, body=JSON)
def test_whatever_a_client_sends_gets_a_2xx_or_4xx_and_the_daemon_serves_on(shared_daemon, method, path, body) -> None:
    if path.endswith("/api/clock") and method == "PATCH":
        body = {key: value for key, value in body.items() if key != "paused"} if isinstance(body, dict) else body
    status, answer = call(shared_daemon.control_url, method, path, raw=json.dumps(body).encode(), as_json=method != "FOO")
    assert 200 <= status < 500, (status, answer)
    if method not in ("HEAD", "FOO"):  # aiohttp's HTTP parser itself refuses an unknown method (400, text)
        assert answer is not None
    assert shared_daemon.process.poll() is None
    if status >= 400 and method not in ("HEAD", "FOO"):
        assert set(answer) >= {"error"}


def _front_mm(scan: dict) -> int:
    """The URG's value straight ahead (step 384, the 341st of the measured steps 44..725)."""
    return scan["values"][384 - 44]


def test_a_live_body_moved_by_put_and_by_a_100_hz_websocket_stream_moves_the_scan(tmp_path: Path) -> None:
    room = write_live_body_room(tmp_path)
    log = tmp_path / "poses.jsonl"
    with ServeProcess(room, ENDPOINTS[:1], extra_args=("--control", "127.0.0.1:0", "--events", str(log))) as daemon:
        url = daemon.control_url
        assert _front_mm(call(url, "GET", "/api/sensors/urg/scan")[1]) == 2900  # the wall: the crate is aside
        status, answer = call(url, "PUT", "/api/bodies/robot/pose", {"position": [1.2, 0.0, 0.0], "yaw_deg": 0})
        assert status == 200 and answer["state"]["bodies"]["robot"]["position"] == [1.2, 0.0, 0.0]
        time.sleep(0.3)
        assert _front_mm(call(url, "GET", "/api/sensors/urg/scan")[1]) == 1000  # the crate's near face
        status, answer = call(url, "PUT", "/api/bodies/robot/pose", {"position": [1, 2, 0], "rotation_deg": [0, 0]})
        assert status == 400 and answer["key"] == "bodies[robot].rotation_deg"
        scans: list[dict] = []

        async def drive() -> int:
            """Poses at 100 Hz for 1.5 s on one connection: the crate backs off from 1.2 m to 2.4 m."""
            async with aiohttp.ClientSession() as http:
                async with http.ws_connect(url + "/api/ws") as ws:
                    await ws.send_json({"subscribe": ["urg"]})
                    sent = 0
                    start = time.monotonic()
                    while sent < 150:
                        x = 1.2 + 1.2 * sent / 149
                        await ws.send_json({"op": "pose", "name": "robot", "position": [x, 0.0, 0.0], "yaw_deg": 0})
                        sent += 1
                        while True:  # read what came meanwhile, without waiting past the next pose's time
                            wait = start + sent / 100 - time.monotonic()
                            try:
                                message = await ws.receive(timeout=max(wait, 0.0005))
                            except asyncio.TimeoutError:
                                break
                            data = json.loads(message.data)
                            assert data["type"] != "error", data
                            if data["type"] == "scan":
                                scans.append(data)
                    while len(scans) < 25:
                        data = json.loads((await ws.receive(timeout=5)).data)
                        if data["type"] == "scan":
                            scans.append(data)
                    return sent

        assert asyncio.run(drive()) == 150
        assert _front_mm(scans[-1]) == 2200  # the crate's near face at its last pose, 2.4 - 0.2
    events = [json.loads(line) for line in log.read_text().splitlines()]
    assert len(events) == 151 and all(event["op"] == "pose" for event in events)
    fronts = [_front_mm(scan) for scan in scans]
    assert len(set(fronts)) >= 5, fronts  # the scans followed the crate
    scene = load_scene(room)

    class Args:
        events_in = log

    urg = create_sensor(scene, "urg", world_from_args(scene, Args()))
    for scan in scans:  # the replay sees the crate wherever the live session did, beam for beam
        np.testing.assert_array_equal(published(urg.scan(scan["time_s"])).values, scan["values"], err_msg=f"at {scan['time_s']}")


def test_ctl_says_what_went_wrong_in_one_line_and_exits_2(daemon: ServeProcess) -> None:
    def ctl(*args: str, url: str = daemon.control_url) -> subprocess.CompletedProcess:
        return subprocess.run([*serve_command(), "ctl", "--url", url, *args], capture_output=True, text=True, timeout=30)

    refused = ctl("set", "region", "room", "density", "-1")
    assert refused.returncode == 2
    assert refused.stderr == "lrf-emulator ctl: 400: smoke.regions[room].density: must be >= 0, got -1.0\n"
    unknown = ctl("plume", "nope", "on")
    assert unknown.returncode == 2 and unknown.stderr.startswith("lrf-emulator ctl: 404: no plume named \"nope\"")
    assert ctl("plume", "fire", "wind", "1", "2").returncode == 2
    nobody = ctl("state", url="http://127.0.0.1:9")
    assert nobody.returncode == 2 and nobody.stderr.count("\n") == 1 and "cannot reach" in nobody.stderr
    applied = ctl("plume", "fire", "rate", "12")
    assert applied.returncode == 0 and '"rate": 12.0' in applied.stdout
    paused = ctl("clock", "--pause")
    assert paused.returncode == 0 and json.loads(ctl("state").stdout)["paused"] is True
    watched = ctl("clock", "--resume"), ctl("watch", "lms", "--count", "2")
    assert watched[1].returncode == 0 and len(watched[1].stdout.splitlines()) == 2
    assert " lms " in watched[1].stdout.splitlines()[0]
    piped = subprocess.run(  # its reader goes away after one line: a quiet stop, as Unix tools do
        f"{shlex.join([*serve_command(), 'ctl', '--url', daemon.control_url, 'watch', 'lms'])} | head -n 1",
        shell=True, capture_output=True, text=True, timeout=30,
    )
    assert len(piped.stdout.splitlines()) == 1 and piped.stderr == "", piped.stderr
    wrong_port = ctl("state", url=f"http://127.0.0.1:{daemon.endpoint('urg', 'tcp').address[1]}")  # a device's port
    assert wrong_port.returncode == 2 and wrong_port.stderr.count("\n") == 1 and "does not answer HTTP" in wrong_port.stderr
    assert ctl("watch", "lms", "--count", "0").returncode == 2
    # the connection options and --debug after the action, as users type them (they were "unrecognized")
    after = subprocess.run([*serve_command(), "ctl", "watch", "lms", "--count", "1", "--url", daemon.control_url, "--debug"],
                           capture_output=True, text=True, timeout=30)
    assert after.returncode == 0 and " lms " in after.stdout, after.stderr
    overridden = ctl("state", "--url", daemon.control_url, url="http://127.0.0.1:9")  # the later --url wins
    assert overridden.returncode == 0 and "time_s" in json.loads(overridden.stdout), overridden.stderr


def test_watchers_that_go_away_leave_the_daemon_quiet(room: Path) -> None:
    """`ctl watch` stopped by ^C, SIGTERM or SIGKILL (no close handshake): the daemon's writer task for
    each is ended with the connection (left waiting, each was later destroyed pending, with a warning
    on the daemon's stderr), and the daemon serves on and stops cleanly."""
    with ServeProcess(room, ENDPOINTS) as daemon:
        for stop in (signal.SIGINT, signal.SIGTERM, signal.SIGKILL) * 2:
            watcher = subprocess.Popen([*serve_command(), "ctl", "--url", daemon.control_url, "watch", "lms"], stdout=subprocess.PIPE)
            assert watcher.stdout.readline()
            watcher.send_signal(stop)
            watcher.wait(timeout=30)
            watcher.stdout.close()
        assert call(daemon.control_url, "GET", "/api/state")[0] == 200
        assert daemon.stop() == 0
        assert "Task was destroyed" not in daemon.stderr and "Traceback" not in daemon.stderr, daemon.stderr


def test_the_state_counts_each_sensors_clients(daemon: ServeProcess) -> None:
    """A client on the URG's TCP endpoint, then one on the LMS's too: the state counts each sensor's own
    (an endpoint is a serial line: one client at a time), and 0 once they leave."""
    def settled(expected: dict[str, int]) -> dict[str, int]:
        deadline = time.monotonic() + 10.0
        while True:
            state = call(daemon.control_url, "GET", "/api/state")[1]
            counted = {name: sensor["clients"] for name, sensor in state["sensors"].items()}
            if counted == expected or time.monotonic() > deadline:
                return counted
            time.sleep(0.05)

    connections = [socket.create_connection(daemon.endpoint("urg", "tcp").address)]
    try:
        assert settled({"urg": 1, "lms": 0}) == {"urg": 1, "lms": 0}
        connections.append(socket.create_connection(daemon.endpoint("lms", "tcp").address))
        assert settled({"urg": 1, "lms": 1}) == {"urg": 1, "lms": 1}
    finally:
        for connection in connections:
            connection.close()
    assert settled({"urg": 0, "lms": 0}) == {"urg": 0, "lms": 0}


def test_a_fleet_daemon_refuses_scans_of_sensors_it_does_not_serve(room: Path) -> None:
    with ServeProcess(room, ENDPOINTS[:1], extra_args=("--sensors", "urg", "--control", "127.0.0.1:0")) as daemon:
        status, answer = call(daemon.control_url, "GET", "/api/sensors/lms/scan")
        assert status == 409 and "not served by this daemon" in answer["error"]
        status, urg = call(daemon.control_url, "GET", "/api/sensors/urg/scan")
        assert status == 200 and len(urg["values"]) == 682 and urg["scan_time"] == 0.1  # steps 44..725, urg_node's fields


def test_a_paused_clock_stops_the_device_stream_and_resuming_continues_it(daemon: ServeProcess) -> None:
    url = daemon.control_url
    host, port = daemon.endpoint("urg", "tcp").address
    with socket.create_connection((host, port), timeout=5) as client:
        client.sendall(b"MD0044072501000\n")
        received = bytearray()

        def messages() -> int:
            return received.count(b"\n\n")

        def read_for(seconds: float) -> None:
            client.settimeout(0.05)
            end = time.monotonic() + seconds
            while time.monotonic() < end:
                try:
                    received.extend(client.recv(1 << 16))
                except socket.timeout:
                    pass

        read_for(0.5)
        assert messages() >= 3  # the echo and a few scans
        status, answer = call(url, "PATCH", "/api/clock", {"paused": True})
        assert status == 200
        read_for(1.0)  # a scan already under way may still arrive (late on a busy machine)
        paused_at = messages()
        read_for(1.0)
        assert messages() == paused_at, "a paused daemon sent scans"
        call(url, "PATCH", "/api/clock", {"paused": False})
        read_for(0.5)
        assert messages() >= paused_at + 3
        client.sendall(b"QT\n")


def test_only_a_live_body_takes_a_pose_from_outside() -> None:
    with ServeProcess("rescue", ["urg=tcp:127.0.0.1:0"], extra_args=("--sensors", "urg", "--control", "127.0.0.1:0")) as d:
        status, answer = call(d.control_url, "PUT", "/api/bodies/east_door/pose", {"position": [0, 0, 0], "yaw_deg": 5})
        assert status == 409 and answer["key"] == "bodies[east_door]" and '"live"' in answer["error"]
        assert call(d.control_url, "GET", "/api/events")[1] == []


def test_an_event_log_that_cannot_be_written_ends_with_one_line_and_every_change_still_applies(room: Path) -> None:
    """A full disk under `--events`: the change stands and is answered 200 with its state, the daemon
    says once that the log stops there, and later changes apply as well (each one answered 500,
    with a traceback, before)."""
    with ServeProcess(room, ENDPOINTS, extra_args=("--control", "127.0.0.1:0", "--events", "/dev/full")) as daemon:
        for density in (0.002, 0.004):
            status, answer = call(daemon.control_url, "PATCH", "/api/smoke/regions/room", {"density": density})
            assert status == 200, answer
            assert answer["state"]["regions"]["room"]["density"] == density
        assert call(daemon.control_url, "GET", "/api/events")[1][-1]["density"] == 0.004
        lines = [line for line in daemon.stderr.splitlines() if "--events /dev/full" in line]
        assert len(lines) == 1 and "cannot write (No space left on device)" in lines[0], daemon.stderr
        assert "Traceback" not in daemon.stderr
