"""The daemon: every sensor of a scene served on its endpoints, on one asyncio loop.

Per sensor: one scan source (the simulation, or anything sensor-like such as
a replayed log) behind an LRU cache, so several endpoints of one sensor
compute each scan once. Per endpoint: its own device session (protocol state
machine) and transport. Each device is woken at its `next_deadline()`
(simulated time, mapped to wall time through the clock's speed).

Scans are computed on one "scan thread", ahead of time: a scan at simulated
time t is a pure function of t, so shortly before a device's next deadline
the scan it will ask for is started, and it is ready when the device asks.
Computing on the loop thread at the deadline took 1–8 ms (railway), which
showed up as scan-period jitter and command latency (docs/transports.md).
A steady stream (the same request at a constant stride, as a streaming device
makes) is computed SCAN_BATCH scans per job with `sensor.scans`, which shares
each numpy pass among them; a request nobody foresaw is still computed alone.
"""

from __future__ import annotations

import asyncio
import dataclasses
import os
from collections import OrderedDict, deque
from concurrent.futures import Executor, Future, ThreadPoolExecutor
from dataclasses import dataclass
from typing import Any, Callable, Mapping, Protocol, Sequence

from emulator.clock import WallClock
from emulator.errors import UserError
from emulator.optics import World
from emulator.scene.model import Scene, SensorSpec
from emulator.sensors import create_sensor
from emulator.sensors.scan import TICKS_PER_S, Scan  # cache keys are µs ticks: the grid scans are computed on
from emulator.transport import Address, EndpointClaims, PtyAddress, parse_endpoint
from emulator.transport.pty import PtyEndpoint
from emulator.transport.tcp import TcpEndpoint
from emulator.transport.timer import PreciseTimer
from protocols.device import Device, Output
from protocols.lms2xx import Lms200Device
from protocols.scip import UrgDevice

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

# the SensorSpec options each protocol device takes (SCENE_FORMAT.md)
DEVICE_OPTIONS: dict[str, tuple[str, ...]] = {
    "urg-04lx": ("serial", "boot_protocol"),
    "lms200": ("baud", "type_string", "angle_deg", "resolution_deg", "units", "firmware_profile"),
}


class Clock(Protocol):
    def now(self) -> float: ...

    def wall_delay(self, sim_seconds: float) -> float: ...


class Cancellable(Protocol):
    def cancel(self) -> None: ...


class ScanSource(Protocol):
    """What a device needs from a sensor: the scan for a request at a simulated time,
    and the same request at several times computed together."""

    def scan(self, time_s: float, **request: Any) -> Scan: ...

    def scans(self, times_s: Sequence[float], **request: Any) -> list[Scan]: ...


SensorFactory = Callable[[SensorSpec], ScanSource]
DeviceFactory = Callable[[SensorSpec, Callable[..., Scan]], Device]
RequestKey = tuple[tuple[str, Any], ...]


class ScanCache:
    """One sensor's scans for all its endpoints: each request computed once, on the
    scan thread, and ahead of time where the next request can be foreseen: the last
    request's window at the device's next deadline (`prefetch`), and the next
    SCAN_BATCH scans of a steady stream, in one `sensor.scans` job."""

    def __init__(
        self, sensor: ScanSource, executor: Executor, size: int = SCAN_CACHE_SIZE, batch: int = SCAN_BATCH
    ) -> None:
        if size < 2 * batch:
            raise ValueError(f"a scan cache of {size} cannot hold two batches of {batch}")
        self._sensor = sensor
        self._executor = executor
        self._size = size
        self._batch = batch
        self._futures: OrderedDict[tuple, Future] = OrderedDict()
        self._last_request: dict[str, Any] | None = None
        self._recent_times: dict[RequestKey, deque[float]] = {}
        self._predicted_until: dict[RequestKey, float] = {}
        self._strides: dict[RequestKey, float] = {}

    def __call__(self, time_s: float, **request: Any) -> Scan:
        """What a device calls: the scan for this request (computed now, alone, if not foreseen)."""
        self._last_request = request
        future = self._future(time_s, request)
        self._follow_stream(time_s, request)
        scan = future.result()
        return scan if scan.time_s == time_s else dataclasses.replace(scan, time_s=time_s)

    def __len__(self) -> int:
        """How many scans (done or under way) the cache holds: at most its size."""
        return len(self._futures)

    def prefetch(self, time_s: float) -> None:
        """Start computing the scan the device will most likely ask for at `time_s`: the next batch
        if it is the stream's next scan past those foreseen (the prefetch lead can exceed a stride)."""
        request = self._last_request
        if request is None:
            return
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
            future = self._executor.submit(self._sensor.scan, time_s, **request)
            self._store(key, future)
        else:
            self._futures.move_to_end(key)
        return future

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
        self._predict(shape, until if until is not None and until > time_s - STRIDE_TOLERANCE_S else time_s, stride, request)

    def _predict(self, shape: RequestKey, after_s: float, stride: float, request: dict[str, Any]) -> None:
        """Foresee the stream's next SCAN_BATCH scans after `after_s`, in one job."""
        predicted = [after_s + j * stride for j in range(1, self._batch + 1)]
        self._predicted_until[shape] = predicted[-1]
        self._submit_batch(predicted, request)

    def _submit_batch(self, times_s: list[float], request: dict[str, Any]) -> None:
        """One `sensor.scans` job for the times not already foreseen; a future per time."""
        wanted = [(time_s, _cache_key(time_s, request)) for time_s in times_s]
        wanted = [(time_s, key) for time_s, key in wanted if key not in self._futures]
        if not wanted:
            return
        job = self._executor.submit(self._sensor.scans, [time_s for time_s, _ in wanted], **request)
        parts: list[Future] = []
        for _, key in wanted:
            parts.append(Future())
            self._store(key, parts[-1])
        job.add_done_callback(lambda done: _settle(done, parts))


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


