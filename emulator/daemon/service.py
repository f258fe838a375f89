"""The daemon: every sensor of a scene served on its endpoints, on one asyncio loop.

Per sensor: one scan source (the simulation, or anything sensor-like such as
a replayed log) behind an LRU cache, so several endpoints of one sensor
compute each scan once. Per endpoint: its own device session (protocol state
machine) and transport. Each device is woken at its `next_deadline()`
(simulated time, mapped to wall time through the clock's speed).

Scans are computed on one "scan thread", ahead of time: a scan at simulated
time t is a pure function of t, so as a device's next wake-up is scheduled
the scan it will ask for then is foreseen (started at once if nothing has
started it yet), and it is ready when the device asks.
Computing on the loop thread at the deadline took 1–8 ms (railway), which
showed up as scan-period jitter and command latency (docs/transports.md).
A steady stream (the same request at a constant stride, as a streaming device
makes) is computed SCAN_BATCH scans per job with `sensor.scans`, which shares
each numpy pass among them; a request nobody foresaw is still computed alone.

Live changes (the control API, `emulator/control`) reach the world through
`Daemon.apply`: the world takes the event from its instant on (in every
worker process too), every scan cache drops what it computed at or after
that instant, and a clock change reschedules every device's wake-up.
"""

from __future__ import annotations

import asyncio
import dataclasses
import gc
import math
import os
import sys
import weakref
from collections import Counter
from concurrent.futures import Executor, Future, ThreadPoolExecutor
from dataclasses import dataclass
from typing import Any, Callable, Mapping, Protocol, Sequence

from emulator.daemon.clock import WallClock
from emulator.daemon.scan_cache import (
    SCAN_BATCH,
    ScanCache,
    ScanObserver,
    SensorFactory,
)
from emulator.daemon.workers import WORKER_NICE, ScanJobFailed, WorkerPool
from emulator.errors import UserError
from emulator.optics import World
from emulator.scene.live import ClockChange, LiveEvent, LiveState, event_record, live_horizon
from emulator.scene.endpoints import Address, PtyAddress, Rfc2217Address, plan_endpoints
from emulator.scene.model import Scene, SensorSpec
from emulator.scene.sick_models import MODELS as SICK_MODELS
from emulator.sensors import create_sensor, hokuyo_model, stream_batch
from emulator.sensors.hokuyo import revolution_phase_ms
from emulator.sensors.sick_cola import power_on_phase_ms
from emulator.sensors.scan import Scan
from emulator.transport import InputHold
from emulator.transport.pty import PtyEndpoint
from emulator.transport.rfc2217 import Rfc2217Endpoint
from emulator.transport.tcp import IDLE_TIMEOUT_S, TcpEndpoint
from emulator.transport.timer import LATE_THRESHOLDS_MS, PreciseTimer, shared_timer
from protocols.device import Device, Output
from protocols.cola import ColaDevice, ColaUnit, UnitModel
from protocols.lms2xx import Lms200Device
from protocols.scip import UrgDevice
from protocols.scip.profiles import PROFILES as SCIP22_PROFILES
from protocols.scip.scip22 import Scip22Device

# the SensorSpec options each protocol device takes (docs/scene-format.md)
DEVICE_OPTIONS: dict[str, tuple[str, ...]] = {
    "urg-04lx": ("serial", "boot_protocol", "timing"),
    **{model: ("serial",) for model in SCIP22_PROFILES},
    "lms200": ("baud", "type_string", "angle_deg", "resolution_deg", "units", "firmware_profile"),
    **{name: ("scan_frequency_hz", "resolution_deg", "serial", "fog_filter") for name in SICK_MODELS},
}
# One CoLa unit per sensor (scan source), shared by its endpoints: its settings outlive connections.
_COLA_UNITS: weakref.WeakKeyDictionary[Any, ColaUnit] = weakref.WeakKeyDictionary()


PRUNE_STEP_S = 1.0  # the live history is pruned when the horizon has moved on this far (simulated s)
OVERLOAD_CHECK_S = 1.0  # how often (wall) the daemon looks whether its sensors fell behind or caught up
RETRY_AFTER_FAILURE_S = 0.1  # a device whose scan failed is polled again this much later (wall)

