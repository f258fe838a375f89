"""`record` → `replay` → an unmodified client gets back exactly the recorded values.

The real `lrf-emulator record` writes a log of a bundled scene; the real
`lrf-emulator replay` process serves it; hokuyolx (PyPI, unmodified) reads the
URG-04LX over TCP, and a pyserial LMS200 host (emulator.bench.lms_client,
which shares no code with the device) reads B0 telegrams over the pty.
"""

from __future__ import annotations

import os
import select
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest
from hokuyolx import HokuyoLX

from emulator.bench.lms_client import LmsSerialClient, Telegram
from emulator.bench.serve_process import ReadyEndpoint, parse_ready_line
from emulator.recording.textlog import Log, read_log

CLI = [sys.executable, "-m", "emulator.cli"]
URG_FRONT = 384 - 44  # step 384 among the logged steps 44..725 (what hokuyolx reads)
LMS_DISTANCE_BITS = 0x1FFF


def record(tmp_path: Path, scene: str, sensor: str, start: float, end: float) -> Path:
    out = tmp_path / f"{scene}.log"
    result = subprocess.run(
        [*CLI, "record", scene, "--sensor", sensor, "--start", str(start), "--end", str(end), "--out", str(out)],
        capture_output=True, text=True, timeout=120,
    )
    assert result.returncode == 0, result.stderr
    return out


@contextmanager
def replaying(log: Path, model: str, endpoint: str, cwd: Path, *extra: str) -> Iterator[ReadyEndpoint]:
    """The real `lrf-emulator replay` process; yields its ready endpoint, SIGTERMs it after."""
    process = subprocess.Popen(
        [*CLI, "replay", str(log), "--device", model, "--endpoint", endpoint, *extra],
        cwd=cwd, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )
    try:
        ready = None
        deadline = time.monotonic() + 30
        while ready is None:
            assert process.stdout is not None
            readable, _, _ = select.select([process.stdout], [], [], max(0.0, deadline - time.monotonic()))
            line = process.stdout.readline() if readable else ""
            if not line:
                process.kill()
                pytest.fail(f"replay not ready: {process.stderr.read() if process.stderr else ''}")
            ready = parse_ready_line(line)
        yield ready
    finally:
        if process.poll() is None:
            process.send_signal(signal.SIGTERM)
        assert process.wait(10) == 0


def recorded_row(log: Log, timestamp_ms: int) -> int:
    """The log row a replayed scan stamped `timestamp_ms` comes from (the replay loops)."""
    period_ms = int(round(np.median(np.diff(log.times_s)) * 1000))
    return (timestamp_ms // period_ms) % len(log.values)


def test_hokuyolx_gets_the_recorded_urg_values(tmp_path: Path, tcp_port: int) -> None:
    log_path = record(tmp_path, "bocas", "urg", 70.0, 74.0)  # the error onset at 71.6 s lies inside; 41 rows: GDs a cycle apart (0.1 s reply + 0.2 s) meet distinct rows
    log = read_log(log_path)
    assert log.values.shape[1] == 682  # record logs the measured steps 44..725
    with replaying(log_path, "urg-04lx", f"tcp:127.0.0.1:{tcp_port}", tmp_path) as ready:
        assert (ready.sensor, ready.model) == ("urg", "urg-04lx")
        laser = HokuyoLX(addr=ready.address, tsync=False, convert_time=False)
        try:
            seen_rows = set()
            for _ in range(12):
                timestamp_ms, values = laser.get_dist()
                row = recorded_row(log, timestamp_ms)
                assert np.array_equal(values, log.values[row]), f"row {row}"
                seen_rows.add(row)
                time.sleep(0.2)
            streamed = list(laser.iter_dist(5))
            assert [pending for _, _, pending in streamed] == [4, 3, 2, 1, 0]
            for values, timestamp_ms, _ in streamed:
                assert np.array_equal(values, log.values[recorded_row(log, timestamp_ms)])
        finally:
            laser.close()
    centre_values = {int(log.values[row, URG_FRONT]) for row in seen_rows}
    assert len(seen_rows) >= 8
    assert centre_values == {2500, 1}  # both the clear target and the smoke error came through


def b0_values(telegram: Telegram) -> np.ndarray:
    count_word, values = telegram.b0_values()
    assert count_word & 0x3FF == 361 and count_word >> 14 == 1  # 361 values in mm
    return np.array(values) & LMS_DISTANCE_BITS


def test_lms200_host_gets_the_recorded_values_over_the_pty(tmp_path: Path) -> None:
    log_path = record(tmp_path, "marulan", "lms", 80.0, 83.0)  # puffs meeting on the right
    log = read_log(log_path)
    assert len({row.tobytes() for row in log.values}) > len(log.values) // 2  # rows tell scans apart
    with replaying(log_path, "lms200", f"pty:{tmp_path / 'ttyLMS0'}", tmp_path) as ready:
        assert (ready.sensor, ready.model) == ("lms", "lms200")
        with LmsSerialClient(ready.path, baud=9600) as lms:
            lms.discard_input()  # the power-on telegram
            acked, reply = lms.request(b"\x30\x01")  # one full scan
            assert acked and reply.command == 0xB0
            first = b0_values(reply)
            assert any(np.array_equal(first, row) for row in log.values)
            lms.switch_baud(38400)
            acked, _ = lms.request(b"\x20\x24")  # continuous output of every scan
            assert acked
            streamed = [event for event in lms.events(2.5) if isinstance(event, Telegram) and event.command == 0xB0]
            lms.request(b"\x20\x25")
    assert len(streamed) >= 5
    for telegram in streamed:
        values = b0_values(telegram)
        assert any(np.array_equal(values, row) for row in log.values)
    assert len({b0_values(t).tobytes() for t in streamed}) >= 3  # the scans advance with the log
    assert os.path.lexists(tmp_path / "ttyLMS0") is False