def simulated_sensors(scene: Scene) -> SensorFactory:
    """Sensors computed from the scene, all sharing one optics world."""
    world = World(scene)
    return lambda spec: create_sensor(scene, spec.name, world=world)


def build_device(spec: SensorSpec, scans: Callable[..., Scan]) -> Device:
    """The protocol device for the sensor's model, configured from its scene options.
    It powers on at simulated time 0: a URG stamp is the scan's simulated time in ms."""
    if spec.model not in DEVICE_OPTIONS:
        raise UserError(f"sensor {spec.name!r}: no protocol for model {spec.model!r}")
    options = {key: spec.options[key] for key in DEVICE_OPTIONS[spec.model] if key in spec.options}
    if spec.model == "urg-04lx":
        return UrgDevice(scans, **options)
    return Lms200Device(scans, **options)


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


class DeviceSession:
    """One endpoint's device: client bytes in, outputs out, woken at its deadlines.

    `prefetch(deadline)` starts the scan the device will want then; `call_later`
    schedules the wake-up (default: the loop's own, millisecond-accurate timers).
    """

    def __init__(
        self,
        device: Device,
        clock: Clock,
        loop: asyncio.AbstractEventLoop,
        prefetch: Callable[[float], None] | None = None,
        call_later: Callable[..., Cancellable] | None = None,
    ) -> None:
        self.device = device
        self.endpoint: PtyEndpoint | TcpEndpoint | None = None
        self._clock = clock
        self._prefetch = prefetch
        self._call_later = call_later or loop.call_later
        self._timer: Cancellable | None = None
        self._prefetch_timer: Cancellable | None = None

    @property
    def baud(self) -> int | None:
        return self.device.baud

    def received(self, data: bytes) -> None:
        self._deliver(self.device.receive(data, self._clock.now()))

    def disconnected(self) -> None:
        self.device.connection_lost()
        self._schedule()

    @property
    def waiting(self) -> bool:
        """A wake-up is scheduled for the device's next deadline."""
        return self._timer is not None

    def start(self) -> None:
        self._schedule()

    def stop(self) -> None:
        for timer in (self._timer, self._prefetch_timer):
            if timer is not None:
                timer.cancel()
        self._timer = self._prefetch_timer = None

    def _wake(self) -> None:
        self._timer = None
        self._deliver(self.device.poll(self._clock.now()))

    def _deliver(self, outputs: list[Output]) -> None:
        if outputs and self.endpoint is not None:
            self.endpoint.send(outputs)
        self._schedule()

    def _schedule(self) -> None:
        self.stop()
        deadline = self.device.next_deadline()
        if deadline is not None:
            delay = self._clock.wall_delay(deadline - self._clock.now())
            self._timer = self._call_later(delay, self._wake)
            if self._prefetch is not None:
                lead = max(0.0, delay - PREFETCH_LEAD_S)
                self._prefetch_timer = self._call_later(lead, self._prefetch, deadline)


