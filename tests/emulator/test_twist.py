"""A robot driven by velocity: `PUT /api/bodies/NAME/twist` on the bundled `rescue-live`.

The control API runs in this process on an injected `ManualClock` (no
sleeping on wall time): a scripted velocity profile is sent command by
command at simulated instants, and the robot's pose (the API's state, the
scan's sensor pose) is compared with an independent integration of the same
commands (small Runge-Kutta steps, not the daemon's closed-form arc). The
robot stops where its footprint touches a wall or a barrel, never inside;
its watchdog stops it when the commands stop; refused twists get a 4xx
naming the limit; the event log replayed gives the same poses bit for bit,
and the WebSocket streams the pose while the robot moves. Against the real
daemon: the documented `ctl pose` / `ctl twist` drive, its replay, and
Foxglove's /tf (live and recorded).
"""

from __future__ import annotations

import asyncio
import base64
import json
import math
import subprocess
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import aiohttp
import numpy as np
import pytest
from control_support import call
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from mcap.reader import make_reader
from mcap.records import Schema
from mcap_protobuf.decoder import DecoderFactory as ProtobufDecoderFactory
from websockets.sync.client import connect

from emulator.bench.serve_process import ServeProcess, serve_command
from emulator.control.events import ControlError, EventWriter, read_events, world_events
from emulator.control.server import ControlAddress, ControlServer
from emulator.control.session import LiveSession
from emulator.daemon.clock import ManualClock
from emulator.daemon.scan_cache import ScanCache
from emulator.daemon.service import Daemon
from emulator.errors import SceneError
from emulator.optics.world import World
from emulator.scene import load_scene
from emulator.scene.drive import Twist, planar_motion
from emulator.scene.bodies import euler_quaternion
from emulator.scene.live import LiveState, PoseChange, TwistChange, event_from_record, event_record
from emulator.scene.model import Pose
from emulator.scene.obstacles import Obstacles
from emulator.sensors import create_sensor
from emulator.sensors.scan_json import scan_json

SCENE = "rescue-live"
RADIUS = 0.3  # rescue-live's robot footprint
WATCHDOG_S = 0.5


# --------------------------------------------------------------------------- the independent integration


def integrate(start: tuple[float, float, float], commands: list[tuple[float, float, float, float]], end_s: float,
              watchdog_s: float = WATCHDOG_S, step_s: float = 1e-4) -> callable:
    """Pose (x, y, yaw) as a function of t: each command (t, vx, vy, wz) holds until the next one or its
    watchdog, integrated with classical RK4 in steps of `step_s` (the daemon uses the closed form)."""
    times = [commands[0][0]]
    states = [np.array(start, dtype=float)]

    def velocity(state: np.ndarray, vx: float, vy: float, wz: float) -> np.ndarray:
        c, s = math.cos(state[2]), math.sin(state[2])
        return np.array([c * vx - s * vy, s * vx + c * vy, wz])

    for index, (t0, vx, vy, wz) in enumerate(commands):
        following = commands[index + 1][0] if index + 1 < len(commands) else end_s
        moving_until = min(following, t0 + watchdog_s)
        state, t = states[-1].copy(), t0
        while t < moving_until - 1e-12:
            h = min(step_s, moving_until - t)
            k1 = velocity(state, vx, vy, wz)
            k2 = velocity(state + 0.5 * h * k1, vx, vy, wz)
            k3 = velocity(state + 0.5 * h * k2, vx, vy, wz)
            k4 = velocity(state + h * k3, vx, vy, wz)
            state = state + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
            t += h
            times.append(t)
            states.append(state.copy())
        if following > moving_until:  # stopped by the watchdog until the next command
            times.append(following)
            states.append(state.copy())
    times_a, states_a = np.array(times), np.array(states)

    def pose_at(t: float) -> np.ndarray:
        index = int(np.searchsorted(times_a, t, side="right")) - 1
        if index < 0:
            return states_a[0]  # before the first command: where it started
        if index + 1 >= len(times_a) or times_a[index] == t:
            return states_a[index]
        fraction = (t - times_a[index]) / (times_a[index + 1] - times_a[index])
        return states_a[index] + fraction * (states_a[index + 1] - states_a[index])  # within one 0.1 ms step

    return pose_at


def yaw_of(pose: dict) -> float:
    return math.radians(pose["rotation_deg"][2])


def assert_close_to(pose: dict, expected: np.ndarray, where: str) -> None:
    error_m = math.hypot(pose["position"][0] - expected[0], pose["position"][1] - expected[1])
    error_deg = abs(math.degrees(math.remainder(yaw_of(pose) - expected[2], 2 * math.pi)))
    assert error_m < 0.01 and error_deg < 0.5, f"{where}: {error_m * 1000:.3f} mm, {error_deg:.4f} deg off"


# --------------------------------------------------------------------------- the API in this process


