"""A sensor's scans for all its endpoints, computed once each, off the loop and ahead of time.

A scan at simulated time t is a pure function of t, so shortly before a
device's next deadline the scan it will ask for is started on the scan
thread, and it is ready when the device asks. A steady stream (the same
request at a constant stride, as a streaming device makes) is computed
SCAN_BATCH scans per job with `sensor.scans`, which shares each numpy pass
among them; a request nobody foresaw is still computed alone.

A live change (the control API) alters the world from its instant on:
`invalidate_from` drops every scan kept or foreseen at or after that instant
and starts them again, so no scan computed ahead of a change is served after it.
"""

from __future__ import annotations

import asyncio
import dataclasses
from collections import OrderedDict, deque
from concurrent.futures import Executor, Future
from typing import Any, Callable, Protocol, Sequence

from emulator.scene.model import SensorSpec
from emulator.sensors.scan import (  # cache keys are µs ticks: the grid scans are computed on
    TICKS_PER_S,
    Scan,
)

SCAN_CACHE_SIZE = 32  # recent scan requests per sensor; endpoints of one sensor share them
# Scans computed per job in a steady stream: `physical` pays ~500 numpy calls a
# pass whatever the number of instants, so 8 share that floor well, while a
# stream that stops wastes at most one batch (0.2 s of LMS200 scans).
SCAN_BATCH = 8
# Two strides are the same stream if they agree this closely: devices ask at
# index × period, which the µs grid rounds to strides one tick apart.
STRIDE_TOLERANCE_S = 1e-6
# Start a scan this long (wall) before its deadline: early enough to be ready,
# late enough not to compete for the CPU with the previous scan's delivery
# (on a pty the kernel forwards bytes on a worker thread that a busy CPU delays).
PREFETCH_LEAD_S = 0.07


class ScanSource(Protocol):
    """What a device needs from a sensor: the scan for a request at a simulated time,
    and the same request at several times computed together."""

    def scan(self, time_s: float, **request: Any) -> Scan: ...

    def scans(self, times_s: Sequence[float], **request: Any) -> list[Scan]: ...


SensorFactory = Callable[[SensorSpec], ScanSource]
ScanObserver = Callable[[Scan], None]
# defer(simulated seconds, fn): run fn on the loop's thread that much later (the daemon's timer)
Defer = Callable[[float, Callable[[], None]], Any]
# A steady stream's next batch is foreseen as a device reads a scan, i.e. while that scan goes
# out on the wire and its client reads it; it is started this many strides later, in the quiet
# between two scans, so the worker computing it does not compete for a core with the delivery
# (measured: the scan at a batch boundary 2.4 ms late on average at 2 cores, others 0.3 ms).
BATCH_START_DELAY_STRIDES = 0.5
RequestKey = tuple[tuple[str, Any], ...]


