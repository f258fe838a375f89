"""A sensor's scans for all its endpoints, computed once each, off the loop and ahead of time.

A scan at simulated time t is a pure function of t, so the scan a device
will ask for at its next deadline is started on the scan thread as that
deadline is scheduled (`prefetch`), and it is ready when the device asks. A
steady stream (the same request at a constant stride, as a streaming device
makes) is computed SCAN_BATCH scans per job with `sensor.scans`, which
shares each numpy pass among them; its next batch is foreseen as one of its
scans is read and the batch runs low (`_follow_stream`), so it needs no
wake-up of its own. A request nobody foresaw is still computed alone, and
started at once.

When the machine cannot keep up (more sensors than its cores compute), a
device that is behind is handed the freshest scan ready that it has not sent
yet, with that scan's own time (`__call__`): it skips revolutions, it never
stalls on an old one nor sends a backlog. The jobs wait in the worker pool,
most urgent first across sensors, and a job leaves out, as it is sent, the
instants no device can send any more (`_bind`); a stream that loses
instants that way is then foreseen every m-th scan (`_spacing`, m ≥ 1 and
fractional: 1.5 is every other scan and every scan in turn), so what is
computed is what goes out, and each sensor gets its share. Counters: `late`
(scans handed out after a fresher one was due) and `skipped` (a stream's
scans never handed out).

A live change (the control API) alters the world from its instant on:
`invalidate_from` drops every scan kept or foreseen at or after that instant
and starts them again, so no scan computed ahead of a change is served after it.
"""

from __future__ import annotations

import asyncio
import copy
import math
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
# A steady stream's next batch is foreseen once the scans foreseen reach less than this long (wall)
# past the device's next scan: a stream faster than 1/PREFETCH_LEAD_S (an LMS200's 37.5 Hz) then
# has its batch under way a few scans ahead, a URG's (10 Hz) one scan ahead.
PREFETCH_LEAD_S = 0.07
# A behind stream is foreseen every m-th scan, m at most this (a sensor then sends one scan in 32).
MAX_SPACING = 32
# A spaced stream's batch spans at most this many strides per scan of a batch: a full batch (which shares
# its numpy passes) up to a spacing of 16. A batch foreseen at a smaller spacing than the workers need by
# the time one takes it is thinned then (`_thinned`), so a long span does not keep a spacing chosen before
# the cost was known. (At 4, a worker given 0.3-0.5 of a core spaced the streams 6-9 and computed jobs
# of 1.2-2.3 instants, each instant at 1.5x the cost of one in a full batch.)
MAX_BATCH_SPAN_STRIDES_PER_SCAN = 16
# A batch is thinned only if the spacing the workers need has grown this much since it was foreseen.
THIN_AT_SPACING_RATIO = 1.5
# A stream's demand lapses this long (wall) after its last scan, or four spaced strides at the spacing
# it had or the workers now need, whichever is longer (its device stopping the stream withdraws it at
# once): a stream waiting for its batch behind a long queue still counts (a fleet starting at 7x
# what its workers compute lost half its demand within 2 s, and was spaced too little).
DEMAND_VALID_S = 3.0
# While the workers keep up, a request read at once (a CoLa poll, a GD) whose own scan is not computed yet
# is handed a scan foreseen before it only if that one is at most this much older (simulated s): a real
# unit answers a poll with its latest scan, at most a period old (10 Hz, the slowest model's). Without the
# bound, a poller that paused got the scan foreseen right after its last poll, seconds to minutes old.
INPUT_STAND_IN_MAX_AGE_S = 0.1


class ScanSource(Protocol):
    """What a device needs from a sensor: the scan for a request at a simulated time,
    and the same request at several times computed together."""

    def scan(self, time_s: float, **request: Any) -> Scan: ...

    def scans(self, times_s: Sequence[float], **request: Any) -> list[Scan]: ...


