"""A driver-like CoLa client (emulator/bench/cola_client.py) against the real daemon over TCP.

A streamed scan equals `lrf-emulator scan` at its time stamp; the unit's
settings are one across its two endpoints (2111 and 2112 on a real unit) and
outlive connections. No maintained CoLa client exists on PyPI (pysicktim,
last released 2019, talks to a TiM561 over USB only), so the client here is
written from SICK's telegram listing, independently of the emulator's encoder.
"""

from __future__ import annotations

import http.client
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from test_replay_clients import replaying

from emulator.bench.cola_client import ColaClient
from protocols.cola.framing import Dialect

ROOM = """
[scene]
name = "cola-clients"
model = "physical"
seed = 5
[[objects]]
name = "wall"
box = {{ size = [0.2, 30.0, 3.0] }}
position = [3.6, 0.0, 1.0]
[[objects]]
name = "post"
cylinder = {{ radius = 0.1, height = 3.0 }}
position = [1.5, 1.0, 1.0]
[[sensors]]
name = "sick"
model = "{model}"
position = [0.0, 0.0, 0.4]
endpoints = ["tcp:127.0.0.1:0", "tcp:127.0.0.1:0"]
"""


def _room(folder: Path, model: str) -> Path:
    scene = folder / f"{model}.toml"
    scene.write_text(ROOM.format(model=model))
    return scene


def _scan_cli(scene: Path, time_s: float) -> list[int]:
    result = subprocess.run(
        [str(Path(sys.executable).with_name("lrf-emulator")), "scan", str(scene), "--sensor", "sick", "--time", f"{time_s:.6f}"],
        capture_output=True, text=True, timeout=120, check=True,
    )
    return json.loads(result.stdout)["values"]


def _get(url: str, path: str) -> tuple[int, dict]:
    host, port = url.split("//", 1)[1].rstrip("/").split(":")
    connection = http.client.HTTPConnection(host, int(port), timeout=10)
    try:
        connection.request("GET", path)
        response = connection.getresponse()
        return response.status, json.loads(response.read())
    finally:
        connection.close()


def test_a_streamed_cola_b_scan_equals_lrf_emulator_scan_at_its_stamp(serve, tmp_path: Path) -> None:
    scene = _room(tmp_path, "tim571")
    daemon = serve(scene)
    host, port = daemon.endpoint("sick", "tcp").address
    with ColaClient(host, port, Dialect.BINARY) as client:
        assert client.ask(b"sEN LMDscandata \x01") == b"sEA LMDscandata \x01"
        scans = [client.scan() for _ in range(4)]
    counters = [scan.scan_counter for scan in scans]
    assert np.all(np.diff(counters) >= 1), counters  # a starved daemon skips a revolution, as it should; never repeats one
    for scan in scans[-2:]:
        assert scan.channels == ["DIST1"] and len(scan.distances) == 811
        assert (scan.start_ticks, scan.step_ticks, scan.scan_frequency) == (-450000, 3333, 1500)
        assert scan.transmission_us == round(scan.scan_counter / 15 * 1e6)
        assert scan.distances == _scan_cli(scene, scan.transmission_us / 1e6)
    assert 3400 < np.median(scans[-1].distances[400:411]) < 3700  # the wall ahead, through physical noise


def test_settings_are_one_across_the_units_endpoints_and_outlive_connections(serve, tmp_path: Path) -> None:
    daemon = serve(_room(tmp_path, "lms111"))
    first, second = [ready.address for ready in daemon.ready if ready.sensor == "sick"]
    with ColaClient(*first, Dialect.ASCII) as ascii_client:
        assert ascii_client.ask(b"sMN SetAccessMode 03 F4724744") == b"sAN SetAccessMode 1"
        assert ascii_client.ask(b"sMN mLMPsetscancfg +2500 +1 +2500 -450000 +2250000") == (
            b"sAN mLMPsetscancfg 0 9C4 1 9C4 FFF92230 225510")
        assert ascii_client.ask(b"sWN LMDscandatacfg 03 00 1 0 0 00 00 0 0 0 0 +1") == b"sWA LMDscandatacfg"
    with ColaClient(*second, Dialect.BINARY) as binary_client:
        assert binary_client.ask(b"sRN LMPscancfg") == (
            b"sRA LMPscancfg \x00\x00\x09\xc4\x00\x01\x00\x00\x09\xc4\xff\xf9\x22\x30\x00\x22\x55\x10")
        assert binary_client.ask(b"sMN mSCreboot") == b"sFA \x00\x01"  # the login stayed with the first connection
        binary_client.send(b"sRN LMDscandata")
        scan = binary_client.scan()
        assert scan.channels == ["DIST1", "DIST2", "RSSI1", "RSSI2"] and len(scan.distances) == 1081


