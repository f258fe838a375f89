"""hokuyolx (PyPI, unmodified) against the real daemon's URG-04LX over TCP.

hokuyolx is written for UST sensors: its default time sync sends `%ST` and
`TM`, which a URG-04LX answers differently, so it is built with
tsync=False, convert_time=False (docs/interop.md). Everything else runs as
shipped: PP to learn the sensor, BM, GD, MD with remaining counts, QT.
"""

from __future__ import annotations

import logging
import socket
from pathlib import Path

import numpy as np
import pytest
from hokuyolx import HokuyoLX
from hokuyolx.exceptions import HokuyoStatusException
from support.interop import urg_step_values

STEPS = 725 - 44 + 1  # 682


@pytest.fixture
def laser(serve, urg_room: Path, tcp_port: int):
    daemon = serve(urg_room, f"urg=tcp:127.0.0.1:{tcp_port}")
    client = HokuyoLX(addr=daemon.endpoint("urg", "tcp").address, tsync=False, convert_time=False)
    yield client
    client.close()


def test_parameters_learned_from_pp(laser: HokuyoLX) -> None:
    assert (laser.amin, laser.amax, laser.aforw, laser.ares) == (44, 725, 384, 1024)
    assert (laser.dmin, laser.dmax, laser.scan_freq) == (20, 5600, 10)
    assert laser.model == "URG-04LX(Hokuyo Automatic Co.,Ltd.)"


def test_get_dist_equals_the_scan_command(laser: HokuyoLX, urg_room: Path) -> None:
    timestamp_ms, values = laser.get_dist()
    assert values.shape == (STEPS,)
    expected = urg_step_values(urg_room, timestamp_ms / 1000.0)
    np.testing.assert_array_equal(values, expected)
    assert np.any(values < 20), "the smoke block should give error codes"
    assert np.any(values >= 20)


def test_md_three_scans_cluster_3(laser: HokuyoLX, urg_room: Path) -> None:
    received = list(laser.iter_dist(3, grouping=3))
    assert [pending for _, _, pending in received] == [2, 1, 0]
    assert all(scan.shape == (228,) for scan, _, _ in received)  # ceil(682 / 3)
    stamps = [stamp for _, stamp, _ in received]
    assert np.all(np.diff(stamps) == 100), stamps
    # Where a cluster holds no error value its output is the minimum of its 3 steps.
    steps = urg_step_values(urg_room, stamps[0] / 1000.0)
    padded = np.concatenate([steps, np.full(228 * 3 - STEPS, 10**6)]).reshape(228, 3)
    clean = np.all(padded >= 20, axis=1)
    assert clean.sum() > 150
    for scan, _, _ in received:
        np.testing.assert_array_equal(scan[clean], padded[clean].min(axis=1))


def test_unlimited_md_stopped_by_qt(laser: HokuyoLX, caplog: pytest.LogCaptureFixture) -> None:
    caplog.set_level(logging.WARNING, logger="hokuyo")
    stream = laser.iter_dist(0)
    pendings = [next(stream)[2] for _ in range(3)]
    assert pendings == [0, 0, 0]  # unlimited: the remaining count stays 00
    laser.standby()  # QT → 00
    laser._sock.settimeout(0.35)  # hokuyolx offers no public read; 3 scan periods of silence
    with pytest.raises(socket.timeout):
        stray = laser._sock.recv(4096)
        pytest.fail(f"data after QT: {stray[:80]!r}")
    laser._sock.settimeout(laser.timeout)
    with pytest.raises(HokuyoStatusException) as laser_off:
        laser.get_dist()
    assert laser_off.value.code == "10"
    assert laser.activate()[0] == 0  # BM after QT: laser on again
    assert laser.get_dist()[1].shape == (STEPS,)
    assert not [r for r in caplog.records if "Discarded" in r.getMessage()]