class Api:
    """The control API of a daemon on `rescue-live` with a ManualClock, over real HTTP and WebSocket."""

    def __init__(self, log: Path | None = None, rate_clock=None) -> None:
        self.scene = load_scene(SCENE)
        self.clock = ManualClock()
        self.daemon = Daemon(self.scene, clock=self.clock, workers=0)
        self.session = LiveSession(self.daemon, EventWriter(log) if log is not None else None)
        # the twist rate limit on an injected clock (the simulated one unless told): commands here come
        # back to back in wall time, each at its own simulated instant
        self.server = ControlServer(self.session, ControlAddress("127.0.0.1", 0), rate_clock=rate_clock or self.clock.now)
        self.http: aiohttp.ClientSession | None = None
        self.url = ""

    async def __aenter__(self) -> Api:
        address = await self.server.start()
        self.url = address.url
        self.http = aiohttp.ClientSession()
        return self

    async def __aexit__(self, *exc_info) -> None:
        await self.http.close()
        await self.server.close()
        self.session.close()
        self.daemon.close()

    async def call(self, method: str, path: str, body=None) -> tuple[int, dict]:
        async with self.http.request(method, self.url + path, data=json.dumps(body) if body is not None else None) as answer:
            return answer.status, await answer.json()

    async def twist(self, at_s: float, vx: float = 0.0, vy: float = 0.0, wz: float = 0.0, name: str = "robot") -> tuple[int, dict]:
        self.clock._now = at_s - 0.5e-6  # the change takes the next µs tick: exactly at_s
        return await self.call("PUT", f"/api/bodies/{name}/twist", {"vx": vx, "vy": vy, "wz": wz})

    async def pose(self, at_s: float, x: float, y: float, yaw_deg: float) -> None:
        self.clock._now = at_s - 0.5e-6
        status, answer = await self.call("PUT", "/api/bodies/robot/pose", {"position": [x, y, 0.0], "yaw_deg": yaw_deg})
        assert status == 200, answer

    async def robot(self, at_s: float) -> dict:
        self.clock._now = at_s
        status, state = await self.call("GET", "/api/state")
        assert status == 200
        return state["bodies"]["robot"]


def run(coroutine) -> object:
    return asyncio.run(coroutine)


# --------------------------------------------------------------------------- the tests


def test_the_closed_form_arc_matches_a_fine_integration() -> None:
    twists = np.array([[0.7, 0.0, 0.0], [0.5, 0.2, 1.3], [0.0, 0.0, -2.0], [0.4, -0.3, 1e-9], [1.0, 0.0, 0.05]])
    start = np.array([[1.0, 2.0, 0.0]] * len(twists))
    yaw0 = 0.3
    quaternions = euler_quaternion(np.array([[0.0, 0.0, math.degrees(yaw0)]] * len(twists)))
    for duration in (0.0, 0.01, 0.5, 3.0):
        positions, turned = planar_motion(start, quaternions, twists, np.full(len(twists), duration))
        for row, (vx, vy, wz) in enumerate(twists):
            expected = integrate((1.0, 2.0, yaw0), [(0.0, vx, vy, wz)], duration, watchdog_s=duration, step_s=1e-3)(duration)
            np.testing.assert_allclose(positions[row, :2], expected[:2], atol=1e-9)
            yaw = math.atan2(2 * (turned[row, 3] * turned[row, 2]), 1 - 2 * turned[row, 2] ** 2)
            assert math.remainder(yaw - expected[2], 2 * math.pi) == pytest.approx(0.0, abs=1e-9)
    same, _ = planar_motion(start, quaternions, twists, np.zeros(len(twists)))
    np.testing.assert_array_equal(same, start)  # no time, no motion: the pose's own bits


def profile() -> list[tuple[float, float, float, float]]:
    """Commands every 0.1 s for 5 s, with a 1 s gap (the watchdog stops the robot at 3.0 s + 0.5 s)."""
    commands = []
    for k in range(50):
        t = 1.0 + 0.1 * k
        if 3.0 < t < 4.0:
            continue
        commands.append((round(t, 6), 0.4 + 0.1 * math.sin(2 * t), 0.05 * math.cos(t), 0.3 * math.cos(1.2 * t)))
    return commands