DeviceFactory = Callable[..., Device]  # (spec, scans, *, phase_ms) → the endpoint's device


class Clock(Protocol):
    def now(self) -> float: ...

    def wall_delay(self, sim_seconds: float) -> float: ...

    def set(self, *, speed: float | None = None, paused: bool | None = None) -> None: ...


class Cancellable(Protocol):
    def cancel(self) -> None: ...


def simulated_sensors(scene: Scene, world: World | None = None) -> SensorFactory:
    """Sensors computed from the scene, all sharing one optics world."""
    world = world if world is not None else World(scene)
    return lambda spec: create_sensor(scene, spec.name, world=world)


def build_device(spec: SensorSpec, scans: Callable[..., Scan], *, phase_ms: int = 0) -> Device:
    """The protocol device for the sensor's model, configured from its scene options.
    It powers on at simulated time 0: a URG stamp is the scan's simulated time in ms;
    a Hokuyo's revolutions complete `phase_ms` past each period; a CoLa unit powers on at `phase_ms`."""
    if spec.model not in DEVICE_OPTIONS:
        raise UserError(f"sensor {spec.name!r}: no protocol for model {spec.model!r}")
    options = {key: spec.options[key] for key in DEVICE_OPTIONS[spec.model] if key in spec.options}
    if spec.model == "urg-04lx":
        return UrgDevice(scans, **options, phase_ms=phase_ms)
    if spec.model in SICK_MODELS:
        return ColaDevice(scans, cola_unit(spec, scans, phase_ms))
    if spec.model in SCIP22_PROFILES:
        return Scip22Device(scans, spec.model, **options, phase_ms=phase_ms)
    return Lms200Device(scans, **options)


def cola_unit(spec: SensorSpec, scans: Callable[..., Scan], phase_ms: int = 0) -> ColaUnit:
    """The CoLa unit behind a sensor's scan source, made at its first endpoint (powered on at `phase_ms`
    with the scene's scan configuration)."""
    unit = _COLA_UNITS.get(scans)
    if unit is None:
        unit = _COLA_UNITS[scans] = ColaUnit(unit_model(spec), power_on_s=phase_ms / 1000)
    return unit


def unit_model(spec: SensorSpec) -> UnitModel:
    """What a CoLa device is told of its unit: the model's table row and the scene's options."""
    sick = SICK_MODELS[spec.model]
    options = spec.options
    default = (int(round(float(options.get("scan_frequency_hz", sick.default[0] / 100)) * 100)),
               int(round(float(options.get("resolution_deg", sick.default[1] / 1e4)) * 1e4)))
    return UnitModel(
        family=sick.family, device_ident=sick.device_ident, firmware_version=sick.firmware_version,
        serial_number=str(options.get("serial", "12345678")),
        start_ticks=int(round(sick.start_deg * 1e4)), stop_ticks=int(round(sick.stop_deg * 1e4)),
        scan_configs=dict(sick.scan_configs), default=default, echoes=sick.echoes, distance_scale=sick.distance_scale,
        fog_filter=bool(options.get("fog_filter", False)),
    )


@dataclass(frozen=True)
class Ready:
    """An endpoint that is serving; `line` is what `serve` prints."""

    sensor: str
    model: str
    uri: str
    slave: str | None = None  # a pty's /dev/pts/N

    @property
    def line(self) -> str:
        text = f"ready {self.sensor} {self.model} {self.uri}"
        return f"{text} -> {self.slave}" if self.slave else text


class _WaitingForScan:
    """Stands for a device's wake-up while its scan is still being computed."""

    def cancel(self) -> None:
        """A wait is called off by replacing it: `_resume` then finds another."""


def _report_failed_scan(error: ScanJobFailed, then: str) -> None:
    """One line on stderr for a scan whose job failed (its worker died twice), and what follows."""
    print(f"scan failed: {type(error).__name__}: {error}; {then}", file=sys.stderr, flush=True)