SensorFactory = Callable[[SensorSpec], ScanSource]
ScanObserver = Callable[[Scan], None]
# defer(simulated seconds, fn): run fn on the loop's thread that much later (the daemon's timer)
Defer = Callable[[float, Callable[[], None]], Any]
Now = Callable[[], float]  # the daemon's simulated time (read from the worker pool's thread too)
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
        now: Now | None = None,
        speed: Callable[[], float] | None = None,
        after_send: bool = False,
    ) -> None:
        if size < 2 * batch:
            raise ValueError(f"a scan cache of {size} cannot hold two batches of {batch}")
        self.waits = 0  # requests that found their scan not yet computed
        self.late = 0  # scans handed out after a fresher one was due (the device was behind)
        self.skipped = 0  # a stream's scans never handed out (the device skipped them)
        self.served = 0  # scans handed out (once per instant)
        self.dropped = 0  # instants left out of jobs as a worker took them (nobody could send them by then)
        self._now = now
        self._clock_speed = speed
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
        self._told_strides: dict[RequestKey, float] = {}  # streams' periods their devices told (`expect`)
        self._observer = observer  # told of each scan handed to a device (once per instant): must return at once
        # `after_send`: what a device's read of its scan sets going (foreseeing the stream's next scans,
        # telling the observer) waits for `settle()`, which the daemon calls once the device's output has
        # gone: a wake-up's work before its send is then the lookup and the encoding alone.
        self._after_send: list[Callable[[], None]] | None = [] if after_send else None
        self._observed_tick: int | None = None
        # scans dropped by a live change whose old job is still under way (`invalidate_from`)
        self._outdated: dict[tuple, Future] = {}
        self._defer = defer
        self._deferred: dict[int, Callable[[], None]] = {}  # id(part future) → start its batch now
        self._served_tick: dict[RequestKey, int] = {}  # per request: the newest instant handed out
        self._bound_tick: dict[RequestKey, int] = {}  # per request: the newest instant a job was sent for
        self._spacing: dict[RequestKey, float] = {}  # a stream foreseen every m-th scan (1: every scan)
        # What `input_scan` chose for a request read at once: (cache key, the scan to hand out, None for
        # the one asked for); the read that follows takes it as it is, for the spacing may turn between.
        self._input_choice: tuple[tuple, Future | None] | None = None

    def __call__(self, time_s: float, **request: Any) -> Scan:
        """What a device calls: the scan for this request (computed now, alone, if not foreseen)."""
        self._last_request = request
        shape, tick = _request_key(request), round(time_s * TICKS_PER_S)
        key = _cache_key(time_s, request)
        future = self._futures.get(key)
        ready = _ready(future)  # (each look at a future takes its lock: once)
        choice = self._input_choice
        if choice is not None and choice[0] == key and (ready or _ready(choice[1])):
            fresher = None if ready else choice[1]  # a request read at once: as `input_scan` chose
        else:  # (a choice a live change has since undone is not waited on: chosen again)
            fresher = None if ready or self._now is None else self._freshest_ready(shape, tick)
            if fresher is None and not ready and self._now is not None and self._behind():
                fresher = self._newest_ready(shape, tick)
        if fresher is not None:  # behind: the freshest scan not yet sent, with its own time (not the one asked)
            self._then(self._follow_stream, time_s, request)
            future = fresher
        else:
            future = self._future(time_s, request)
            self._then(self._follow_stream, time_s, request)
            if not _ready(future):
                future = self._future(time_s, request)  # a dropped instant is started again
                self._start_now(future)  # a batch still waiting for its quiet moment: the caller needs it now
                self.waits += 1  # the caller's thread waits for a computation (a miss, or a late job)
        try:
            scan = future.result()
        except BaseException:
            self._forget(future)  # computed again if asked again (a restarted worker may succeed)
            raise
        scan_tick = round(scan.time_s * TICKS_PER_S)
        if scan_tick == tick and scan.time_s != time_s:
            scan = _with_time(scan, time_s)
        if scan_tick != self._observed_tick:  # several endpoints of one sensor: count and tell once
            self._observed_tick = scan_tick
            self._count_served(shape, scan_tick, late=scan_tick < tick)
            if self._observer is not None:
                self._then(self._observer, scan)
        return scan

    def _then(self, work: Callable[..., None], *args: Any) -> None:
        """`work(*args)` now, or (`after_send`) at the next `settle()`, in order."""
        if self._after_send is None:
            work(*args)
        else:
            self._after_send.append(lambda: work(*args))

    def ready_scan(self, time_s: float) -> Scan | None:
        """The last request's scan at `time_s` if it is computed, else None; nothing else happens (no
        counting, no foreseeing): a device encodes its next scan ahead with it. None while behind: the
        device will then send a fresher scan than the one asked for."""
        request = self._last_request
        if request is None or (self._now is not None and self._behind()):
            return None
        future = self._futures.get(_cache_key(time_s, request))
        return future.result() if _ready(future) else None

    def settle(self) -> None:
        """Do what reads of scans put off (`after_send`): the device's output has gone."""
        while self._after_send:
            work, self._after_send = self._after_send, []
            for item in work:
                item()

    def _count_served(self, shape: RequestKey, tick: int, *, late: bool) -> None:
        previous = self._served_tick.get(shape)
        self._served_tick[shape] = max(tick, previous if previous is not None else tick)
        self.served += 1
        self.late += late
        stride = self._strides.get(shape)
        if previous is not None and stride is not None and tick > previous:
            self.skipped += max(0, round((tick - previous) / (stride * TICKS_PER_S)) - 1)

    def _newest_ready(self, shape: RequestKey, tick: int) -> Future | None:
        """The newest computed scan of this request not after `tick`, even one already handed out."""
        ready = [(key[0], future) for key, future in self._futures.items() if key[1:] == shape and key[0] <= tick and _ready(future)]
        return max(ready, key=lambda pair: pair[0])[1] if ready else None

    def _freshest_ready(self, shape: RequestKey, tick: int, oldest: int = -1) -> Future | None:
        """The newest computed scan of this request after the last one handed out (and not before
        `oldest`) and not after `tick` (only a cache that knows the daemon's clock hands one out for a
        later one: a direct caller always gets the scan it asked for)."""
        served = max(self._served_tick.get(shape, -1), oldest - 1)
        ready = [(key[0], future) for key, future in self._futures.items()
                 if served < key[0] <= tick and key[1:] == shape and _ready(future)]
        return max(ready, key=lambda pair: pair[0])[1] if ready else None

    def next_scan(self, time_s: float) -> tuple[Future | None, float | None]:
        """What a device due to read the last request's scan at `time_s` must wait for before it is
        polled, so that it never waits on the loop: (job, instant). No job: a scan is ready now, or
        will be at `instant` (simulated s; sleep till then). A device that is behind waits for the
        earliest scan under way that it has not sent (polled, it sends the freshest one ready);
        between a spaced stream's scans it sleeps till the next one, unless a worker is free."""
        request = self._last_request
        if request is None:
            return None, None
        shape, tick = _request_key(request), round(time_s * TICKS_PER_S)
        now = self._now() if self._now is not None else None
        limit = tick if now is None else max(tick, round(now * TICKS_PER_S))  # a poll reads the newest due
        served = self._served_tick.get(shape, -1)
        # Scans not sent yet, due by `limit` or later. Called on every scan: the ticks are compared first,
        # and only the scans due are checked (each check takes a future's lock), the later ones if needed.
        due: list[tuple[int, Future]] = []
        later: list[tuple[int, Future]] = []
        for key, future in self._futures.items():
            held_tick = key[0]
            if held_tick > served and key[1:] == shape:
                (due if held_tick <= limit else later).append((held_tick, future))
        due = [(held_tick, future) for held_tick, future in due if not future.cancelled()]
        if any(future.done() for _, future in due):
            return None, None
        if due:
            first = min(due, key=_tick_of)[1]
            self._start_now(first)
            return first, None
        outdated = self._outdated.get(_cache_key(time_s, request))
        if outdated is not None and not outdated.done():
            return outdated, None  # a live change dropped it: started again once its old job ends
        if later and self._behind():  # a spaced stream's next scan: the revolutions between are skipped
            for later_tick, future in sorted(later, key=_tick_of):
                if not future.cancelled():
                    self._start_now(future)
                    return (None if future.done() else future), later_tick / TICKS_PER_S
        return self._future(self._current(time_s, shape), request, foreseen=True), None

    def input_scan(self, time_s: float) -> Future | None:
        """The job a request read at once (a GD, an LMS200 30 01) must wait for, if any: none when a
        scan not yet sent is ready; else the scan at `time_s`, computed before every job waiting
        (a command's reply, an LMS200's ACK with it, must not wait for a behind fleet's turn)."""
        request = self._last_request
        if request is None:
            return None
        key = _cache_key(time_s, request)
        future = self._futures.get(key)
        self._input_choice = (key, None)
        if _ready(future):
            return None
        stand_in = self._input_stand_in(key[1:], key[0])
        if stand_in is not None:
            self._input_choice = (key, stand_in)
            return None
        if _held(future) and self._idle():  # under way, or waiting for its quiet moment
            self._start_now(future)
            return future
        if _held(future):
            future.cancel()  # its batch leaves it out; this job goes first
        self._outdated.pop(key, None)
        return self._submit_one(time_s, request, key, urgency=-math.inf)

    def _input_stand_in(self, shape: RequestKey, tick: int) -> Future | None:
        """The scan a request read at once gets when its own is not computed: behind, the freshest one
        not sent yet, else the newest there is (an LMS200's ACK must not wait for a behind fleet's
        turn); on time, the freshest not sent yet if at most INPUT_STAND_IN_MAX_AGE_S old; else none
        (it is computed first of all jobs)."""
        if self._now is None:
            return None
        if self._behind():
            fresher = self._freshest_ready(shape, tick)
            return fresher if fresher is not None else self._newest_ready(shape, tick)
        return self._freshest_ready(shape, tick, oldest=tick - round(INPUT_STAND_IN_MAX_AGE_S * TICKS_PER_S))

    def _current(self, time_s: float, shape: RequestKey) -> float:
        """The stream's newest instant due by now at or after `time_s` (a behind device's next scan)."""
        stride, now = self._strides.get(shape), self._now() if self._now is not None else None
        if stride is None or now is None or now < time_s + stride:
            return time_s
        return time_s + ((now - time_s) // stride) * stride

    def _behind(self) -> bool:
        """Whether the workers cannot compute every scan of every stream (streams are spaced): a
        revolution between a spaced stream's scans is then skipped, not computed alone."""
        return getattr(self._executor, "spacing", 1.0) > 1.0

    def _job_cost_s(self, instants: int) -> float:
        """Wall seconds a worker takes lately for a job of `instants` (0 if the executor cannot tell)."""
        job_cost_s = getattr(self._executor, "job_cost_s", None)
        if job_cost_s is not None:
            return job_cost_s(instants) or 0.0
        return instants * (getattr(self._executor, "instant_cost_s", None) or 0.0)

    def _idle(self) -> bool:
        """Whether a scan asked for now is computed at once (a free worker, nothing waiting)."""
        return getattr(self._executor, "idle", True)

    def expect(self, request: dict[str, Any], stride_s: float | None = None) -> None:
        """The request a device will make, told before its first one: that first scan is then
        foreseen (`prefetch`, `pending`) like every later one, instead of making its caller wait.
        `stride_s`: its stream's period, if it streams and can say: the stream is then batched from
        its first scans, even when a busy machine makes it skip some."""
        if self._last_request is None:
            self._last_request = dict(request)
        shape = _request_key(request)
        if stride_s is None:
            if self._told_strides.pop(shape, None) is not None and hasattr(self._executor, "demand"):
                self._executor.demand((id(self), shape), 0.0, 0.0)  # the stream stopped: its demand with it,
                for key, future in list(self._futures.items()):  # and the scans foreseen for it that wait
                    if key[1:] == shape and not future.done():
                        future.cancel()
        else:
            self._told_strides[shape] = stride_s

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
        for shape, bound in self._bound_tick.items():
            self._bound_tick[shape] = min(bound, first_tick - 1)  # what was sent from then on counts no more
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
        future = self._futures.get(key)
        return None if future is None or future.cancelled() else future

    def __len__(self) -> int:
        """How many scans (done or under way) the cache holds: at most its size."""
        return len(self._futures)

    def prefetch(self, time_s: float) -> None:
        """Make sure the scan the device will most likely ask for at `time_s` is foreseen (called as its
        wake-up is scheduled; a lookup when it is): the next batch if it is the stream's next scan past
        those foreseen, else that scan alone, started at once."""
        request = self._last_request
        if request is None:
            return
        outdated = self._outdated.get(_cache_key(time_s, request))
        if outdated is not None and not outdated.done():
            return  # started again once its outdated job ends (`pending`)
        shape = _request_key(request)
        until, stride = self._predicted_until.get(shape), self._strides.get(shape)
        step = None if stride is None else stride * math.ceil(self._spacing.get(shape, 1.0))
        if until is not None and step is not None and until < time_s <= until + step + STRIDE_TOLERANCE_S:
            self._predict(shape, until, stride, request)
        elif stride is not None and self._behind() and not _held(
            self._futures.get(_cache_key(time_s, request))
        ):
            return  # behind: a stream's scans come from its batches (and `next_scan`), not one by one
        else:
            self._future(time_s, request, foreseen=True)

    def _future(self, time_s: float, request: dict[str, Any], *, foreseen: bool = False) -> Future:
        """The scan's future, started if need be; a `foreseen` one is dropped if, once a worker is
        free for it, its device can no longer send it (one asked for is always computed)."""
        key = _cache_key(time_s, request)
        future = self._futures.get(key)
        if future is None or future.cancelled():
            self._outdated.pop(key, None)
            future = self._submit_one(time_s, request, key, foreseen=foreseen)
        else:
            self._futures.move_to_end(key)
        return future

    def _submit_one(
        self, time_s: float, request: dict[str, Any], key: tuple, urgency: float | None = None, *, foreseen: bool = False
    ) -> Future:
        """One scan, computed alone (held in the cache under `key` before a worker may take it);
        queued by its instant, or by `urgency`."""
        schedule = getattr(self._executor, "schedule", None)
        if schedule is None:
            future = self._executor.submit(self._sensor.scan, time_s, **request)
            self._store(key, future)
            return future
        part: Future = Future()
        self._store(key, part)

        def prepare() -> tuple | None:
            bound = self._bind(key[1:], [(time_s, key, part)], foreseen=foreseen)
            return (bound[0][0],) if bound else None

        job = schedule(self._sensor.scan, time_s if urgency is None else urgency, prepare, request)
        job.add_done_callback(lambda done: _settle_one(done, part))
        return part

    def _bind(
        self, shape: RequestKey, entries: list[tuple[float, tuple, Future]], *, foreseen: bool
    ) -> list[tuple[float, Future]]:
        """The instants a job computes, chosen as a worker takes it (on the pool's thread): of
        `entries` (time, cache key, future), those still held; of a `foreseen` job, not those its
        device already passed, and of those due by the time it is done only the newest, moved on to the stream's
        current revolution if a later one has completed meanwhile (a device sends the freshest
        scan; computing an older one would be wasted), unless a job already sent computes that one
        or a later. The futures left out are cancelled (whoever waits for one looks again)."""
        kept = [(time_s, key, part) for time_s, key, part in entries if self._futures.get(key) is part and not part.done()]
        now = self._now() if self._now is not None else None
        rebound = False
        if foreseen and kept:
            served = self._served_tick.get(shape, -1)
            kept = [entry for entry in kept if entry[1][0] > served]
            stride = self._strides.get(shape)
            if now is not None:
                # due by the time the job is done (what a job of as many instants takes a worker lately)
                done_by = now + self._job_cost_s(len(kept)) * self._speed()
                due = [entry for entry in kept if entry[0] <= done_by]
                kept = [entry for entry in kept if entry[0] > done_by]
                if due:
                    time_s, key, part = due[-1]
                    if stride is not None and time_s + stride <= now:
                        time_s, rebound = time_s + math.floor((now - time_s) / stride + 1e-9) * stride, True
                    if not rebound or round(time_s * TICKS_PER_S) > self._bound_tick.get(shape, -1):
                        kept.insert(0, (time_s, key, part))
            if stride is not None and len(kept) > 1:
                kept = self._thinned(kept, stride)
            if kept:
                self._bound_tick[shape] = max(self._bound_tick.get(shape, -1), round(kept[-1][0] * TICKS_PER_S))
        for _, _, part in entries:
            if all(part is not kept_part for _, _, kept_part in kept):
                self.dropped += part.cancel()
        return [(time_s, part) for time_s, _, part in kept]

    def _thinned(self, kept: list[tuple[float, tuple, Future]], stride: float) -> list[tuple[float, tuple, Future]]:
        """A batch foreseen at a smaller spacing than the workers need now (a fleet starting, or
        the machine giving them less of its cores) computes only every m-th scan of it: the others
        would be skipped by the device (it sends the freshest) at the cost of what the stream needs."""
        spacing = min(MAX_SPACING, getattr(self._executor, "spacing", 1.0))
        foreseen_at = (kept[-1][0] - kept[0][0]) / ((len(kept) - 1) * stride)  # the batch's own spacing
        if spacing < THIN_AT_SPACING_RATIO * foreseen_at:
            return kept  # the spacing's ordinary swings: the batch stays whole
        gap = (spacing - 1.0) * stride - STRIDE_TOLERANCE_S  # a batch at spacing m has gaps of ⌊m⌋ or ⌈m⌉ strides
        thinned = [kept[0]]
        for entry in kept[1:]:
            if entry[0] - thinned[-1][0] >= gap:
                thinned.append(entry)
        return thinned

    def _forget(self, future: Future) -> None:
        for key in [key for key, stored in self._futures.items() if stored is future]:
            del self._futures[key]

    def _store(self, key: tuple, future: Future) -> None:
        self._futures[key] = future
        if len(self._futures) > self._size:
            self._futures.popitem(last=False)

    def _follow_stream(self, time_s: float, request: dict[str, Any]) -> None:
        """Batch the stream's next scans once its last two strides agree (a device that is behind
        then asks at whole multiples of it) and at most one foreseen scan is left: the batch is
        then one stride ahead of its first use."""
        shape = _request_key(request)
        times = self._recent_times.setdefault(shape, deque(maxlen=3))
        if times and round(times[-1] * TICKS_PER_S) == round(time_s * TICKS_PER_S):
            return  # another endpoint asking for the same scan
        times.append(time_s)
        stride = self._strides.get(shape)
        gap = times[-1] - times[-2] if len(times) > 1 else None
        told = self._told_strides.get(shape)
        if told is not None:
            if gap is not None and not (gap > 0 and _multiple(gap, told)):
                return  # a request off the stream's grid (a GD between its scans): the stream goes on
            stride = self._strides[shape] = told
        elif stride is not None and gap is not None and gap > 0 and _multiple(gap, stride):
            pass  # the same stream, maybe skipping scans
        elif len(times) == 3 and gap is not None and gap > 0 and abs(gap - (times[1] - times[0])) <= STRIDE_TOLERANCE_S:
            stride = self._strides[shape] = gap
        else:
            self._predicted_until.pop(shape, None)
            self._strides.pop(shape, None)
            self._spacing.pop(shape, None)
            return
        assert stride is not None
        previous = self._spacing.get(shape, 1.0)
        spacing = self._adjust_spacing(shape, stride)
        if previous > 1.0 >= spacing:  # caught up: every scan again from now on (those foreseen are kept)
            self._predict(shape, time_s, stride, request)
            return
        # behind, the next batch is foreseen two scans ahead: it waits its turn among the other sensors';
        # on time, while the scans foreseen reach less than PREFETCH_LEAD_S past the next one
        lead = 2 * stride * spacing if spacing > 1.0 else stride + PREFETCH_LEAD_S * self._speed()
        until = self._predicted_until.get(shape)
        if until is not None and until - time_s > lead + STRIDE_TOLERANCE_S:
            return  # enough foreseen
        if until is not None and until > time_s - STRIDE_TOLERANCE_S:
            self._predict(shape, until, stride, request)
        elif self._spacing.get(shape, 1.0) <= 1.0:  # a new stream: its first batch is short by the phase
            self._predict(shape, time_s, stride, request, count=self._batch - self._phase)
        else:
            self._predict(shape, time_s, stride, request)

    def _adjust_spacing(self, shape: RequestKey, stride: float) -> float:
        """Every how many scans the stream is foreseen: what the workers can keep up with, the same
        for every stream (1 with a thread, or while they keep up). The stream states its demand."""
        demand = getattr(self._executor, "demand", None)
        if demand is not None:  # stated again at the stream's next scan, or it lapses (its client left)
            spacing = max(self._spacing.get(shape, 1.0), getattr(self._executor, "spacing", 1.0))
            demand((id(self), shape), self._speed() / stride, max(DEMAND_VALID_S, 4.0 * spacing * stride / self._speed()))
        spacing = self._spacing[shape] = min(MAX_SPACING, getattr(self._executor, "spacing", 1.0))
        return spacing

    def _speed(self) -> float:
        """Simulated seconds per wall second."""
        return self._clock_speed() if self._clock_speed is not None else 1.0

    def _predict(
        self, shape: RequestKey, after_s: float, stride: float, request: dict[str, Any], count: int | None = None
    ) -> None:
        """Foresee the stream's next `count` scans after `after_s` (default SCAN_BATCH, every m-th scan of
        a spaced stream: as many as span SCAN_BATCH strides), in one job, started in the quiet half a
        stride later (`BATCH_START_DELAY_STRIDES`) when the cache can defer."""
        spacing = self._spacing.get(shape, 1.0)
        count = count or max(1, min(self._batch, math.floor(MAX_BATCH_SPAN_STRIDES_PER_SCAN * self._batch / spacing)))
        predicted = [after_s + round(j * spacing) * stride for j in range(1, count + 1)]  # on the revolutions' grid
        self._predicted_until[shape] = predicted[-1]
        self._submit_batch(predicted, request, delay_s=BATCH_START_DELAY_STRIDES * stride)

    def _submit_batch(self, times_s: list[float], request: dict[str, Any], delay_s: float = 0.0) -> None:
        """One `sensor.scans` job for the times not already foreseen; a future per time, held
        at once (so `pending` finds them), the job itself started now or `delay_s` later."""
        shape = _request_key(request)
        wanted = [(time_s, _cache_key(time_s, request)) for time_s in times_s]
        wanted = [(time_s, key) for time_s, key in wanted if not _held(self._futures.get(key))]
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
            schedule = getattr(self._executor, "schedule", None)
            if schedule is None:
                job = self._executor.submit(self._sensor.scans, [time_s for time_s, _ in held], **request)
                job.add_done_callback(lambda done: _settle(done, [part for _, part in held]))
                return
            sent: list[Future] = []

            def prepare() -> tuple | None:
                """At the moment a worker takes the job: the instants it computes (on the pool's thread)."""
                bound = self._bind(shape, [(time_s, key, part) for (time_s, key), part in zip(wanted, parts)], foreseen=True)
                sent.extend(part for _, part in bound)
                return ([time_s for time_s, _ in bound],) if bound else None

            job = schedule(self._sensor.scans, held[0][0], prepare, request)
            job.add_done_callback(lambda done: _settle(done, sent))

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
    if not request:  # a URG's: several lookups a scan
        return ()
    return tuple(sorted(request.items()))


def _tick_of(pair: tuple[int, Future]) -> int:
    return pair[0]


def _with_time(scan: Scan, time_s: float) -> Scan:
    """The scan with the device's own float for its instant (the same µs tick): a shallow copy, as
    `dataclasses.replace` makes, at a fraction of its cost (it ran on every scan of a batch)."""
    copied = copy.copy(scan)
    object.__setattr__(copied, "time_s", time_s)
    return copied


def _cache_key(time_s: float, request: dict[str, Any]) -> tuple:
    """The µs tick and the request: a foreseen t + j·d meets the device's (index + j) × period."""
    return (round(time_s * TICKS_PER_S), *_request_key(request))


def _settle(job: Future, parts: list[Future]) -> None:
    """Hand each of a batch job's scans (or its failure) to the future of its time."""
    for index, part in enumerate(parts):
        if part.done():
            continue  # dropped meanwhile (cancelled): nobody waits for it
        if job.cancelled():
            part.cancel()
        elif job.exception() is not None:
            part.set_exception(job.exception())
        else:
            part.set_result(job.result()[index])


def _settle_one(job: Future, part: Future) -> None:
    if part.done():
        return
    if job.cancelled():
        part.cancel()
    elif job.exception() is not None:
        part.set_exception(job.exception())
    else:
        part.set_result(job.result())


def _ready(future: Future | None) -> bool:
    """A computed scan (not a failure, not dropped)."""
    return future is not None and future.done() and not future.cancelled() and future.exception() is None


def _held(future: Future | None) -> bool:
    """A scan computed or under way (not dropped)."""
    return future is not None and not future.cancelled()


def _multiple(gap: float, stride: float) -> bool:
    """Whether `gap` is a whole number of `stride`s (each µs-rounded)."""
    count = round(gap / stride)
    return count >= 1 and abs(gap - count * stride) <= count * STRIDE_TOLERANCE_S
