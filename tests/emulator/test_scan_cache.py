"""The daemon's ScanCache with a real sensor (railway's LMS200, `physical`): a steady
stream is computed in batches of SCAN_BATCH, an irregular one scan by scan, a miss
alone and never behind a batch, and the cache stays bounded."""

from __future__ import annotations

import math
import threading
from concurrent.futures import ThreadPoolExecutor
from typing import Any, Iterator, Sequence

import numpy as np
import pytest

from emulator.daemon.scan_cache import PREFETCH_LEAD_S, SCAN_BATCH, ScanCache
from emulator.scene import load_scene
from emulator.sensors import create_sensor
from emulator.sensors.lms200 import LmsSensor, configured_window
from emulator.sensors.response import apply_model_override
from emulator.sensors.scan import Scan

LMS_SCAN_PERIOD_S = 2 / 75  # a 0.5° scan takes two mirror revolutions
TICK = 1e-6


def railway_lms() -> LmsSensor:
    sensor = create_sensor(apply_model_override(load_scene("railway"), "physical"), "lms")
    assert isinstance(sensor, LmsSensor)
    return sensor


@pytest.fixture(scope="module")
def sensor() -> LmsSensor:
    return railway_lms()


@pytest.fixture(scope="module")
def request_keywords(sensor: LmsSensor) -> dict[str, Any]:
    return configured_window(sensor.spec.options)


@pytest.fixture
def scan_thread() -> Iterator[ThreadPoolExecutor]:
    executor = ThreadPoolExecutor(max_workers=1, thread_name_prefix="scan")  # as the daemon's
    yield executor
    executor.shutdown(wait=True, cancel_futures=True)


class Recording:
    """The sensor, with every `scan`/`scans` call logged in order; `scans` waits for `gate`."""

    def __init__(self, sensor: LmsSensor) -> None:
        self.sensor = sensor
        self.calls: list[tuple[str, list[float]]] = []
        self.gate = threading.Event()
        self.gate.set()
        self.batches_done = 0

    def scan(self, time_s: float, **request: Any) -> Scan:
        self.calls.append(("scan", [time_s]))
        return self.sensor.scan(time_s, **request)

    def scans(self, times_s: Sequence[float], **request: Any) -> list[Scan]:
        self.calls.append(("scans", list(times_s)))
        self.gate.wait(timeout=10)  # bounded: a test that waits here wrongly fails instead of hanging
        scans = self.sensor.scans(times_s, **request)
        self.batches_done += 1
        return scans

    def computed_ticks(self) -> list[int]:
        return sorted(round(t / TICK) for _, times in self.calls for t in times)


def test_a_steady_stream_is_served_from_batches_with_the_same_values(
    sensor: LmsSensor, request_keywords: dict[str, Any], scan_thread: ThreadPoolExecutor
) -> None:
    recording = Recording(sensor)
    cache = ScanCache(recording, scan_thread)
    indices = range(1, 4 * SCAN_BATCH + 1)
    served = [cache(index * LMS_SCAN_PERIOD_S, **request_keywords) for index in indices]

    alone = [times for kind, times in recording.calls if kind == "scan"]
    batches = [times for kind, times in recording.calls if kind == "scans"]
    assert len(alone) == 3  # two strides to see the stream, then batches only
    assert len(batches) >= 3 and all(len(times) == SCAN_BATCH for times in batches)
    computed = recording.computed_ticks()
    assert len(computed) == len(set(computed)), "a scan was computed twice"
    assert len(computed) <= len(indices) + SCAN_BATCH + 1  # a stream that stops wastes one batch ahead
    reference = railway_lms()
    for index, scan in zip(indices, served):
        time_s = index * LMS_SCAN_PERIOD_S
        assert scan.time_s == time_s  # the device stamps with the time it asked for
        np.testing.assert_array_equal(scan.values, reference.scan(time_s, **request_keywords).values)


