"""Scans computed in worker processes: the same scans as in-process, and a dead worker is restarted."""

from __future__ import annotations

import os
import signal
import threading
from pathlib import Path
from concurrent.futures import Future

import numpy as np
import pytest

from emulator.bench.serve_load import child_pids
from emulator.bench.serve_process import ServeProcess
from emulator.daemon.scan_cache import ScanCache
from emulator.daemon.workers import WORKER_NICE, RemoteSensor, WorkerFailed, WorkerPool
from emulator.optics import World
from emulator.scene import load_scene
from emulator.scene.live import RegionChange, event_record
from emulator.sensors import create_sensor
from emulator.sensors.lms200 import configured_window


@pytest.fixture(scope="module")
def railway_pool():
    scene = load_scene("railway")
    restarts: list[str] = []
    pool = WorkerPool(scene, ["urg", "lms"], 2, on_restart=restarts.append, nice=19)
    pool.start()
    yield scene, pool, restarts
    pool.close()


def test_worker_scans_equal_in_process_scans(railway_pool) -> None:
    scene, pool, _ = railway_pool
    world = World(scene)
    executor = pool.executor()
    for name, request in (("urg", {}), ("lms", configured_window(scene.sensor("lms").options))):
        local = create_sensor(scene, name, world=world)
        times = [5.0 + 0.1 * j for j in range(4)]
        batch = executor.submit(pool.sensor(name).scans, times, **request).result(timeout=60)
        alone = executor.submit(pool.sensor(name).scan, 7.25, **request).result(timeout=60)
        for scan, expected in zip([*batch, alone], [*local.scans(times, **request), local.scan(7.25, **request)]):
            assert scan.time_s == expected.time_s
            np.testing.assert_array_equal(scan.values, expected.values)


def _nice_of(pid: int) -> int:
    return int(Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[16])  # field 19: nice


def test_workers_compute_at_the_nice_value_asked_with_one_math_thread(railway_pool) -> None:
    _, pool, _ = railway_pool
    ours = _nice_of(os.getpid())  # pytest may itself run under `nice`: os.nice adds
    assert [_nice_of(pid) for pid in pool.pids] == [min(19, ours + 19)] * 2 and WORKER_NICE == 0
    for pid in pool.pids:  # one thread of numpy math per worker: BLAS threads would spin on a second core
        assert len(list(Path(f"/proc/{pid}/task").iterdir())) <= 2  # was 3 with a BLAS thread
        assert b"OPENBLAS_NUM_THREADS=1" in Path(f"/proc/{pid}/environ").read_bytes().split(b"\0")
    assert "OPENBLAS_NUM_THREADS" not in os.environ
    with pytest.raises(ValueError, match="nice increment must be 0..19, got 20"):
        WorkerPool(load_scene("railway"), ["urg"], nice=20)


def test_a_scan_cache_over_workers_serves_a_stream(railway_pool) -> None:
    scene, pool, _ = railway_pool
    cache = ScanCache(pool.sensor("urg"), pool.executor(), phase=3)
    local = create_sensor(scene, "urg", world=World(scene))
    for index in range(1, 20):
        cache.prefetch(index / 10)
        pending = cache.pending(index / 10)
        assert pending is None or isinstance(pending, Future)
        np.testing.assert_array_equal(cache(index / 10).values, local.scan(index / 10).values)


def test_a_killed_worker_is_restarted_and_its_jobs_computed_again(railway_pool) -> None:
    scene, pool, restarts = railway_pool
    executor = pool.executor()
    executor.submit(pool.sensor("urg").scan, 1.0).result(timeout=60)
    victim = pool.pids[0]
    jobs = [executor.submit(pool.sensor("urg").scans, [2.0 + 0.1 * j for j in range(8)]) for _ in range(6)]
    os.kill(victim, signal.SIGKILL)
    local = create_sensor(scene, "urg", world=World(scene))
    for job in jobs:
        scans = job.result(timeout=120)  # never hangs: recomputed by the new worker
        np.testing.assert_array_equal(scans[0].values, local.scan(2.0).values)
    assert pool.pids[0] != victim
    assert len(restarts) == 1 and "scan worker 0 (sensors urg, lms) died" in restarts[0]
    later = executor.submit(pool.sensor("urg").scan, 3.0).result(timeout=60)
    np.testing.assert_array_equal(later.values, local.scan(3.0).values)