def test_a_scripted_velocity_profile_is_followed_within_1_cm_and_half_a_degree(tmp_path: Path) -> None:
    commands = profile()
    expected = integrate((5.0, 1.75, 0.0), commands, 8.0)
    checks = np.round(np.arange(0.5, 8.0, 0.037), 6)

    async def drive() -> tuple[list[dict], list[dict]]:
        poses, scans = [], []
        async with Api(tmp_path / "events.jsonl") as api:
            urg = create_sensor(api.scene, "urg", api.daemon.world)
            pending = list(commands)
            for t in checks:
                while pending and pending[0][0] <= t:
                    at, vx, vy, wz = pending.pop(0)
                    status, answer = await api.twist(at, vx, vy, wz)
                    assert status == 200, answer
                poses.append(await api.robot(float(t)))
                scans.append(scan_json(urg.scan(float(t)), urg))
        return poses, scans

    poses, scans = run(drive())
    for t, pose, scan in zip(checks, poses, scans):
        assert_close_to(pose, expected(t), f"state at {t} s")
        x, y, yaw = expected(t)
        mount = np.array([x + 0.15 * math.cos(yaw), y + 0.15 * math.sin(yaw), 0.35])  # urg at (0.15, 0, 0.35)
        np.testing.assert_allclose(scan["pose"]["position"], mount, atol=0.01, err_msg=f"scan at {t} s")
    moved = math.dist(poses[0]["position"], poses[-1]["position"])
    assert moved > 1.5, moved
    # the watchdog: no command between 3.0 and 4.0 s, so the robot stands still from 3.5 s on
    standing = [pose["position"] for t, pose in zip(checks, poses) if 3.5 <= t < 4.0]
    assert len(standing) > 5 and all(position == standing[0] for position in standing)
    assert all(pose["twist"] == {"vx": 0.0, "vy": 0.0, "wz": 0.0} for t, pose in zip(checks, poses) if 3.5 <= t < 4.0)


def test_the_watchdog_stops_the_robot_after_the_last_command() -> None:
    async def drive() -> list[dict]:
        async with Api() as api:
            assert (await api.twist(2.0, vx=0.6, wz=0.4))[0] == 200
            return [await api.robot(t) for t in (2.25, 2.5, 2.6, 10.0)]

    quarter, at_watchdog, after, much_later = run(drive())
    assert quarter["twist"] == {"vx": 0.6, "vy": 0.0, "wz": 0.4}
    assert at_watchdog["twist"] == after["twist"] == {"vx": 0.0, "vy": 0.0, "wz": 0.0}
    assert at_watchdog["position"] == after["position"] == much_later["position"]
    expected = integrate((5.0, 1.75, 0.0), [(2.0, 0.6, 0.0, 0.4)], 10.0)
    assert_close_to(at_watchdog, expected(2.5), "at the watchdog")
    arc = 0.6 * WATCHDOG_S  # the path's length
    chord = 2 * 0.6 / 0.4 * math.sin(0.4 * WATCHDOG_S / 2)
    assert math.dist(at_watchdog["position"][:2], (5.0, 1.75)) == pytest.approx(chord, abs=1e-9) and chord < arc


def test_a_wall_and_a_barrel_stop_the_robot_at_contact_not_inside() -> None:
    async def drive() -> dict:
        async with Api() as api:
            await api.pose(1.0, 5.0, 1.75, -90.0)  # facing south: the south wall's inner face is y = 0
            for k in range(30):
                assert (await api.twist(1.1 + 0.1 * k, vx=0.8))[0] == 200
            at_wall = await api.robot(5.0)
            still_pushing = await api.robot(3.5)
            await api.twist(5.0, vx=-0.5)  # backing off is not blocked
            backed = await api.robot(5.5)
            await api.pose(6.0, 5.0, 0.6, 0.0)  # facing east, at a barrel of radius 0.3 centred at (6.0, 0.6)
            for k in range(10):
                await api.twist(6.1 + 0.1 * k, vx=0.7, vy=0.0)
            at_barrel = await api.robot(8.0)
            await api.pose(9.0, 5.0, 0.32, 0.0)  # 2 cm from the wall: sliding along it is not blocked
            await api.twist(9.1, vx=0.5)
            along = await api.robot(9.6)
            return {"wall": at_wall, "pushing": still_pushing, "backed": backed, "barrel": at_barrel, "along": along}

    poses = run(drive())
    x, y, _ = poses["wall"]["position"]
    assert x == pytest.approx(5.0, abs=1e-12)
    assert RADIUS - 1e-9 <= y <= RADIUS + 1e-6  # touching the wall (y = 0) with its 0.3 m radius: not inside
    assert poses["pushing"]["position"] == poses["wall"]["position"]  # reached before 3.5 s, pushing since
    assert poses["backed"]["position"][1] == pytest.approx(y + 0.25, abs=1e-9)
    bx, by, _ = poses["barrel"]["position"]
    # the barrel's mesh has a vertex at (5.7, 0.6) facing the robot: contact 0.3 m before it
    assert 5.4 - 1e-6 <= bx <= 5.4 + 1e-9 and by == pytest.approx(0.6, abs=1e-12)
    assert poses["along"]["position"][:2] == pytest.approx([5.25, 0.32], abs=1e-9)


