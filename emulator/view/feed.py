"""The scans a running daemon hands to its devices, for viewers and recorders on other threads.

The daemon's scan caches call `LiveFeed.scan_delivered` on the loop thread for
each new scan; it only stores the scan as its sensor's latest and puts it in
each subscriber's bounded queue (dropping it, and counting, when a subscriber
falls behind): nothing is encoded or written on the loop.

A sensor nobody reads has no scans, yet a viewer wants to see what it would
see: while anyone watches (`watchers` > 0), each such sensor's configured scan
(its scene options' window) is asked of its scan cache at most IDLE_RATE_HZ
times a second, so it is computed where the devices' scans are (the scan
thread or a worker process), and fed like a delivered one. The request is
made on the loop thread (the cache is the loop's); the idle thread only
decides when. With no one watching this costs nothing.
"""

from __future__ import annotations

import asyncio
import queue
import threading
import time
from concurrent.futures import Future
from typing import Any, Callable, Mapping

from emulator.daemon.scan_cache import ScanCache
from emulator.sensors.scan import Scan

IDLE_RATE_HZ = 10.0
IDLE_AFTER_S = 0.5  # wall seconds without a delivered scan before a sensor counts as unread
SUBSCRIBER_QUEUE = 256


class LiveFeed:
    """Latest scans per sensor, subscriber queues, and idle scans while someone watches."""

    def __init__(self, now: Callable[[], float]) -> None:
        self._now = now
        self.latest: dict[str, Scan] = {}
        self._delivered_at: dict[str, float] = {}
        self._subscribers: list[queue.Queue[Scan]] = []
        self.dropped = 0
        self._watchers = 0
        self._lock = threading.Lock()
        self._caches: Mapping[str, ScanCache] = {}
        self._requests: Mapping[str, dict[str, Any]] = {}
        self._loop: asyncio.AbstractEventLoop | None = None
        self._pending: dict[str, Future] = {}
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def subscribe(self, size: int = SUBSCRIBER_QUEUE) -> queue.Queue[Scan]:
        """A queue that receives every scan from now on (the oldest are dropped if it is not emptied)."""
        subscriber: queue.Queue[Scan] = queue.Queue(maxsize=size)
        self._subscribers = [*self._subscribers, subscriber]
        return subscriber

    def scan_delivered(self, scan: Scan) -> None:
        """Called by a scan cache on the loop thread: store and queue, nothing more."""
        self._delivered_at[scan.sensor] = time.monotonic()
        self._publish(scan)

    def _publish(self, scan: Scan) -> None:
        self.latest[scan.sensor] = scan
        for subscriber in self._subscribers:
            try:
                subscriber.put_nowait(scan)
            except queue.Full:
                self.dropped += 1

    def watch(self) -> None:
        """Someone started watching: keep unread sensors scanning (module docstring)."""
        with self._lock:
            self._watchers += 1

    def unwatch(self) -> None:
        with self._lock:
            self._watchers = max(0, self._watchers - 1)

    @property
    def watchers(self) -> int:
        return self._watchers

    def start(
        self, caches: Mapping[str, ScanCache], requests: Mapping[str, dict[str, Any]], loop: asyncio.AbstractEventLoop
    ) -> None:
        """Begin idle scanning of the daemon's started `caches` with each sensor's configured
        `requests`; the requests are made on `loop`, the daemon's."""
        self._caches, self._requests, self._loop = caches, requests, loop
        self._thread = threading.Thread(target=self._idle_loop, name="feed-idle", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)

    def _idle_loop(self) -> None:
        while not self._stop.wait(1.0 / IDLE_RATE_HZ):
            if self._watchers > 0:
                self._scan_unread()

    def _scan_unread(self) -> None:
        wall = time.monotonic()
        for name in list(self._requests):  # the sensors served (a daemon may hold caches for others)
            if wall - self._delivered_at.get(name, -1e9) < IDLE_AFTER_S:
                continue
            pending = self._pending.get(name)
            if pending is not None and not pending.done():
                continue
            try:
                self._loop.call_soon_threadsafe(self._request_idle_scan, name)
            except RuntimeError:  # the loop has closed: the daemon is stopping
                return

    def _request_idle_scan(self, name: str) -> None:
        """On the loop: ask the sensor's cache for its configured scan now."""
        try:
            future = self._caches[name].request(self._now(), **self._requests[name])
        except (KeyError, RuntimeError):  # not started yet, or the scan executor has shut down
            return
        self._pending[name] = future
        future.add_done_callback(self._idle_done)

    def _idle_done(self, future: Future) -> None:
        if not future.cancelled() and future.exception() is None:
            self._publish(future.result())
