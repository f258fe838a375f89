"""MCAP: `record --format mcap` read back with the `mcap` reader, the ±inf/NaN conventions,
and a foxglove.LaserScan topic in JSON turned back into device values (ROS 2 bags:
tests/interop/test_ros2_bags.py)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap.writer import Writer
from mcap_protobuf.decoder import DecoderFactory as ProtobufDecoderFactory

from emulator.errors import UserError
from emulator.recording.laserscan import ranges_to_values, values_to_ranges
from emulator.recording.mcap_replay import read_laser_scans
from emulator.sensors import lms200, urg04lx

CLI = [sys.executable, "-m", "emulator.cli"]


def run_cli(*args: str) -> str:
    result = subprocess.run([*CLI, *args], capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    return result.stdout


def scan_json(sensor: str, time_s: float) -> dict:
    return json.loads(run_cli("scan", "railway", "--sensor", sensor, "--time", repr(time_s)))


@pytest.mark.parametrize("sensor", ["urg", "lms"])
def test_record_mcap_holds_the_scans_of_scan_with_their_wire_values(tmp_path: Path, sensor: str) -> None:
    out = tmp_path / "railway.mcap"
    run_cli("record", "railway", "--sensor", sensor, "--start", "9.9", "--end", "10.5", "--out", str(out), "--format", "mcap")
    with out.open("rb") as file:
        reader = make_reader(file, decoder_factories=[ProtobufDecoderFactory()])
        summary = reader.get_summary()
        channels = {channel.topic: channel for channel in summary.channels.values()}
        schemas = {topic: summary.schemas[channel.schema_id] for topic, channel in channels.items()}
        counts = {topic: summary.statistics.channel_message_counts[channel.id] for topic, channel in channels.items()}
        assert {topic: schema.name for topic, schema in schemas.items()} == {
            f"/{sensor}/scan": "foxglove.LaserScan", f"/{sensor}/values": "lrf.DeviceValues",
            "/tf": "foxglove.FrameTransforms", "/scene": "foxglove.SceneUpdate",
        }
        assert schemas[f"/{sensor}/scan"].encoding == "protobuf" and channels[f"/{sensor}/values"].message_encoding == "json"
        scans = list(reader.iter_decoded_messages(topics=[f"/{sensor}/scan"]))
        values = [json.loads(message.data) for _, _, message, in reader.iter_messages(topics=[f"/{sensor}/values"])]
    period = 0.1 if sensor == "urg" else 2 / 75
    expected_count = len([k for k in range(0, 1000) if 9.9 - 1e-9 <= k * period <= 10.5 + 1e-9])
    assert counts[f"/{sensor}/scan"] == counts[f"/{sensor}/values"] == counts["/tf"] == expected_count
    assert counts["/scene"] >= 2  # the solids, then smoke and plumes
    # the scan at 10.0 s, as `scan` gives it
    times = [message.log_time / 1e9 for _, _, message, _ in scans]
    row = int(np.argmin(np.abs(np.array(times) - 10.0)))
    reference = scan_json(sensor, times[row])
    decoded = scans[row][3]
    assert values[row]["values"] == reference["values"]
    assert values[row]["unit"] == reference["unit"] and values[row]["model"] == reference["model"]
    ranges = np.array(decoded.ranges)
    expected = np.array([np.nan if r is None else r for r in reference["ranges_m"]])
    finite = ~np.isnan(expected)
    assert np.allclose(ranges[finite], expected[finite], atol=1e-6)  # float32 on the wire
    assert not np.any(np.isfinite(ranges[~finite]))  # every error code is non-finite
    assert decoded.frame_id == sensor
    assert decoded.start_angle == pytest.approx(np.radians(reference["angles_deg"][0]))
    assert decoded.end_angle == pytest.approx(np.radians(reference["angles_deg"][-1]))
    assert decoded.timestamp.seconds + decoded.timestamp.nanos * 1e-9 == pytest.approx(times[row])


def test_error_codes_become_inf_or_nan_and_come_back() -> None:
    urg = np.array([0, 1, 7, 19, 20, 2500, 5600])
    ranges = values_to_ranges(urg, urg04lx.MODEL)
    assert ranges[0] == np.inf and ranges[3] == -np.inf and np.isnan(ranges[1]) and np.isnan(ranges[2])
    assert ranges[4:].tolist() == [0.02, 2.5, 5.6]
    assert ranges_to_values(ranges, urg04lx.MODEL).tolist() == [0, 1, 1, 19, 20, 2500, 5600]
    lms = np.array([8191, 8183, 8190, 0, 1234])
    ranges = values_to_ranges(lms, lms200.MODEL, "cm")
    assert ranges[:2].tolist() == [np.inf, np.inf] and np.isnan(ranges[2]) and ranges[4] == 12.34
    assert ranges_to_values(ranges, lms200.MODEL, "cm").tolist() == [8191, 8191, 8187, 0, 1234]
    # too far for the device's mode: "no echo" for the URG, "above maximum" for the LMS200 in mm
    assert ranges_to_values(np.array([7.0]), urg04lx.MODEL).tolist() == [0]
    assert ranges_to_values(np.array([9.0]), lms200.MODEL, "mm").tolist() == [8183]
    assert ranges_to_values(np.array([9.0]), lms200.MODEL, "cm").tolist() == [900]


def test_foxglove_json_laserscan_and_hostile_files(tmp_path: Path) -> None:
    path = tmp_path / "json.mcap"
    with path.open("wb") as file:
        writer = Writer(file)
        writer.start()
        schema = writer.register_schema("foxglove.LaserScan", "jsonschema", b"{}")
        channel = writer.register_channel("/front", "json", schema)
        for index in range(2):
            body = {"timestamp": {"sec": 5 + index, "nsec": 0}, "frame_id": "front",
                    "start_angle": -0.1, "end_angle": 0.1, "ranges": [2.0, 2.5, None if index else 3.0]}
            writer.add_message(channel, log_time=index, data=json.dumps(body).encode(), publish_time=index)
        writer.finish()
    scans = read_laser_scans(path, None)
    assert scans.times_s.tolist() == [0.0, 1.0] and scans.steps_rad[0] == pytest.approx(0.1)
    with pytest.raises(UserError, match="not a LaserScan topic"):
        read_laser_scans(path, "/nope")
    broken = tmp_path / "broken.mcap"
    broken.write_bytes(path.read_bytes()[:200])
    with pytest.raises(UserError, match="broken.mcap"):
        read_laser_scans(broken, "/front")


def test_record_mcap_holds_a_multi_echo_units_intensities_and_echoes(tmp_path: Path) -> None:
    """rescue's UTM-30LX-EW under `physical`: the LaserScan's intensities, and the wire values' echoes
    and their intensities, as `scan` gives them."""
    out = tmp_path / "rescue.mcap"
    run_cli("record", "rescue", "--sensor", "utm", "--model", "physical", "--start", "20", "--end", "20.05",
            "--out", str(out), "--format", "mcap")
    with out.open("rb") as file:
        reader = make_reader(file, decoder_factories=[ProtobufDecoderFactory()])
        decoded = [message for _, _, _, message in reader.iter_decoded_messages(topics=["/utm/scan"])]
    with out.open("rb") as file:
        values = [json.loads(message.data) for _, _, message in make_reader(file).iter_messages(topics=["/utm/values"])]
    assert len(decoded) == len(values) == 3  # 40 Hz
    reference = json.loads(run_cli("scan", "rescue", "--sensor", "utm", "--model", "physical", "--time", "20"))
    assert list(decoded[0].intensities) == [float(v) for v in reference["intensities"]]
    assert values[0]["intensities"] == reference["intensities"]
    assert values[0]["echoes"] == reference["echoes"] and values[0]["echo_intensities"] == reference["echo_intensities"]
    assert sum(row[1] >= 0 for row in values[0]["echoes"]) > 100  # the wall behind the smoke