def test_refused_twists_get_a_4xx_naming_the_limit() -> None:
    async def refusals() -> list[tuple[int, dict]]:
        async with Api() as api:
            put = lambda body, name="robot": api.call("PUT", f"/api/bodies/{name}/twist", body)  # noqa: E731
            return [
                await put({"vx": 1.2}),
                await put({"vx": 0.8, "vy": 0.8}),
                await put({"wz": -2.5}),
                await put({"vx": "fast"}),
                await put({"vx": 0.1, "speed": 1}),
                await put({}),
                await put({"vx": 0.1}, name="east_door"),
                await put({"vx": 0.1}, name="nobody"),
                await api.call("POST", "/api/bodies/robot/twist", {"vx": 0.1}),
                await api.call("PUT", "/api/bodies/robot/twist", [0.1, 0, 0]),
            ]

    answers = run(refusals())
    statuses = [status for status, _ in answers]
    assert statuses == [400, 400, 400, 400, 400, 400, 409, 404, 405, 400]
    over, diagonal, turning, text, unknown, empty, not_live, unknown_body, _, not_object = [a for _, a in answers]
    assert over == {"error": "bodies[robot].twist: speed 1.2 m/s is over the body's limit "
                             "bodies[robot].drive.max_speed = 1 m/s", "key": "bodies[robot].drive.max_speed"}
    assert "speed 1.13137 m/s" in diagonal["error"]
    assert turning["key"] == "bodies[robot].drive.max_turn_rate" and "-2.5 rad/s" in turning["error"]
    assert text["key"] == "bodies[robot].twist.vx" and "expected a number" in text["error"]
    assert unknown["key"] == "bodies[robot].twist.speed"
    assert empty["error"] == "bodies[robot].twist: expected at least one of: vx, vy, wz"
    assert "not driven from outside" in not_live["error"]
    assert "no body named" in unknown_body["error"]
    assert not_object["error"].startswith("bodies[robot].twist: expected a table")


def test_the_event_log_replayed_gives_the_same_poses_bit_for_bit(tmp_path: Path) -> None:
    log = tmp_path / "events.jsonl"

    async def drive() -> tuple[LiveState, list]:
        async with Api(log) as api:
            await api.pose(0.5, 5.0, 1.75, -90.0)
            for at, vx, vy, wz in profile():
                await api.twist(at, vx, vy, wz)  # toward the south wall: it stops there on the way
            return api.daemon.live, list(api.session.events)

    live, applied = run(drive())
    lines = [json.loads(line) for line in log.read_text().splitlines()]
    assert lines[1] == {"t": 1.0, "op": "twist", "name": "robot", "vx": 0.4 + 0.1 * math.sin(2.0),
                        "vy": 0.05 * math.cos(1.0), "wz": 0.3 * math.cos(1.2)}  # what was sent, nothing derived
    replayed = World(load_scene(SCENE))
    for event in world_events(read_events(log, replayed.scene)):
        replayed.apply(event)
    times = np.linspace(0.0, 8.0, 4001)
    live_frames = live.bodies.frames("robot", times)
    again = replayed.bodies.frames("robot", times)
    np.testing.assert_array_equal(again.positions, live_frames.positions)
    np.testing.assert_array_equal(again.rotations, live_frames.rotations)
    assert live_frames.positions[:, 1].min() == pytest.approx(RADIUS, abs=1e-6)  # it met the wall
    # a worker process is sent the events as applied (a twist with where it stops): it needs no solids
    worker = LiveState(load_scene(SCENE))
    for event in applied:
        worker.apply(event_from_record(event_record(event)))
    assert "obstacles" not in worker.__dict__  # the solids were never cut: every twist came resolved
    np.testing.assert_array_equal(worker.bodies.frames("robot", times).positions, live_frames.positions)


def test_the_websocket_streams_the_pose_while_the_robot_moves() -> None:
    async def watch() -> list[dict]:
        async with Api() as api:
            async with api.http.ws_connect(api.url + "/api/ws") as ws:
                assert json.loads((await ws.receive(timeout=5)).data)["type"] == "state"
                api.clock._now = 1.0
                await ws.send_json({"op": "twist", "name": "robot", "vx": 0.5, "wz": 0.0})
                seen: list[dict] = []
                while len([m for m in seen if m["type"] == "poses"]) < 3:
                    message = json.loads((await ws.receive(timeout=5)).data)
                    assert message["type"] != "error", message
                    seen.append(message)
                    api.clock._now += 0.1
                api.clock._now = 2.0  # past the watchdog: one last message, the robot standing
                while seen[-1]["type"] != "poses" or any(seen[-1]["bodies"]["robot"]["twist"].values()):
                    seen.append(json.loads((await ws.receive(timeout=5)).data))
                return seen

    messages = run(watch())
    poses = [message for message in messages if message["type"] == "poses"]
    xs = [message["bodies"]["robot"]["position"][0] for message in poses]
    assert xs[0] < xs[1] < xs[2], xs
    for message in poses[:-1]:
        assert message["bodies"]["robot"]["position"][0] == pytest.approx(5.0 + 0.5 * min(message["time_s"] - 1.000001, 0.5), abs=1e-9)
    assert poses[-1]["bodies"]["robot"]["position"][0] == pytest.approx(5.25, abs=1e-9)


