"""The daemon prefetches the scan a device will ask for, not merely its next deadline."""

from __future__ import annotations

import asyncio
import heapq
import re
import itertools
import socket
import threading
from concurrent.futures import Future
from types import SimpleNamespace
from typing import Any, Callable

import numpy as np

from emulator.bench.serve_process import ServeProcess
from emulator.daemon.clock import ManualClock
from emulator.daemon.scan_cache import ScanCache
from emulator.daemon.service import DeviceSession
from emulator.daemon.workers import WorkerFailed
from emulator.sensors.scan import Scan
from tests.emulator.test_serve_disconnect import stats
from protocols.lms2xx import Lms200Device, build_telegram


class SimulatedTimers:
    """`call_later` on a ManualClock: callbacks run in time order as `run_until` advances it."""

    def __init__(self, clock: ManualClock) -> None:
        self.clock = clock
        self._heap: list[tuple[float, int, Any]] = []
        self._order = itertools.count()

    def call_later(self, delay: float, callback: Callable[..., None], *args: Any) -> SimpleNamespace:
        handle = SimpleNamespace(cancelled=False)
        handle.cancel = lambda: setattr(handle, "cancelled", True)
        heapq.heappush(self._heap, (self.clock.now() + delay, next(self._order), (handle, callback, args)))
        return handle

    def run_until(self, end: float) -> None:
        while self._heap and self._heap[0][0] <= end:
            when, _, (handle, callback, args) = heapq.heappop(self._heap)
            if not handle.cancelled:
                self.clock.advance(when - self.clock.now())
                callback(*args)


def test_an_lms200_on_a_slow_line_is_prefetched_the_scan_it_then_sends() -> None:
    """At 38400 baud a telegram takes 190 ms: the device's deadline is when the line frees,
    and it then sends the newest complete scan, which the prefetch must aim at."""
    clock = ManualClock()
    timers = SimulatedTimers(clock)
    asked: list[float] = []
    prefetched: list[float] = []

    def scans(time_s: float, *, count: int, **_: Any) -> SimpleNamespace:
        asked.append(time_s)
        return SimpleNamespace(values=np.full(count, 1000))

    device = Lms200Device(scans, baud=38400)
    loop = asyncio.new_event_loop()
    try:
        session = DeviceSession(device, clock, loop, prefetch=prefetched.append, call_later=timers.call_later)
        session.start()
        timers.run_until(0.5)
        session.received(build_telegram(0, b"\x20\x24"))
        timers.run_until(5.0)
    finally:
        loop.close()
    assert len(asked) > 20
    assert set(asked) <= set(prefetched), sorted(set(asked) - set(prefetched))[:5]


class RecordingSource:
    def scan(self, time_s: float) -> Scan:
        return Scan("urg", "urg-04lx", time_s, np.zeros(3), np.full(3, 1000))

    def scans(self, times_s: list[float]) -> list[Scan]:
        return [self.scan(time_s) for time_s in times_s]


class HeldExecutor:
    """Runs jobs only when released (or after `give_up_s`, so a test that blocks on one ends)."""

    def __init__(self, give_up_s: float = 2.0) -> None:
        self.run_at_once = True
        self.held: list[tuple[Future, Callable[[], Any]]] = []
        self._give_up_s = give_up_s

    def submit(self, fn: Callable[..., Any], *args: Any, **kwargs: Any) -> Future:
        future: Future = Future()
        job = (future, lambda: future.set_result(fn(*args, **kwargs)))
        if self.run_at_once:
            job[1]()
        else:
            self.held.append(job)
            threading.Timer(self._give_up_s, self.release).start()
        return future

    def release(self) -> None:
        while self.held:
            future, run = self.held.pop(0)
            if not future.done():
                run()


class OneScanDevice:
    """Wants the scan at 1.0 s once, at its deadline 1.0 s."""

    def __init__(self, scans: Callable[..., Any]) -> None:
        self.scans, self.sent = scans, []
        self.baud = None

    def next_deadline(self) -> float | None:
        return None if self.sent else 1.0

    def poll(self, now: float) -> list:
        self.sent.append(self.scans(1.0))
        return []


def test_a_scan_nobody_foresaw_is_started_at_the_deadline_and_waited_for_without_blocking_the_loop() -> None:
    executor = HeldExecutor()
    cache = ScanCache(RecordingSource(), executor)
    cache(0.5)  # an earlier client's request: the cache knows what this sensor is asked for
    executor.run_at_once = False
    loop = asyncio.new_event_loop()
    device = OneScanDevice(cache)
    session: DeviceSession

    def wake_only(delay: float, callback: Callable[..., None], *args: Any) -> Any:
        if callback == session._wake:  # prefetch timers never fire: the scan is not foreseen
            return loop.call_later(delay, callback, *args)
        return SimpleNamespace(cancel=lambda: None)

    session = DeviceSession(device, ManualClock(1.0), loop, cache.prefetch, wake_only, pending=cache.pending)
    try:
        session.start()
        loop.run_until_complete(asyncio.sleep(0.05))
        assert device.sent == [] and len(executor.held) == 1  # started, and the device waits for it
        executor.release()
        loop.run_until_complete(asyncio.sleep(0.05))
    finally:
        loop.close()
    assert [scan.time_s for scan in device.sent] == [1.0]
    assert cache.waits == 0  # the loop never waited on the computation