def test_an_irregular_stream_computes_only_what_is_asked(
    sensor: LmsSensor, request_keywords: dict[str, Any], scan_thread: ThreadPoolExecutor
) -> None:
    recording = Recording(sensor)
    cache = ScanCache(recording, scan_thread)
    indices = np.cumsum([1, *[7, 8, 7, 9] * 3])  # a slow line rate skips scans unevenly
    for index in indices:
        cache(int(index) * LMS_SCAN_PERIOD_S, **request_keywords)
    assert [kind for kind, _ in recording.calls] == ["scan"] * len(indices)
    assert recording.computed_ticks() == sorted(round(int(i) * LMS_SCAN_PERIOD_S / TICK) for i in indices)


def test_a_miss_is_computed_alone_and_never_waits_for_a_batch(
    sensor: LmsSensor, request_keywords: dict[str, Any], scan_thread: ThreadPoolExecutor
) -> None:
    recording = Recording(sensor)
    cache = ScanCache(recording, scan_thread)
    recording.gate.clear()  # any batch stays unfinished until the test opens the gate
    times = [index * LMS_SCAN_PERIOD_S for index in (1, 2, 3)]
    for time_s in times:
        assert cache(time_s, **request_keywords).time_s == time_s
    # the third request made the stream steady: it was served alone, ahead of the batch it started
    assert recording.batches_done == 0
    assert recording.calls[:3] == [("scan", [time_s]) for time_s in times]
    assert recording.calls[3][0] == "scans" and len(recording.calls[3][1]) == SCAN_BATCH
    recording.gate.set()
    cache(4 * LMS_SCAN_PERIOD_S, **request_keywords)  # foreseen: from the batch
    assert recording.batches_done == 1 and len(recording.calls) == 4


def test_the_cache_stays_bounded(
    sensor: LmsSensor, request_keywords: dict[str, Any], scan_thread: ThreadPoolExecutor
) -> None:
    size = 2 * SCAN_BATCH
    cache = ScanCache(Recording(sensor), scan_thread, size=size)
    held = []
    for index in range(1, 6 * SCAN_BATCH):
        cache(index * LMS_SCAN_PERIOD_S, **request_keywords)
        held.append(len(cache))
    assert max(held) == size  # it fills up, and no further
    with pytest.raises(ValueError, match="two batches"):
        ScanCache(Recording(sensor), scan_thread, size=2 * SCAN_BATCH - 1)


def test_a_stream_faster_than_the_prefetch_lead_has_its_batches_foreseen_that_far_ahead(
    sensor: LmsSensor, request_keywords: dict[str, Any], scan_thread: ThreadPoolExecutor
) -> None:
    """The daemon has no prefetch wake-up: as a device reads a scan, and its next wake-up is
    scheduled (`prefetch` of its next scan), the stream's next batch is foreseen once those foreseen
    reach less than PREFETCH_LEAD_S (70 ms, about 2.6 strides of an LMS200 stream) past its next
    scan; in batches, nothing computed twice."""
    recording = Recording(sensor)
    cache = ScanCache(recording, scan_thread)
    for index in range(1, 5 * SCAN_BATCH):
        cache(index * LMS_SCAN_PERIOD_S, **request_keywords)
        cache.prefetch((index + 1) * LMS_SCAN_PERIOD_S)
        ahead = math.floor((LMS_SCAN_PERIOD_S + PREFETCH_LEAD_S) / LMS_SCAN_PERIOD_S)
        foreseen = [cache.pending((index + j) * LMS_SCAN_PERIOD_S) is not None for j in range(1, ahead + 1)]
        assert all(foreseen[: 1 if index < 3 else ahead]), (index, foreseen)  # its stride is known from the third
    scan_thread.shutdown(wait=True)
    alone = [times for kind, times in recording.calls if kind == "scan"]
    assert len(alone) <= 3, f"{len(alone)} scans computed alone: {alone}"
    assert [len(times) for kind, times in recording.calls if kind == "scans"][1:] == [SCAN_BATCH] * 4
    ticks = recording.computed_ticks()
    assert len(ticks) == len(set(ticks)), "a scan was computed twice"