@pytest.mark.parametrize(("drive", "message"), [
    ("{ radius = 0 }", "bodies[0].drive.radius: must be > 0, got 0"),
    ("{ max_speed = 11 }", "bodies[0].drive.max_speed: must be <= 10, got 11"),
    ("{ watchdog = 6 }", "bodies[0].drive.watchdog: must be <= 2, got 6"),
    ("{ height = 0.01 }", "bodies[0].drive.height: must be > 0.02, got 0.01"),
    ("{ wheels = 4 }", "bodies[0].drive.wheels: unknown key (expected one of: radius, height, clearance, max_speed, "
                       "max_turn_rate, watchdog)"),
])
def test_a_broken_drive_table_is_one_line_naming_the_key(tmp_path: Path, drive: str, message: str) -> None:
    path = tmp_path / "driven.toml"
    path.write_text(f'[[bodies]]\nname = "robot"\ntrajectory = "live"\ndrive = {drive}\n\n'
                    '[[sensors]]\nname = "urg"\nmodel = "urg-04lx"\nbody = "robot"\n')
    with pytest.raises(SceneError) as error:
        load_scene(path)
    assert str(error.value) == f"driven.toml: {message}"


def test_only_a_live_body_has_a_drive(tmp_path: Path) -> None:
    path = tmp_path / "still.toml"
    path.write_text('[[bodies]]\nname = "robot"\ndrive = { radius = 0.2 }\n\n'
                    '[[sensors]]\nname = "urg"\nmodel = "urg-04lx"\nbody = "robot"\n')
    with pytest.raises(SceneError, match=r'still.toml: bodies\[0\].drive: only a body with trajectory = "live"'):
        load_scene(path)


def test_a_twist_stamped_before_the_last_event_is_refused() -> None:
    live = LiveState(load_scene(SCENE))
    live.apply(TwistChange(2.0, "robot", Twist(0.5)))
    with pytest.raises(ValueError, match="earlier than the body's last event"):
        live.apply(TwistChange(1.0, "robot", Twist(0.5)))


# --------------------------------------------------------------------------- the real daemon, as a user drives it


def test_the_readme_examples_drive_rescue_lives_robot_and_the_session_replays(tmp_path: Path) -> None:
    """`ctl pose robot 1.0 2.0 --yaw 90` and `ctl twist robot 0.3 -0.5 --for 1` on `serve rescue-live`
    (scans in worker processes, which get each twist resolved); the pose follows the logged commands;
    Foxglove's /tf (recorded with --mcap) carries it; `scan --events-in` replays the session's last scan."""
    log, recording = tmp_path / "session.jsonl", tmp_path / "session.mcap"
    with ServeProcess(SCENE, ["urg=tcp:127.0.0.1:0", f"lms=pty:{tmp_path / 'lms'}"],
                      extra_args=("--events", str(log), "--mcap", str(recording))) as daemon:
        def ctl(*args: str) -> subprocess.CompletedProcess:
            return subprocess.run([*serve_command(), "ctl", "--url", daemon.control_url, *args],
                                  capture_output=True, text=True, timeout=60)

        posed = ctl("pose", "robot", "1.0", "2.0", "--yaw", "90")
        assert posed.returncode == 0 and posed.stdout.startswith('applied {"t": '), posed.stderr
        driven = ctl("twist", "robot", "0.3", "-0.5", "--for", "1")
        assert driven.returncode == 0, driven.stderr
        assert '"op": "twist", "name": "robot", "vx": 0.3, "vy": 0.0, "wz": -0.5' in driven.stdout
        refused = ctl("twist", "robot", "1.5", "0")
        assert refused.returncode == 2 and refused.stderr == (
            "lrf-emulator ctl: 400: bodies[robot].twist: speed 1.5 m/s is over the body's limit "
            "bodies[robot].drive.max_speed = 1 m/s\n")
        deadline = time.monotonic() + 10  # the real clock: wait out the watchdog
        while any((state := json.loads(ctl("state").stdout))["bodies"]["robot"]["twist"].values()):
            assert time.monotonic() < deadline
            time.sleep(0.1)
        time.sleep(0.3)  # a scan measured after the robot stopped
        status, scan = call(daemon.control_url, "GET", "/api/sensors/urg/scan")
        assert status == 200 and scan["time_s"] > state["time_s"]
    events = [json.loads(line) for line in log.read_text().splitlines()]
    assert events[0]["op"] == "pose" and len(events) >= 4 and {event["op"] for event in events[1:]} == {"twist"}
    commands = [(event["t"], event["vx"], event["vy"], event["wz"]) for event in events[1:]]
    expected = integrate((1.0, 2.0, math.pi / 2), commands, scan["time_s"])(scan["time_s"])
    robot = state["bodies"]["robot"]
    assert_close_to(robot, expected, "after the drive")
    assert math.dist(robot["position"][:2], (1.0, 2.0)) > 0.3  # it drove, to the right of north
    assert robot["position"][0] > 1.1 and robot["rotation_deg"][2] < 90.0
    with recording.open("rb") as file:
        transforms = [
            transform for _, _, _, decoded in make_reader(file, decoder_factories=[ProtobufDecoderFactory()])
            .iter_decoded_messages(topics=["/tf"]) for transform in decoded.transforms if transform.child_frame_id == "robot"
        ]
    xs = [transform.translation.x for transform in transforms]
    assert xs[-1] == pytest.approx(robot["position"][0], abs=1e-9) and len(set(xs)) >= 5, xs  # /tf followed it
    replayed = subprocess.run(
        [*serve_command(), "scan", SCENE, "--sensor", "urg", "--time", repr(scan["time_s"]), "--events-in", str(log)],
        capture_output=True, text=True, timeout=120,
    )
    assert replayed.returncode == 0, replayed.stderr
    again = json.loads(replayed.stdout)
    assert again["values"] == scan["values"]  # the workers' scan, replayed in one process: beam for beam
    yaw = math.radians(robot["rotation_deg"][2])
    urg_at = [robot["position"][0] + 0.15 * math.cos(yaw), robot["position"][1] + 0.15 * math.sin(yaw), 0.35]
    assert again["pose"]["position"] == pytest.approx(urg_at, abs=1e-9)


