"""The daemon in-process: endpoint plans, shared scans across endpoints, pluggable
scan sources (what `replay` uses), sub-millisecond wake-ups."""

from __future__ import annotations

import asyncio
import socket
import statistics
import threading
import time
from pathlib import Path
from typing import Iterator

import numpy as np
import pytest

from emulator.daemon.clock import WallClock
from emulator.daemon.scan_cache import SCAN_BATCH
from emulator.daemon.service import Daemon, Ready
from emulator.errors import UserError
from emulator.scene.model import Pose, Scene, SensorSpec
from emulator.sensors.scan import Scan
from emulator.transport.timer import LATE_THRESHOLDS_MS, PreciseTimer


def scene_with(*sensors: SensorSpec) -> Scene:
    return Scene(
        path=None, name="test", description="", seed=0, model="formsma2011", density_to_extinction=250.0,
        materials={}, objects=(), regions=(), plumes=(), sensors=sensors,
    )


def urg(name: str = "urg", endpoints: tuple[str, ...] = ()) -> SensorSpec:
    return SensorSpec(name, "urg-04lx", Pose(), endpoints, {"serial": "H0706400", "boot_protocol": "scip2"})


class RecordedSensor:
    """A sensor-like scan source (as a replayed log is): values 1000 + step + scan index."""

    def __init__(self) -> None:
        self.requests: list[float] = []
        self.batches: list[list[float]] = []
        self._lock = threading.Lock()

    def scan(self, time_s: float) -> Scan:
        with self._lock:
            self.requests.append(time_s)
        index = int(round(time_s * 10))
        values = 1000 + np.arange(769) + index
        return Scan("urg", "urg-04lx", time_s, np.zeros(769), values)

    def scans(self, times_s: list[float]) -> list[Scan]:
        with self._lock:
            self.batches.append(list(times_s))
        return [self.scan(time_s) for time_s in times_s]


class Running:
    """A daemon on a loop thread; `ready` holds its ready endpoints."""

    def __init__(self, daemon: Daemon) -> None:
        self.daemon = daemon
        self.ready: list[Ready] = []
        self.loop = asyncio.new_event_loop()
        self._thread = threading.Thread(
            target=self.loop.run_until_complete, args=(daemon.run(self.ready.append),), daemon=True
        )
        self._thread.start()

    def tcp(self, index: int) -> tuple[str, int]:
        deadline = time.monotonic() + 5
        while len(self.ready) <= index:
            assert time.monotonic() < deadline
            time.sleep(0.01)
        _, host, port = self.ready[index].uri.split(":")
        return host, int(port)

    def stop(self) -> None:
        self.loop.call_soon_threadsafe(self.daemon.stop)
        self._thread.join(5)
        self.loop.close()


@pytest.fixture
def recorded() -> Iterator[tuple[Running, RecordedSensor]]:
    sensor = RecordedSensor()
    scene = scene_with(urg(endpoints=("tcp:127.0.0.1:0", "tcp:127.0.0.1:0")))
    running = Running(Daemon(scene, clock=WallClock(), sensor_factory=lambda spec: sensor))
    yield running, sensor
    running.stop()


def md_scans(address: tuple[str, int], count: int) -> list[bytes]:
    """`count` MD scans (3-char, steps 0..768) as whole messages."""
    with socket.create_connection(address, timeout=3) as client:
        client.sendall(b"MD00000768010%02d\n" % count)
        buffer = b""
        while buffer.count(b"\n\n") < count + 1:
            buffer += client.recv(65536)
    return buffer.split(b"\n\n")[1 : count + 1]


def decode(message: bytes) -> list[int]:
    data = b"".join(line[:-1] for line in message.split(b"\n")[3:])
    codes = np.frombuffer(data, dtype=np.uint8).astype(int).reshape(-1, 3) - 0x30
    return list((codes[:, 0] << 12) | (codes[:, 1] << 6) | codes[:, 2])


def test_the_scan_source_is_pluggable_and_served_unchanged(recorded: tuple[Running, RecordedSensor]) -> None:
    running, sensor = recorded
    scans = md_scans(running.tcp(0), 3)
    for message in scans:
        values = decode(message)
        assert len(values) == 769
        assert values[1:] == [v + 1 for v in values[:-1]]  # 1000 + step + index, straight through
        assert 1000 <= values[0] < 1000 + 10 * 3600