def test_a_new_clients_first_scans_are_computed_ahead_and_the_loop_never_waits_for_one() -> None:
    """A URG's and an LMS200's first streamed scans, against the real daemon and its workers:
    the devices say what they will ask for (`scan_request`), so not one scan makes the loop wait
    (`scan_waits`, counted each time a device's request finds its scan still being computed)."""
    with ServeProcess("railway", ["urg=tcp:127.0.0.1:0", "lms=tcp:127.0.0.1:0"], extra_args=["--workers", "2"]) as daemon:
        for _ in range(3):  # three clients in turn: each one's first scan is new to its sensor's cache
            with socket.create_connection(daemon.endpoint("urg").address, timeout=5) as urg, \
                    socket.create_connection(daemon.endpoint("lms").address, timeout=5) as lms:
                urg.sendall(b"MD0044072501000\n")
                lms.sendall(build_telegram(0x00, b"\x20\x24"))
                received = b""
                while received.count(b"\n\n") < 3:  # the echo and two scans
                    received += urg.recv(65536)
                lms_received = b""
                while b"\x02\x80\xd6\x02\xb0" not in lms_received:  # a B0 scan telegram's head (9600 Bd)
                    lms_received += lms.recv(65536)
        assert stats(daemon)["scan_waits"] == 0


def test_a_wake_up_sends_first_and_settles_the_scan_caches_bookkeeping_after() -> None:
    """What a device's read of its scan put off (the next batch foreseen, the view told) runs after its
    output has gone, at each delivery: a wake-up's work before its send stays the lookup and encoding."""
    clock = ManualClock()
    timers = SimulatedTimers(clock)
    order: list[str] = []

    def scans(time_s: float, *, count: int, **_: Any) -> SimpleNamespace:
        order.append("read")
        return SimpleNamespace(values=np.full(count, 1000))

    device = Lms200Device(scans, baud=500000)
    loop = asyncio.new_event_loop()
    try:
        session = DeviceSession(device, clock, loop, call_later=timers.call_later, settle=lambda: order.append("settle"))
        session.endpoint = SimpleNamespace(send=lambda outputs: order.append("send"))  # type: ignore[assignment]
        session.start()
        timers.run_until(0.1)
        session.received(build_telegram(0, b"\x20\x24"))  # every scan, continuously
        timers.run_until(0.5)
    finally:
        loop.close()
    tokens = "".join({"read": "R", "send": "s", "settle": "t"}[name] for name in order)
    assert re.fullmatch(r"(R*s?t)*", tokens), tokens  # each delivery: its reads, its send, then the settle
    assert tokens.count("Rst") > 10  # the scans streamed: read, sent, settled


def test_a_streaming_hokuyo_encodes_its_next_scan_after_a_send_and_its_deadline_only_sends() -> None:
    """After each send (and the settle) the session lets the device encode its next scan if the scan
    cache has it (`ready_scan`); at the deadline the scan is looked up, found encoded, and sent."""
    from protocols.scip.scip22 import Scip22Device

    clock = ManualClock()
    timers = SimulatedTimers(clock)
    order: list[str] = []
    kept: dict[int, Scan] = {}

    def scan_at(time_s: float) -> Scan:
        tick = round(time_s * 1e6)
        if tick not in kept:
            kept[tick] = Scan("ust", "UST-10LX", time_s, np.zeros(1081), np.full(1081, 1000 + tick % 977))
        return kept[tick]

    def read(time_s: float) -> Scan:
        order.append("read")
        return scan_at(time_s)

    device = Scip22Device(read, "ust-10lx")
    encode = device._encode_data
    device._encode_data = lambda *args: (order.append("encode"), encode(*args))[1]  # type: ignore[method-assign]
    loop = asyncio.new_event_loop()
    try:
        session = DeviceSession(device, clock, loop, call_later=timers.call_later, settle=lambda: order.append("settle"),
                                ready_scan=scan_at)
        session.endpoint = SimpleNamespace(send=lambda outputs: order.append("send"))  # type: ignore[assignment]
        session.start()
        session.received(b"MD0000108000000\n")
        timers.run_until(0.5)
    finally:
        loop.close()
    tokens = "".join({"read": "R", "encode": "E", "send": "s", "settle": "t"}[name] for name in order)
    assert tokens.count("RstE") >= 15  # looked up, sent, settled, the next one encoded
    assert tokens.count("REs") <= 1  # encoded at its deadline: at most the stream's first scan


class FailingOnceDevice:
    """A device whose first request reads a scan whose job failed (its worker died twice)."""

    baud = None

    def __init__(self) -> None:
        self.received: list[bytes] = []

    def receive(self, data: bytes, now: float) -> list:
        self.received.append(data)
        if len(self.received) == 1:
            raise WorkerFailed("worker 0 died twice computing it")
        return []

    def poll(self, now: float) -> list:
        return []

    def next_deadline(self) -> float | None:
        return None

    def connection_lost(self) -> None:
        pass


def test_a_request_whose_scan_failed_is_reported_and_the_next_input_is_taken(capsys: Any) -> None:
    """The failure escaped into the loop's exception handler, and the transport fed the client's next
    input no more (the client's requests waited for ever)."""
    loop = asyncio.new_event_loop()
    device = FailingOnceDevice()
    session = DeviceSession(device, ManualClock(1.0), loop)
    try:
        assert session.received(b"GD0044072501\n") is None
        assert session.received(b"VV\n") is None
    finally:
        loop.close()
    assert device.received == [b"GD0044072501\n", b"VV\n"]
    assert capsys.readouterr().err == "scan failed: WorkerFailed: worker 0 died twice computing it; the request that read it is not answered\n"