def ticks(times: Sequence[float]) -> list[int]:
    return [round(t / TICK) for t in times]


class DeferredStarts:
    """The daemon's `defer`, by hand: what each batch asked to run, and how much later."""

    def __init__(self) -> None:
        self.waiting: list[tuple[float, Any]] = []

    def __call__(self, delay_s: float, start: Any) -> None:
        self.waiting.append((delay_s, start))

    def run_all(self) -> None:
        waiting, self.waiting = self.waiting, []
        for _, start in waiting:
            start()


def stream_made_steady(
    sensor: LmsSensor, request_keywords: dict[str, Any], scan_thread: ThreadPoolExecutor
) -> tuple[Recording, DeferredStarts, ScanCache]:
    """A cache that defers by hand, asked for scans 1, 2, 3: the third makes the stream steady and
    foresees the batch 4..11, which waits in `deferred`."""
    recording = Recording(sensor)
    deferred = DeferredStarts()
    cache = ScanCache(recording, scan_thread, defer=deferred)
    for index in (1, 2, 3):
        cache(index * LMS_SCAN_PERIOD_S, **request_keywords)
    return recording, deferred, cache


def test_a_streams_batch_starts_half_a_stride_later_in_the_quiet_between_scans(
    sensor: LmsSensor, request_keywords: dict[str, Any], scan_thread: ThreadPoolExecutor
) -> None:
    """Foreseen while a scan is being delivered, the next batch is started half a stride later,
    so its worker does not compete with that delivery; meanwhile its scans are already held."""
    recording = Recording(sensor)
    deferred = DeferredStarts()
    cache = ScanCache(recording, scan_thread, defer=deferred)
    served = [cache(index * LMS_SCAN_PERIOD_S, **request_keywords) for index in (1, 2, 3)]
    assert [kind for kind, _ in recording.calls] == ["scan"] * 3  # the batch is foreseen, not started
    assert [delay for delay, _ in deferred.waiting] == [pytest.approx(LMS_SCAN_PERIOD_S / 2)]
    ahead = cache.pending(4 * LMS_SCAN_PERIOD_S)
    assert ahead is not None and not ahead.done()  # a device waiting for it finds it
    deferred.run_all()
    ahead.result(timeout=30)
    kind, times = recording.calls[3]
    assert kind == "scans" and ticks(times) == [round(index * LMS_SCAN_PERIOD_S / TICK) for index in range(4, 4 + SCAN_BATCH)]
    deferred.run_all()  # nothing is started twice
    served.append(cache(4 * LMS_SCAN_PERIOD_S, **request_keywords))
    assert len(recording.calls) == 4
    reference = railway_lms()
    for index, scan in zip((1, 2, 3, 4), served):
        np.testing.assert_array_equal(scan.values, reference.scan(index * LMS_SCAN_PERIOD_S, **request_keywords).values)


def test_a_caller_that_needs_a_scan_of_a_batch_not_yet_started_starts_it_at_once(
    sensor: LmsSensor, request_keywords: dict[str, Any], scan_thread: ThreadPoolExecutor
) -> None:
    recording, deferred, cache = stream_made_steady(sensor, request_keywords, scan_thread)
    scan = cache(5 * LMS_SCAN_PERIOD_S, **request_keywords)  # would wait forever for a start that never comes
    assert scan.time_s == 5 * LMS_SCAN_PERIOD_S and recording.calls[3][0] == "scans"
    deferred.run_all()
    assert [kind for kind, _ in recording.calls].count("scans") == 1


