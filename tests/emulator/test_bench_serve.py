"""`bench --section serve`: a real daemon streaming N URGs to N clients, measured from outside."""

from __future__ import annotations

import dataclasses
import os
import socket

import pytest

from emulator.bench.serve_load import _LmsStream, cpu_seconds, fleet_scene_text, measure_serve
from protocols.lms2xx import build_telegram
from emulator.scene import load_scene


def test_the_generated_scene_has_n_urgs_on_free_tcp_ports(tmp_path) -> None:
    path = tmp_path / "urgs.toml"
    path.write_text(fleet_scene_text(3))
    scene = load_scene(path)
    assert [(spec.name, spec.model, spec.endpoints) for spec in scene.sensors] == [
        (f"urg0{index}", "urg-04lx", ("tcp:127.0.0.1:0",)) for index in range(3)
    ]
    assert scene.plumes == load_scene("railway").plumes


def test_the_dense_plume_fleet_stands_inside_the_haze_with_larger_puffs(tmp_path) -> None:
    import dataclasses

    path = tmp_path / "plume.toml"
    path.write_text(fleet_scene_text(4, dense_plume=True))
    scene, railway = load_scene(path), load_scene("railway")
    (plume,), (original,) = scene.plumes, railway.plumes
    assert plume.size == 0.4 and original.size == 0.35
    assert dataclasses.replace(plume, size=original.size) == original  # only the puffs' size differs
    haze = next(region for region in scene.regions if region.name == "haze")
    low = [c - s / 2 for c, s in zip(haze.pose.position, haze.shape.size)]
    high = [c + s / 2 for c, s in zip(haze.pose.position, haze.shape.size)]
    for spec in scene.sensors:
        assert all(lo < value < hi for lo, value, hi in zip(low, spec.pose.position, high)), spec.pose


def test_cpu_is_read_from_the_process_accounting() -> None:
    before = cpu_seconds(os.getpid())
    sum(range(3_000_000))
    assert cpu_seconds(os.getpid()) > before


def test_an_lms_stream_counts_each_b0_telegram_once_however_the_bytes_arrive() -> None:
    scan = build_telegram(0x80, b"\xb0" + bytes(724) + b"\x10")  # 732 bytes, like a 0.5° scan
    reply = build_telegram(0x80, b"\xa0\x00\x10")
    wire = b"\x06" + reply + scan * 3
    stream = _LmsStream(socket.socket())
    for index, start in enumerate(range(0, len(wire), 97)):  # torn anywhere, STX/length included
        stream.feed(wire[start : start + 97], float(index))
    stream.sock.close()
    assert len(stream.arrivals) == 3 and not stream.buffer
    assert stream.arrivals == sorted(stream.arrivals)


def test_two_urgs_and_an_lms200_streamed_to_their_clients_are_counted_and_timed() -> None:
    row = measure_serve(2, 1.5, workers=1, model="formsma2011", lms_count=1)
    assert 45 <= row["lms_scans_received"] <= 65  # 37.5/s × 1.5 s
    assert 0 <= row["lms_period_deviation_p50_ms"] <= row["lms_period_deviation_p99_ms"]
    assert 25 <= row["scans_received"] <= 35  # 2 sensors × 10/s × 1.5 s
    assert 0.8 <= row["rate"] <= 1.2
    assert row["cpu_ms_per_scan"] > 0 and row["cpu_cores"] > 0
    assert 0 <= row["jitter_p50_ms"] <= row["jitter_p99_ms"]
    assert 0 <= row["on_time"] <= 1


def test_ust_10lx_streams_are_counted_at_their_40_hz() -> None:
    row = measure_serve(2, 1.5, workers=1, model="formsma2011", hokuyo="ust-10lx")
    assert row["hokuyo"] == "ust-10lx"
    assert 100 <= row["scans_received"] <= 140  # 2 sensors × 40/s × 1.5 s
    assert 0.8 <= row["rate"] <= 1.2
    assert 0 <= row["jitter_p50_ms"] <= row["jitter_p99_ms"]


def test_a_scip_stream_is_timed_when_the_daemon_sent_each_message_not_when_the_client_read_it() -> None:
    """Kernel receive stamps: a message read 60 ms after it was sent counts as arrived when sent."""
    import time

    from emulator.bench.serve_load import _Stream
    from protocols.scip.encoding import encode_values

    def message(stamp: int) -> bytes:
        return b"MD0000108001000\n99b\n" + encode_values([stamp], 4) + b"x\n" + b"0" * 64 + b"0\n\n"

    with socket.create_server(("127.0.0.1", 0)) as server:
        client = socket.create_connection(server.getsockname())
        sender, _ = server.accept()
        with client, sender:
            stream = _Stream(client)
            offset = time.time() - time.monotonic()
            sender.sendall(b"MD0000108001000\n00P\n\n" + message(100))
            stream.receive(offset)  # the echo and the first message: the length is known from here on
            sent = []
            for stamp in (140, 180):
                sent.append(time.monotonic())
                sender.sendall(message(stamp))
                time.sleep(0.06)
                stream.receive(offset)
    assert stream.stamps == [100, 140, 180]
    for arrival, sent_at in zip(stream.arrivals[1:], sent):
        assert sent_at - 0.001 <= arrival <= sent_at + 0.01  # not 60 ms later, when it was read
    assert stream.read_late == 0


