"""Bodies (docs/scene-format.md, "Bodies"): the format's rules, poses as functions of t, moving sensors and
solids, each beam cast at the instant its step is measured, and the ground truth beside a scan."""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from emulator.errors import SceneError
from emulator.optics import World
from emulator.scene import load_scene
from emulator.scene import loader as scene_loader
from emulator.scene.bodies import LiveEvents, euler_quaternion, live_frames, matrix_euler_deg
from emulator.scene.model import Density, Pose
from emulator.sensors import beam_times_s, create_sensor, lms200, urg04lx

ROBOT = '[[bodies]]\nname = "robot"\n'
RIDER = '[[sensors]]\nname = "urg"\nmodel = "urg-04lx"\nbody = "robot"\n'
MOVES = "trajectory = { keyframes = [[0, 0, 0, 0], [1, 1, 0, 0]] }\n"


def write(directory: Path, text: str, name: str = "x.toml") -> Path:
    path = directory / name
    path.write_text(text, encoding="utf-8")
    return path


# --------------------------------------------------------------------------- the format's rules

ERRORS = [
    (ROBOT + "speed = 1\n" + RIDER, "bodies[0].speed: unknown key (expected one of: name, position, rotation_deg, trajectory, drive)"),
    (ROBOT + MOVES, 'bodies[0].name: body "robot" carries nothing (no sensor or object has body = "robot")'),
    (ROBOT + MOVES + RIDER.replace('"robot"', '"robto"'), 'sensors[0].body: unknown body "robto" (bodies: robot)'),
    (ROBOT + MOVES + '[[objects]]\nname = "crate"\nbox = { size = [1, 1, 1] }\nbody = "cart"\n',
     'objects[0].body: unknown body "cart" (bodies: robot)'),
    (ROBOT + MOVES + RIDER + ROBOT, 'bodies[1].name: duplicate name "robot" (also bodies[0])'),
    (ROBOT + "trajectory = { keyframes = [[0, 0, 0, 0], [2, 1, 0, 0], [1, 2, 0, 0]] }\n" + RIDER,
     "bodies[0].trajectory.keyframes[2][0]: keyframe times must not decrease, got 1 after 2"),
    (ROBOT + "trajectory = { keyframes = [[0, 0, 0]] }\n" + RIDER,
     "bodies[0].trajectory.keyframes[0]: expected 4 numbers [t, x, y, yaw_deg] or 7 [t, x, y, z, roll_deg, pitch_deg, yaw_deg], got 3 numbers"),
    (ROBOT + "trajectory = { keyframes = [[0, 0, 0, 0], [1, 0, 0, 0, 0, 0, 0]] }\n" + RIDER,
     "bodies[0].trajectory.keyframes[1]: expected 4 numbers like row 0, got 7 numbers"),
    (ROBOT + 'trajectory = { keyframes = [[0, 0, "x", 0]] }\n' + RIDER,
     'bodies[0].trajectory.keyframes[0][2]: expected a number, got "x"'),
    (ROBOT + "trajectory = { keyframes = [[0, 1e300, 0, 0]] }\n" + RIDER,
     "bodies[0].trajectory.keyframes[0][1]: must lie within ±100000, got 1e+300"),
    (ROBOT + "trajectory = { keyframes = [] }\n" + RIDER,
     "bodies[0].trajectory.keyframes: expected a non-empty list of [t, x, y, yaw_deg] or [t, x, y, z, roll_deg, pitch_deg, yaw_deg], got []"),
    (ROBOT + 'trajectory = "dead"\n' + RIDER,
     'bodies[0].trajectory: expected "live", { keyframes = [...] } or { file = "run.tum" }, got "dead"'),
    (ROBOT + 'trajectory = { keyframes = [[0, 0, 0, 0]], file = "a.tum" }\n' + RIDER,
     "bodies[0].trajectory: needs exactly one of: keyframes, file"),
    (ROBOT + "trajectory = { speed = 1 }\n" + RIDER, "bodies[0].trajectory.speed: unknown key (expected one of: keyframes, file)"),
    (ROBOT + 'trajectory = { file = "missing.tum" }\n' + RIDER,
     "bodies[0].trajectory.file: cannot read missing.tum: No such file or directory"),
    ('[[smoke.regions]]\nname = "fog"\nbox = { size = [1, 1, 1] }\ndensity = 0.1\nbody = "robot"\n',
     "smoke.regions[0].body: smoke regions cannot ride on a body (the paper's smoke areas never move)"),
]