class ScanCache:
    """One sensor's scans for all its endpoints: each request computed once, on the
    scan thread, and ahead of time where the next request can be foreseen: the last
    request's window at the device's next deadline (`prefetch`), and the next
    SCAN_BATCH scans of a steady stream, in one `sensor.scans` job."""

    def __init__(
        self,
        sensor: ScanSource,
        executor: Executor,
        size: int = SCAN_CACHE_SIZE,
        batch: int = SCAN_BATCH,
        *,
        phase: int = 0,
        observer: ScanObserver | None = None,
        defer: Defer | None = None,
    ) -> None:
        if size < 2 * batch:
            raise ValueError(f"a scan cache of {size} cannot hold two batches of {batch}")
        self.waits = 0  # requests that found their scan not yet computed
        self._sensor = sensor
        self._executor = executor
        self._size = size
        self._batch = batch
        # A stream's first batch is `phase` scans short, so the batches of sensors with
        # different phases fall due at different scans instead of all together.
        self._phase = phase % batch
        self._futures: OrderedDict[tuple, Future] = OrderedDict()
        self._last_request: dict[str, Any] | None = None
        self._recent_times: dict[RequestKey, deque[float]] = {}
        self._predicted_until: dict[RequestKey, float] = {}
        self._strides: dict[RequestKey, float] = {}
        self._observer = observer  # told of each scan handed to a device (once per instant): must return at once
        self._observed_tick: int | None = None
        # scans dropped by a live change whose old job is still under way (`invalidate_from`)
        self._outdated: dict[tuple, Future] = {}
        self._defer = defer
        self._deferred: dict[int, Callable[[], None]] = {}  # id(part future) → start its batch now

    def __call__(self, time_s: float, **request: Any) -> Scan:
        """What a device calls: the scan for this request (computed now, alone, if not foreseen)."""
        self._last_request = request
        future = self.request(time_s, **request)
        self._start_now(future)  # a batch still waiting for its quiet moment: the caller needs it now
        if not future.done():
            self.waits += 1  # the caller's thread waits for a computation (a miss, or a late job)
        try:
            scan = future.result()
        except BaseException:
            self._forget(future)  # computed again if asked again (a restarted worker may succeed)
            raise
        scan = scan if scan.time_s == time_s else dataclasses.replace(scan, time_s=time_s)
        if self._observer is not None:
            tick = round(time_s * TICKS_PER_S)
            if tick != self._observed_tick:  # several endpoints of one sensor: tell once
                self._observed_tick = tick
                self._observer(scan)
        return scan

    def expect(self, request: dict[str, Any]) -> None:
        """The request a device will make, told before its first one: that first scan is then
        foreseen (`prefetch`, `pending`) like every later one, instead of making its caller wait."""
        if self._last_request is None:
            self._last_request = dict(request)

    def request(self, time_s: float, **request: Any) -> Future:
        """The scan for this request as a future (for readers that must not block, like the control API);
        a steady stream of them is foreseen and batched as a device's is."""
        future = self._future(time_s, request)
        self._follow_stream(time_s, request)
        return future

    def holds(self, time_s: float, future: Future, **request: Any) -> bool:
        """Whether `future` is still this request's scan (a live change since may have replaced it)."""
        return self._futures.get(_cache_key(time_s, request)) is future

    def invalidate_from(self, time_s: float) -> None:
        """Drop every scan kept or foreseen at or after `time_s` (the world changed from then on).

        Only the earliest dropped scan of each request is started again at once (the one a device
        may already be waiting for), and only if its old job is finished: a job still under way
        for it is `outdated`, and the scan is started again once it ends and someone asks
        (`pending`, `prefetch`). So a stream of changes (a 100 Hz pose stream) keeps at most one
        job per scan under way instead of queueing one per change. The later scans are computed
        when foreseen again; the stream's batching resumes from the earliest."""
        first_tick = round(time_s * TICKS_PER_S)
        earliest: dict[tuple, tuple] = {}
        for key in [key for key in self._futures if key[0] >= first_tick]:
            job = self._futures.pop(key)
            if key[1:] not in earliest or key[0] < earliest[key[1:]][0][0]:
                earliest[key[1:]] = (key, job)
        for shape, (key, job) in earliest.items():
            again_s = key[0] / TICKS_PER_S
            if self._predicted_until.get(shape, -1.0) >= again_s:
                self._predicted_until[shape] = again_s
            if job.done():
                self._submit_batch([again_s], dict(shape))
            else:
                self._outdated[key] = job
                self._restart_when_done(key, job)
        for key in sorted(self._outdated, key=lambda key: key[0])[: max(0, len(self._outdated) - self._size)]:
            del self._outdated[key]  # the oldest: long past, no device asks for them any more

    def _restart_when_done(self, key: tuple, job: Future) -> None:
        """Start an outdated scan again as soon as its old job ends (on the loop's thread, which owns
        the cache), so a device seldom waits for two jobs in turn; without a running loop (a direct
        caller) it is started when asked for (`pending`, `prefetch`, a call)."""
        try:
            loop = asyncio.get_running_loop()
        except RuntimeError:
            return
        def restart(_: Future) -> None:
            try:
                loop.call_soon_threadsafe(self._restart_outdated, key, job)
            except RuntimeError:  # the loop was closed meanwhile (the daemon stopped)
                pass

        job.add_done_callback(restart)

    def _restart_outdated(self, key: tuple, job: Future) -> None:
        if self._outdated.get(key) is job and key not in self._futures:
            self._future(key[0] / TICKS_PER_S, dict(key[1:]))

    def pending(self, time_s: float) -> Future | None:
        """The job computing the last request's scan at `time_s`, if one was started: a daemon
        waits for it (without blocking) before waking the device that will ask for it."""
        if self._last_request is None:
            return None
        key = _cache_key(time_s, self._last_request)
        if key not in self._futures and key in self._outdated:  # a live change dropped it
            outdated = self._outdated[key]
            if not outdated.done():
                return outdated  # wait for it to end, then ask again
            return self._future(time_s, self._last_request)
        return self._futures.get(key)

    def __len__(self) -> int:
        """How many scans (done or under way) the cache holds: at most its size."""
        return len(self._futures)

    def prefetch(self, time_s: float) -> None:
        """Start computing the scan the device will most likely ask for at `time_s`: the next batch
        if it is the stream's next scan past those foreseen (the prefetch lead can exceed a stride)."""
        request = self._last_request
        if request is None:
            return
        outdated = self._outdated.get(_cache_key(time_s, request))
        if outdated is not None and not outdated.done():
            return  # started again once its outdated job ends (`pending`)
        shape = _request_key(request)
        until, stride = self._predicted_until.get(shape), self._strides.get(shape)
        if until is not None and stride is not None and abs(time_s - (until + stride)) <= STRIDE_TOLERANCE_S:
            self._predict(shape, until, stride, request)
        else:
            self._future(time_s, request)

    def _future(self, time_s: float, request: dict[str, Any]) -> Future:
        key = _cache_key(time_s, request)
        future = self._futures.get(key)
        if future is None:
            self._outdated.pop(key, None)
            future = self._executor.submit(self._sensor.scan, time_s, **request)
            self._store(key, future)
        else:
            self._futures.move_to_end(key)
        return future

    def _forget(self, future: Future) -> None:
        for key in [key for key, stored in self._futures.items() if stored is future]:
            del self._futures[key]

    def _store(self, key: tuple, future: Future) -> None:
        self._futures[key] = future
        if len(self._futures) > self._size:
            self._futures.popitem(last=False)

    def _follow_stream(self, time_s: float, request: dict[str, Any]) -> None:
        """Batch the stream's next scans once its last two strides agree and at most
        one foreseen scan is left: the batch is then one stride ahead of its first use."""
        shape = _request_key(request)
        times = self._recent_times.setdefault(shape, deque(maxlen=3))
        if times and round(times[-1] * TICKS_PER_S) == round(time_s * TICKS_PER_S):
            return  # another endpoint asking for the same scan
        times.append(time_s)
        strides = [later - earlier for earlier, later in zip(times, list(times)[1:])]
        if len(strides) < 2 or strides[-1] <= 0 or abs(strides[-1] - strides[-2]) > STRIDE_TOLERANCE_S:
            self._predicted_until.pop(shape, None)
            self._strides.pop(shape, None)
            return
        stride = self._strides[shape] = strides[-1]
        until = self._predicted_until.get(shape)
        if until is not None and until - time_s > stride + STRIDE_TOLERANCE_S:
            return  # enough foreseen
        if until is not None and until > time_s - STRIDE_TOLERANCE_S:
            self._predict(shape, until, stride, request)
        else:  # a new stream: its first batch is short by the phase
            self._predict(shape, time_s, stride, request, count=self._batch - self._phase)

    def _predict(
        self, shape: RequestKey, after_s: float, stride: float, request: dict[str, Any], count: int | None = None
    ) -> None:
        """Foresee the stream's next `count` (default SCAN_BATCH) scans after `after_s`, in one job,
        started in the quiet half a stride later (`BATCH_START_DELAY_STRIDES`) when the cache can defer."""
        predicted = [after_s + j * stride for j in range(1, (count or self._batch) + 1)]
        self._predicted_until[shape] = predicted[-1]
        self._submit_batch(predicted, request, delay_s=BATCH_START_DELAY_STRIDES * stride)

    def _submit_batch(self, times_s: list[float], request: dict[str, Any], delay_s: float = 0.0) -> None:
        """One `sensor.scans` job for the times not already foreseen; a future per time, held
        at once (so `pending` finds them), the job itself started now or `delay_s` later."""
        wanted = [(time_s, _cache_key(time_s, request)) for time_s in times_s]
        wanted = [(time_s, key) for time_s, key in wanted if key not in self._futures]
        if not wanted:
            return
        parts: list[Future] = []
        for _, key in wanted:
            parts.append(Future())
            self._store(key, parts[-1])

        def start() -> None:
            if not any(id(part) in self._deferred for part in parts):
                return  # started already (a caller needed one of its scans first)
            for part in parts:
                self._deferred.pop(id(part), None)
            held = [(time_s, part) for (time_s, key), part in zip(wanted, parts) if self._futures.get(key) is part]
            for (_, key), part in zip(wanted, parts):
                if self._futures.get(key) is not part:
                    part.cancel()  # dropped meanwhile (a live change): nobody waits for it
            if not held:
                return
            job = self._executor.submit(self._sensor.scans, [time_s for time_s, _ in held], **request)
            job.add_done_callback(lambda done: _settle(done, [part for _, part in held]))

        for part in parts:
            self._deferred[id(part)] = start
        if self._defer is None or delay_s <= 0:
            start()
        else:
            self._defer(delay_s, start)

    def _start_now(self, future: Future) -> None:
        start = self._deferred.get(id(future))
        if start is not None:
            start()


def _request_key(request: dict[str, Any]) -> RequestKey:
    return tuple(sorted(request.items()))


def _cache_key(time_s: float, request: dict[str, Any]) -> tuple:
    """The µs tick and the request: a foreseen t + j·d meets the device's (index + j) × period."""
    return (round(time_s * TICKS_PER_S), *_request_key(request))


def _settle(job: Future, parts: list[Future]) -> None:
    """Hand each of a batch job's scans (or its failure) to the future of its time."""
    if job.cancelled():
        for part in parts:
            part.cancel()
    elif job.exception() is not None:
        for part in parts:
            part.set_exception(job.exception())
    else:
        for part, scan in zip(parts, job.result()):
            part.set_result(scan)