def test_the_screened_search_stops_where_every_millimetre_sampled_stops() -> None:
    """`travel_time` skips the spans of path that cannot touch a solid; a plain search sampling the
    whole path every millimetre (against every outline) must find the same contact, for random drives
    through rescue-live's clutter."""
    scene = load_scene(SCENE)
    drive = scene.body("robot").drive
    obstacles = Obstacles(scene)
    outlines = obstacles.outlines(drive.clearance, drive.height)
    rng = np.random.default_rng(3)
    stopped = 0
    for _ in range(60):
        position = np.array([rng.uniform(0.5, 15.5), rng.uniform(0.5, 3.2), 0.0])
        if outlines.clearance(position[None, :2])[0] < drive.radius:
            continue
        quaternion = euler_quaternion(np.array([0.0, 0.0, rng.uniform(-180, 180)]))
        twist = np.array([rng.uniform(-1, 1) * 0.7, rng.uniform(-1, 1) * 0.7, rng.uniform(-2, 2)])
        horizon = 3.0  # longer than the watchdog: paths of up to 3 m
        found = obstacles.travel_time(drive, position, quaternion, twist, horizon)
        speed = math.hypot(twist[0], twist[1])
        times = np.minimum(np.arange(int(np.ceil(horizon / (0.001 / speed))) + 1) * (0.001 / speed), horizon)
        centres = planar_motion(np.tile(position, (len(times), 1)), np.tile(quaternion, (len(times), 1)),
                                np.tile(twist, (len(times), 1)), times)[0][:, :2]
        around = outlines.near(centres.min(axis=0) - 1.0, centres.max(axis=0) + 1.0)  # a metre around: all that matter
        clearance = around.clearance(centres)
        inside = np.flatnonzero(clearance < drive.radius - 1e-6)
        if len(inside):
            stopped += 1
            assert times[inside[0] - 1] <= found <= times[inside[0]], (position, twist)
        else:
            assert found == horizon
    assert stopped >= 10  # enough of them met something


TWIST_VALUES = st.one_of(st.none(), st.booleans(), st.integers(-10**20, 10**20), st.text(max_size=4),
                         st.floats(allow_nan=True, allow_infinity=True), st.lists(st.floats(), max_size=3))
TWIST_BODIES = st.one_of(
    st.dictionaries(st.sampled_from(["vx", "vy", "wz", "speed", "yaw_deg"]), TWIST_VALUES, max_size=4),
    TWIST_VALUES,
)


