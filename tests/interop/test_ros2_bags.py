"""A ROS 2 bag in MCAP (sensor_msgs/msg/LaserScan in CDR, written here with mcap-ros2-support,
as a real robot's bag holds it) becomes a virtual device: resampled onto the device's beams,
metres turned into device values, and served by the real `replay` to an unmodified client."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pytest
from hokuyolx import HokuyoLX
from mcap_ros2.writer import Writer as Ros2Writer
from test_replay_clients import replaying

from emulator.recording.laserscan import ranges_to_values
from emulator.recording.mcap_replay import LaserScanReplay, read_laser_scans
from emulator.sensors import lms200, urg04lx

ROS2_LASERSCAN = """std_msgs/Header header
float32 angle_min
float32 angle_max
float32 angle_increment
float32 time_increment
float32 scan_time
float32 range_min
float32 range_max
float32[] ranges
float32[] intensities
================================================================================
MSG: std_msgs/Header
builtin_interfaces/Time stamp
string frame_id
================================================================================
MSG: builtin_interfaces/Time
int32 sec
uint32 nanosec
"""


def write_ros2_bag(path: Path, rows: list[list[float]], angle_min: float, increment: float) -> None:
    with path.open("wb") as file:
        writer = Ros2Writer(file)
        schema = writer.register_msgdef("sensor_msgs/msg/LaserScan", ROS2_LASERSCAN)
        for index, ranges in enumerate(rows):
            stamp = 1_700_000_000 + index * 0.1
            message = {
                "header": {"stamp": {"sec": int(stamp), "nanosec": int(round((stamp % 1) * 1e9))}, "frame_id": "laser"},
                "angle_min": angle_min, "angle_max": angle_min + increment * (len(ranges) - 1),
                "angle_increment": increment, "time_increment": 0.0, "scan_time": 0.1,
                "range_min": 0.05, "range_max": 30.0, "ranges": ranges, "intensities": [],
            }
            writer.write_message("/scan", schema, message, log_time=int(stamp * 1e9) + 5, publish_time=int(stamp * 1e9))
        writer.finish()


def test_a_ros2_laserscan_bag_becomes_urg_and_lms_values(tmp_path: Path) -> None:
    bag = tmp_path / "bag.mcap"
    increment = np.radians(1.0)
    rows = [[1.0 + 0.01 * beam + row for beam in range(181)] for row in range(3)]
    rows[1][90] = float("nan")  # an invalid reading
    rows[2][90] = float("inf")  # nothing in range
    rows[2][91] = 0.01  # under range_min
    rows[2][92] = 45.0  # over range_max
    write_ros2_bag(bag, rows, -np.pi / 2, increment)
    scans = read_laser_scans(bag, "/scan")
    assert scans.times_s.tolist() == pytest.approx([0.0, 0.1, 0.2])
    lms = LaserScanReplay(scans, lms200.MODEL, "lms")
    first = lms.scan(0.0, start_deg=0.0, step_deg=1.0, count=181, unit="mm").values
    assert first.tolist() == [round((1.0 + 0.01 * beam) * 1000) for beam in range(181)]
    half = lms.scan(0.0, start_deg=0.0, step_deg=0.5, count=361, unit="cm").values
    assert half[:3].tolist() == [100, 101, 101]  # a 0.5° beam halfway between two recorded ones takes the next
    assert lms.scan(0.1, start_deg=90.0, step_deg=1.0, count=1, unit="mm").values.tolist() == [8187]
    assert lms.scan(0.2, start_deg=90.0, step_deg=1.0, count=3, unit="mm").values.tolist() == [8191, 0, 8191]
    urg = LaserScanReplay(scans, urg04lx.MODEL, "urg").scan(0.0).values
    front = urg04lx.FRONT_STEP
    assert urg[front] == 1900  # 0 rad is the bag's beam 90
    assert urg[front + 256] == 2800  # 2π/1024 · 256 = 90° left: the bag's last beam
    assert urg[0] == 0  # -135°: outside the bag's ±90°, no echo
    assert urg[front - 300] == 0


def test_hokuyolx_gets_a_ros2_bag_as_urg_values(tmp_path: Path, tcp_port: int) -> None:
    """Through SCIP: metres become millimetres, NaN the smoke code 1, +inf no echo 0, under range_min 19."""
    bag = tmp_path / "robot.mcap"
    step = 2 * np.pi / 1024
    rows = []
    for row in range(4):
        ranges = 1.0 + 0.002 * np.arange(682) + 0.5 * row
        ranges[300], ranges[301], ranges[302] = np.nan, np.inf, 0.01
        rows.append(ranges.tolist())
    write_ros2_bag(bag, rows, (44 - 384) * step, step)
    expected = [ranges_to_values(np.array(ranges, dtype=np.float32), "urg-04lx", "mm", 0.05, 30.0) for ranges in rows]
    assert [int(v) for v in expected[0][300:303]] == [1, 0, 19]
    with replaying(bag, "urg-04lx", f"tcp:127.0.0.1:{tcp_port}", tmp_path, "--topic", "/scan") as ready:
        laser = HokuyoLX(addr=ready.address, tsync=False, convert_time=False)
        try:
            seen = set()
            for _ in range(6):
                timestamp_ms, values = laser.get_dist()
                row = (timestamp_ms // 100) % len(rows)
                assert np.array_equal(values, expected[row]), f"row {row}"
                seen.add(row)
                time.sleep(0.15)
        finally:
            laser.close()
    assert len(seen) >= 3