@pytest.mark.parametrize(("text", "expected"), ERRORS, ids=[expected for _, expected in ERRORS])
def test_a_body_rule_broken_is_one_line_naming_file_table_and_key(tmp_path: Path, text: str, expected: str) -> None:
    with pytest.raises(SceneError) as raised:
        load_scene(write(tmp_path, text))
    assert str(raised.value) == f"x.toml: {expected}"


TUM_ERRORS = [
    ("0 0 0 0 0 0 0 1\n\n# comment\n1 0 0 0 0 0 1\n", "run.tum line 4: expected 8 numbers, got 7"),
    ("0 0 0 0 0 0 0 1\n1 0 0 zero 0 0 0 1\n", 'run.tum line 2: not a number: "zero"'),
    ("0 0 0 0 0 0 0 1\n1 0 0 nan 0 0 0 1\n", "run.tum line 2: numbers must be finite"),
    ("2 0 0 0 0 0 0 1\n1 0 0 0 0 0 0 1\n", "run.tum line 2: times must not decrease, got 1 after 2"),
    ("0 0 0 0 0 0 0 0\n", "run.tum line 1: quaternion qx qy qz qw must not be zero"),
    ("0 0 0 2e5 0 0 0 1\n", "run.tum line 1: x y z must lie within ±100000"),
    ("# nothing\n", "run.tum holds no pose (lines 't x y z qx qy qz qw')"),
    (b"0 0 0 0 0 0 0 1\n\xff\n", "run.tum: not UTF-8 text (byte 16)"),
]


@pytest.mark.parametrize(("content", "expected"), TUM_ERRORS, ids=[expected for _, expected in TUM_ERRORS])
def test_a_tum_file_that_does_not_parse_names_its_line(tmp_path: Path, content: str | bytes, expected: str) -> None:
    (tmp_path / "run.tum").write_bytes(content if isinstance(content, bytes) else content.encode())
    with pytest.raises(SceneError) as raised:
        load_scene(write(tmp_path, ROBOT + 'trajectory = { file = "run.tum" }\n' + RIDER))
    assert str(raised.value) == f"x.toml: bodies[0].trajectory.file: {expected}"


