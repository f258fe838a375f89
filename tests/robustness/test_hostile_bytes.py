"""Hypothesis-driven hostile bytes on every endpoint kind of one running daemon.

Each example writes arbitrary bytes (and sometimes hangs up mid-stream) to one
endpoint of the URG or the LMS200; afterwards the daemon is alive, the other
sensor still answers on its own endpoint, and its memory stays bounded. Add an
endpoint kind to `hostile.RAW_CLIENTS` and to ENDPOINTS here and it is attacked too.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from emulator.bench.hostile import RAW_CLIENTS, open_raw, rss_kib
from emulator.bench.serve_process import ServeProcess
from tests.robustness.conftest import SCALE

# (sensor, scheme) pairs attacked; each kind in RAW_CLIENTS on both sensors
ENDPOINTS = [(sensor, scheme) for scheme in sorted(RAW_CLIENTS) for sensor in ("urg", "lms")]
RSS_GROWTH_LIMIT_KIB = 64 * 1024

# Bytes a parser must survive: random runs, command-like lines, LMS frame starts with wild lengths.
hostile_chunks = st.one_of(
    st.binary(max_size=4096),
    st.lists(st.sampled_from([b"GD0000076801\n", b"MD0044072501000\n", b"QT\n", b"SCIP2.0\n", b"\x02\x00\xff\xff",
                              b"\x02\x00\x02\x00\x20\x24", b"\r", b"\n" * 64, b"X" * 200]), max_size=200).map(b"".join),
)


@pytest.fixture(scope="module")
def served(tmp_path_factory: pytest.TempPathFactory):
    folder: Path = tmp_path_factory.mktemp("hostile")
    endpoints = [f"urg=pty:{folder / 'ttyURG0'}", "urg=tcp:127.0.0.1:0",
                 f"lms=pty:{folder / 'ttyLMS0'}", "lms=tcp:127.0.0.1:0", f"urg=pty:{folder / 'ttyURGwatch'}"]
    with ServeProcess("railway", endpoints) as daemon:
        yield daemon, str(folder / "ttyURGwatch")


def urg_answers(path: str) -> bool:
    client = open_raw(f"pty:{path}")
    try:
        client.send(b"VV\n")
        reply = b""
        for _ in range(50):
            reply += client.drain(0.1)
            if b"\n\n" in reply:
                break
        return reply.startswith(b"VV\n00P\n")
    finally:
        client.close()


@pytest.mark.parametrize(("sensor", "scheme"), ENDPOINTS)
def test_hostile_bytes_on_any_endpoint_leave_the_daemon_serving(served, sensor: str, scheme: str) -> None:
    daemon, watch_path = served
    uri = next(ready.uri for ready in daemon.ready if ready.sensor == sensor and ready.uri.startswith(scheme + ":")
               and not ready.uri.endswith("ttyURGwatch"))
    rss_before = rss_kib(daemon.pid)

    @settings(max_examples=int(15 * SCALE), deadline=None, suppress_health_check=list(HealthCheck))
    @given(chunks=st.lists(hostile_chunks, min_size=1, max_size=4), hang_up_early=st.booleans())
    def attack(chunks: list[bytes], hang_up_early: bool) -> None:
        client = open_raw(uri, 9600 if sensor == "lms" else None)
        try:
            for chunk in chunks:
                client.send(chunk, timeout_s=0.5)
                if not hang_up_early:
                    client.drain(0.01)
        finally:
            client.close()
        assert daemon.process.poll() is None, daemon.stderr[-2000:]

    attack()
    assert urg_answers(watch_path), "the watching client got no reply after the attack"
    assert rss_kib(daemon.pid) - rss_before < RSS_GROWTH_LIMIT_KIB
    assert "Traceback" not in daemon.stderr