class _HeldInput:
    """A slice of client input kept until the scan it may read is computed, and what the transport
    runs once the device has taken it (`then`)."""

    def __init__(self, data: bytes) -> None:
        self.data = data
        self._taken: Callable[[], None] | None = None

    def then(self, taken: Callable[[], None]) -> None:
        self._taken = taken

    def taken(self) -> None:
        if self._taken is not None:
            self._taken()


class DeviceSession:
    """One endpoint's device: client bytes in, outputs out, woken at its deadlines.

    `prefetch(scan_time)`, called as the wake-up is scheduled, makes sure the scan the
    device will want then is foreseen (started at once if nobody foresaw it; a steady
    stream's batches are foreseen as its scans are read, with no wake-up of their own);
    `call_later` schedules the wake-up (default: the loop's own, millisecond-accurate timers).
    `pending(scan_time)` gives the job computing that scan, if any: at its deadline
    the device is woken only once that job is done, so the loop never waits on a
    computation (the device then finds its scan ready). Client bytes likewise:
    a device that says which scan a request now would read (`latest_scan_time`,
    e.g. a URG's GD) gets them once that scan is computed; meanwhile the transport's
    slice waits here and the rest of the client's input in the kernel (a flood of GDs
    blocked the loop on every new scan and starved the other sensors; input held
    here instead was handed over in one piece, 64 KiB of scan requests at once).
    `settle()` runs once the device's output has gone: what its reads of scans put off
    (foreseeing the next batch, telling the view), so a wake-up's work before its send stays small and even; then a
    device that can (`prepare_next`) encodes its next scan ahead if `ready_scan` has it.
    """

    def __init__(
        self,
        device: Device,
        clock: Clock,
        loop: asyncio.AbstractEventLoop,
        prefetch: Callable[[float], None] | None = None,
        call_later: Callable[..., Cancellable] | None = None,
        pending: Callable[[float], Future | None] | None = None,
        expect: Callable[[dict, float | None], None] | None = None,
        next_scan: Callable[[float], tuple[Future | None, float | None]] | None = None,
        input_scan: Callable[[float], Future | None] | None = None,
        settle: Callable[[], None] | None = None,
        ready_scan: Callable[[float], Any] | None = None,
    ) -> None:
        self.device = device
        self.endpoint: PtyEndpoint | TcpEndpoint | None = None
        self._clock = clock
        self._loop = loop
        self._prefetch = prefetch
        self._pending = pending
        self._expect = expect
        self._next_scan = next_scan
        self._input_scan = input_scan
        self._settle = settle
        self._ready_scan = ready_scan
        self._call_later = call_later or loop.call_later
        self._timer: Cancellable | None = None
        self._held: _HeldInput | None = None  # input waiting for the scan it may read

    @property
    def baud(self) -> int | None:
        return self.device.baud

    def received(self, data: bytes) -> InputHold | None:
        job = self._input_scan_job()
        if job is not None and not job.done():
            held = self._held = _HeldInput(data)
            job.add_done_callback(lambda _: self._loop.call_soon_threadsafe(self._release, held))
            return held.then
        try:
            outputs = self.device.receive(data, self._clock.now())
        except ScanJobFailed as error:  # as in _poll; the client's input goes on (it would wait for ever)
            _report_failed_scan(error, "the request that read it is not answered")
            return None
        self._deliver(outputs)
        return None

    def _input_scan_job(self) -> Future | None:
        """The job computing the scan a request received now would read, started if need be."""
        latest_scan_time = getattr(self.device, "latest_scan_time", None)
        if latest_scan_time is None or self._prefetch is None or self._pending is None:
            return None
        time_s = latest_scan_time(self._clock.now())
        if time_s is None:
            return None
        self._tell_request()
        if self._input_scan is not None:
            return self._input_scan(time_s)
        self._prefetch(time_s)
        return self._pending(time_s)

    def _release(self, held: _HeldInput) -> None:
        """The scan held input waited for is ready: hand the input over (unless the client left), and
        let the transport go on once the device has taken it (a live change may have put the scan off
        again: then once that one is computed)."""
        if self._held is held:
            self._held = None
            again = self.received(held.data)
            if again is None:
                held.taken()
            else:
                again(held.taken)

    def disconnected(self) -> None:
        self._held = None
        self.device.connection_lost()
        self._tell_request()  # its stream stopped: the scan cache stops counting on it
        self._schedule()

    @property
    def waiting(self) -> bool:
        """A wake-up is scheduled for the device's next deadline."""
        return self._timer is not None

    def start(self) -> None:
        self._schedule()

    def reschedule(self) -> None:
        """Wake at the deadline again as the clock now maps it (its speed or pause changed)."""
        self._schedule()

    def stop(self) -> None:
        if self._timer is not None:
            self._timer.cancel()
        self._timer = None

    def _wake(self) -> None:
        self._timer = None
        deadline = self.device.next_deadline()
        job = at = None
        if self._next_scan is not None and deadline is not None:
            job, at = self._next_scan(self._scan_time(deadline))
        elif self._pending is not None and deadline is not None:
            scan_time = self._scan_time(deadline)
            job = self._pending(scan_time)
            if job is None and self._prefetch is not None:
                self._prefetch(scan_time)  # not foreseen (a new client, a missed prefetch): start it, don't block
                job = self._pending(scan_time)
        if job is not None and not job.done():
            waiting = self._timer = _WaitingForScan()
            job.add_done_callback(lambda _: self._loop.call_soon_threadsafe(self._resume, waiting))
            return
        if at is not None and (delay := self._clock.wall_delay(at - self._clock.now())) > 0:
            if delay != float("inf"):  # behind: the next scan computed is a later revolution's
                self._timer = self._call_later(delay, self._wake)
            return
        self._poll(at)

    def _resume(self, waiting: _WaitingForScan) -> None:
        """The scan the device waited for is ready (unless the wait was called off meanwhile);
        woken again rather than polled: a live change may have replaced that job with another."""
        if self._timer is waiting:
            self._timer = None
            self._wake()

    def _poll(self, at: float | None = None) -> None:
        """Let the device send what is due (by `at` at the earliest: a timer may wake a hair before the
        instant it was set for); a scan that failed (its worker died twice) is
        reported on stderr and the device tried again a moment later, never left asleep."""
        try:
            outputs = self.device.poll(max(self._clock.now(), at if at is not None else -math.inf))
        except ScanJobFailed as error:
            _report_failed_scan(error, f"retrying in {RETRY_AFTER_FAILURE_S:g} s")
            self.stop()
            self._timer = self._call_later(RETRY_AFTER_FAILURE_S, self._wake)
            return
        self._deliver(outputs)

    def _deliver(self, outputs: list[Output]) -> None:
        if outputs and self.endpoint is not None:
            self.endpoint.send(outputs)
        if self._settle is not None:  # the scan cache's bookkeeping, once the output has gone
            self._settle()
        self._schedule()
        prepare_next = getattr(self.device, "prepare_next", None)
        if prepare_next is not None and self._ready_scan is not None:  # its next scan encoded ahead, if computed
            prepare_next(self._ready_scan)

    def _tell_request(self) -> None:
        """Tell the scan cache what the device will ask for, if it can say (`scan_request`), so even
        its first scan is computed ahead and waited for without blocking the loop."""
        scan_request = getattr(self.device, "scan_request", None)
        scan_stride = getattr(self.device, "scan_stride_s", None)
        if self._expect is not None and scan_request is not None:
            self._expect(scan_request(), scan_stride() if scan_stride is not None else None)

    def _schedule(self) -> None:
        self.stop()
        deadline = self.device.next_deadline()
        if deadline is not None:
            self._tell_request()
            delay = self._clock.wall_delay(deadline - self._clock.now())
            if delay == float("inf"):
                return  # the clock is paused: rescheduled when it resumes
            self._timer = self._call_later(delay, self._wake)
            if self._prefetch is not None:  # no wake-up of its own: a stream's batches are foreseen as it is read
                self._prefetch(self._scan_time(deadline))

    def _scan_time(self, deadline: float) -> float:
        """The scan the device will ask for at `deadline`: the one it names if it can
        (an LMS200 on a slow line sends the newest scan complete when the line frees),
        else the deadline itself (a URG's scan times are its deadlines)."""
        next_scan_time = getattr(self.device, "next_scan_time", None)
        scan_time = next_scan_time() if next_scan_time is not None else None
        return deadline if scan_time is None else scan_time


