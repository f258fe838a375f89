"""Scans computed in worker processes, so a daemon uses every core and its loop never computes.

Each worker process builds its own optics world from the scene and holds
every sensor served; the daemon's scan caches hand jobs to the pool (through a
`WorkerExecutor`, a `concurrent.futures` executor whose `submit` takes a
`RemoteSensor`'s `scan` or `scans`, or `WorkerPool.schedule`) and get `Scan`s
back, pickled over a pipe.

Jobs wait in the pool, not in the workers' pipes: a worker holds one scan job
at a time, and when it is free it takes the most urgent job waiting (earliest
simulated instant first, across sensors). A scheduled job is prepared only as
it is sent, so it leaves out the instants no device can still send by then
(a machine that cannot keep up computes only scans that will go out).

The protocol on the pipe, parent → worker: `("scan", job, sensor, time_s, request)`,
`("scans", job, sensor, times_s, request)`, `("apply", job, events)` (world changes,
records of `scene.live.event_record`, applied at their simulated instants: live control; and
`{"op": "prune", "t"}`, the daemon's horizon: `LiveState.prune`; `{"op": "restore", "state"}`, a
`LiveState.export` a restarted worker starts from, the events after it carrying their `gen`) and
`("stop",)`; worker → parent: `("ready", pid)` once its world is built, then
`("done", job, result, cpu_s)` or `("failed", job, message, cpu_s)`, `cpu_s` the worker's CPU time
since its previous answer (what the job cost it, whatever share of a core the machine gave it).

Nothing writes to a worker's pipe while holding the pool's lock or on the
daemon's loop: each worker has an outbox drained by a sender thread of its
own. A pipe holds 64 KiB; a worker busy with a batch while world changes
arrive, or one stopped, leaves it full, and a write then waits. Under the
lock that was a deadlock (the reader thread, which must take the lock to
settle the worker's answer, could not drain the worker, which could not read
the pipe), and on the loop it froze every device and signal.

A worker that dies (killed, out of memory) is restarted with the same scene,
sensors and applied events, and the jobs it held are sent again (a scan is a
pure function of its time, so a repeat is the same scan); a job that kills a
worker twice fails with `WorkerCrashed`, so a device gets an error, never a
hang.
"""

from __future__ import annotations

import contextlib
import gc
import itertools
import multiprocessing
import multiprocessing.connection
import os
import queue
import sys
import threading
import time
import types
from concurrent.futures import Executor, Future
from dataclasses import dataclass, field
from multiprocessing.reduction import ForkingPickler
from typing import Any, Callable, Iterator, Sequence

from emulator.daemon.scheduler import Prepare, Scheduler
from emulator.scene.live import event_from_record
from emulator.scene.model import Scene
from emulator.sensors.scan import Scan

WORKER_START_TIMEOUT_S = 120.0  # building a world from a large mesh scene can take a while
SENDER_STOP_TIMEOUT_S = 2.0  # a sender thread given up on (a daemon thread) when its pipe never drains
MAX_ATTEMPTS = 2  # a job is sent to at most this many worker lives
# How many nice levels a worker computes below the daemon (`serve --worker-nice`; os.nice adds, at most 19). Workers compute a batch (0.2–0.8 s) ahead while a
# late byte on the wire is a protocol fault, so on a machine with idle cores a higher value (19) lets
# a busy worker give way at once to the daemon's loop and its clients; but against other busy
# processes a nice-19 worker gets ~1.5 % of a core and scans stall (an LMS200 ACK then waited for
# its telegram's scan for up to 1.5 s), so the default is the daemon's own priority.
WORKER_NICE = 0
# Scan jobs a worker holds at once: the next one waits in its pipe, so the worker does not idle while
# the daemon reads a result and prepares the next (on a busy machine the daemon itself waits for a core).
JOBS_PER_WORKER = 2


