"""`serve --model`: the daemon serves the preset named on the command line, not the scene's."""

from __future__ import annotations

import socket

import numpy as np

from emulator.bench.serve_process import ServeProcess
from emulator.scene import load_scene
from emulator.sensors import create_sensor
from emulator.sensors.response import apply_model_override
from protocols.scip.encoding import decode_values, join_data_lines

GD_FULL = b"GD0000076801"


def served_scan(address: tuple[str, int]) -> tuple[int, np.ndarray]:
    """(timestamp ms, 769 values) of one GD reply over TCP, after switching the laser on."""
    with socket.create_connection(address, timeout=3) as client:
        reply = b""
        for command in (b"BM\n", GD_FULL + b"\n"):
            client.sendall(command)
            reply = b""
            while not reply.endswith(b"\n\n"):
                reply += client.recv(65536)
    lines = reply.split(b"\n")
    assert lines[0] == GD_FULL and lines[1] == b"00P", reply[:40]
    stamp = int(decode_values(lines[2][:-1], 4)[0])
    return stamp, decode_values(join_data_lines(b"\n".join(lines[3:-2]) + b"\n"), 3)


def test_serve_model_physical_serves_the_physical_preset() -> None:
    with ServeProcess("bocas", ["urg=tcp:127.0.0.1:0"], extra_args=["--model", "physical"]) as daemon:
        stamp, values = served_scan(daemon.endpoint("urg", "tcp").address)
    scene = load_scene("bocas")
    physical = create_sensor(apply_model_override(scene, "physical"), "urg").scan(stamp / 1000.0)
    paper = create_sensor(scene, "urg").scan(stamp / 1000.0)
    np.testing.assert_array_equal(values, physical.values)
    # clear-air noise makes the physical preset differ from the noiseless paper rule
    assert np.count_nonzero(values != paper.values) > 100
