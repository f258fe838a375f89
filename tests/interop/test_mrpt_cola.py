"""MRPT's CSICKTim561Eth and CLMS100Eth (Debian mrpt-apps, unmodified) over CoLa-A on TCP.

rawlog-grabber logs in, reads the unit's identity and state, configures the
scan (CLMS100Eth) and then polls `sRN LMDscandata`; every scan it saves must
be the daemon's scan of the same room (a wall 3.5 m ahead, nothing else):
the TiM's 811 and the LMS111's 1081 ranges in mm.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from support.ports import free_tcp_port

from emulator.bench import mrpt
from emulator.scene import load_scene
from emulator.sensors import create_sensor

ROOM = """
[scene]
name = "cola-room"
[[objects]]
name = "wall"
box = {{ size = [0.2, 30.0, 3.0] }}
position = [3.6, 0.0, 1.0]
[[sensors]]
name = "sick"
model = "{model}"
position = [0.0, 0.0, 0.4]
endpoints = ["tcp:127.0.0.1:2111"]
"""


def _room(folder: Path, model: str) -> Path:
    scene = folder / f"{model}.toml"
    scene.write_text(ROOM.format(model=model))
    return scene


def _grab(serve, folder: Path, model: str, driver: str, scans: int, timeout_s: float):
    scene = _room(folder, model)
    port = free_tcp_port()
    serve(scene, f"sick=tcp:127.0.0.1:{port}")
    section = (f"[SICK]\ndriver = {driver}\nprocess_rate = 10\nsensorLabel = SICK\n"
               f"ip_address = 127.0.0.1\nTCP_port = {port}\n")
    grabbed = mrpt.grab(folder, section, until=lambda saved: saved >= scans, timeout_s=timeout_s)
    assert grabbed.returncode == 0 and grabbed.rawlog is not None, grabbed.output[-3000:]
    exported = grabbed.scans("SICK")
    expected = create_sensor(load_scene(scene), "sick").configured_scan(1.0).values
    return exported, expected


def test_csicktim561eth_reads_the_daemons_scans(serve, tmp_path: Path) -> None:
    exported, expected = _grab(serve, tmp_path, "tim561", "CSICKTim561Eth", scans=8, timeout_s=60)
    assert len(exported.times_s) >= 5
    assert exported.ranges_m.shape[1] == 811
    millimetres = np.rint(exported.ranges_m * 1000).astype(int)
    np.testing.assert_array_equal(millimetres, np.tile(expected, (len(millimetres), 1)))
    assert (expected[400:411] > 3000).all()  # the wall straight ahead is in the scan


def test_clms100eth_configures_and_reads_the_daemons_scans(serve, tmp_path: Path) -> None:
    exported, expected = _grab(serve, tmp_path, "lms111", "CLMS100Eth", scans=8, timeout_s=90)
    assert len(exported.times_s) >= 5
    assert exported.ranges_m.shape[1] == 1081  # mLMPsetscancfg chose 25 Hz at 0.25°
    assert (np.rint(exported.ranges_m[:, 535:546] * 1000) > 3000).all()
