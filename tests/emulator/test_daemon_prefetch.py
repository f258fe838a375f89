"""The daemon prefetches the scan a device will ask for, not merely its next deadline."""

from __future__ import annotations

import asyncio
import heapq
import itertools
from types import SimpleNamespace
from typing import Any, Callable

import numpy as np

from emulator.daemon.clock import ManualClock
from emulator.daemon.service import DeviceSession
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
