"""A fleet: daemons serving groups of one scene's sensors, sharing an epoch, agree on the world.

Two real `serve` processes on loopback, each given `--sensors` and the same
`--epoch`: they never talk to each other, yet a scan of one instant is the
same from both, and the same as `lrf-emulator scan` computes for that instant.
"""

from __future__ import annotations

import socket
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
from support.interop import scan_values, urg_step_values

from emulator.bench.serve_load import fleet_scene_text
from emulator.bench.serve_process import ServeProcess
from tests.emulator.test_serve import MD_FULL, decode_md_scan, run_serve

TIMESTAMP_WRAP_MS = 1 << 24  # a URG stamp is 24 bits of milliseconds


def md_scans(address: tuple[str, int], count: int) -> list[tuple[int, list[int]]]:
    """(timestamp ms, values) of the first `count` scans of an unlimited MD stream over TCP."""
    with socket.create_connection(address, timeout=5) as client:
        client.sendall(MD_FULL + b"\n")
        buffer = b""
        while buffer.count(b"\n\n") < count + 1:  # the echo + count scans
            chunk = client.recv(65536)
            assert chunk, "the daemon closed the stream"
            buffer += chunk
    messages = [message + b"\n\n" for message in buffer.split(b"\n\n")[: count + 1]]
    assert messages[0] == MD_FULL + b"\n00P\n\n"
    return [decode_md_scan(message) for message in messages[1:]]


def test_two_daemons_with_one_epoch_serve_the_same_scan_of_an_instant_as_scan(tmp_path: Path) -> None:
    epoch = time.time() - 20.0  # 20 s into the scene: the plume is up
    common = ["--epoch", repr(epoch), "--workers", "1"]
    with ServeProcess("railway", ["urg=tcp:127.0.0.1:0"], extra_args=["--sensors", "urg", *common]) as first:
        with ServeProcess(
            "railway", ["urg=tcp:127.0.0.1:0", "lms=tcp:127.0.0.1:0"], extra_args=["--sensors", "urg,lms", *common]
        ) as second:
            assert [ready.sensor for ready in first.ready] == ["urg"]
            assert sorted(ready.sensor for ready in second.ready) == ["lms", "urg"]
            asked_at = time.time()
            with ThreadPoolExecutor(2) as clients:  # both streams at once
                streams = [clients.submit(md_scans, daemon.endpoint("urg").address, 6) for daemon in (first, second)]
                from_first, from_second = (dict(stream.result()) for stream in streams)
    expected_ms = (asked_at - epoch) * 1000 % TIMESTAMP_WRAP_MS
    assert all(abs(stamp - expected_ms) < 3000 for stamp in [*from_first, *from_second]), (expected_ms, from_first.keys())
    shared = sorted(set(from_first) & set(from_second))
    assert shared, f"no instant in common: {sorted(from_first)} vs {sorted(from_second)}"
    stamp = shared[0]
    assert from_first[stamp] == from_second[stamp]
    np.testing.assert_array_equal(from_first[stamp], urg_step_values(Path("railway"), stamp / 1000))


def test_the_urgs_of_a_scene_turn_out_of_step_and_a_fleet_agrees_on_each_ones_instants(tmp_path: Path) -> None:
    """Three URGs in one scene complete their scans 0, 33 and 66 ms past each 100 ms, in every daemon
    serving them; a scan is still the world at its own stamp (as `scan` computes it)."""
    scene = tmp_path / "three-urgs.toml"
    scene.write_text(fleet_scene_text(3))
    epoch = time.time() - 20.0
    common = ["--epoch", repr(epoch), "--workers", "1"]
    names = ["urg00", "urg01", "urg02"]
    endpoints = [f"{name}=tcp:127.0.0.1:0" for name in names]
    with ServeProcess(scene, endpoints[:2], extra_args=["--sensors", "urg00,urg01", *common]) as first:
        with ServeProcess(scene, endpoints[1:], extra_args=["--sensors", "urg01,urg02", *common]) as second:
            wanted = [(first, "urg00"), (first, "urg01"), (second, "urg01"), (second, "urg02")]
            with ThreadPoolExecutor(len(wanted)) as clients:
                streams = [clients.submit(md_scans, daemon.endpoint(name).address, 4) for daemon, name in wanted]
                scans = [dict(stream.result()) for stream in streams]
    phases = [{stamp % 100 for stamp in stream} for stream in scans]
    assert phases == [{0}, {33}, {33}, {66}], phases
    shared = sorted(set(scans[1]) & set(scans[2]))
    assert shared and scans[1][shared[0]] == scans[2][shared[0]]
    stamp = max(scans[3])
    _, expected = scan_values(scene, "urg02", stamp / 1000)
    np.testing.assert_array_equal(scans[3][stamp], expected)  # `scan` gives the measured steps 44..725


def test_sensors_must_be_of_the_scene_and_the_epoch_not_in_the_future(tmp_path: Path) -> None:
    unknown = run_serve("railway", "--sensors", "urg,radar", cwd=tmp_path)
    assert unknown.returncode == 2 and "--sensors: no sensor named 'radar'" in unknown.stderr
    future = run_serve("railway", "--epoch", repr(time.time() + 3600), cwd=tmp_path)
    assert future.returncode == 2 and "--epoch" in future.stderr and "future" in future.stderr
    outside = run_serve("railway", "--sensors", "urg", "--endpoint", "lms=tcp:127.0.0.1:0", cwd=tmp_path)
    assert outside.returncode == 2 and "not among --sensors" in outside.stderr
    assert "Traceback" not in unknown.stderr + future.stderr + outside.stderr
