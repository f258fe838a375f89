"""Every SCIP 2.2 Hokuyo against hostile clients on the real daemon: junk, floods, half lines, a client
that stops reading. Each complete line gets the unit's status, the attacked endpoint answers the next
client, and a client streaming another sensor gets its scans meanwhile."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from emulator.bench.hostile import RawClient, open_raw, rss_kib
from emulator.bench.serve_process import ServeProcess
from protocols.scip.scip22 import BOOT_S, REBOOT_DELAY_S
from tests.robustness.conftest import SCALE

MODELS = ("utm-30lx", "utm-30lx-ew", "ust-10lx", "ust-20lx")
RSS_GROWTH_LIMIT_KIB = 64 * 1024
STALL_S = 1.0  # a gap this long between two scans of the watched sensor is a stall
SCENE = """
[scene]
name = "scip22-robustness"
[[objects]]
name = "wall"
box = { size = [0.2, 30.0, 3.0] }
position = [3.6, 0.0, 1.0]
""" + "".join(
    f'[[sensors]]\nname = "{name}"\nmodel = "{name}"\nposition = [0.0, {index * 0.3}, 0.4]\n'
    f'endpoints = ["{"pty:{folder}/tty-" + name if name == "utm-30lx" else "tcp:127.0.0.1:0"}"]\n'
    for index, name in enumerate(MODELS)
)

scip_chunks = st.one_of(
    st.binary(max_size=4096),
    st.lists(st.sampled_from([
        b"GD0000108001\n", b"HE0000108000\n", b"ND0000108000000\n", b"ME0000108001000\n", b"BM\n", b"QT\n",
        b"TM0\n", b"TM1\n", b"RB\n", b"%ST\n", b"II\n", b"&&&&", b"\r", b"\n" * 64, b"X" * 200, b"GD9999999999\n",
    ]), max_size=200).map(b"".join),
)


@pytest.fixture(scope="module")
def served(tmp_path_factory: pytest.TempPathFactory):
    folder = tmp_path_factory.mktemp("scip22")
    scene = folder / "scip22.toml"
    scene.write_text(SCENE.replace("{folder}", str(folder)))
    with ServeProcess(scene, ()) as daemon:
        yield daemon


def uri(daemon: ServeProcess, model: str) -> str:
    return next(ready.uri for ready in daemon.ready if ready.sensor == model)


def ask(client: RawClient, command: bytes, timeout_s: float = 3.0) -> bytes:
    """The reply to `command` (whatever came before it is skipped)."""
    client.send(command + b"\n")
    received = b""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        received += client.drain(0.05)
        start = received.find(command + b"\n")
        end = received.find(b"\n\n", start)
        if start >= 0 and end >= 0:
            return received[start : end + 2]
    raise AssertionError(f"no reply to {command!r}; got {received[-200:]!r}")


def answers(daemon: ServeProcess, model: str) -> bool:
    """The next client, starting as drivers do (urg_library sends QT and ignores what comes back), is
    answered. On a pty a client that hung up mid-line and a next one opening at once can leave that
    half line in the unit's input, as on a real USB unit; QT's reply (perhaps an error for the joined
    line) ends it."""
    client = open_raw(uri(daemon, model))
    try:
        ask(client, b"QT")
        return ask(client, b"VV").startswith(b"VV\n00P\n")
    finally:
        client.close()


def watcher(model: str) -> str:
    return "ust-10lx" if model != "ust-10lx" else "utm-30lx-ew"


class Watch:
    """A client streaming another sensor (MD) on its own thread: its scans keep coming."""

    def __init__(self, daemon: ServeProcess, model: str) -> None:
        self.client = open_raw(uri(daemon, model))
        assert ask(self.client, b"MD0000108001000").startswith(b"MD0000108001000\n00P\n")
        self.arrivals: list[float] = []
        self._started = time.monotonic()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._read, daemon=True)
        self._thread.start()

    def _read(self) -> None:
        pending = b""
        while not self._stop.is_set():
            pending += self.client.drain(0.05)
            while (end := pending.find(b"\n\n")) >= 0:
                if pending.startswith(b"MD0000108001") and b"\n99b\n" in pending[: end + 2]:
                    self.arrivals.append(time.monotonic())
                pending = pending[end + 2 :]

    def check(self, watched_s: float = 1.0) -> None:
        time.sleep(max(0.0, self._started + watched_s - time.monotonic()))
        self._stop.set()
        self._thread.join(timeout=5.0)
        self.client.close()
        assert len(self.arrivals) >= 5, self.arrivals
        gaps = np.diff([self._started, *self.arrivals, time.monotonic()])
        assert gaps.max() < STALL_S, gaps.max()  # lateness is the bench's to measure, on a quiet machine


@pytest.mark.parametrize("model", MODELS)
def test_hostile_bytes_leave_every_hokuyo_answering(served: ServeProcess, model: str) -> None:
    rss_before = rss_kib(served.pid)
    watch = Watch(served, watcher(model))

    @settings(max_examples=int(10 * SCALE), deadline=None, suppress_health_check=list(HealthCheck))
    @given(chunks=st.lists(scip_chunks, min_size=1, max_size=4), hang_up_early=st.booleans())
    def attack(chunks: list[bytes], hang_up_early: bool) -> None:
        client = open_raw(uri(served, model))
        try:
            for chunk in chunks:
                client.send(chunk, timeout_s=0.5)
                if not hang_up_early:
                    client.drain(0.01)
        finally:
            client.close()
        assert served.process.poll() is None, served.stderr[-2000:]

    attack()
    watch.check()
    # the attack's RBs may have confirmed a reboot: a second later it drops whoever is connected, as a
    # unit does; the next client is answered once it has booted
    time.sleep(REBOOT_DELAY_S + BOOT_S + 0.2)
    assert answers(served, model)
    assert rss_kib(served.pid) - rss_before < RSS_GROWTH_LIMIT_KIB
    assert "Traceback" not in served.stderr


@pytest.mark.parametrize("model", MODELS)
def test_a_flood_of_unknown_commands_gets_0e_each_and_starves_no_one(served: ServeProcess, model: str) -> None:
    watch = Watch(served, watcher(model))
    client = open_raw(uri(served, model))
    try:
        count = 2000
        client.send(b"XX\n" * count, timeout_s=10.0)
        received = b""
        deadline = time.monotonic() + 20.0
        while received.count(b"XX\n0Ee\n\n") < count and time.monotonic() < deadline:
            received += client.drain(0.1)
        assert received.count(b"XX\n0Ee\n\n") == count
        assert ask(client, b"PP").startswith(b"PP\n00P\n")
    finally:
        client.close()
    watch.check()


def test_a_client_that_stops_reading_costs_another_sensor_nothing(served: ServeProcess) -> None:
    stalled = open_raw(uri(served, "utm-30lx-ew"))
    try:
        stalled.send(b"NE0000108000000\n")  # three echoes with intensity, never read
        watch = Watch(served, "ust-20lx")
        time.sleep(3.0)
        watch.check()
    finally:
        stalled.close()
    assert answers(served, "utm-30lx-ew")


def test_commands_written_without_reading_are_all_answered_once_the_client_reads(served: ServeProcess) -> None:
    """A client streaming scans writes 3000 VVs and a QT without reading, then reads. Replies past
    the outbox's bound used to make the daemon discard the client's further input: 512 VVs were
    answered, the QT was lost and the stream ran on. Now the client is not read until it has read
    (its bytes wait in the kernel, as with a real unit's TCP window): every command is answered, in
    order, and the QT ends the stream."""
    count = 3000
    client = open_raw(uri(served, "ust-10lx"))
    try:
        client.send(b"MD0000108000000\n" + b"VV\n" * count + b"QT\n", timeout_s=10.0)
        time.sleep(1.0)  # replies pile up unread past the outbox's bound
        received = b""
        deadline = time.monotonic() + 30.0
        while b"QT\n00P\n\n" not in received and time.monotonic() < deadline:
            received += client.drain(0.1)
        assert received.count(b"VV\n00P\n") == count
        assert b"QT\n00P\n\n" in received
        after_qt = received.split(b"QT\n00P\n\n", 1)[1] + client.drain(0.3)
        assert b"MD0000108000000\n99b\n" not in after_qt  # the stream stopped
    finally:
        client.close()
    assert answers(served, "ust-10lx")
