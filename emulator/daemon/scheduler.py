"""Which scan job a free worker computes next, and how often each stream can be computed.

Jobs wait here, not in the workers' pipes. A free worker takes the most
urgent job (the earliest simulated instant, across sensors), and the job is
prepared only then, so it can leave out what no device can send any more by
that moment (the scan caches decide what, `ScanCache._bind`).

When the streams want more instants per second than the workers compute,
`spacing` says every how many scans each stream is computed: their demand
(stated by each stream, `demand`) over what an instant has cost the workers
lately, in wall time (so the share of the cores the machine gives them counts).
One figure for every stream: each sensor gets the same share.
"""

from __future__ import annotations

import heapq
import itertools
import time
from collections import deque
from concurrent.futures import Future
from dataclasses import dataclass, field
from typing import Any, Callable

# A job's message, made as a worker takes it: ("scan"/"scans", sensor, *args), or None when nothing
# it would compute is still wanted (its future is then cancelled).
Prepare = Callable[[], tuple | None]

COST_WINDOW_S = 3.0  # an instant's cost: the workers' wall time over the instants they computed in this long
# Spacing for 5 % more demand than measured: the daemon's loop and its clients share the cores.
SPACING_HEADROOM = 1.05


@dataclass(order=True)
class _Waiting:
    urgency: float
    order: int
    prepare: Prepare = field(compare=False)
    future: Future = field(compare=False)


class Scheduler:
    """Scan jobs waiting for one of `workers` workers. Not thread-safe: its owner locks."""

    def __init__(self, workers: int, wall: Callable[[], float] = time.monotonic) -> None:
        self.workers = max(1, workers)
        self._wall = wall
        self._waiting: list[_Waiting] = []  # a heap
        self._order = itertools.count()
        self._computed: deque[tuple[float, float, int]] = deque()  # (finished at, wall s, instants) of recent jobs
        # their sums, kept as jobs come and go: `spacing` is read on every scan handed out
        self._computed_wall_s = 0.0
        self._computed_instants = 0
        self._demand: dict[Any, tuple[float, float]] = {}  # stream → (instants per wall second, valid until)

    def __len__(self) -> int:
        """Jobs waiting (some may turn out to be no longer wanted)."""
        return len(self._waiting)

    def push(self, urgency: float, prepare: Prepare) -> Future:
        """Queue a job; `urgency`: its earliest instant (simulated s), smaller first."""
        future: Future = Future()
        heapq.heappush(self._waiting, _Waiting(urgency, next(self._order), prepare, future))
        return future

    def take(self) -> tuple[tuple, Future] | None:
        """The most urgent job still wanted, prepared now (its message and future); None if none waits.
        Jobs found no longer wanted on the way are dropped (their futures cancelled)."""
        while self._waiting:
            waiting = heapq.heappop(self._waiting)
            if waiting.future.cancelled():
                continue
            try:
                message = waiting.prepare()
            except Exception as error:  # a bug in a cache's preparation: that job fails, the others go on
                waiting.future.set_exception(error)
                continue
            if message is None:
                waiting.future.cancel()
                continue
            return message, waiting.future
        return None

    def cancel_all(self) -> None:
        for waiting in self._waiting:
            waiting.future.cancel()
        self._waiting.clear()

    def computed(self, instants: int, wall_s: float) -> None:
        """A worker computed `instants` in `wall_s` (from sending the job to its result)."""
        now = self._wall()
        self._computed.append((now, wall_s, max(1, instants)))
        self._computed_wall_s += wall_s
        self._computed_instants += max(1, instants)
        while self._computed and self._computed[0][0] < now - COST_WINDOW_S:
            _, old_wall_s, old_instants = self._computed.popleft()
            self._computed_wall_s -= old_wall_s
            self._computed_instants -= old_instants

    @property
    def instant_cost_s(self) -> float | None:
        """Wall seconds a worker took per instant over the last COST_WINDOW_S (None before any job)."""
        if not self._computed:
            return None
        return max(0.0, self._computed_wall_s) / self._computed_instants

    def demand(self, stream: Any, per_second: float, valid_s: float) -> None:
        """A stream wants `per_second` instants each wall second, for `valid_s` (wall) unless stated
        again (each of its scans does): a client that left stops counting."""
        self._demand[stream] = (per_second, self._wall() + valid_s)

    @property
    def spacing(self) -> float:
        """Every how many scans each stream should be computed so that the workers keep up
        (1 while they do; 1.5: two scans in three)."""
        cost = self.instant_cost_s
        if cost is None:
            return 1.0
        now = self._wall()
        for stream in [stream for stream, (_, until) in self._demand.items() if until < now]:
            del self._demand[stream]
        wanted = sum(rate for rate, _ in self._demand.values())
        overload = wanted * cost * SPACING_HEADROOM / self.workers
        return max(1.0, overload)