@pytest.fixture(scope="module")
def driven() -> tuple[LiveSession, ManualClock]:
    """One daemon's session on rescue-live for many examples (its clock only moves forward)."""
    clock = ManualClock(1.0)
    daemon = Daemon(load_scene(SCENE), clock=clock, workers=0)
    yield LiveSession(daemon), clock
    daemon.close()


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(bodies=st.lists(TWIST_BODIES, min_size=1, max_size=6), steps=st.lists(st.floats(0.0, 0.4), min_size=6, max_size=6))
def test_whatever_twist_a_client_sends_is_applied_or_refused_and_the_robot_stays_out_of_the_walls(driven, bodies, steps) -> None:
    session, clock = driven
    outlines = session.daemon.live.obstacles.outlines(0.02, 0.6)
    for body, step in zip(bodies, steps):
        clock.advance(step + 1e-6)
        try:
            session.request("twist", "robot", body)
        except ControlError as error:
            assert error.status == 400 and error.key.startswith("bodies[robot]"), error
        clock.advance(0.3)
        robot = session.state()["bodies"]["robot"]
        x, y, _ = robot["position"]
        assert all(math.isfinite(value) for value in (x, y, robot["rotation_deg"][2]))
        assert outlines.clearance(np.array([[x, y]]))[0] >= RADIUS - 1e-9  # never inside a solid


def test_foxglove_live_publishes_the_driven_robot_on_tf(tmp_path: Path) -> None:
    """A Foxglove WebSocket client subscribed to /tf sees the robot's frame move while it is driven."""
    with ServeProcess(SCENE, ["urg=tcp:127.0.0.1:0", f"lms=pty:{tmp_path / 'lms'}"],
                      extra_args=("--foxglove", "127.0.0.1:0")) as daemon:
        with connect(daemon.service("foxglove"), subprotocols=["foxglove.sdk.v1"], open_timeout=10) as websocket:
            advertised = None
            while advertised is None:
                frame = websocket.recv(timeout=10)
                if isinstance(frame, str) and json.loads(frame).get("op") == "advertise":
                    advertised = next(c for c in json.loads(frame)["channels"] if c["topic"] == "/tf")
            schema = Schema(id=1, name=advertised["schemaName"], encoding="protobuf",
                            data=base64.b64decode(advertised["schema"]))
            decode = ProtobufDecoderFactory().decoder_for("protobuf", schema)
            websocket.send(json.dumps({"op": "subscribe", "subscriptions": [{"id": 1, "channelId": advertised["id"]}]}))
            xs: list[float] = []
            deadline = time.monotonic() + 20
            while len(set(xs)) < 4 and time.monotonic() < deadline:
                assert call(daemon.control_url, "PUT", "/api/bodies/robot/twist", {"vx": 0.5})[0] == 200
                frame = websocket.recv(timeout=10)
                if isinstance(frame, bytes) and frame[0] == 0x01:
                    transforms = decode(frame[13:]).transforms
                    xs += [t.translation.x for t in transforms if t.child_frame_id == "robot"]
    assert len(set(xs)) >= 4 and xs[-1] > xs[0] >= 5.0, xs  # east from (5, 1.75), frame after frame


# --------------------------------------------------------------------------- a repeated twist


def test_a_repeated_twist_moves_the_stop_on_and_keeps_the_path_before_it_bit_for_bit() -> None:
    """A cmd_vel bridge sends the same twist 10-100 times a second: each repeat while the body still
    moves only moves its stop on (the same path, to the last bit, up to the old stop); a twist that
    differs, or one after the body stopped, starts from where the body is."""
    live = LiveState(load_scene(SCENE))
    twist = Twist(0.6, 0.0, 0.4)
    live.apply(TwistChange(2.0, "robot", twist))
    assert live.changed_from_s == 2.0
    times = np.linspace(2.0, 3.5, 61)
    before = live.bodies.frames("robot", times)
    live.apply(TwistChange(2.3, "robot", twist))
    assert live.changed_from_s == 2.0 + WATCHDOG_S  # the old stop
    after = live.bodies.frames("robot", times)
    kept = times <= 2.0 + WATCHDOG_S
    np.testing.assert_array_equal(after.positions[kept], before.positions[kept])
    np.testing.assert_array_equal(after.rotations[kept], before.rotations[kept])
    expected = integrate((5.0, 1.75, 0.0), [(2.0, 0.6, 0.0, 0.4), (2.3, 0.6, 0.0, 0.4)], 3.5)
    for t in (2.6, 2.7, 2.8, 3.0):  # on along the same arc, up to the new watchdog (2.8 s), then standing
        position = after.positions[np.isclose(times, t)][0]
        np.testing.assert_allclose(position[:2], expected(t)[:2], atol=1e-6, err_msg=f"at {t}")
    assert len(live.bodies.live_events("robot").times) == 1  # one row, its stop moved on
    live.apply(TwistChange(2.3, "robot", twist))  # the same again at the same instant: the same stop
    assert live.changed_from_s == math.inf
    live.apply(TwistChange(2.4, "robot", Twist(0.3, 0.0, 0.0)))  # another twist: from now
    assert live.changed_from_s == 2.4 and len(live.bodies.live_events("robot").times) == 2
    live.apply(TwistChange(5.0, "robot", Twist(0.3, 0.0, 0.0)))  # the same, but the body had stopped
    assert live.changed_from_s == 5.0 and len(live.bodies.live_events("robot").times) == 3
    with pytest.raises(ValueError, match="earlier than the body's last event"):
        live.apply(TwistChange(4.0, "robot", Twist(0.3, 0.0, 0.0)))
    standing = live.bodies.frames("robot", np.array([6.0, 9.0])).positions
    for t in (6.0, 6.01, 6.02):  # zero twists to a body that stands (an idle bridge): nothing changes
        live.apply(TwistChange(t, "robot", Twist()))
        assert live.changed_from_s == math.inf
    assert len(live.bodies.live_events("robot").times) == 3
    np.testing.assert_array_equal(live.bodies.frames("robot", np.array([6.0, 9.0])).positions, standing)
    with pytest.raises(ValueError, match="earlier than the body's last event"):
        live.apply(TwistChange(6.015, "robot", Twist(0.3, 0.0, 0.0)))  # its instant was taken all the same
    live.apply(TwistChange(6.03, "robot", Twist(0.3, 0.0, 0.0)))
    live.apply(TwistChange(6.05, "robot", Twist()))  # a zero twist to a moving body stops it: from now
    assert live.changed_from_s == 6.05


