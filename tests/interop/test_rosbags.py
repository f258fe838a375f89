"""`record --format rosbag2|rosbag1`: bags read back by rosbags, the ROS 2 one also by the mcap reader
with mcap-ros2-support; ranges byte-identical to `lrf-emulator scan`; REP 105 frames that compose to
the scan's own pose; ground-truth odometry; `replay` serving a bag to an unmodified client."""

from __future__ import annotations

import json
import math
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml
from hokuyolx import HokuyoLX
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory as Ros2DecoderFactory
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_typestore
from test_replay_clients import replaying

from emulator.bench.cola_client import ColaClient
from emulator.recording.laserscan import ranges_to_values, values_to_ranges
from emulator.recording.rosbag import DEFAULT_EPOCH_S
from protocols.cola.framing import Dialect

CLI = [sys.executable, "-m", "emulator.cli"]
EPOCH_NS = DEFAULT_EPOCH_S * 1_000_000_000
ECHO_ROOM = """
[scene]
name = "echo-room"
model = "physical"
seed = 5
[[objects]]
name = "wall"
box = { size = [0.2, 30.0, 3.0] }
position = [3.6, 0.0, 1.0]
[[sensors]]
name = "sick"
model = "lms511"
position = [0.0, 0.0, 0.4]
endpoints = ["tcp:127.0.0.1:0"]
"""