def test_a_huge_tum_file_is_refused_before_it_is_parsed(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(scene_loader, "TUM_MAX_BYTES", 64)
    (tmp_path / "run.tum").write_text("0 0 0 0 0 0 0 1\n" * 5)
    with pytest.raises(SceneError, match=r"^x\.toml: bodies\[0\]\.trajectory\.file: run\.tum is larger than 0 MiB$"):
        load_scene(write(tmp_path, ROBOT + 'trajectory = { file = "run.tum" }\n' + RIDER))
    monkeypatch.setattr(scene_loader, "TUM_MAX_BYTES", 1 << 20)
    monkeypatch.setattr(scene_loader, "TUM_MAX_LINES", 4)
    with pytest.raises(SceneError, match=r"run\.tum has more than 4 lines$"):
        load_scene(write(tmp_path, ROBOT + 'trajectory = { file = "run.tum" }\n' + RIDER))



def test_a_fifo_as_a_tum_file_is_refused_without_waiting_for_a_writer(tmp_path: Path) -> None:
    os.mkfifo(tmp_path / "run.tum")  # opened to read, it blocked the loader until someone wrote to it
    with pytest.raises(SceneError, match=r"^x\.toml: bodies\[0\]\.trajectory\.file: run\.tum is not a regular file"):
        load_scene(write(tmp_path, ROBOT + 'trajectory = { file = "run.tum" }\n' + RIDER))

# --------------------------------------------------------------------------- poses as functions of t


def body_frames(tmp_path: Path, trajectory: str, times: list[float], extra: str = ""):
    scene = load_scene(write(tmp_path, ROBOT + extra + f"trajectory = {trajectory}\n" + RIDER))
    return World(scene).bodies.frames("robot", np.array(times))


def yaws(frames) -> list[float]:
    return [matrix_euler_deg(rotation)[2] for rotation in frames.rotations]


def test_planar_keyframes_move_linearly_turn_along_the_shortest_arc_and_hold_outside(tmp_path: Path) -> None:
    frames = body_frames(
        tmp_path, "{ keyframes = [[1, 0, 0, 170], [3, 4, 2, -170]] }", [0, 1, 2, 2.5, 3, 9],
        'position = [0, 0, 0.25]\nrotation_deg = [0, 5, 0]\n',
    )
    np.testing.assert_allclose(frames.positions, [[0, 0, 0.25], [0, 0, 0.25], [2, 1, 0.25], [3, 1.5, 0.25], [4, 2, 0.25], [4, 2, 0.25]])
    # 170° → -170° is 20° through 180°, not 340° back through 0°
    np.testing.assert_allclose(np.mod(yaws(frames), 360.0), [170, 170, 180, 185, 190, 190], atol=1e-9)
    assert [matrix_euler_deg(r)[1] for r in frames.rotations] == pytest.approx([5.0] * 6)  # pitch from rotation_deg


def test_full_rows_set_every_axis_and_two_rows_at_one_time_jump(tmp_path: Path) -> None:
    frames = body_frames(
        tmp_path, "{ keyframes = [[0, 0, 0, 0, 0, 0, 0], [2, 2, 0, 1, 0, 0, 0], [2, 5, 5, 1, 0, 0, 90], [4, 5, 5, 1, 0, 0, 90]] }",
        [1, 1.999999, 2, 3],
    )
    np.testing.assert_allclose(frames.positions[[0, 2, 3]], [[1, 0, 0.5], [5, 5, 1], [5, 5, 1]])
    assert frames.positions[1] == pytest.approx([2, 0, 1], abs=1e-5)  # just before the jump: still on the first leg
    assert yaws(frames) == pytest.approx([0, 0, 90, 90], abs=1e-9)


def test_a_tum_file_is_the_same_trajectory_as_its_keyframes(tmp_path: Path) -> None:
    q = euler_quaternion(np.array([0.0, 0.0, 90.0]))
    (tmp_path / "run.tum").write_text(f"# t x y z qx qy qz qw\n0 0 0 0 0 0 0 1\n2 2 2 0 {q[0]} {q[1]} {q[2]} {q[3]}\n")
    from_file = body_frames(tmp_path, '{ file = "run.tum" }', [0.5, 1, 3])
    from_rows = body_frames(tmp_path, "{ keyframes = [[0, 0, 0, 0], [2, 2, 2, 90]] }", [0.5, 1, 3])
    np.testing.assert_allclose(from_file.positions, from_rows.positions, atol=1e-12)
    np.testing.assert_allclose(from_file.rotations, from_rows.rotations, atol=1e-12)


def test_keyframed_smoke_density_steps_where_two_rows_share_a_time() -> None:
    density = Density(((0.0, 0.0), (10.0, 0.004), (10.0, 0.0), (20.0, 0.002)))
    assert [density.at(t) for t in (-1.0, 5.0, 10.0, 15.0, 30.0)] == pytest.approx([0.0, 0.002, 0.0, 0.001, 0.002])
    assert density.at(9.999) == pytest.approx(0.004, rel=1e-3)
    np.testing.assert_allclose(density.at(np.array([5.0, 10.0, 15.0])), [0.002, 0.0, 0.001])


def test_a_live_pose_holds_from_its_event_on_and_never_looks_ahead() -> None:
    initial = Pose((1.0, 0.0, 0.0))
    times = np.array([2.0, 4.0])
    events = LiveEvents(times, np.array([[2.0, 0, 0], [3.0, 0, 0]]), euler_quaternion(np.array([[0, 0, 90.0], [0, 0, 0.0]])),
                        np.zeros((2, 3)), times)
    frames = live_frames(events, initial, np.array([0.0, 2.0, 3.9, 4.0, 100.0]))
    np.testing.assert_allclose(frames.positions[:, 0], [1, 2, 2, 3, 3])
    assert yaws(frames) == pytest.approx([0, 90, 90, 0, 0], abs=1e-9)
    first = LiveEvents(events.times[:1], events.positions[:1], events.quaternions[:1], events.twists[:1], events.until[:1])
    truncated = live_frames(first, initial, np.array([3.9]))
    np.testing.assert_array_equal(truncated.positions, frames.positions[2:3])  # a later event never changes an earlier instant


# --------------------------------------------------------------------------- moving sensors and solids

WALL = '[[objects]]\nname = "wall"\nbox = { size = [0.2, 20, 3] }\nposition = [5.1, 0, 0]\n'


def scene_of(tmp_path: Path, text: str, model: str = "formsma2011"):
    return load_scene(write(tmp_path, f'[scene]\nmodel = "{model}"\n' + text))


def test_a_live_body_carries_its_sensor_to_each_recorded_pose(tmp_path: Path) -> None:
    scene = scene_of(tmp_path, ROBOT + 'trajectory = "live"\n' + RIDER + WALL)
    world = World(scene)
    sensor = create_sensor(scene, "urg", world)
    assert sensor.scan(1.0).values[384] == 5000
    world.bodies.add_live_pose("robot", 2.0, Pose((2.0, 0.0, 0.0)))
    assert sensor.scan(1.9).values[384] == 5000 and sensor.scan(2.1).values[384] == 3000
    with pytest.raises(ValueError, match="earlier than the last one"):
        world.bodies.add_live_pose("robot", 1.0, Pose())


def test_a_sensor_on_a_body_at_rest_gives_exactly_the_fixed_sensors_scans(tmp_path: Path) -> None:
    base = WALL + '[[smoke.regions]]\nname = "fog"\nbox = { size = [3, 3, 3] }\nposition = [2, 1, 0]\ndensity = 0.001\n'
    mounted = ROBOT + 'position = [0.5, 0.2, 0]\nrotation_deg = [0, 0, 10]\n' + RIDER.replace('body = "robot"\n', 'body = "robot"\nposition = [0, 0, 0]\n')
    fixed = '[[sensors]]\nname = "urg"\nmodel = "urg-04lx"\nposition = [0.5, 0.2, 0]\nrotation_deg = [0, 0, 10]\n'
    for model in ("formsma2011", "physical"):
        on_body = create_sensor(scene_of(tmp_path, base + mounted, model), "urg").scans([0.1, 0.2, 0.3])
        alone = create_sensor(scene_of(tmp_path, base + fixed, model), "urg").scans([0.1, 0.2, 0.3])
        for a, b in zip(on_body, alone):
            np.testing.assert_array_equal(a.values, b.values)


def test_a_solid_on_a_moving_body_is_met_where_the_body_is_and_the_nearer_surface_wins(tmp_path: Path) -> None:
    door = (
        '[[bodies]]\nname = "door"\ntrajectory = { keyframes = [[0, 2, -3, 0], [1, 2, 0, 0], [2, 4, 0, 0], [3, 6, 0, 0]] }\n'
        '[[objects]]\nname = "panel"\nbody = "door"\nbox = { size = [0.1, 1, 2] }\nposition = [0.05, 0, 0]\n'
    )
    text = door + WALL + '[[sensors]]\nname = "urg"\nmodel = "urg-04lx"\n'
    # step 384 is measured 384 steps (37.5 ms) before the scan completes: the door is where it was then
    expected = [5000, 2000, round(1000 * (2 + 2 * (1.5 - 0.0375 - 1))), 5000]  # clear, door, door, door behind the wall
    for model, tolerance_mm in (("formsma2011", 0), ("physical", 40)):  # physical: the datasheet's range noise
        sensor = create_sensor(scene_of(tmp_path, text, model), "urg")
        ahead = [int(scan.values[384]) for scan in sensor.scans([0.0, 1.0, 1.5, 3.5])]
        assert ahead == pytest.approx(expected, abs=tolerance_mm)
        assert ahead == [int(sensor.scan(t).values[384]) for t in (0.0, 1.0, 1.5, 3.5)]  # batched = one at a time


def pole_centres(values: np.ndarray, near_mm: int) -> list[float]:
    """Mean step of each run of steps whose value is below `near_mm` (a pole in front of the far wall)."""
    steps = np.flatnonzero((values >= 20) & (values < near_mm))
    runs = np.split(steps, np.flatnonzero(np.diff(steps) > 1) + 1)
    return [float(run.mean()) for run in runs if len(run)]


def test_a_turning_body_skews_its_scan_by_omega_times_the_time_between_the_beams(tmp_path: Path) -> None:
    """Poles at bearings −45° and +45°: turning at ω (counter-clockwise, as the steps sweep), the beam
    that sees the second pole is fired Δt later, when the sensor has turned ω·Δt further, so the poles'
    apparent separation shrinks by ω·Δt (Δt = steps between them × 100 ms / 1024)."""
    poles = "".join(
        f'[[objects]]\nname = "pole{i}"\ncylinder = {{ radius = 0.02, height = 2 }}\n'
        f"position = [{2 * math.cos(math.radians(b)):.9f}, {2 * math.sin(math.radians(b)):.9f}, 0]\n"
        for i, b in enumerate((-45.0, 45.0))
    )
    room = '[[objects]]\nname = "room"\ncylinder = { radius = 4, height = 2 }\nmaterial = "default"\n'
    omega_deg_s = 180.0
    rows = ", ".join(f"[{t / 10}, 0, 0, {omega_deg_s * t / 10}]" for t in range(0, 101))  # 18° apart: no arc is ambiguous
    turning = f"trajectory = {{ keyframes = [{rows}] }}\n"
    step_deg = 360.0 / 1024
    separations = {}
    for name, trajectory in (("still", "trajectory = { keyframes = [[0, 0, 0, 0]] }\n"), ("turning", turning)):
        scene = scene_of(tmp_path, ROBOT + trajectory + RIDER + poles + room)
        scan = create_sensor(scene, "urg").scan(4.0)  # turned 720°: facing ahead again as the scan completes
        first, second = pole_centres(scan.values, 3000)
        separations[name] = (second - first) * step_deg
    assert separations["still"] == pytest.approx(90.0, abs=0.5 * step_deg)
    beams_apart = separations["turning"] / step_deg
    delta_t = beams_apart * urg04lx.PERIOD_S / urg04lx.STEPS_PER_REVOLUTION
    predicted = separations["still"] - omega_deg_s * delta_t  # 180°/s × ~24.4 ms ≈ 4.4°
    assert separations["still"] - separations["turning"] > 4.0
    assert separations["turning"] == pytest.approx(predicted, abs=step_deg)


def test_lms200_interlaced_beams_are_measured_a_revolution_apart(tmp_path: Path) -> None:
    """At 0.5° the integer angles come from the first mirror revolution, the half degrees from the second
    (telegram listing §10.10.2): driving at 10 m/s toward a wall, a half-degree beam sees the wall
    nearer by about 10 m/s × 13.3 ms than its integer-degree neighbour."""
    speed = 10.0
    text = (
        ROBOT + f"trajectory = {{ keyframes = [[0, 0, 0, 0], [0.4, {0.4 * speed}, 0, 0]] }}\n"
        + '[[sensors]]\nname = "lms"\nmodel = "lms200"\nbody = "robot"\n'
        + '[[objects]]\nname = "wall"\nbox = { size = [0.2, 40, 3] }\nposition = [10.1, 0, 0]\n'
    )
    sensor = create_sensor(scene_of(tmp_path, text), "lms")
    scan = sensor.scan(0.3, start_deg=0.0, step_deg=0.5, count=361)
    ahead_integer, ahead_half = int(scan.values[180]), int(scan.values[181])  # 90°, 90.5°
    expected_mm = speed * lms200.PERIOD_S * (1 - 0.5 / 360) * 1000.0
    assert ahead_integer - ahead_half == pytest.approx(expected_mm, abs=2.0)
    offsets = beam_times_s(scan)[[180, 181]] - scan.time_s
    np.testing.assert_allclose(offsets, [-lms200.PERIOD_S * 1.25, -lms200.PERIOD_S * (0.25 - 0.5 / 360)])
    window = sensor.scan(0.3, start_deg=40.0, step_deg=0.25, count=401)  # 100° at 0.25°: four revolutions
    revolution = np.rint((beam_times_s(window) - 0.3) / lms200.PERIOD_S + 0.5 - (window.angles_rad + np.pi / 2) / (2 * np.pi))
    np.testing.assert_array_equal(revolution[:8], [-3, -2, -1, 0, -3, -2, -1, 0])


def test_physical_batches_of_a_moving_sensor_equal_its_scans_one_at_a_time(tmp_path: Path) -> None:
    text = (
        ROBOT + "trajectory = { keyframes = [[0, 0, 0, 0], [4, 2, 1, 120]] }\n" + RIDER + WALL
        + '[[sensors]]\nname = "lms"\nmodel = "lms200"\nbody = "robot"\nposition = [0.1, 0, 0.2]\n'
        + '[[smoke.plumes]]\nname = "fire"\nsource = [2.5, 0, 0]\nrate = 20\nlifetime = 5\nsize = 0.3\ndensity = 0.01\n'
    )
    scene = scene_of(tmp_path, text, "physical")
    for name in ("urg", "lms"):
        sensor = create_sensor(scene, name)
        times = [1.0 + k * sensor.configured_period_s for k in range(4)]
        batched = sensor.scans(times) if name == "urg" else sensor.scans(times, **lms200.configured_window(scene.sensor(name).options))
        for time_s, scan in zip(times, batched):
            np.testing.assert_array_equal(scan.values, sensor.configured_scan(time_s).values)
        assert not np.array_equal(batched[0].values, batched[-1].values)  # it does move


# --------------------------------------------------------------------------- ground truth


def lrf(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "emulator.cli", *args], capture_output=True, text=True, cwd=cwd, timeout=120)