def test_endpoints_of_one_sensor_compute_each_scan_once(recorded: tuple[Running, RecordedSensor]) -> None:
    running, sensor = recorded
    results: list[list[bytes]] = [[], []]
    threads = [
        threading.Thread(target=lambda i=i: results[i].extend(md_scans(running.tcp(i), 5))) for i in range(2)
    ]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join(10)
    stamps = [{message.split(b"\n")[2] for message in result} for result in results]
    assert len(stamps[0] & stamps[1]) >= 3  # both clients streamed the same scans
    assert len(sensor.requests) == len(set(sensor.requests)), "a scan was computed twice"


def test_a_served_stream_is_computed_in_batches_each_scan_once(recorded: tuple[Running, RecordedSensor]) -> None:
    running, sensor = recorded
    md_scans(running.tcp(0), 2 * SCAN_BATCH + 4)
    assert len(sensor.batches) >= 2 and all(len(batch) == SCAN_BATCH for batch in sensor.batches)
    batched = sum(len(batch) for batch in sensor.batches)
    assert len(sensor.requests) - batched <= 4  # only the scans before the stream was seen, alone
    ticks = [round(time_s * 1e6) for time_s in sensor.requests]
    assert len(ticks) == len(set(ticks)), "a scan was computed twice"


def test_plan_errors_name_what_is_wrong(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    scene = scene_with(urg(endpoints=("tcp:127.0.0.1:0",)), urg("second", ()))
    with pytest.raises(UserError, match=r"no sensor named 'lms' \(known: second, urg\)"):
        Daemon(scene, {"lms": ["tcp:127.0.0.1:0"]})
    monkeypatch.chdir(tmp_path)
    with pytest.raises(UserError, match="already used by sensor"):
        Daemon(scene, {"urg": ["pty:ttyA"], "second": [f"pty:{tmp_path / 'ttyA'}"]})
    with pytest.raises(UserError, match="already used by sensor"):
        Daemon(scene, {"urg": ["tcp:127.0.0.1:10940", "tcp:127.0.0.1:10940"]})
    Daemon(scene, {"urg": ["tcp:127.0.0.1:0", "tcp:127.0.0.1:0"]})  # two fresh ports are two endpoints


def test_precise_timer_runs_in_order_skips_cancelled_and_is_sub_millisecond() -> None:
    loop = asyncio.new_event_loop()
    timer = PreciseTimer(loop)
    fired: list[tuple[int, float]] = []
    start = time.monotonic() + 0.05
    handles = [timer.call_at(start + 0.013 * i, lambda i=i: fired.append((i, time.monotonic()))) for i in range(20)]
    for index in (3, 11):
        handles[index].cancel()
    loop.run_until_complete(asyncio.sleep(start + 0.013 * 20 + 0.05 - time.monotonic()))
    timer.close()
    loop.close()
    assert [i for i, _ in fired] == [i for i in range(20) if i not in (3, 11)]
    lateness_ms = [(at - (start + 0.013 * i)) * 1000 for i, at in fired]
    assert min(lateness_ms) >= 0
    assert statistics.median(lateness_ms) < 0.5, lateness_ms


def test_precise_timer_counts_a_wake_up_the_loop_was_kept_from() -> None:
    """A loop busy for 20 ms past a timer's time makes that wake-up late by more than every threshold."""
    loop = asyncio.new_event_loop()
    timer = PreciseTimer(loop)
    fired: list[float] = []
    due = time.monotonic() + 0.005
    timer.call_at(due, lambda: fired.append(time.monotonic()))
    loop.call_soon(time.sleep, 0.025)  # the loop's thread is held (as by another thread with the GIL)
    loop.run_until_complete(asyncio.sleep(0.05))
    timer.close()
    loop.close()
    assert len(fired) == 1 and fired[0] - due >= 0.02
    assert timer.wakes == 1
    assert timer.late == [1] * len(LATE_THRESHOLDS_MS)
