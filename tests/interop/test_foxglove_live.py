"""Foxglove live and the session's MCAP, from the real `serve` process.

A Python client speaking Foxglove's WebSocket protocol (subprotocol
`foxglove.sdk.v1`, as foxglove-sdk names the ws-protocol's v1: the server
advertises its channels, the client subscribes, binary MessageData frames follow) receives `foxglove.LaserScan`
messages and decodes them with the schema the server advertised. The MCAP
written by `serve --mcap` is read back with the `mcap` reader; its scans
equal `lrf-emulator scan` at their instants.
"""

from __future__ import annotations

import base64
import json
import struct
import subprocess
import sys
from pathlib import Path

import numpy as np
from mcap.reader import make_reader
from mcap.records import Schema
from mcap_protobuf.decoder import DecoderFactory as ProtobufDecoderFactory
from websockets.sync.client import connect

CLI = [sys.executable, "-m", "emulator.cli"]
SUBPROTOCOL = "foxglove.sdk.v1"  # foxglove-sdk's name for the ws-protocol (formerly foxglove.websocket.v1)
MESSAGE_DATA = 0x01


def receive_json(websocket, op: str) -> dict:
    for _ in range(50):
        frame = websocket.recv(timeout=10)
        if isinstance(frame, str) and json.loads(frame).get("op") == op:
            return json.loads(frame)
    raise AssertionError(f"no {op} message")


def laser_scans_over_websocket(url: str, topic: str, count: int) -> list:
    """Subscribe to `topic` and decode `count` LaserScan messages with the advertised schema."""
    with connect(url, subprotocols=[SUBPROTOCOL], open_timeout=10) as websocket:
        assert websocket.subprotocol == SUBPROTOCOL
        advertised = receive_json(websocket, "advertise")["channels"]
        channel = next(channel for channel in advertised if channel["topic"] == topic)
        assert (channel["schemaName"], channel["encoding"]) == ("foxglove.LaserScan", "protobuf")
        schema = Schema(id=1, name=channel["schemaName"], encoding="protobuf", data=base64.b64decode(channel["schema"]))
        decode = ProtobufDecoderFactory().decoder_for("protobuf", schema)
        websocket.send(json.dumps({"op": "subscribe", "subscriptions": [{"id": 7, "channelId": channel["id"]}]}))
        scans = []
        while len(scans) < count:
            frame = websocket.recv(timeout=10)
            if isinstance(frame, bytes) and frame[0] == MESSAGE_DATA:
                subscription, _log_time = struct.unpack_from("<IQ", frame, 1)
                assert subscription == 7
                scans.append(decode(frame[13:]))
        return scans


def scan_json(sensor: str, time_s: float) -> dict:
    result = subprocess.run([*CLI, "scan", "railway", "--sensor", sensor, "--time", repr(time_s)],
                            capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    return json.loads(result.stdout)


def assert_ranges_match_scan(ranges: list[float], reference: dict) -> None:
    ranges = np.asarray(ranges)
    expected = np.array([np.nan if r is None else r for r in reference["ranges_m"]])
    finite = ~np.isnan(expected)
    assert np.allclose(ranges[finite], expected[finite], atol=1e-6)
    assert not np.any(np.isfinite(ranges[~finite]))


def test_foxglove_client_receives_laser_scans_and_the_session_is_recorded(serve, tmp_path: Path, tcp_port: int) -> None:
    recording = tmp_path / "session.mcap"
    daemon = serve("railway", f"urg=tcp:127.0.0.1:{tcp_port}", f"lms=pty:{tmp_path / 'lms'}",
                   extra_args=("--foxglove", "127.0.0.1:0", "--mcap", str(recording)))
    url = daemon.service("foxglove")
    assert url.startswith("ws://127.0.0.1:")
    scans = laser_scans_over_websocket(url, "/urg/scan", 3)
    assert all(scan.frame_id == "urg" and len(scan.ranges) == 682 for scan in scans)  # steps 44..725
    stamps = [scan.timestamp.seconds + scan.timestamp.nanos * 1e-9 for scan in scans]
    assert stamps == sorted(stamps) and len(set(stamps)) == 3
    assert_ranges_match_scan(list(scans[-1].ranges), scan_json("urg", round(stamps[-1], 6)))
    assert daemon.stop() == 0
    with recording.open("rb") as file:
        reader = make_reader(file, decoder_factories=[ProtobufDecoderFactory()])
        summary = reader.get_summary()
        counts = {channel.topic: summary.statistics.channel_message_counts.get(channel.id, 0)
                  for channel in summary.channels.values()}
        assert set(counts) == {"/urg/scan", "/urg/values", "/lms/scan", "/lms/values", "/tf", "/scene"}
        assert counts["/urg/scan"] == counts["/urg/values"] >= 3 and counts["/lms/scan"] >= 3 and counts["/tf"] >= 3
        last = None
        for _, _, message, decoded in reader.iter_decoded_messages(topics=["/lms/scan"]):
            last = (message.log_time / 1e9, decoded)
    time_s, decoded = last
    assert_ranges_match_scan(list(decoded.ranges), scan_json("lms", round(time_s, 6)))