class ScanJobFailed(RuntimeError):
    """A scan job did not produce its scans (the daemon reports it and tries again later)."""


class WorkerCrashed(ScanJobFailed):
    """A scan job's worker died (twice) while computing it."""


def _mapping_proxy(items: dict) -> types.MappingProxyType:
    return types.MappingProxyType(items)


# Scenes hold read-only mappings (types.MappingProxyType), which pickle refuses: send them as dicts.
ForkingPickler.register(types.MappingProxyType, lambda proxy: (_mapping_proxy, (dict(proxy),)))


def apply_events(world: Any, scene: Scene, events: Sequence[dict]) -> None:
    """Apply world-change events (records of `scene.live.event_record`) to a worker's world,
    as the daemon applied them: the worker's scans then match the daemon's world."""
    for record in events:
        if record["op"] == "prune":  # the daemon's horizon moved on: forget what only earlier instants needed
            world.live.prune(record["t"])
        elif record["op"] == "restore":  # a restarted worker: the daemon's live state as it was then
            world.live.restore(record["state"])
        elif record.get("gen", float("inf")) > world.live.generation:  # not in a state restored already
            world.apply(event_from_record(record))


@dataclass(frozen=True)
class RemoteSensor:
    """A sensor held by a worker: its `scan`/`scans` are what a `WorkerExecutor` runs there.
    Calling them directly is an error (the daemon must not compute on its own thread)."""

    name: str

    def scan(self, time_s: float, **request: Any) -> Scan:
        raise RuntimeError(f"sensor {self.name!r} is computed in a worker: submit its scan to a WorkerExecutor")

    def scans(self, times_s: Sequence[float], **request: Any) -> list[Scan]:
        raise RuntimeError(f"sensor {self.name!r} is computed in a worker: submit its scans to a WorkerExecutor")


def _worker_main(
    scene: Scene, sensor_names: Sequence[str], connection: multiprocessing.connection.Connection, nice: int
) -> None:
    """A worker's life: build the world once (at the daemon's priority, so start-up is not
    starved), then answer jobs in order `nice` levels lower until told to stop."""
    from emulator.daemon.memory import keep_freed_memory
    from emulator.optics import World  # imported here: the parent need not build one
    from emulator.sensors import create_sensor

    keep_freed_memory()

    world = World(scene)
    sensors = {name: create_sensor(scene, name, world=world) for name in sensor_names}
    for sensor in sensors.values():  # load (or compile) the numba kernels and build each sensor's arrays now:
        sensor.configured_scan(0.0)  # a first job that did it took ~1 s, and spaced the streams for seconds
    gc.freeze()  # the world lives as long as the worker: a full collection need not walk it (50-80 ms)
    os.nice(nice)
    connection.send(("ready", multiprocessing.current_process().pid))
    cpu_mark = time.process_time()
    while True:
        try:
            message = connection.recv()
        except (EOFError, OSError):
            return  # the daemon went away
        kind = message[0]
        if kind == "stop":
            return
        job = message[1]
        try:
            if kind == "scan":
                _, _, name, time_s, request = message
                result: Any = sensors[name].scan(time_s, **request)
            elif kind == "scans":
                _, _, name, times_s, request = message
                result = sensors[name].scans(times_s, **request)
            elif kind == "apply":
                apply_events(world, scene, message[2])
                result = len(message[2])
            else:
                raise ValueError(f"unknown worker message {kind!r}")
        except Exception as error:  # the daemon gets it as the job's exception
            answer: tuple = ("failed", job, f"{type(error).__name__}: {error}")
        else:
            answer = ("done", job, result)
        cpu_now = time.process_time()
        connection.send((*answer, cpu_now - cpu_mark))
        cpu_mark = cpu_now


def _deliver(outbox: queue.SimpleQueue, connection: multiprocessing.connection.Connection) -> None:
    """A worker's sender thread: write its outbox's messages to its pipe in order, until None or a
    broken pipe (the reader sees the worker's end too, and restarts it with the jobs it held)."""
    while (message := outbox.get()) is not None:
        try:
            connection.send(message)
        except (OSError, ValueError):
            return