def test_a_failing_job_fails_with_the_workers_error_and_events_of_unknown_kind_are_refused(railway_pool) -> None:
    _, pool, _ = railway_pool
    failing = pool.executor().submit(pool.sensor("urg").scan, 1.0, bogus=1)
    with pytest.raises(WorkerFailed, match="TypeError"):
        failing.result(timeout=60)
    with pytest.raises(TypeError):
        pool.executor().submit(print, "not a sensor")
    with pytest.raises(RuntimeError, match="computed in a worker"):
        RemoteSensor("urg").scan(1.0)
    applied = pool.apply([])
    assert [future.result(timeout=60) for future in applied] == [0, 0]


def test_a_restarted_worker_replays_the_world_events_applied_before_it_died() -> None:
    """A live change reaches every worker; a worker restarted after it still sees it."""
    scene = load_scene("railway")
    change = RegionChange(2.0, "car_end_smoke", 40.0)  # dense smoke in front of both sensors from 2 s on
    local_world = World(scene)
    local_world.apply(change)
    local = create_sensor(scene, "urg", world=local_world)
    untouched = create_sensor(scene, "urg", world=World(scene))
    assert not np.array_equal(local.scan(3.0).values, untouched.scan(3.0).values)  # the change shows
    pool = WorkerPool(scene, ["urg"], on_restart=lambda line: None)
    pool.start()
    try:
        assert [future.result(timeout=60) for future in pool.apply([event_record(change)])] == [1]
        os.kill(pool.pids[0], signal.SIGKILL)
        scan = pool.executor().submit(pool.sensor("urg").scan, 3.0).result(timeout=120)
        np.testing.assert_array_equal(scan.values, local.scan(3.0).values)
    finally:
        pool.close()


def test_serve_passes_worker_nice_to_its_workers() -> None:
    with ServeProcess("railway", ["urg=tcp:127.0.0.1:0"], extra_args=["--workers", "1", "--worker-nice", "7"]) as daemon:
        workers = [pid for pid in child_pids(daemon.pid) if b"spawn_main" in Path(f"/proc/{pid}/cmdline").read_bytes()]
        assert len(workers) == 1 and _nice_of(workers[0]) == min(19, _nice_of(daemon.pid) + 7)


def test_world_changes_for_a_worker_that_does_not_read_never_hold_the_caller() -> None:
    """A worker that stops reading (here: stopped by SIGSTOP; in a daemon: busy with a batch while a
    control client sends changes) fills its pipe. Handing it changes must still return at once: the
    daemon's loop calls `apply`, and a write that waited there froze every device and signal (and,
    under the pool's lock, deadlocked against the reader thread settling the worker's answers).
    Once the worker runs again every change arrives, in order, and it computes scans as before."""
    scene = load_scene("railway")
    pool = WorkerPool(scene, ["urg"], on_restart=lambda line: None)
    pool.start()
    worker = pool.pids[0]
    changes = [RegionChange(2.0 + 1e-3 * index, "car_end_smoke", 0.01 * (index % 7)) for index in range(4000)]
    calls = [[event_record(change) for change in changes[start:start + 40]] for start in range(0, len(changes), 40)]
    handed: list[list[Future]] = []

    def hand_changes() -> None:
        for records in calls:  # 100 calls, several hundred KiB pickled: far past a pipe's 64 KiB
            handed.append(pool.apply(records))

    try:
        os.kill(worker, signal.SIGSTOP)
        caller = threading.Thread(target=hand_changes, daemon=True)
        caller.start()
        caller.join(timeout=30)
        assert not caller.is_alive(), f"apply waited on a full pipe: {len(handed)} of 100 calls returned"
        os.kill(worker, signal.SIGCONT)
        assert [future.result(timeout=60) for futures in handed for future in futures] == [40] * 100
        world = World(scene)
        for change in changes:
            world.apply(change)
        local = create_sensor(scene, "urg", world=world)
        for time_s in (3.0, 5.9995, 7.0):
            scan = pool.executor().submit(pool.sensor("urg").scan, time_s).result(timeout=60)
            np.testing.assert_array_equal(scan.values, local.scan(time_s).values)
    finally:
        os.kill(worker, signal.SIGCONT)
        pool.close()