def test_a_reboot_drops_both_endpoints_clients_and_the_unit_serves_the_next_ones(serve, tmp_path: Path) -> None:
    """`mSCreboot` on one endpoint: its answer, then the unit closes that connection and the other
    endpoint's streaming one, as a real unit's network restarts; clients connecting afterwards are
    served, the saved settings restored and the scan counter from 1."""
    daemon = serve(_room(tmp_path, "lms111"))
    first, second = [ready.address for ready in daemon.ready if ready.sensor == "sick"]
    with ColaClient(*first, Dialect.ASCII) as streaming, ColaClient(*second, Dialect.ASCII) as rebooting:
        assert streaming.ask(b"sEN LMDscandata 1") == b"sEA LMDscandata 1"
        while (before := streaming.scan().scan_counter) < 30:
            pass
        assert rebooting.ask(b"sMN SetAccessMode 03 F4724744") == b"sAN SetAccessMode 1"
        assert rebooting.ask(b"sMN mSCreboot") == b"sAN mSCreboot"
        with pytest.raises(ConnectionError):
            rebooting.next_telegram(timeout_s=3.0)
        with pytest.raises(ConnectionError):
            while True:
                streaming.scan(timeout_s=3.0)
    with ColaClient(*first, Dialect.ASCII) as client:
        client.send(b"sRN LMDscandata")
        scan = client.scan()
        assert scan.scan_counter < before  # counted again from the reboot
        assert client.ask(b"sRN LMPscancfg").startswith(b"sRA LMPscancfg ")


def test_the_control_api_serves_a_cola_sensors_scans_as_its_clients_get_them(serve, tmp_path: Path) -> None:
    scene = _room(tmp_path, "tim571")
    daemon = serve(scene)
    host, port = daemon.endpoint("sick", "tcp").address
    with ColaClient(host, port, Dialect.ASCII) as client:
        assert client.ask(b"sEN LMDscandata 1") == b"sEA LMDscandata 1"
        streamed = {scan.transmission_us: scan.distances for scan in (client.scan() for _ in range(3))}
        status, answer = _get(daemon.control_url, "/api/sensors/sick/scan")
    assert status == 200 and answer["model"] == "tim571" and len(answer["values"]) == 811
    assert answer["scan_time"] == pytest.approx(1 / 15)
    assert answer["time_s"] * 15 == pytest.approx(round(answer["time_s"] * 15), abs=1e-4)  # on the unit's scan grid
    if round(answer["time_s"] * 1e6) in streamed:
        assert streamed[round(answer["time_s"] * 1e6)] == answer["values"]
    assert answer["values"] == _scan_cli(scene, answer["time_s"])


def test_a_recorded_cola_log_replays_through_the_real_protocol(tmp_path: Path) -> None:
    scene = _room(tmp_path, "lms111")
    log = tmp_path / "lms111.log"
    subprocess.run([str(Path(sys.executable).with_name("lrf-emulator")), "record", str(scene), "--sensor", "sick",
                    "--end", "1", "--out", str(log)], capture_output=True, text=True, timeout=120, check=True)
    recorded = [[int(value) for value in line.split()[2::2]] for line in log.read_text().splitlines()
                if line and not line.startswith("#")]
    with replaying(log, "lms111", "tcp:127.0.0.1:0", tmp_path) as ready:
        with ColaClient(*ready.address, Dialect.BINARY) as client:
            assert client.ask(b"sRN LMPscancfg")[15:19] == (5000).to_bytes(4, "big")  # 50 Hz, as recorded
            client.send(b"sRN LMDscandata")
            scan = client.scan()
    assert len(scan.distances) == 541 and scan.distances in recorded