def _discard_waiting(outbox: queue.SimpleQueue) -> None:
    with contextlib.suppress(queue.Empty):
        while True:
            outbox.get_nowait()


# numpy's BLAS starts a thread per core and keeps it spinning after each call: a worker (already one
# per core) then holds two cores during a batch, and the daemon's loop waits for one to send a scan.
SINGLE_THREAD_MATH = {"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}


@contextlib.contextmanager
def _one_math_thread() -> Iterator[None]:
    """The environment a worker is spawned with (read by numpy's BLAS when the worker imports it);
    the daemon's own environment is restored at once."""
    saved = {name: os.environ.get(name) for name in SINGLE_THREAD_MATH}
    os.environ.update(SINGLE_THREAD_MATH)
    try:
        yield
    finally:
        for name, value in saved.items():
            if value is None:
                os.environ.pop(name, None)
            else:
                os.environ[name] = value


class WorkerFailed(ScanJobFailed):
    """A job raised in its worker; the message names the worker's exception."""


@dataclass
class _Job:
    message: tuple
    future: Future
    attempts: int = 0
    sent_at: float = 0.0  # monotonic time it was sent to its worker


@dataclass
class _Worker:
    """One worker process and the jobs it holds (at most one scan job, and world changes)."""

    index: int
    sensor_names: tuple[str, ...]
    process: Any = None
    connection: multiprocessing.connection.Connection | None = None
    jobs: dict[int, _Job] = field(default_factory=dict)
    lives: int = 0
    outbox: queue.SimpleQueue | None = None  # messages for its pipe, written by its sender thread
    sender: threading.Thread | None = None

    last_done: float = 0.0  # monotonic time its last scan job came back

    @property
    def computing(self) -> int:
        """Scan jobs sent to it and not yet back."""
        return sum(job.message[0] != "apply" for job in self.jobs.values())


class WorkerPool:
    """`count` worker processes, each holding every one of `sensor_names` of `scene`; scan
    jobs wait here and go to whichever worker is free, the most urgent first.
    `start()` returns once every world is built.
    `on_restart(line)` reports a restarted worker (the daemon prints it on stderr)."""

    def __init__(
        self,
        scene: Scene,
        sensor_names: Sequence[str],
        count: int = 1,
        *,
        on_restart: Callable[[str], None] = lambda line: print(line, file=sys.stderr, flush=True),
        nice: int = WORKER_NICE,
        live_state: Callable[[], dict] | None = None,
    ) -> None:
        if not 0 <= nice <= 19:
            raise ValueError(f"a worker's nice increment must be 0..19, got {nice}")
        self.scene = scene
        self.nice = nice
        self._context = multiprocessing.get_context("spawn")
        self._sensor_names = tuple(sensor_names)
        self._workers = [_Worker(index, self._sensor_names) for index in range(max(1, count))]
        self._scheduler = Scheduler(len(self._workers))
        # what a restarted worker starts from: the daemon's live state (`LiveState.export`, bounded by its
        # horizon) when given, else every event applied so far, replayed
        self._live_state = live_state
        self._events: list[dict] = []
        self._job_ids = itertools.count()
        self._lock = threading.Lock()
        self._on_restart = on_restart
        self._closed = False
        self.jobs_computed = 0  # scan jobs a worker finished, and the instants they held (the bench's job sizes)
        self.instants_computed = 0

    @property
    def pids(self) -> list[int]:
        return [worker.process.pid for worker in self._workers if worker.process is not None]

    def start(self) -> None:
        for worker in self._workers:
            self._launch(worker)
        for worker in self._workers:
            self._await_ready(worker)

    def sensor(self, name: str) -> RemoteSensor:
        if name not in self._sensor_names:
            raise KeyError(f"no worker holds sensor {name!r}")
        return RemoteSensor(name)

    def executor(self) -> WorkerExecutor:
        return WorkerExecutor(self)

    def submit(self, sensor: str, method: str, *args: Any) -> Future:
        """Run `method` ("scan" or "scans") of `sensor` with `args` in a worker; its urgency is its
        (earliest) instant, `args[0]`."""
        first = args[0] if method == "scan" else min(args[0], default=0.0)
        message = (method, sensor, *args)
        return self.schedule(first, lambda: message)

    def schedule(self, urgency: float, prepare: Prepare) -> Future:
        """Queue a scan job: when a worker is free and no job waiting is more urgent (a smaller
        `urgency`, simulated seconds), `prepare()` makes its message (None: drop the job, its
        future cancelled) and the worker computes it. The future holds its result."""
        with self._lock:
            if self._closed:
                raise RuntimeError("the worker pool is closed")
            future = self._scheduler.push(urgency, prepare)
            self._dispatch()
        return future

    @property
    def idle(self) -> bool:
        """A worker is free and no job waits: a scan asked for now is computed at once."""
        with self._lock:
            return not len(self._scheduler) and any(worker.computing < JOBS_PER_WORKER for worker in self._workers)

    def demand(self, stream: Any, per_second: float, valid_s: float) -> None:
        """A stream wants `per_second` instants each wall second (`Scheduler.demand`)."""
        with self._lock:
            self._scheduler.demand(stream, per_second, valid_s)

    @property
    def spacing(self) -> float:
        """Every how many scans each stream is computed so that the workers keep up (`Scheduler.spacing`;
        a lookup, read on every scan handed out)."""
        return self._scheduler.spacing

    @property
    def instant_cost_s(self) -> float | None:
        return self._scheduler.instant_cost_s

    def job_cost_s(self, instants: int) -> float | None:
        """Wall seconds a job of `instants` takes a worker lately (`Scheduler.job_cost_s`)."""
        return self._scheduler.job_cost_s(instants)

    @property
    def waiting(self) -> int:
        """Scan jobs waiting for a free worker."""
        return len(self._scheduler)

    def _dispatch(self) -> None:
        """Hand the most urgent waiting jobs to the free workers (lock held)."""
        free = [worker for worker in self._workers if worker.computing < JOBS_PER_WORKER and worker.connection is not None]
        while free and (taken := self._scheduler.take()) is not None:
            message, future = taken
            worker = min(free, key=lambda candidate: candidate.computing)
            if worker.computing + 1 >= JOBS_PER_WORKER:
                free.remove(worker)
            job = next(self._job_ids)
            worker.jobs[job] = _Job((message[0], job, *message[1:]), future, sent_at=time.monotonic())
            self._send(worker, job)

    def apply(self, events: Sequence[dict]) -> list[Future]:
        """Send world-change events to every worker; one future per worker (the count applied)."""
        events = [dict(event) for event in events]
        futures = []
        with self._lock:
            if self._live_state is None:
                self._events += events
            for worker in self._workers:
                job = next(self._job_ids)
                futures.append(Future())
                worker.jobs[job] = _Job(("apply", job, events), futures[-1])
                self._send(worker, job)
        return futures

    def close(self) -> None:
        with self._lock:
            self._closed = True
            workers = list(self._workers)
        for worker in workers:
            if worker.outbox is not None:
                _discard_waiting(worker.outbox)  # what is not sent yet no longer matters: stop goes next
                worker.outbox.put(("stop",))  # its sender leaves on the None `_retire_sender` adds
        with self._lock:
            self._scheduler.cancel_all()
        for worker in workers:
            if worker.process is not None:
                worker.process.join(timeout=2.0)
                if worker.process.is_alive():
                    worker.process.kill()
                    worker.process.join()
            for job in worker.jobs.values():
                job.future.cancel()
            worker.jobs.clear()
            self._retire_sender(worker)
            if worker.connection is not None:
                worker.connection.close()

    # -- inside ------------------------------------------------------------

    def _launch(self, worker: _Worker) -> None:
        parent, child = self._context.Pipe()
        process = self._context.Process(
            target=_worker_main,
            args=(self.scene, worker.sensor_names, child, self.nice),
            name=f"lrf-scan-worker-{worker.index}",
            daemon=True,
        )
        with _one_math_thread():
            process.start()
        child.close()
        worker.process, worker.connection = process, parent
        worker.outbox = queue.SimpleQueue()
        worker.sender = threading.Thread(
            target=_deliver, args=(worker.outbox, parent), name=f"scan-worker-{worker.index}-sender", daemon=True
        )
        worker.sender.start()
        worker.lives += 1

    @staticmethod
    def _retire_sender(worker: _Worker) -> None:
        """Stop the worker's sender thread before its pipe is closed: it leaves at the end of its outbox,
        or at once when the pipe broke (the worker died or was killed, so a blocked write fails)."""
        if worker.outbox is not None:
            worker.outbox.put(None)
        if worker.sender is not None:
            worker.sender.join(timeout=SENDER_STOP_TIMEOUT_S)

    def _await_ready(self, worker: _Worker) -> None:
        connection = worker.connection
        assert connection is not None
        if not connection.poll(WORKER_START_TIMEOUT_S):
            raise RuntimeError(f"scan worker {worker.index} did not start within {WORKER_START_TIMEOUT_S:g} s")
        try:
            connection.recv()
        except EOFError:
            raise RuntimeError(
                f"scan worker {worker.index} exited while building its world (exit code {worker.process.exitcode})"
            ) from None
        threading.Thread(
            target=self._read, args=(worker, connection), name=f"scan-worker-{worker.index}-reader", daemon=True
        ).start()

    def _send(self, worker: _Worker, job_id: int) -> None:
        """Hand one job to the worker's sender thread (lock held): it never waits for the pipe."""
        job = worker.jobs[job_id]
        job.attempts += 1
        worker.outbox.put(job.message)

    def _read(self, worker: _Worker, connection: multiprocessing.connection.Connection) -> None:
        """Settle the worker's jobs as results arrive; on EOF the worker died: restart it."""
        while True:
            try:
                kind, job_id, result, *cpu = connection.recv()
            except (EOFError, OSError):
                break
            with self._lock:
                job = worker.jobs.pop(job_id, None)
                if job is not None and kind == "done" and job.message[0] in ("scan", "scans"):
                    instants = 1 if job.message[0] == "scan" else len(job.message[3])
                    self.jobs_computed += 1
                    self.instants_computed += instants
                    done = time.monotonic()  # its worker's time on it: from when it was sent or the job before came back
                    self._scheduler.computed(instants, done - max(job.sent_at, worker.last_done), cpu[0] if cpu else None)
                    worker.last_done = done
                self._dispatch()  # this worker may be free: its next job goes out before this one is settled
            if job is None or job.future.cancelled():
                continue
            if kind == "done":
                job.future.set_result(result)
            else:
                job.future.set_exception(WorkerFailed(f"scan worker {worker.index}: {result}"))
        self._restart(worker, connection)

    def _restart(self, worker: _Worker, dead: multiprocessing.connection.Connection) -> None:
        with self._lock:
            if self._closed or worker.connection is not dead:
                return
            worker.process.join(timeout=1.0)
            exit_code = worker.process.exitcode
            held = dict(worker.jobs)
            retried = {job_id: job for job_id, job in held.items() if job.attempts < MAX_ATTEMPTS}
            failed = [job for job_id, job in held.items() if job_id not in retried]
            worker.jobs = retried
            self._retire_sender(worker)
            dead.close()
            self._launch(worker)
        for job in failed:
            job.future.set_exception(
                WorkerCrashed(f"scan worker {worker.index} died twice computing {job.message[0]} of {job.message[2]!r}")
            )
        self._on_restart(
            f"scan worker {worker.index} (sensors {', '.join(worker.sensor_names)}) died, exit code {exit_code}:"
            f" restarted, {len(retried)} job(s) sent again"
        )
        try:
            self._await_ready(worker)
        except RuntimeError as error:
            with self._lock:
                jobs, worker.jobs = list(worker.jobs.values()), {}
            for job in jobs:
                job.future.set_exception(WorkerCrashed(str(error)))
            return
        with self._lock:
            # the events the dead worker held (or had applied) are all replayed in one job, which
            # settles the held `apply` jobs when it is done
            held_applies = [job for job in worker.jobs.values() if job.message[0] == "apply"]
            worker.jobs = {job_id: job for job_id, job in worker.jobs.items() if job.message[0] != "apply"}
            replayed = [{"op": "restore", "state": self._live_state()}] if self._live_state is not None else list(self._events)
            if replayed:
                job = next(self._job_ids)
                replay = Future()
                worker.jobs[job] = _Job(("apply", job, replayed), replay, attempts=0)
                replay.add_done_callback(lambda done: _settle_like(done, [held.future for held in held_applies]))
                self._send(worker, job)
            for job_id in list(worker.jobs):
                if worker.jobs[job_id].message[0] != "apply":
                    self._send(worker, job_id)
            self._dispatch()


def _settle_like(done: Future, futures: list[Future]) -> None:
    """Give `futures` the outcome of `done` (a replay standing in for the jobs it covers)."""
    for future in futures:
        if future.done():
            continue
        if done.cancelled():
            future.cancel()
        elif done.exception() is not None:
            future.set_exception(done.exception())
        else:
            future.set_result(done.result())


def _remote(fn: Callable[..., Any]) -> RemoteSensor:
    sensor = getattr(fn, "__self__", None)
    if not isinstance(sensor, RemoteSensor) or fn.__name__ not in ("scan", "scans"):
        raise TypeError(f"a WorkerExecutor runs RemoteSensor.scan/scans, not {fn!r}")
    return sensor


class WorkerExecutor(Executor):
    """An executor whose jobs are a `RemoteSensor`'s `scan` or `scans`, run in its worker."""

    def __init__(self, pool: WorkerPool) -> None:
        self._pool = pool

    def submit(self, fn: Callable[..., Any], /, *args: Any, **kwargs: Any) -> Future:
        sensor = _remote(fn)
        return self._pool.submit(sensor.name, fn.__name__, *args, kwargs)

    def schedule(
        self, fn: Callable[..., Any], urgency: float, prepare_args: Callable[[], tuple | None], request: dict
    ) -> Future:
        """`fn(*prepare_args(), **request)` in a worker, queued by `urgency` (its earliest instant):
        the arguments are made as a worker takes the job (None: nothing is still wanted, the job is
        dropped and its future cancelled)."""
        sensor = _remote(fn)

        def prepare() -> tuple | None:
            args = prepare_args()
            return None if args is None else (fn.__name__, sensor.name, *args, request)

        return self._pool.schedule(urgency, prepare)

    @property
    def idle(self) -> bool:
        return self._pool.idle

    @property
    def spacing(self) -> float:
        return self._pool.spacing

    @property
    def instant_cost_s(self) -> float | None:
        """What an instant costs a worker lately (wall s; read without the pool's lock: a job's
        preparation asks for it while the pool holds it)."""
        return self._pool.instant_cost_s

    def job_cost_s(self, instants: int) -> float | None:
        return self._pool.job_cost_s(instants)

    def demand(self, stream: Any, per_second: float, valid_s: float) -> None:
        self._pool.demand(stream, per_second, valid_s)

    def shutdown(self, wait: bool = True, *, cancel_futures: bool = False) -> None:
        """The pool is the daemon's to close."""