def run(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run([*CLI, *args], cwd=cwd, capture_output=True, text=True, timeout=300)


@pytest.fixture(scope="module")
def bags(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The rescue robot's URG and LMS200 over 1 s, as a ROS 2 and a ROS 1 bag."""
    folder = tmp_path_factory.mktemp("bags")
    for fmt, out in (("rosbag2", "rescue"), ("rosbag1", "rescue.bag")):
        result = run("record", "rescue", "--sensor", "urg,lms", "--start", "2", "--end", "3", "--format", fmt, "--out", out, cwd=folder)
        assert result.returncode == 0, result.stderr
    return folder


def read_all(path: Path) -> dict[str, list[tuple[int, object]]]:
    """topic → [(log time ns, message)] read with rosbags."""
    topics: dict[str, list[tuple[int, object]]] = {}
    with AnyReader([path], default_typestore=get_typestore(Stores.ROS2_HUMBLE)) as reader:
        for connection, log_time, raw in reader.messages():
            topics.setdefault(connection.topic, []).append((log_time, reader.deserialize(raw, connection.msgtype)))
    return topics


def scan_cli(sensor: str, time_s: float, cwd: Path, scene: str = "rescue") -> dict:
    result = run("scan", scene, "--sensor", sensor, "--time", repr(time_s), cwd=cwd)
    assert result.returncode == 0, result.stderr
    return json.loads(result.stdout)


def expected_ranges(reference: dict) -> np.ndarray:
    return values_to_ranges(np.asarray(reference["values"]), reference["model"], reference["unit"]).astype(np.float32)


def test_the_ros2_bag_is_a_directory_as_ros2_bag_record_makes_it(bags: Path) -> None:
    metadata = yaml.safe_load((bags / "rescue" / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert metadata["storage_identifier"] == "mcap"
    [storage] = metadata["relative_file_paths"]
    assert (bags / "rescue" / storage).is_file()
    topics = {entry["topic_metadata"]["name"]: entry for entry in metadata["topics_with_message_count"]}
    assert {name: entry["topic_metadata"]["type"] for name, entry in topics.items()} == {
        "/tf_static": "tf2_msgs/msg/TFMessage", "/tf": "tf2_msgs/msg/TFMessage", "/odom": "nav_msgs/msg/Odometry",
        "/urg/scan": "sensor_msgs/msg/LaserScan", "/urg/values": "std_msgs/msg/Int32MultiArray",
        "/lms/scan": "sensor_msgs/msg/LaserScan", "/lms/values": "std_msgs/msg/Int32MultiArray",
    }
    assert all(entry["topic_metadata"]["serialization_format"] == "cdr" for entry in topics.values())
    assert topics["/urg/scan"]["message_count"] == 11  # t = 2.0, 2.1, ..., 3.0
    assert topics["/lms/scan"]["message_count"] == 38  # 0.5° (2/75 s) from 2.0 to 3.0
    assert "durability: 1" in topics["/tf_static"]["topic_metadata"]["offered_qos_profiles"]  # transient local: latched


def test_ranges_are_byte_identical_to_scan_and_fields_are_the_drivers(bags: Path) -> None:
    topics = read_all(bags / "rescue")
    for sensor, index in (("urg", 4), ("lms", 17)):
        log_time, message = topics[f"/{sensor}/scan"][index]
        time_s = round((log_time - EPOCH_NS) / 1e9, 6)
        reference = scan_cli(sensor, time_s, bags)
        assert np.asarray(message.ranges, dtype=np.float32).tobytes() == expected_ranges(reference).tobytes()
        assert message.header.frame_id == sensor
        stamp_ns = message.header.stamp.sec * 1_000_000_000 + message.header.stamp.nanosec
        # the first beam's instant (the LMS200's scans complete at k · 2/75 s: `scan --time` takes it to the µs)
        assert abs(stamp_ns - (EPOCH_NS + round(reference["times_s"][0] * 1e9))) <= 1000
        for field in ("angle_min", "angle_max", "angle_increment", "time_increment", "scan_time", "range_min", "range_max"):
            assert getattr(message, field) == pytest.approx(reference[field], rel=1e-6), field
        values = topics[f"/{sensor}/values"][index][1]
        assert np.asarray(values.data).tolist() == reference["values"]
    urg = topics["/urg/scan"][0][1]
    assert len(urg.ranges) == 682 and urg.angle_min == pytest.approx((44 - 384) * 2 * math.pi / 1024)


def test_the_ros2_bag_reads_with_the_mcap_reader_and_mcap_ros2_support(bags: Path) -> None:
    by_rosbags = read_all(bags / "rescue")
    [storage] = (bags / "rescue").glob("*.mcap")
    with storage.open("rb") as file:
        reader = make_reader(file, decoder_factories=[Ros2DecoderFactory()])
        decoded = [(message.log_time, ros) for _, _, message, ros in reader.iter_decoded_messages(topics=["/urg/scan"])]
    assert [time for time, _ in decoded] == [time for time, _ in by_rosbags["/urg/scan"]]
    for (_, ros), (_, theirs) in zip(decoded, by_rosbags["/urg/scan"]):
        assert np.asarray(ros.ranges, dtype=np.float32).tobytes() == np.asarray(theirs.ranges, dtype=np.float32).tobytes()
        assert (ros.angle_min, ros.header.frame_id) == (theirs.angle_min, theirs.header.frame_id)


def test_the_ros1_bag_holds_the_same_messages(bags: Path) -> None:
    ros2, ros1 = read_all(bags / "rescue"), read_all(bags / "rescue.bag")
    assert set(ros1) == set(ros2)
    for topic in ("/urg/scan", "/lms/scan"):
        assert [t for t, _ in ros1[topic]] == [t for t, _ in ros2[topic]]
        for (_, one), (_, two) in zip(ros1[topic], ros2[topic]):
            assert np.asarray(one.ranges, dtype=np.float32).tobytes() == np.asarray(two.ranges, dtype=np.float32).tobytes()
    with AnyReader([bags / "rescue.bag"]) as reader:
        digests = {c.topic: c.digest for c in reader.connections}
    assert digests["/tf"] == "94810edda583a504dfda3829e70d7eec"  # ROS 1's tf2_msgs/TFMessage md5sum
    assert digests["/urg/scan"] == "90c7ef2dc6895d81024acba2ac42f369"  # sensor_msgs/LaserScan


def _matrix(transform: object) -> np.ndarray:
    t, q = transform.transform.translation, transform.transform.rotation
    x, y, z, w = q.x, q.y, q.z, q.w
    m = np.eye(4)
    m[:3, :3] = [[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                 [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                 [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]]
    m[:3, 3] = (t.x, t.y, t.z)
    return m


def test_rep_105_frames_compose_to_the_scans_pose_and_odometry_is_the_ground_truth(bags: Path) -> None:
    topics = read_all(bags / "rescue")
    [(_, static)] = topics["/tf_static"]
    statics = {(t.header.frame_id, t.child_frame_id): _matrix(t) for t in static.transforms}
    assert set(statics) == {("map", "odom"), ("base_link", "urg"), ("base_link", "lms")}
    np.testing.assert_allclose(statics[("map", "odom")], np.eye(4))
    time_s = 2.5
    stamp = EPOCH_NS + int(time_s * 1e9)
    [dynamic] = [m for t, m in topics["/tf"] if m.transforms[0].header.stamp.sec * 10**9 + m.transforms[0].header.stamp.nanosec == stamp]
    [odom_to_base] = [t for t in dynamic.transforms if (t.header.frame_id, t.child_frame_id) == ("odom", "base_link")]
    map_to_urg = statics[("map", "odom")] @ _matrix(odom_to_base) @ statics[("base_link", "urg")]
    pose = scan_cli("urg", time_s, bags)["pose"]
    np.testing.assert_allclose(map_to_urg[:3, 3], pose["position"], atol=1e-9)
    yaw = math.degrees(math.atan2(map_to_urg[1, 0], map_to_urg[0, 0]))
    assert yaw == pytest.approx(pose["rotation_deg"][2], abs=1e-6)
    odometry = [(t, m) for t, m in topics["/odom"]]
    assert all(m.header.frame_id == "odom" and m.child_frame_id == "base_link" for _, m in odometry)
    positions = np.array([[m.pose.pose.position.x, m.pose.pose.position.y] for _, m in odometry])
    speeds = np.linalg.norm(np.diff(positions, axis=0), axis=1) / 0.02
    forward = np.array([m.twist.twist.linear.x for _, m in odometry])
    assert speeds.max() > 0.2  # the robot drives
    np.testing.assert_allclose(forward[1:-1], (speeds[1:] + speeds[:-1]) / 2, atol=0.05)  # ahead, in base_link


def test_frame_names_and_epoch_are_options(tmp_path: Path) -> None:
    result = run("record", "rescue", "--sensor", "urg", "--start", "0.5", "--end", "0.7", "--format", "rosbag2",
                 "--out", "named", "--map-frame", "world", "--odom-frame", "truth", "--base-frame", "robot",
                 "--epoch", "1700000000", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    topics = read_all(tmp_path / "named")
    [(log_time, static)] = topics["/tf_static"]
    assert {(t.header.frame_id, t.child_frame_id) for t in static.transforms} == {("world", "truth"), ("robot", "urg")}
    assert topics["/odom"][0][1].child_frame_id == "robot"
    assert topics["/urg/scan"][0][0] == 1_700_000_000_500_000_000
    again = run("record", "rescue", "--sensor", "urg", "--start", "0", "--end", "0.1", "--format", "rosbag2", "--out", "named", cwd=tmp_path)
    assert again.returncode == 2 and "exists" in again.stderr and "Traceback" not in again.stderr


def test_a_sensor_with_echoes_gets_a_multi_echo_scan(tmp_path: Path) -> None:
    (tmp_path / "room.toml").write_text(ECHO_ROOM)
    result = run("record", "room.toml", "--sensor", "sick", "--start", "0", "--end", "0.2", "--format", "rosbag1", "--out", "e.bag", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    topics = read_all(tmp_path / "e.bag")
    log_time, echoes = topics["/sick/echoes"][1]
    reference = scan_cli("sick", round((log_time - EPOCH_NS) / 1e9, 6), tmp_path, "room.toml")
    scan = topics["/sick/scan"][1][1]
    assert len(echoes.ranges) == len(scan.ranges) == len(reference["values"])
    first = np.array([e.echoes[0] if len(e.echoes) else np.inf for e in echoes.ranges], dtype=np.float32)
    assert first.tobytes() == np.asarray(scan.ranges, dtype=np.float32).tobytes()  # echo 1 is the single-echo scan
    ahead = len(scan.ranges) // 2
    assert scan.ranges[ahead] == pytest.approx(3.5, abs=0.02)  # the wall's near face
    assert echoes.angle_min == scan.angle_min == pytest.approx(math.radians(-95))


@pytest.mark.parametrize("bag", ["rescue", "rescue.bag"])
def test_replay_serves_a_bag_to_hokuyolx(bags: Path, bag: str, tcp_port: int) -> None:
    topics = read_all(bags / bag)
    recorded = [ranges_to_values(np.asarray(m.ranges, dtype=float), "urg-04lx", "mm", m.range_min, m.range_max)
                for _, m in topics["/urg/scan"]]
    with replaying(bags / bag, "urg-04lx", f"tcp:127.0.0.1:{tcp_port}", bags, "--topic", "/urg/scan") as ready:
        laser = HokuyoLX(addr=ready.address, tsync=False, convert_time=False)
        try:
            _, values = laser.get_dist()
        finally:
            laser.close()
    assert any(np.array_equal(values, row) for row in recorded)


@pytest.mark.parametrize("sensors, fmt, words", [
    ("urg,lms", "text", "records one sensor"), ("urg,urg", "rosbag2", "name each sensor once"), ("urg,nope", "rosbag1", "nope"),
])
def test_a_wrong_sensor_list_is_one_line_exit_2(tmp_path: Path, sensors: str, fmt: str, words: str) -> None:
    result = run("record", "rescue", "--sensor", sensors, "--end", "0.2", "--format", fmt, "--out", "x", cwd=tmp_path)
    assert result.returncode == 2 and words in result.stderr and "Traceback" not in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1 and not (tmp_path / "x").exists()


def test_a_velocity_driven_session_recorded_as_a_bag_carries_the_commanded_twist(tmp_path: Path) -> None:
    """rescue-live's robot driven by a twist (an event log as `serve --events` writes it): the bag's ground-truth
    odometry moves at the commanded velocity in base_link until the watchdog (0.5 s) stops it."""
    (tmp_path / "session.jsonl").write_text('{"t": 1.0, "op": "twist", "name": "robot", "vx": 0.3, "vy": 0.0, "wz": 0.5}\n')
    result = run("record", "rescue-live", "--sensor", "urg", "--start", "0.5", "--end", "2", "--format", "rosbag2",
                 "--out", "live", "--events-in", "session.jsonl", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    odometry = {round((t - EPOCH_NS) / 1e9, 2): m.twist.twist for t, m in read_all(tmp_path / "live")["/odom"]}
    driving = [twist for t, twist in odometry.items() if 1.0 < t < 1.5]
    assert len(driving) == 24
    # central differences over 40 ms of an arc: the chord is shorter than the arc by (0.02 rad)² / 24
    assert all(abs(w.linear.x - 0.3) < 1e-4 and abs(w.linear.y) < 1e-3 and abs(w.angular.z - 0.5) < 1e-6 for w in driving)
    assert all(w.linear.x == 0.0 for t, w in odometry.items() if t < 1.0 or t > 1.5)


@pytest.mark.parametrize("epoch", ["nan", "0", "-5", "1e20", "abc"])
def test_an_epoch_a_ros_time_cannot_hold_is_one_line_exit_2(tmp_path: Path, epoch: str) -> None:
    result = run("record", "rescue", "--sensor", "urg", "--end", "0.2", "--format", "rosbag1", "--out", "x.bag",
                 "--epoch", epoch, cwd=tmp_path)
    assert result.returncode == 2 and "--epoch" in result.stderr and "Traceback" not in result.stderr
    assert not (tmp_path / "x.bag").exists()


@pytest.mark.parametrize("broken", ["garbage.bag", "bad_yaml", "truncated"])
def test_a_broken_bag_is_one_line_exit_2(bags: Path, tmp_path: Path, broken: str) -> None:
    if broken == "garbage.bag":
        (tmp_path / broken).write_bytes(b"#ROSBAG V2.0\n" + bytes(range(256)) * 4)
    elif broken == "bad_yaml":
        (tmp_path / broken).mkdir()
        (tmp_path / broken / "metadata.yaml").write_text("rosbag2_bagfile_information: [unclosed\n")
    else:
        shutil.copytree(bags / "rescue", tmp_path / broken)
        [storage] = (tmp_path / broken).glob("*.mcap")
        storage.write_bytes(storage.read_bytes()[:20000])
    result = run("replay", broken, "--device", "urg-04lx", "--topic", "/urg/scan", "--endpoint", "tcp:127.0.0.1:0", cwd=tmp_path)
    assert result.returncode == 2 and "Traceback" not in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1 and f"{broken}: cannot read the bag" in result.stderr


@pytest.mark.parametrize("fmt, out, topic", [("rosbag2", "utm", "/utm/scan"), ("mcap", "utm.mcap", "/utm/scan")])
def test_replay_serves_a_recorded_utms_intensities_to_hokuyolx(tmp_path: Path, tcp_port: int, fmt: str, out: str, topic: str) -> None:
    """rescue's UTM-30LX-EW in its haze (`physical`), recorded, then replayed as a UTM-30LX-EW: hokuyolx's
    GE (range and intensity) gets a recorded scan's ranges and intensities (it got intensity 0)."""
    result = run("record", "rescue", "--sensor", "utm", "--model", "physical", "--start", "20", "--end", "20.2",
                 "--format", fmt, "--out", out, cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    recorded = [json.loads(run("scan", "rescue", "--sensor", "utm", "--model", "physical", "--time", repr(20 + k * 0.025),
                               cwd=tmp_path).stdout) for k in range(9)]
    with replaying(tmp_path / out, "utm-30lx-ew", f"tcp:127.0.0.1:{tcp_port}", tmp_path, "--topic", topic) as ready:
        laser = HokuyoLX(addr=ready.address, tsync=False, convert_time=False)
        try:
            _, scan = laser.get_intens()  # (steps, 2): range, intensity
        finally:
            laser.close()
    ranges, intensities = scan[:, 0], scan[:, 1]
    match = [reference for reference in recorded if np.array_equal(ranges, reference["values"])]
    assert match, "the ranges are none of the recorded scans'"
    assert np.array_equal(intensities, match[0]["intensities"]) and np.count_nonzero(intensities) > 500


@pytest.mark.parametrize("fmt, out", [("rosbag2", "sick"), ("mcap", "sick.mcap")])
def test_replay_serves_a_recorded_cola_units_scans_and_rssi_to_a_cola_client(tmp_path: Path, fmt: str, out: str) -> None:
    """An LMS511 recorded, then replayed as an LMS511: it powers on in the recorded scan configuration,
    and a CoLa client polling it gets a recorded scan's first echoes and their RSSI (a LaserScan topic
    could not be replayed as a CoLa SICK at all: "unknown model")."""
    scene = tmp_path / "echo-room.toml"
    scene.write_text(ECHO_ROOM)
    result = run("record", str(scene), "--sensor", "sick", "--start", "1", "--end", "1.2", "--format", fmt, "--out", out, cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    recorded = [json.loads(run("scan", str(scene), "--sensor", "sick", "--time", repr(1 + k / 25), cwd=tmp_path).stdout)
                for k in range(6)]
    with replaying(tmp_path / out, "lms511", "tcp:127.0.0.1:0", tmp_path, "--topic", "/sick/scan") as ready:
        with ColaClient(*ready.address, Dialect.ASCII) as client:
            assert client.ask(b"sRN LMPscancfg").startswith(b"sRA LMPscancfg 9C4 1 1388 ")  # 25 Hz at 0.5°, as recorded
            assert client.ask(b"sMN SetAccessMode 03 F4724744") == b"sAN SetAccessMode 1"
            assert client.ask(b"sWN LMDscandatacfg 01 00 1 1 0 00 00 0 0 0 0 +1") == b"sWA LMDscandatacfg"  # echo 1 + 16-bit RSSI
            client.send(b"sRN LMDscandata")
            polled = client.scan()
    match = [reference for reference in recorded if polled.distances == reference["values"]]
    assert match, "the distances are none of the recorded scans'"
    assert polled.channels == ["DIST1", "RSSI1"] and sum(value > 0 for value in polled.distances) > 300
    assert polled.rssi == match[0]["intensities"] and max(polled.rssi) > 0