def test_scan_json_gives_the_pose_at_its_time_stamp_and_each_beams_instant(tmp_path: Path) -> None:
    write(tmp_path, ROBOT + "trajectory = { keyframes = [[0, 0, 0, 0], [2, 2, 0, 90]] }\n"
          + RIDER.replace('body = "robot"\n', 'body = "robot"\nposition = [0.5, 0, 0.3]\n') + WALL)
    result = lrf("scan", "x.toml", "--sensor", "urg", "--time", "1", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    out = json.loads(result.stdout)
    # the body at (1, 0) turned 45°: the sensor 0.5 m ahead of it along 45°
    half = math.sqrt(0.5) * 0.5
    assert out["pose"]["position"] == pytest.approx([1 + half, half, 0.3])
    assert out["pose"]["rotation_deg"] == pytest.approx([0, 0, 45])
    assert out["pose"]["quaternion"] == pytest.approx([0, 0, math.sin(math.radians(22.5)), math.cos(math.radians(22.5))])
    # steps 44..725 of a scan completed by step 768 at t = 1 s, 100 ms per 1024 steps
    assert out["times_s"][-1] == pytest.approx(1 - 43 * 0.1 / 1024, abs=1e-9)
    assert out["times_s"][0] == pytest.approx(1 - 724 * 0.1 / 1024, abs=1e-9)


def test_record_writes_the_ground_truth_beside_the_log(tmp_path: Path) -> None:
    write(tmp_path, ROBOT + "trajectory = { keyframes = [[0, 0, 0, 0], [2, 2, 0, 90]] }\n" + RIDER + WALL)
    result = lrf("record", "x.toml", "--sensor", "urg", "--start", "0.5", "--end", "1.5", "--out", "run.log", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    rows = [line.split() for line in (tmp_path / "run.log.tum").read_text().splitlines() if not line.startswith("#")]
    log_lines = [line for line in (tmp_path / "run.log").read_text().splitlines() if line and not line.startswith("#")]
    assert len(rows) == 11 == len(log_lines)
    truth = np.array(rows, dtype=float)
    np.testing.assert_allclose(truth[:, 0], np.arange(5, 16) / 10)
    np.testing.assert_allclose(truth[:, 1], truth[:, 0], atol=1e-9)  # x = t on this leg
    yaw = np.degrees(2 * np.arctan2(truth[:, 6], truth[:, 7]))
    np.testing.assert_allclose(yaw, 45 * truth[:, 0], atol=1e-6)
    # the file reads back as a trajectory
    text = ROBOT + 'trajectory = { file = "run.log.tum" }\n' + RIDER
    frames = World(load_scene(write(tmp_path, text, "y.toml"))).bodies.frames("robot", np.array([1.0]))
    assert frames.positions[0] == pytest.approx([1.0, 0.0, 0.0])


def test_the_shortcut_for_a_body_at_rest_between_movements_gives_the_interpolated_poses() -> None:
    """A scan's instants where the body stands still take one pose for all; everywhere else the
    general path runs: both must agree at every window of instants, jumps and holds included."""
    from emulator.scene.bodies import Keyframes, keyframe_frames

    rows = np.array([[0, 0, 0], [1, 0, 0], [2, 0, 30], [3, 0, 30], [3, 1, 60], [4, 1, 60], [5, 1, 60], [6, 2, 90]], dtype=float)
    keyframes = Keyframes(
        rows[:, 0], np.column_stack([rows[:, 1], np.zeros((len(rows), 2))]), euler_quaternion(np.column_stack([np.zeros((len(rows), 2)), rows[:, 2]]))
    )
    rng = np.random.default_rng(12)
    for _ in range(400):
        start = rng.uniform(-1.0, 7.0)
        times = start + np.sort(rng.uniform(0.0, rng.choice([0.0, 0.05, 0.5, 2.0]), 50))
        if rng.random() < 0.2:
            times = np.full(5, float(rng.choice(rows[:, 0])))
        fast = keyframe_frames(keyframes, times)
        slow = [keyframe_frames(keyframes, np.array([t, t + 100.0])) for t in times]  # a span that never stands still
        np.testing.assert_allclose(fast.positions, [frames.positions[0] for frames in slow], atol=1e-12)
        np.testing.assert_allclose(fast.rotations, [frames.rotations[0] for frames in slow], atol=1e-12)


def _product_table_matrices(quaternions: np.ndarray) -> np.ndarray:
    """Rotation matrices as a sum over the 16 products q_i q_j weighted by a table (the former way)."""
    table = np.zeros((16, 9))
    terms = (
        ((1, 1, -2), (2, 2, -2)), ((0, 1, 2), (2, 3, -2)), ((0, 2, 2), (1, 3, 2)),
        ((0, 1, 2), (2, 3, 2)), ((0, 0, -2), (2, 2, -2)), ((1, 2, 2), (0, 3, -2)),
        ((0, 2, 2), (1, 3, -2)), ((1, 2, 2), (0, 3, 2)), ((0, 0, -2), (1, 1, -2)),
    )
    for row, pair in enumerate(terms):
        for i, j, weight in pair:
            table[4 * i + j, row] += weight
    products = (quaternions[..., :, None] * quaternions[..., None, :]).reshape(*quaternions.shape[:-1], 16)
    return (np.einsum("...i,ij->...j", products, table) + np.eye(3).reshape(9)).reshape(*quaternions.shape[:-1], 3, 3)


def test_rotation_matrices_keep_their_bits_whatever_else_is_computed_with_them() -> None:
    """quaternion_matrix works entry by entry: the same bits as the product table, alone or among
    thousands, signed zeros included (a scan's poses must not depend on its batch)."""
    from emulator.scene.bodies import quaternion_matrix

    rng = np.random.default_rng(3)
    quaternions = rng.normal(size=(5000, 4))
    quaternions[:1000] /= np.linalg.norm(quaternions[:1000], axis=1, keepdims=True)
    quaternions[1000:2000][rng.random((1000, 4)) < 0.3] = 0.0
    quaternions[2000:3000][rng.random((1000, 4)) < 0.3] = -0.0
    quaternions[3000:3100, :3] = 0.0  # about no axis at all
    together = quaternion_matrix(quaternions)
    assert together.shape == (5000, 3, 3)
    np.testing.assert_array_equal(together.view(np.int64), _product_table_matrices(quaternions).view(np.int64))
    for index in (0, 1500, 2500, 3050, 4999):
        np.testing.assert_array_equal(quaternion_matrix(quaternions[index]).view(np.int64), together[index].view(np.int64))
    np.testing.assert_array_equal(quaternion_matrix(quaternions[:7].reshape(7, 1, 4)).reshape(7, 3, 3), together[:7])


def test_keyframe_poses_interpolated_from_kept_segments_have_the_bits_of_interpolating_each_instant() -> None:
    """Each keyframe segment's arc is computed once; every pose must equal slerping the instant's two
    rows afresh, bit for bit (a pose's bits feed every beam's range)."""
    from emulator.scene.bodies import Keyframes, keyframe_frames, quaternion_matrix, slerp

    rng = np.random.default_rng(8)
    times = np.sort(np.concatenate([rng.uniform(0, 10, 30), [0.0, 0.0, 2.0, 2.0, 10.0]]))
    keyframes = Keyframes(times, rng.normal(size=(len(times), 3)), euler_quaternion(rng.uniform(-180, 180, (len(times), 3))))
    instants = np.concatenate([rng.uniform(-1, 11, 3000), times])
    frames = keyframe_frames(keyframes, instants)
    after = np.searchsorted(times, instants, side="right") - 1
    start = np.clip(after, 0, len(times) - 1)
    end = np.minimum(start + 1, len(times) - 1)
    span = times[end] - times[start]
    with np.errstate(divide="ignore", invalid="ignore"):
        fraction = np.clip(np.where(after < 0, 0.0, np.where(span > 0, (instants - times[start]) / span, 0.0)), 0.0, 1.0)
    exact = ((fraction == 0.0) | keyframes.still_after[start])[:, None]
    p0, q0 = keyframes.positions[start], keyframes.quaternions[start]
    positions = np.where(exact, p0, p0 + fraction[:, None] * (keyframes.positions[end] - p0))
    rotations = quaternion_matrix(np.where(exact, q0, slerp(q0, keyframes.quaternions[end], fraction)))
    np.testing.assert_array_equal(frames.positions, positions)
    np.testing.assert_array_equal(frames.rotations, rotations)


def test_only_beams_that_pass_near_a_moving_body_are_cast_at_it_and_every_hit_is_still_found(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The sphere around a body's origin that bounds its objects picks the beams cast in its frame;
    the hits must be those of casting every beam, grazing and end-on beams included."""
    import emulator.optics.moving as moving

    door = (
        '[[bodies]]\nname = "door"\nposition = [3, 1, 0]\n'
        "trajectory = { keyframes = [[0, 3, 1, 0, 0, 0, 0], [1, 3, 1, 0.5, 10, 0, 90], [2, 2, 2, 0, 0, 20, 200]] }\n"
        '[[objects]]\nname = "panel"\nbody = "door"\nbox = { size = [0.05, 1.2, 2] }\nposition = [0.6, 0, 1]\n'
        '[[objects]]\nname = "knob"\nbody = "door"\nsphere = { radius = 0.05 }\nposition = [1.1, 0.1, 1]\n'
    )
    world = World(scene_of(tmp_path, door + WALL + RIDER.replace('body = "robot"\n', "")))
    rng = np.random.default_rng(4)
    count = 20000
    origins = rng.uniform([-2, -3, -1], [8, 5, 3], (count, 3))
    targets = np.array([3.6, 1.0, 1.0]) + rng.normal(size=(count, 3)) * rng.choice([0.01, 0.3, 1.5], (count, 1))
    directions = targets - origins
    directions[: count // 4, 2] = 0.0  # level beams, as a scanner's
    directions /= np.linalg.norm(directions, axis=1)[:, None]
    times = rng.choice([0.0, 0.5, 1.0, 1.7, 3.0], count) + rng.uniform(0, 0.01, count)
    picked = world.solids(origins, directions, 8.0, 0.0, times)
    assert np.sum(picked.object_index == 0) > 1000 and np.sum(picked.object_index == 1) >= 5  # panel and knob met
    monkeypatch.setattr(moving, "_passing_within", lambda centers, radius, o, d, length: np.ones(len(o), dtype=bool))
    every = world.solids(origins, directions, 8.0, 0.0, times)
    for name in ("range_m", "object_index", "reflectivity", "cos_incidence"):
        np.testing.assert_array_equal(getattr(picked, name), getattr(every, name), err_msg=name)


def test_a_mounted_frame_has_the_bits_of_mounting_at_each_instant_alone() -> None:
    """`Frames.then` composes all instants in one product: each must equal its own 3x3 product."""
    from emulator.scene.bodies import Frames, quaternion_matrix

    rng = np.random.default_rng(9)
    local = Pose((0.05, -0.13, 0.55), (3.0, -7.0, 110.0))
    position, rotation = np.asarray(local.position), local.rotation_matrix()
    for count in (1, 2, 3, 7, 361, 2888):
        rotations = quaternion_matrix(rng.normal(size=(count, 4)) / 2.0)
        origins = rng.normal(size=(count, 3))
        frames = Frames(origins, rotations).then(local)
        for index in range(0, count, max(1, count // 50)):
            np.testing.assert_array_equal(frames.positions[index], origins[index] + rotations[index] @ position)
            np.testing.assert_array_equal(frames.rotations[index], rotations[index] @ rotation)
    still = Frames(np.broadcast_to([1.0, 2.0, 0.0], (5, 3)), np.broadcast_to(quaternion_matrix(np.array([0.0, 0.0, 0.6, 0.8])), (5, 3, 3))).then(local)
    np.testing.assert_array_equal(still.rotations, np.broadcast_to(still.rotations[0], (5, 3, 3)))
