"""Which scan job a free worker computes next, and how often each stream can be computed.

Jobs wait here, not in the workers' pipes. A free worker takes the most
urgent job (the earliest simulated instant, across sensors), and the job is
prepared only then, so it can leave out what no device can send any more by
that moment (the scan caches decide what, `ScanCache._bind`).

When the streams want more instants per second than the workers compute,
`spacing` says every how many scans each stream is computed: their demand
(stated by each stream, `demand`) over what an instant costs the workers, one
figure for every stream, so each sensor gets the same share. The cost is the
workers' own CPU time, which each job reports (a fixed part per job and a part
per instant, fitted over the last jobs), over the share of a core they got
(their CPU over wall time): the wall time of the jobs as they came, which
shrank as batches did, is not taken for an instant's cost. A batch's fixed
part counts as much as the batches at that spacing share it (`batch_at`).
"""

from __future__ import annotations

import heapq
import itertools
import math
import time
from collections import deque
from concurrent.futures import Future
from dataclasses import dataclass, field
from typing import Any, Callable

from emulator.daemon.scan_cache import MAX_BATCH_SPAN_STRIDES_PER_SCAN, SCAN_BATCH

# A job's message, made as a worker takes it: ("scan"/"scans", sensor, *args), or None when nothing
# it would compute is still wanted (its future is then cancelled).
Prepare = Callable[[], tuple | None]

# What an instant costs: the workers' jobs finished in this long (wall). On a shared machine the share of a
# core a worker gets swings over seconds; a spacing that follows each swing spaces the streams unevenly
# (a batch keeps the spacing it was foreseen at for its span). In the simulation with the workers' share
# alternating 0.25 / 0.55 every 3 s: 3 s of jobs gave 71-76 % of what they computed, fairness 0.64-0.79;
# 6 s, 91-93 % and 0.93-0.97.
COST_WINDOW_S = 6.0
# Spacing for 5 % more demand than measured: the daemon's loop and its clients share the cores.
SPACING_HEADROOM = 1.05
# A job's fixed cost in instants' worth (its numpy passes whatever the count: one instant alone costs
# ~1.5x one in a batch of 8), until jobs of different sizes in the window tell it (`computed`).
PRIOR_JOB_COST_INSTANTS = 0.6
MAX_JOB_COST_INSTANTS = 8.0
# The share of a core below which a worker's CPU over wall time is not believed (a stalled clock read).
MIN_CPU_SHARE = 0.02
DEMAND_PURGE_S = 0.1  # lapsed demands are looked for at most this often (wall)