def _names(names: list[str], shown: int = 5) -> str:
    return ", ".join(names[:shown]) + (f", … {len(names) - shown} more" if len(names) > shown else "")


def _served(scene: Scene, sensors: Sequence[str] | None) -> Scene:
    """The scene as far as endpoints go: sensors not served keep no endpoints to clash with."""
    if sensors is None:
        return scene
    return dataclasses.replace(
        scene, sensors=tuple(spec if spec.name in sensors else dataclasses.replace(spec, endpoints=()) for spec in scene.sensors)
    )


def _only(plan: list, sensors: Sequence[str] | None) -> list:
    """The plan's entries for the `sensors` served (all when None)."""
    return plan if sensors is None else [(spec, addresses) for spec, addresses in plan if spec.name in sensors]


class Daemon:
    """Serves `scene`'s sensors. `endpoints_override` maps a sensor name to the
    URIs that replace its scene endpoints; `sensor_factory` supplies scan sources
    (default: the simulation); `device_factory` builds each endpoint's device.
    `workers` > 0 computes the simulation's scans in that many worker processes
    (at most one per sensor); `sensors` serves only those of the scene (a fleet).
    `live` holds the live changes applied (`apply`); None for a supplied scan source.
    `on_scan` is told of every scan handed to a device (on the loop thread: it must
    return at once, e.g. by queueing the scan for a recorder's own thread).
    `report(line)` prints the line said when sensors fall behind and when they catch up (stderr)."""

    def __init__(
        self,
        scene: Scene,
        endpoints_override: Mapping[str, Sequence[str]] | None = None,
        clock: Clock | None = None,
        *,
        sensor_factory: SensorFactory | None = None,
        device_factory: DeviceFactory = build_device,
        workers: int = 0,
        worker_nice: int = WORKER_NICE,
        sensors: Sequence[str] | None = None,
        on_scan: ScanObserver | None = None,
        idle_timeout_s: float = IDLE_TIMEOUT_S,
        report: Callable[[str], None] = lambda line: print(line, file=sys.stderr, flush=True),
    ) -> None:
        self.scene = scene
        self.idle_timeout_s = idle_timeout_s
        self.clock = clock or WallClock()
        self.sessions: list[DeviceSession] = []
        self.endpoints: list[PtyEndpoint | TcpEndpoint] = []
        self._on_scan = on_scan
        self._plan = _only(plan_endpoints(_served(scene, sensors), endpoints_override), sensors)
        self._overridden = frozenset(endpoints_override or ())
        self._served_names = frozenset(spec.name for spec, _ in self._plan)
        self._sensor_factory = sensor_factory
        self._device_factory = device_factory
        self._scan_thread = ThreadPoolExecutor(max_workers=1, thread_name_prefix="scan")
        self._workers = workers if sensor_factory is None else 0  # a supplied scan source stays in-process
        self._worker_nice = worker_nice
        self.pool: WorkerPool | None = None
        # The world in this process (scans on the scan thread), or only the live changes'
        # record (scans in workers, each applying the same events to its own world).
        self.world = World(scene) if sensor_factory is None and self._workers <= 0 else None
        self.live: LiveState | None = self.world.live if self.world is not None else None
        if sensor_factory is None and self.world is None:
            self.live = LiveState(scene)
        if self.live is not None:
            self.live.prepare_obstacles()  # now, rather than on the loop at a live body's first twist
        self._before_workers: list[LiveEvent] = []  # world events applied before the workers started
        self.scan_caches: dict[str, ScanCache] = {}  # per sensor served, once started
        self._endpoint_sensors: list[tuple[str, PtyEndpoint | TcpEndpoint]] = []
        self._timer: PreciseTimer | None = None
        self._stopped = asyncio.Event()  # set by stop(), even before run() has begun
        self._report = report
        self._behind_since: float | None = None  # wall time the sensors fell behind (None: on time)
        self._missed_then: dict[str, int] = {}  # late + skipped per sensor at the last check
        self._missed_at_behind = 0

    def start(
        self, loop: asyncio.AbstractEventLoop, on_ready: Callable[[Ready], None], refused: Sequence[str] = ()
    ) -> None:
        """Bind every endpoint, then call `on_ready` for each: a client reading the
        `ready` lines never finds one endpoint serving while a later one fails.
        If any cannot be bound, or the caller `refused` something of its own (a
        port taken), all are closed and one UserError names every one, a line
        each, with where it was asked for."""
        factory, executor = self._scan_sources()
        self._timer = shared_timer(loop)
        readies = []
        failures: list[str] = []
        for ordinal, (spec, addresses) in enumerate(self._plan):
            scans = self.scan_caches[spec.name] = ScanCache(
                factory(spec), executor, batch=stream_batch(spec) or SCAN_BATCH, phase=ordinal, observer=self._on_scan,
                defer=self._defer, now=self.clock.now, speed=lambda: self.clock.speed, after_send=True,
            )
            for position, address in enumerate(addresses):
                device = self._device_factory(spec, scans, phase_ms=self._phase_ms(spec))
                session = DeviceSession(
                    device, self.clock, loop, scans.prefetch, self._timer.call_later, pending=scans.pending,
                    expect=scans.expect, next_scan=scans.next_scan, input_scan=scans.input_scan, settle=scans.settle,
                    ready_scan=scans.ready_scan,
                )
                try:
                    readies.append(self._open(spec, address, session, loop))
                except UserError as error:
                    failures.append(f"{self._origin(spec, position)}: {error}")
                    continue
                self.sessions.append(session)
        if failures or refused:
            self.close()
            raise UserError("\n".join([*failures, *refused]))
        if self.world is not None:  # readers (the control API) can ask any sensor of the world
            for spec in self.scene.sensors:
                if spec.name not in self.scan_caches:
                    self.scan_caches[spec.name] = ScanCache(factory(spec), executor)
        for session in self.sessions:
            session.start()
        self._timer.call_later(OVERLOAD_CHECK_S, self._check_overload)
        for ready in readies:
            on_ready(ready)

    def sensor_counters(self) -> dict[str, dict[str, int]]:
        """Per sensor served: scans handed out, those sent after a fresher one was due (`late`: the
        daemon was behind) and a stream's scans never sent (`skipped`)."""
        return {
            name: {"served": cache.served, "late": cache.late, "skipped": cache.skipped}
            for name, cache in self.scan_caches.items()
            if name in self._served_names
        }

    def _check_overload(self) -> None:
        """Once a second: one line when sensors start skipping or sending late scans, one when a
        whole second passed without any again."""
        if self._timer is None:
            return
        self._timer.call_later(OVERLOAD_CHECK_S, self._check_overload)
        missed = {name: counts["late"] + counts["skipped"] for name, counts in self.sensor_counters().items()}
        behind = sorted(name for name, count in missed.items() if count > self._missed_then.get(name, 0))
        self._missed_then = missed
        now = self._loop_time()
        if behind and self._behind_since is None:
            self._behind_since, self._missed_at_behind = now, sum(missed.values())
            self._report(
                f"behind: {len(behind)} of {len(missed)} sensors ({_names(behind)}) skipped or sent late scans;"
                " the workers cannot compute every scan in time, each sensor sends its freshest scan"
            )
        elif not behind and self._behind_since is not None:
            self._report(
                f"caught up: every sensor on time again after {now - self._behind_since - OVERLOAD_CHECK_S:.1f} s behind"
                f" ({sum(missed.values()) - self._missed_at_behind} more scans skipped or late meanwhile)"
            )
            self._behind_since = None

    @staticmethod
    def _loop_time() -> float:
        return asyncio.get_running_loop().time()

    def _scan_sources(self) -> tuple[SensorFactory, Executor]:
        """Where scans are computed: in worker processes (sensors dealt out in turn), else
        on the scan thread (a supplied scan source, or `workers=0`)."""
        if self._workers <= 0:
            return self._sensor_factory or simulated_sensors(self.scene, self.world), self._scan_thread
        names = [spec.name for spec, _ in self._plan]
        count = min(self._workers, len(names)) or 1
        live = self.live
        self.pool = WorkerPool(self.scene, names, count, nice=self._worker_nice,
                               live_state=live.export if live is not None else None)
        self.pool.start()
        if self._before_workers:  # changes applied before the workers existed (serve --events-in)
            self.pool.apply([event_record(event) for event in self._before_workers])
            self._before_workers.clear()  # the pool keeps them from now on (a restarted worker replays them)
        pool = self.pool
        return (lambda spec: pool.sensor(spec.name)), pool.executor()

    def _defer(self, sim_seconds: float, start: Callable[[], None]) -> None:
        """Run `start` on the loop `sim_seconds` of simulated time from now (at once if the clock is paused)."""
        delay = self.clock.wall_delay(sim_seconds)
        if self._timer is None or not math.isfinite(delay):
            start()
        else:
            self._timer.call_later(delay, start)

    def _phase_ms(self, spec: SensorSpec) -> int:
        """A simulated Hokuyo's revolution phase, or a CoLa unit's power-on instant, in its scene (a supplied
        scan source keeps phase 0: a replay's scans lie where they were recorded)."""
        if self._sensor_factory is not None:
            return 0
        if spec.model in SICK_MODELS:
            return power_on_phase_ms(self.scene, spec.name)
        model = hokuyo_model(spec.model)
        return 0 if model is None else revolution_phase_ms(self.scene, spec.name, model)

    def _origin(self, spec: SensorSpec, position: int) -> str:
        """Where an endpoint was asked for: `--endpoint urg` or `x.toml: sensors[0].endpoints[1]`."""
        if spec.name in self._overridden:
            return f"--endpoint {spec.name}"
        scene_file = self.scene.path.name if self.scene.path is not None else "scene"
        return f"{scene_file}: sensors[{self.scene.sensors.index(spec)}].endpoints[{position}]"

    def _open(
        self, spec: SensorSpec, address: Address, session: DeviceSession, loop: asyncio.AbstractEventLoop
    ) -> Ready:
        if isinstance(address, PtyAddress):
            endpoint: PtyEndpoint | TcpEndpoint = PtyEndpoint(address, session)
            slave = endpoint.open(loop)
            uri, detail = str(address), slave
        else:
            kind = Rfc2217Endpoint if isinstance(address, Rfc2217Address) else TcpEndpoint
            endpoint = kind(address, session, idle_timeout_s=self.idle_timeout_s)
            uri, detail = str(endpoint.open(loop)), None
        session.endpoint = endpoint
        self.endpoints.append(endpoint)
        self._endpoint_sensors.append((spec.name, endpoint))
        return Ready(spec.name, spec.model, uri, detail)

    async def run(
        self, on_ready: Callable[[Ready], None] | None = None, on_started: Callable[[], None] | None = None,
        refused: Sequence[str] = (),
    ) -> None:
        """Serve until `stop()`; endpoints are closed (symlinks removed) on the way out.
        `on_started` runs once every endpoint serves; `refused` as for `start`."""
        try:
            self.start(asyncio.get_running_loop(), on_ready or (lambda ready: None), refused)
            if on_started is not None:
                on_started()
            await self._stopped.wait()
        finally:
            self.close()

    def stop(self) -> None:
        self._stopped.set()

    def apply(self, event: LiveEvent) -> LiveEvent:
        """A live change from its instant on: the world takes it (here, or in every worker), and
        every scan computed at or after that instant is computed again; a clock change reschedules
        every device. The event as applied (a twist with the instant it stops: workers are sent
        that). ValueError for a live pose or twist stamped before the body's last one."""
        if isinstance(event, ClockChange):
            self.clock.set(speed=event.speed, paused=event.paused)
            for session in self.sessions:
                session.reschedule()
            return event
        if self.live is None:
            raise UserError("this daemon serves recorded scans: its world cannot change")
        event = self.live.apply(event)
        # no scan is computed before the horizon any more: forget the history only it needed (here and in workers)
        # (never past the event itself: a log replayed in order keeps every change it still needs)
        # (moved on once a simulated second at most: a 100 Hz stream pays for it once in 100 changes)
        horizon = min(live_horizon(self.clock.now(), self.clock.speed), event.time_s)
        prune = horizon >= self.live.horizon + PRUNE_STEP_S
        if prune:
            self.live.prune(horizon)
        if self.pool is not None:
            # `gen`: a restarted worker given the state with this event in it already skips it
            records = [{**event_record(event), "gen": self.live.generation}]
            self.pool.apply(records + [{"op": "prune", "t": horizon}] if prune else records)  # queued before the scans submitted below
        elif self.world is None:
            self._before_workers.append(event)
        changed_from_s = self.live.changed_from_s  # a repeated twist changes the path from the old stop on
        if changed_from_s != float("inf"):
            for scans in self.scan_caches.values():
                scans.invalidate_from(changed_from_s)
        return event

    def client_counts(self) -> Counter[str]:
        """How many clients are connected to each sensor's endpoints, in one pass over them (asked per
        sensor, a 256-sensor fleet's state took 2 ms of the loop)."""
        return Counter(name for name, endpoint in self._endpoint_sensors if endpoint.link is not None)

    def close(self) -> None:
        for session in self.sessions:
            session.stop()
        for endpoint in self.endpoints:
            endpoint.close()
        self.sessions.clear()
        self.endpoints.clear()
        self._endpoint_sensors.clear()
        self._scan_thread.shutdown(wait=False, cancel_futures=True)
        if self.pool is not None:
            self.pool.close()
            self.pool = None
        if self._timer is not None:
            self._timer.close()
            self._timer = None

    def stats(self) -> dict[str, int]:
        """Counters for operators, leak tests and the bench (printed on SIGUSR1); `wakes` and
        `late_Nms`: the loop's timer wake-ups, and those more than N ms late (timer.py)."""
        links = [endpoint.link for endpoint in self.endpoints if endpoint.link is not None]
        timer = self._timer
        return {
            "endpoints": len(self.endpoints),
            "clients": len(links),
            "served": sum(endpoint.clients_served for endpoint in self.endpoints),
            "dropped": sum(link.outbox.dropped for link in links),
            "timers": sum(session.waiting for session in self.sessions),
            "scan_waits": sum(cache.waits for cache in self.scan_caches.values()),
            "late": sum(cache.late for cache in self.scan_caches.values()),
            "skipped": sum(cache.skipped for cache in self.scan_caches.values()),
            "jobs_waiting": self.pool.waiting if self.pool is not None else 0,
            # every how many revolutions each stream is computed, in % (100: every one; the workers keep up)
            "spacing_pct": round(100 * self.pool.spacing) if self.pool is not None else 100,
            "instants_dropped": sum(cache.dropped for cache in self.scan_caches.values()),
            # scan jobs the workers computed and their instants (of which `served` went out)
            "jobs_computed": self.pool.jobs_computed if self.pool is not None else 0,
            "instants_computed": self.pool.instants_computed if self.pool is not None else 0,
            "served_scans": sum(cache.served for cache in self.scan_caches.values()),
            "tasks": len(asyncio.all_tasks()),
            "fds": len(os.listdir("/proc/self/fd")),
            "gc_frozen": gc.get_freeze_count(),  # objects kept out of the collector's sight (serve freezes them once started)
            "wakes": timer.wakes if timer is not None else 0,
            **{f"late_{ms}ms": timer.late[index] if timer is not None else 0 for index, ms in enumerate(LATE_THRESHOLDS_MS)},
        }
