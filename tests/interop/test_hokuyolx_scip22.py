"""hokuyolx (PyPI, unmodified; written for the UST series) against the real daemon's
UST-10LX and UTM-30LX-EW over TCP: identity, ranges, intensities, streaming.

The UST gets hokuyolx as shipped, time sync included (%ST, TM0/TM1/TM2); the
UTM-30LX-EW lacks the UST's %ST, so it is built with tsync=False.
"""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path

import numpy as np
import pytest
from hokuyolx import HokuyoLX
from support.interop import scan_values

from emulator.scene import load_scene
from emulator.sensors import create_sensor

II_RETRY_S = 6.0  # longer than the 4.096 s a ':' can stay in TIME's third character

STEPS = 1081


def step_values(scene: Path, sensor: str, time_s: float) -> np.ndarray:
    """The `scan` command's values of steps 0..1080 (step 540 ahead, 1440 per turn)."""
    angles, values = scan_values(scene, sensor, time_s)
    np.testing.assert_allclose(angles, (np.arange(STEPS) - 540) * 0.25, atol=1e-6)
    return values


@pytest.fixture
def ust(serve, ust_room: Path, tcp_port: int):
    daemon = serve(ust_room, f"ust=tcp:127.0.0.1:{tcp_port}")
    client = HokuyoLX(addr=daemon.endpoint("ust", "tcp").address, convert_time=False)
    yield client
    client.close()


@pytest.fixture
def utm(serve, utm_room: Path, tcp_port: int):
    daemon = serve(utm_room, f"utm=tcp:127.0.0.1:{tcp_port}")
    client = HokuyoLX(addr=daemon.endpoint("utm", "tcp").address, tsync=False, convert_time=False)
    yield client
    client.close()


def test_ust_identity_and_time_sync(ust: HokuyoLX) -> None:
    assert (ust.model, ust.amin, ust.amax, ust.aforw, ust.ares) == ("UST-10LX", 0, 1080, 540, 1440)
    assert (ust.dmin, ust.dmax, ust.scan_freq) == (20, 30000, 40)
    assert ust.version()["PROT"] == "SCIP 2.2"
    assert ust.laser_state() == (3, "Single scan state")  # hokuyolx activated it after syncing
    assert ust.tzero != 0, "time_sync read TM1 ten times"


def test_ust_ranges_and_intensities_equal_the_scan_command(ust: HokuyoLX, ust_room: Path) -> None:
    stamp, ranges = ust.get_dist()
    assert ranges.shape == (STEPS,)
    np.testing.assert_array_equal(ranges, step_values(ust_room, "ust", stamp / 1000))
    assert np.any(ranges < 20) and np.any(ranges >= 20)
    stamp, pairs = ust.get_intens()
    assert pairs.shape == (STEPS, 2)
    np.testing.assert_array_equal(pairs[:, 0], step_values(ust_room, "ust", stamp / 1000))


def test_ust_streams_every_25_ms(ust: HokuyoLX) -> None:
    received = list(ust.iter_intens(4, start=100, end=900, grouping=2))
    assert [pending for _, _, pending in received] == [3, 2, 1, 0]
    assert all(scan.shape == (401, 2) for scan, _, _ in received)
    stamps = [stamp for _, stamp, _ in received]
    assert np.all(np.diff(stamps) == 25), stamps


def sensor_state(client: HokuyoLX) -> dict:
    """hokuyolx's `sensor_state`, read again when it trips on the TIME field: it splits each II line
    on ':', and a real UTM's four-character encoded TIME holds a ':' whenever one of its 6-bit groups
    is 10. The lowest group moves every millisecond, the next every 64 ms, the third every 4.096 s: a
    ':' in the third stays for 4.096 s (seconds 40.96-45.06 of the device's clock, then every 262 s),
    so the readings go on for up to II_RETRY_S of wall time, not a count of quick retries."""
    deadline = time.monotonic() + II_RETRY_S
    while time.monotonic() < deadline:
        try:
            return client.sensor_state()
        except ValueError:
            time.sleep(0.05)
    raise AssertionError(f"II never parsed in {II_RETRY_S} s")