def batch_at(spacing: float) -> int:
    """The instants a stream's batch holds when it is computed every `spacing`-th scan
    (`ScanCache._predict`: SCAN_BATCH, fewer for a spacing past MAX_BATCH_SPAN_STRIDES_PER_SCAN)."""
    return max(1, min(SCAN_BATCH, math.floor(MAX_BATCH_SPAN_STRIDES_PER_SCAN * SCAN_BATCH / spacing)))


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
        # (finished at, wall s, instants, CPU s) of recent jobs, and their sums kept as jobs come and go
        self._computed: deque[tuple[float, float, int, float]] = deque()
        self._computed_wall_s = 0.0
        self._computed_instants = 0
        self._computed_cpu_s = 0.0
        self._sum_n2 = 0.0
        self._sum_n_cpu = 0.0
        self._job_cost_instants = PRIOR_JOB_COST_INSTANTS
        self._cpu_per_instant_s: float | None = None
        self._cpu_share = 1.0
        self._demand: dict[Any, tuple[float, float]] = {}  # stream → (instants per wall second, valid until)
        self._wanted = 0.0  # their sum
        self._purge_at = -math.inf
        self._spacing = 1.0

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

    def computed(self, instants: int, wall_s: float, cpu_s: float | None = None) -> None:
        """A worker computed `instants` in `wall_s` (from sending the job to its result), of which
        it spent `cpu_s` computing (its own CPU time; None: all of it)."""
        now = self._wall()
        instants = max(1, instants)
        cpu_s = wall_s if cpu_s is None else max(0.0, cpu_s)
        self._computed.append((now, wall_s, instants, cpu_s))
        self._add(wall_s, instants, cpu_s, 1)
        while self._computed and self._computed[0][0] < now - COST_WINDOW_S:
            _, old_wall_s, old_instants, old_cpu_s = self._computed.popleft()
            self._add(old_wall_s, old_instants, old_cpu_s, -1)
        self._fit()
        self._update_spacing()

    def _add(self, wall_s: float, instants: int, cpu_s: float, sign: int) -> None:
        self._computed_wall_s += sign * wall_s
        self._computed_instants += sign * instants
        self._computed_cpu_s += sign * cpu_s
        self._sum_n2 += sign * instants * instants
        self._sum_n_cpu += sign * instants * cpu_s

    def _fit(self) -> None:
        """A job's CPU as a fixed part plus a part per instant, from the jobs in the window: the fixed
        part's size (in instants) is learnt while their sizes differ (a stream's first batch is
        short), and kept when they all hold as many."""
        jobs = len(self._computed)
        if not jobs:
            return
        mean_n, mean_cpu = self._computed_instants / jobs, self._computed_cpu_s / jobs
        variance = self._sum_n2 / jobs - mean_n * mean_n
        if jobs >= 4 and variance >= 0.5:
            per_instant = (self._sum_n_cpu / jobs - mean_n * mean_cpu) / variance
            fixed = mean_cpu - per_instant * mean_n
            if per_instant > 0.0:
                self._job_cost_instants = min(MAX_JOB_COST_INSTANTS, max(0.0, fixed / per_instant))
        # the window's CPU shared as its jobs' fixed parts and instants
        self._cpu_per_instant_s = self._computed_cpu_s / (self._computed_instants + jobs * self._job_cost_instants)
        wall = max(0.0, self._computed_wall_s)
        self._cpu_share = min(1.0, max(MIN_CPU_SHARE, self._computed_cpu_s / wall)) if wall > 0 else 1.0

    @property
    def instant_cost_s(self) -> float | None:
        """Wall seconds a worker takes per instant in a full batch lately (None before any job):
        its CPU per instant over the share of a core it got."""
        return None if self._cpu_per_instant_s is None else self.job_cost_s(SCAN_BATCH) / SCAN_BATCH

    def job_cost_s(self, instants: int) -> float | None:
        """Wall seconds a worker takes lately for a job of `instants` (None before any job)."""
        if self._cpu_per_instant_s is None:
            return None
        return (self._job_cost_instants + max(1, instants)) * self._cpu_per_instant_s / self._cpu_share

    @property
    def cpu_share(self) -> float:
        """The share of a core a busy worker got lately (CPU over wall time of its jobs)."""
        return self._cpu_share

    def demand(self, stream: Any, per_second: float, valid_s: float) -> None:
        """A stream wants `per_second` instants each wall second, for `valid_s` (wall) unless stated
        again (each of its scans does): a client that left stops counting."""
        now = self._wall()
        previous = self._demand.get(stream)
        self._wanted += per_second - (previous[0] if previous is not None else 0.0)
        self._demand[stream] = (per_second, now + valid_s)
        if now >= self._purge_at or per_second != (previous[0] if previous is not None else None):
            self._purge(now)
            self._update_spacing()

    def _purge(self, now: float) -> None:
        self._purge_at = now + DEMAND_PURGE_S
        for stream in [stream for stream, (_, until) in self._demand.items() if until < now]:
            self._wanted -= self._demand.pop(stream)[0]
        if not self._demand:
            self._wanted = 0.0  # no rounding left over

    @property
    def spacing(self) -> float:
        """Every how many scans each stream should be computed so that the workers keep up
        (1 while they do; 1.5: two scans in three). Kept up to date as jobs finish and demands
        change (read on every scan handed out: a lookup, safe from any thread)."""
        return self._spacing

    def _update_spacing(self) -> None:
        """The workers' wall time per instant at the batches streams get at a spacing, times the demand:
        spacing shrinks a batch (`batch_at`), whose instants then cost more each; found by iterating."""
        if self._cpu_per_instant_s is None:
            self._spacing = 1.0
            return
        spacing = 1.0
        for _ in range(4):
            cost = self.job_cost_s(batch_at(spacing)) / batch_at(spacing)
            spacing = max(1.0, self._wanted * cost * SPACING_HEADROOM / self.workers)
        self._spacing = spacing
