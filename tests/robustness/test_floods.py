"""Floods against one endpoint of the real daemon: the other sensor keeps answering and streaming."""

from __future__ import annotations

import numpy as np
import pytest

from emulator.bench.hostile import (
    NOMINAL_SCANS_PER_S,
    RAW_CLIENTS,
    Flood,
    attach_lms,
    lms_command_latencies,
    lms_scan_rate,
    open_raw,
    rss_kib,
)
from emulator.bench.lms_client import host_telegram
from emulator.bench.serve_process import ServeProcess
from tests.robustness.conftest import SCALE


@pytest.mark.parametrize("scheme", sorted(RAW_CLIENTS))
def test_one_64_kib_write_of_bad_commands_leaves_the_other_sensor_answering(daemon: ServeProcess, scheme: str) -> None:
    """b"X\\n" × 32768 in one write cost 36 s of CPU (the outbox walked its queue on every put)."""
    with attach_lms(daemon.endpoint("lms", "pty").path) as lms:
        attacker = open_raw(daemon.endpoint("urg", scheme).uri)
        try:
            assert attacker.send(b"X\n" * 32768) > 0
            assert lms_command_latencies(lms, 3, timeout_s=3.0).max() < 3.0
        finally:
            attacker.close()
    assert daemon.stop(timeout_s=5.0) == 0


@pytest.mark.parametrize("scheme", sorted(RAW_CLIENTS))
def test_thousands_of_unknown_lms_telegrams_leave_the_other_endpoint_answering(daemon: ServeProcess, scheme: str) -> None:
    """9360 unknown LMS telegrams in one write (each ACKed and answered 92) took 11.8 s."""
    uri = [ready.uri for ready in daemon.ready if ready.sensor == "lms" and ready.uri.startswith(scheme)][0]
    telegrams = host_telegram(b"\x55") * 9360
    watcher_scheme = "tcp" if scheme == "pty" else "pty"
    attacker = open_raw(uri, 9600)
    try:
        attacker.send(telegrams, timeout_s=1.0)
        urg = open_raw(daemon.endpoint("urg", watcher_scheme).uri)
        try:
            urg.send(b"VV\n")
            reply = b""
            for _ in range(30):
                reply += urg.drain(0.1)
                if reply.endswith(b"\n\n"):
                    break
            assert reply.startswith(b"VV\n00P\n")
        finally:
            urg.close()
    finally:
        attacker.close()
    assert daemon.stop(timeout_s=5.0) == 0


def test_a_gd_flood_and_junk_leave_the_lms200_stream_its_rate(daemon: ServeProcess) -> None:
    """64 KiB bursts of GD0000076801 took the LMS200 beside them from 37.5 to 2.7 scans/s."""
    duration_s = 4.0 * SCALE
    with attach_lms(daemon.endpoint("lms", "pty").path) as lms:
        rss_before = rss_kib(daemon.pid)
        with Flood(daemon.endpoint("urg", "tcp").uri, "gd"), Flood(daemon.endpoint("urg", "pty").uri, "junk", period_s=1.0):
            rate = lms_scan_rate(lms, duration_s)
            latencies = lms_command_latencies(lms, 20)
        rss_after = rss_kib(daemon.pid)
    assert rate >= 0.9 * NOMINAL_SCANS_PER_S, f"{rate:.1f} scans/s of {NOMINAL_SCANS_PER_S}"
    assert np.percentile(latencies, 99) < 0.2, latencies
    assert rss_after - rss_before < 50_000, (rss_before, rss_after)