def test_utm_30lx_ew_over_tcp(utm: HokuyoLX, utm_room: Path) -> None:
    assert (utm.model, utm.dmin, utm.dmax, utm.scan_freq) == ("UTM-30LX-EW", 23, 60000, 40)
    assert sensor_state(utm)["MESM"] == "003 Single_scan"
    stamp, ranges = utm.get_dist()
    np.testing.assert_array_equal(ranges, step_values(utm_room, "utm", stamp / 1000))
    scans = list(utm.iter_dist(3))
    assert np.all(np.diff([stamp for _, stamp, _ in scans]) == 25)


def decode_echo_lines(lines: list[str], client: HokuyoLX) -> list[list[tuple[int, int]]]:
    """Range + intensity echoes per step from HE data lines (hokuyolx checks each line's sum; the
    '&'-prefixed further echoes are read here: hokuyolx 0.9 decodes single echoes only)."""
    text = "".join(client._check_sum(line) for line in lines if line)
    steps: list[list[tuple[int, int]]] = []
    position = 0
    while position < len(text):
        further = text[position] == "&"
        position += further
        echo = (HokuyoLX._convert2int(text[position : position + 3]), HokuyoLX._convert2int(text[position + 3 : position + 6]))
        position += 6
        if further:
            steps[-1].append(echo)
        else:
            steps.append([echo])
    return steps


def test_multi_echo_with_intensity_under_physical(serve, ust_room: Path, tcp_port: int) -> None:
    """hokuyolx's own request/response path (send, header check, status sum) carries HE; every echo
    equals the simulated sensor's at the scan's stamp, and some beams in the smoke block have two."""
    daemon = serve(ust_room, f"ust=tcp:127.0.0.1:{tcp_port}", extra_args=("--model", "physical"))
    client = HokuyoLX(addr=daemon.endpoint("ust", "tcp").address, convert_time=False)
    try:
        status, lines = client._send_req("HE", "0000108000")
        stamp = client._convert2ts(lines[0], False)
        steps = decode_echo_lines(lines[1:], client)
    finally:
        client.close()
    assert status == "00" and len(steps) == STEPS
    scene = dataclasses.replace(load_scene(ust_room), model="physical")
    scan = create_sensor(scene, "ust").scan(stamp / 1000)
    for step, echoes in enumerate(steps):
        count = max(1, int((scan.echoes[step] >= 0).sum()))
        assert echoes == [(int(scan.echoes[step, k]), int(scan.echo_intensities[step, k])) for k in range(count)], step
    assert sum(len(echoes) > 1 for echoes in steps) >= 1


def test_ust_reboot_drops_the_connection_and_a_reconnect_finds_the_unit_booted(serve, ust_room: Path, tcp_port: int) -> None:
    """hokuyolx's `reboot()` (RB twice: 01, then 00) on the real daemon: a second later the unit drops
    the connection, as the specification says; hokuyolx reconnecting then finds it booted, with the
    laser off and its timer restarted."""
    daemon = serve(ust_room, f"ust=tcp:127.0.0.1:{tcp_port}")
    address = daemon.endpoint("ust", "tcp").address
    client = HokuyoLX(addr=address, tsync=False, convert_time=False)  # it switches the laser on
    try:
        assert client.laser_state()[0] == 3
        before_ms, before_s = client.get_dist()[0], time.monotonic()
        client.reboot()
        rebooted_at = time.monotonic()
        client._sock.settimeout(5.0)
        assert client._sock.recv(1) == b"", "the unit did not drop the connection"
        dropped_after = time.monotonic() - rebooted_at
    finally:
        client.close()
    assert 0.8 <= dropped_after <= 2.5, dropped_after  # it waits a second for the host to disconnect
    again = HokuyoLX(addr=address, activate=False, tsync=False, convert_time=False)  # answered once it has booted
    try:
        assert again.laser_state()[0] == 0  # booted with its power-on settings: laser off
        again.activate()
        stamp_ms, ranges = again.get_dist()
        unrestarted_ms = before_ms + (time.monotonic() - before_s) * 1000  # what the old timer would read
        assert ranges.shape == (STEPS,)
        assert stamp_ms < unrestarted_ms - 1000, (stamp_ms, unrestarted_ms)  # restarted at the reboot, 1 s after RB
    finally:
        again.close()