def _plan(
    scene: Scene, endpoints_override: Mapping[str, Sequence[str]] | None
) -> list[tuple[SensorSpec, tuple[Address, ...]]]:
    """Each sensor with the endpoints it is served on; UserError for unknown sensors or bad URIs."""
    overrides = dict(endpoints_override or {})
    known = {spec.name for spec in scene.sensors}
    for name in overrides:
        if name not in known:
            raise UserError(f"--endpoint: no sensor named {name!r} (known: {', '.join(sorted(known)) or 'none'})")
    plan = []
    claims = EndpointClaims()
    for spec in scene.sensors:
        addresses = tuple(parse_endpoint(uri) for uri in overrides.get(spec.name, spec.endpoints))
        for address in addresses:
            clash = claims.claim(address, spec.name)
            if clash is not None:
                raise UserError(f"endpoint {address} given twice (sensors {clash[1]!r} and {spec.name!r})")
        if addresses:
            plan.append((spec, addresses))
    return plan


class Daemon:
    """Serves `scene`'s sensors. `endpoints_override` maps a sensor name to the
    URIs that replace its scene endpoints; `sensor_factory` supplies scan sources
    (default: the simulation); `device_factory` builds each endpoint's device."""

    def __init__(
        self,
        scene: Scene,
        endpoints_override: Mapping[str, Sequence[str]] | None = None,
        clock: Clock | None = None,
        *,
        sensor_factory: SensorFactory | None = None,
        device_factory: DeviceFactory = build_device,
    ) -> None:
        self.scene = scene
        self.clock = clock or WallClock()
        self.sessions: list[DeviceSession] = []
        self.endpoints: list[PtyEndpoint | TcpEndpoint] = []
        self._plan = _plan(scene, endpoints_override)
        self._sensor_factory = sensor_factory
        self._device_factory = device_factory
        self._scan_thread = ThreadPoolExecutor(max_workers=1, thread_name_prefix="scan")
        self._timer: PreciseTimer | None = None
        self._stopped = asyncio.Event()  # set by stop(), even before run() has begun

    def start(self, loop: asyncio.AbstractEventLoop, on_ready: Callable[[Ready], None]) -> None:
        """Open every endpoint, calling `on_ready` as each one serves."""
        factory = self._sensor_factory or simulated_sensors(self.scene)
        self._timer = PreciseTimer(loop)
        for spec, addresses in self._plan:
            scans = ScanCache(factory(spec), self._scan_thread)
            for address in addresses:
                device = self._device_factory(spec, scans)
                session = DeviceSession(device, self.clock, loop, scans.prefetch, self._timer.call_later)
                ready = self._open(spec, address, session, loop)
                self.sessions.append(session)
                session.start()
                on_ready(ready)

    def _open(
        self, spec: SensorSpec, address: Address, session: DeviceSession, loop: asyncio.AbstractEventLoop
    ) -> Ready:
        if isinstance(address, PtyAddress):
            endpoint: PtyEndpoint | TcpEndpoint = PtyEndpoint(address, session)
            slave = endpoint.open(loop)
            uri, detail = str(address), slave
        else:
            endpoint = TcpEndpoint(address, session)
            uri, detail = str(endpoint.open(loop)), None
        session.endpoint = endpoint
        self.endpoints.append(endpoint)
        return Ready(spec.name, spec.model, uri, detail)

    async def run(self, on_ready: Callable[[Ready], None] | None = None) -> None:
        """Serve until `stop()`; endpoints are closed (symlinks removed) on the way out."""
        try:
            self.start(asyncio.get_running_loop(), on_ready or (lambda ready: None))
            await self._stopped.wait()
        finally:
            self.close()

    def stop(self) -> None:
        self._stopped.set()

    def close(self) -> None:
        for session in self.sessions:
            session.stop()
        for endpoint in self.endpoints:
            endpoint.close()
        self.sessions.clear()
        self.endpoints.clear()
        self._scan_thread.shutdown(wait=False, cancel_futures=True)
        if self._timer is not None:
            self._timer.close()
            self._timer = None

    def stats(self) -> dict[str, int]:
        """Counters for operators and leak tests (printed on SIGUSR1)."""
        links = [endpoint.link for endpoint in self.endpoints if endpoint.link is not None]
        return {
            "endpoints": len(self.endpoints),
            "clients": len(links),
            "served": sum(endpoint.clients_served for endpoint in self.endpoints),
            "dropped": sum(link.outbox.dropped for link in links),
            "timers": sum(session.waiting for session in self.sessions),
            "tasks": len(asyncio.all_tasks()),
            "fds": len(os.listdir("/proc/self/fd")),
        }