def test_rescues_utm_streams_me_and_each_gap_is_measured_against_its_25_ms_period() -> None:
    from emulator.bench.serve_load import measure_utm_stream

    row = measure_utm_stream(duration_s=1.5, slowest_at_s=0.0, model="formsma2011")
    assert row["hokuyo"] == "utm-30lx-ew"
    assert 45 <= row["scans_received"] <= 75  # 40/s × 1.5 s
    assert row["window_sim_s"][0] >= 0 and abs(row["window_sim_s"][1] - row["window_sim_s"][0] - 1.5) < 0.11
    assert 0 <= row["gap_deviation_p50_ms"] <= row["gap_deviation_p99_ms"] <= row["gap_deviation_max_ms"]
    assert 0 <= row["within_5pct"] <= 1


@pytest.mark.parametrize(("hokuyo", "me"), [("ust-10lx", False), ("utm-30lx-ew", True)])
def test_the_floor_sends_messages_framed_as_the_daemons_line_for_line(hokuyo: str, me: bool) -> None:
    """The floor is only a floor if its messages are the daemon's size: each line as long as a Scip22Device's."""
    import numpy as np

    from emulator.bench.scip_floor import scan_message
    from emulator.bench.serve_load import md_unlimited, me_unlimited
    from emulator.sensors.hokuyo_models import HOKUYO_MODELS
    from protocols.scip.scip22 import Scip22Device

    @dataclasses.dataclass(frozen=True)
    class Scan:
        time_s: float
        values: np.ndarray
        intensities: np.ndarray

    steps = HOKUYO_MODELS[hokuyo].steps
    device = Scip22Device(lambda t: Scan(t, np.full(steps, 1234), np.full(steps, 56)), hokuyo, start_time=0.0)
    command = (me_unlimited if me else md_unlimited)(hokuyo)
    device.receive(command, 1.0)
    sent = [output.data for output in device.poll(1.2) if output.data.startswith(command[:2]) and b"\n99" in output.data]
    assert sent, "the device streamed nothing"
    model = HOKUYO_MODELS[hokuyo]
    floor = bytes(scan_message(command.rstrip(b"\n"), model.last_valid_step - model.first_valid_step + 1, 6 if me else 3, 1234))
    assert [len(line) for line in floor.split(b"\n")] == [len(line) for line in sent[-1].split(b"\n")]


def test_the_floor_streams_ust_10lx_at_their_40_hz() -> None:
    from emulator.bench.serve_load import measure_serve_floor

    row = measure_serve_floor(2, 1.5, hokuyo="ust-10lx")
    assert row["model"] == "floor"
    assert 100 <= row["scans_received"] <= 140  # 2 streams × 40/s × 1.5 s
    assert 0.8 <= row["rate"] <= 1.2
    assert 0 <= row["jitter_p50_ms"] <= row["jitter_p99_ms"]


def test_a_burner_keeps_its_share_of_a_core_busy() -> None:
    """The loaded floor is only the daemon's CPU demand if the burner burns what it is told: its bursts
    and pauses (the pause formula checked exactly), and its CPU over wall time measured on a real run."""
    import time as clock

    from emulator.bench.burner import burn, idle_after

    assert idle_after(0.016, 0.5) == pytest.approx(0.016)
    assert idle_after(0.016, 1.0) == 0.0
    with pytest.raises(ValueError):
        idle_after(0.016, 0.0)
    wall, cpu = clock.monotonic(), clock.process_time()
    bursts = burn(0.5, burst_ms=10.0, until=wall + 0.4)
    share = (clock.process_time() - cpu) / (clock.monotonic() - wall)
    assert bursts >= 10
    assert 0.3 < share < 0.75  # half a core, give or take the sleeps' wake-ups on a shared machine


def test_the_loaded_floor_runs_burners_beside_the_senders_and_says_so() -> None:
    from emulator.bench.serve_load import burners, measure_serve_floor, worker_cores

    with burners(1.25) as processes:
        assert len(processes) == 2 and all(process.poll() is None for process in processes)
    assert all(process.poll() is not None for process in processes)  # stopped on leaving
    row = measure_serve_floor(2, 1.0, hokuyo="ust-10lx", burn_cores=0.3)
    assert row["model"] == "floor+cpu" and row["burn_cores"] == 0.3 and row["scans_received"] > 0
    daemon_row = {"scans_received": 400, "cpu_ms_per_scan": 3.0, "daemon_cpu_ms_per_scan": 1.0, "duration_s": 2.0}
    assert worker_cores(daemon_row) == pytest.approx(0.4)  # (3 - 1) ms x 400 scans over 2 s