def test_scans_a_live_change_drops_before_their_batch_starts_are_not_computed(
    sensor: LmsSensor, request_keywords: dict[str, Any], scan_thread: ThreadPoolExecutor
) -> None:
    recording, deferred, cache = stream_made_steady(sensor, request_keywords, scan_thread)
    cache.invalidate_from(8 * LMS_SCAN_PERIOD_S)  # scans 8.. of the foreseen batch 4..11 are dropped
    deferred.run_all()
    scan_thread.shutdown(wait=True)
    batch = [times for kind, times in recording.calls if kind == "scans"][0]
    assert ticks(batch) == [round(index * LMS_SCAN_PERIOD_S / TICK) for index in range(4, 8)]


class SubmitLog:
    """An executor that notes each job as it is submitted (on the caller's thread), then runs it."""

    def __init__(self, executor: ThreadPoolExecutor) -> None:
        self.executor = executor
        self.jobs: list[tuple[str, list[float]]] = []

    def submit(self, fn: Any, /, *args: Any, **kwargs: Any) -> Any:
        times = list(args[0]) if fn.__name__ == "scans" else [args[0]]
        self.jobs.append((fn.__name__, times))
        return self.executor.submit(fn, *args, **kwargs)


def test_after_send_the_next_batch_is_foreseen_at_settle_and_the_stream_is_the_same(
    sensor: LmsSensor, request_keywords: dict[str, Any], scan_thread: ThreadPoolExecutor
) -> None:
    """As the daemon runs it (`after_send`): a device's read of its scan does only the lookup; foreseeing
    the stream's next batch and telling the observer wait for `settle()`, which the daemon calls once
    the output has gone. Settled after every read, the jobs, the scans and the observer's calls are
    those of a cache that does it all at once."""
    times = [index * LMS_SCAN_PERIOD_S for index in range(1, 3 * SCAN_BATCH + 1)]
    runs = {}
    for after_send in (False, True):
        log, observed = SubmitLog(scan_thread), []
        cache = ScanCache(sensor, log, observer=lambda scan: observed.append(scan.time_s), after_send=after_send)
        served = []
        for index, time_s in enumerate(times):
            served.append(cache(time_s, **request_keywords))
            if after_send and index == 2:  # the read that makes the stream steady: its batch waits for settle
                assert [kind for kind, _ in log.jobs] == ["scan"] * 3
                assert observed == times[:2]
                cache.settle()
                assert log.jobs[3][0] == "scans" and observed == times[:3]
            cache.settle()
        runs[after_send] = (log.jobs, [scan.time_s for scan in served], observed)
    assert runs[True] == runs[False]
    assert [kind for kind, _ in runs[True][0]].count("scans") >= 2


def test_a_poll_after_a_pause_reads_the_scan_of_now_not_one_foreseen_before_the_pause(
    scan_thread: ThreadPoolExecutor,
) -> None:
    """A 10 Hz poller (each request read at once, as a CoLa `sRN LMDscandata`) has its next polls
    foreseen; it pauses 4 s and polls again: it gets the scan of the instant it asked for, not the
    last one foreseen before the pause (it used to, of any age), while the workers keep up."""
    from tests.emulator.test_overload import RecordingSensor

    clock = {"now": 0.0}
    sensor = RecordingSensor("tim")
    cache = ScanCache(sensor, scan_thread, now=lambda: clock["now"])

    def poll(time_s: float) -> Scan:
        clock["now"] = time_s
        job = cache.input_scan(time_s)
        if job is not None:
            job.result(timeout=10)
        return cache(time_s)

    for index in range(20):
        assert poll(index * 0.1).time_s == pytest.approx(index * 0.1)
    scan_thread.submit(lambda: None).result(timeout=10)  # the foreseen polls are computed
    foreseen_after = max(sensor.computed)
    assert foreseen_after > 1.95  # the batch reaches past the last poll: there is a stale scan to hand out
    assert poll(1.9 + 4.0).time_s == pytest.approx(5.9)
