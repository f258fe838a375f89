"""The SCIP 2.2 Hokuyos served by the real daemon: a USB UTM-30LX on a pty, the control API's scans,
and a fleet of UST-10LX whose daemons agree on every scan of an instant."""

from __future__ import annotations

import socket
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
from support.interop import scan_values, write_room

from emulator.bench.hostile import open_raw
from emulator.bench.serve_load import fleet_scene_text, sensor_name
from emulator.bench.serve_process import ServeProcess
from tests.emulator.control_support import call

MD_ALL = b"MD0000108001000"


def checked_lines(message: bytes) -> list[bytes]:
    lines = message.split(b"\n")[:-2]
    for line in lines[1:]:
        assert line[-1] == (sum(line[:-1]) & 0x3F) + 0x30, line
    return [lines[0], *(line[:-1] for line in lines[1:])]


def decode(chars: bytes, width: int) -> list[int]:
    values = []
    for start in range(0, len(chars), width):
        value = 0
        for char in chars[start : start + width]:
            value = (value << 6) | (char - 0x30)
        values.append(value)
    return values


def md_scans(address: tuple[str, int], count: int) -> dict[int, list[int]]:
    """{stamp: values} of the first `count` scans of an unlimited MD of steps 0..1080."""
    with socket.create_connection(address, timeout=5) as client:
        client.sendall(MD_ALL + b"\n")
        buffer = b""
        while buffer.count(b"\n\n") < count + 1:
            chunk = client.recv(65536)
            assert chunk, "the daemon closed the stream"
            buffer += chunk
    messages = [message + b"\n\n" for message in buffer.split(b"\n\n")[: count + 1]]
    assert messages[0] == MD_ALL + b"\n00P\n\n"
    scans = {}
    for message in messages[1:]:
        echo, status, stamp, *data = checked_lines(message)
        assert (echo, status) == (MD_ALL, b"99")
        scans[decode(stamp, 4)[0]] = decode(b"".join(data), 3)
    return scans


def reply(client, command: bytes, timeout_s: float = 5.0) -> bytes:
    client.send(command + b"\n")
    received, deadline = b"", time.monotonic() + timeout_s
    while b"\n\n" not in received and time.monotonic() < deadline:
        received += client.drain(0.05)
    return received


def test_a_usb_utm_30lx_on_a_pty(tmp_path: Path) -> None:
    scene = write_room(tmp_path, "utm-usb")
    with ServeProcess(scene, ()) as daemon:
        client = open_raw(f"pty:{daemon.endpoint('utm', 'pty').path}")
        try:
            assert b"PROT:SCIP 2.2;" in reply(client, b"VV")
            assert reply(client, b"ND0000108000000") == b"ND0000108000000\n0Ee\n\n"  # no multi-echo
            assert reply(client, b"BM") == b"BM\n00P\n\n"
            echo, status, stamp, *data = checked_lines(reply(client, b"GE0540054001"))
            assert (echo, status) == (b"GE0540054001", b"00")
            distance, intensity = decode(b"".join(data), 3)
            _, values = scan_values(scene, "utm", decode(stamp, 4)[0] / 1000)
            assert distance == values[540] and intensity > 0
        finally:
            client.close()


def test_the_control_api_serves_a_utm_30lx_ew_scan_at_its_period(tmp_path: Path) -> None:
    with ServeProcess("rescue", ["utm=tcp:127.0.0.1:0"], extra_args=("--sensors", "utm", "--control", "127.0.0.1:0")) as d:
        status, scan = call(d.control_url, "GET", "/api/sensors/utm/scan")
    assert status == 200 and scan["model"] == "utm-30lx-ew"
    assert len(scan["values"]) == 1081 and scan["scan_time"] == 0.025
    assert scan["range_min"] == 0.023 and scan["range_max"] == 60.0


def test_a_fleet_of_ust_10lx_sweeps_out_of_step_and_agrees_on_each_instant(tmp_path: Path) -> None:
    """Three UST-10LX in one scene start their sweeps 0, 8 and 16 ms past each 25 ms in every daemon
    serving them; a scan is the world at its own stamp (as `scan` computes it)."""
    scene = tmp_path / "three-usts.toml"
    scene.write_text(fleet_scene_text(3, hokuyo="ust-10lx"))
    names = [sensor_name("ust-10lx", index) for index in range(3)]
    endpoints = [f"{name}=tcp:127.0.0.1:0" for name in names]
    common = ["--epoch", repr(time.time() - 20.0), "--workers", "1"]
    with ServeProcess(scene, endpoints[:2], extra_args=["--sensors", ",".join(names[:2]), *common]) as first:
        with ServeProcess(scene, endpoints[1:], extra_args=["--sensors", ",".join(names[1:]), *common]) as second:
            wanted = [(first, names[0]), (first, names[1]), (second, names[1]), (second, names[2])]
            with ThreadPoolExecutor(len(wanted)) as clients:
                streams = [clients.submit(md_scans, daemon.endpoint(name).address, 8) for daemon, name in wanted]
                scans = [stream.result() for stream in streams]
    assert [{stamp % 25 for stamp in stream} for stream in scans] == [{0}, {8}, {8}, {16}]
    shared = sorted(set(scans[1]) & set(scans[2]))
    assert shared and scans[1][shared[0]] == scans[2][shared[0]]
    stamp = max(scans[3])
    _, expected = scan_values(scene, names[2], stamp / 1000)
    np.testing.assert_array_equal(scans[3][stamp], expected)