def test_a_repeated_twist_keeps_the_scans_computed_before_the_old_stop() -> None:
    """The daemon drops only the scans from the instant the path changed: a cmd_vel stream repeating
    one twist leaves the scans foreseen before the old stop in the cache (not computed again per twist)."""
    scene = load_scene(SCENE)
    daemon = Daemon(scene, clock=ManualClock(), workers=0)
    try:
        urg = next(spec for spec in scene.sensors if spec.model == "urg-04lx")
        with ThreadPoolExecutor(1) as executor:
            cache = daemon.scan_caches[urg.name] = ScanCache(create_sensor(scene, urg.name, daemon.world), executor)
            daemon.apply(TwistChange(2.0, "robot", Twist(0.6, 0.0, 0.0)))
            instants = [2.1, 2.3, 2.45, 2.6, 2.8]
            futures = {t: cache.request(t) for t in instants}
            daemon.apply(TwistChange(2.2, "robot", Twist(0.6, 0.0, 0.0)))  # the stop moves from 2.5 to 2.7
            assert [cache.holds(t, futures[t]) for t in instants] == [True, True, True, False, False]
            daemon.apply(TwistChange(2.25, "robot", Twist(0.6, 0.0, 0.3)))  # another twist: from 2.25 on
            assert [cache.holds(t, futures[t]) for t in instants] == [True, False, False, False, False]
    finally:
        daemon.close()


def test_a_100_hz_stream_of_one_twist_keeps_the_body_moving_and_stops_it_a_watchdog_after_the_last() -> None:
    """Each repeat only searches the path on from the old stop: the body still follows the arc of the
    stream (an independent integration of every command), into free space and then up to a wall."""
    live = LiveState(load_scene(SCENE))
    live.apply(PoseChange(1.0, "robot", Pose((5.0, 1.75, 0.0), (0.0, 0.0, -90.0))))  # facing the south wall, y = 0
    commands = [(1.0 + k / 100, 0.6, 0.0, 0.05) for k in range(150)]  # 1.5 s at 100 Hz
    for t, vx, vy, wz in commands:
        live.apply(TwistChange(t, "robot", Twist(vx, vy, wz)))
    events = live.bodies.live_events("robot")
    assert len(events.times) == 2 and events.until[-1] == commands[-1][0] + WATCHDOG_S  # one row, moved on
    expected = integrate((5.0, 1.75, math.radians(-90.0)), commands, 4.0)
    times = np.array([1.5, 2.0, 2.49, 2.9, 3.5])
    positions = live.bodies.frames("robot", times).positions
    for t, position in zip(times, positions):
        np.testing.assert_allclose(position[:2], expected(t)[:2], atol=1e-6, err_msg=f"at {t}")
    live.apply(TwistChange(3.0, "robot", Twist(0.6, 0.0, 0.05)))  # stopped at the watchdog: from here
    assert live.changed_from_s == 3.0
    for k in range(1, 400):  # on at 100 Hz until the wall stops it: contact, then the same stop
        live.apply(TwistChange(3.0 + k / 100, "robot", Twist(0.6, 0.0, 0.05)))
    until = float(live.bodies.live_events("robot").until[-1])
    assert until < 6.0 and live.changed_from_s == math.inf  # the stop is a contact, and stays
    stop = live.bodies.frames("robot", np.array([until, 7.0])).positions
    drive = live.bodies.body("robot").drive
    near = live.obstacles.outlines(stop[0][2] + drive.clearance, stop[0][2] + drive.height)
    np.testing.assert_array_equal(stop[0], stop[1])
    assert RADIUS - 1e-6 <= float(near.clearance(stop[:1, :2])[0]) <= RADIUS + 1e-3  # touching, not inside
