"""The latest scan of each sensor, for `GET /api/sensors/{name}/scan` and WebSocket subscribers.

A sensor's scans come from the daemon's scan cache (computed once, on the
scan thread, shared with the devices that ask for the same window), at the
sensor's configured period: the scan the scene's options select, in the JSON
of `lrf-emulator scan`. While a WebSocket client subscribes to a sensor, one
task per sensor takes each scan as it completes in simulated time and hands
the serialized message to every subscriber; turning scans into JSON runs off
the loop, once per scan whatever the number of subscribers.
"""

from __future__ import annotations

import asyncio
import dataclasses
import json
import math
from concurrent.futures import Executor
from typing import Any, Callable

from emulator.daemon.scan_cache import ScanCache
from emulator.daemon.service import Daemon
from emulator.scene.model import SensorSpec
from emulator.sensors.lms200 import PERIOD_S as LMS_REVOLUTION_S
from emulator.sensors.lms200 import REVOLUTIONS_PER_SCAN, configured_window
from emulator.sensors.scan import Scan
from emulator.sensors.scan_json import scan_json
from emulator.scene.sick_models import MODELS as SICK_MODELS
from emulator.sensors import hokuyo_model, sick_cola

Subscriber = Callable[[str], None]  # gets each scan message, serialized


def configured_request(spec: SensorSpec) -> dict[str, Any]:
    """The scan keywords of the scan the scene's options select (none for a Hokuyo): the LMS200's window,
    a CoLa SICK's scan configuration (the request its device makes at power-on)."""
    if spec.model in SICK_MODELS:
        return sick_cola.configured_request(spec.options)
    return configured_window(spec.options) if spec.model == "lms200" else {}


def _scan_text(scan: Scan, period_s: float) -> str:
    return json.dumps(scan_json(scan, None, period_s))


def configured_period_s(spec: SensorSpec) -> float:
    """The time one configured scan takes: a Hokuyo's revolution (0.1 s URG-04LX, 25 ms the others);
    1, 2 or 4 mirror revolutions (LMS200)."""
    hokuyo = hokuyo_model(spec.model)
    if hokuyo is not None:
        return hokuyo.period_s
    if spec.model in SICK_MODELS:  # one turn at the configured scan frequency
        return 1.0 / float(spec.options["scan_frequency_hz"])
    return REVOLUTIONS_PER_SCAN[configured_window(spec.options)["step_deg"]] * LMS_REVOLUTION_S


class ScanFeed:
    """Latest scans and per-sensor subscriptions over the daemon's scan caches."""

    def __init__(self, daemon: Daemon, serializer: Executor, clock_changed: asyncio.Event) -> None:
        self._daemon = daemon
        self._serializer = serializer
        self._clock_changed = clock_changed
        self._specs = {spec.name: spec for spec in daemon.scene.sensors}
        self._subscribers: dict[str, set[Subscriber]] = {}
        self._tasks: dict[str, asyncio.Task] = {}
        self._served: dict[str, tuple[Scan, float, str]] = {}  # per sensor: what `latest` served last (cache's scan, time, text)

    def spec(self, name: str) -> SensorSpec | None:
        return self._specs.get(name)

    def serves(self, name: str) -> bool:
        """Whether this daemon computes the sensor's scans (a fleet's daemon serves only its group)."""
        return name in self._daemon.scan_caches

    async def latest(self, name: str) -> str:
        """The sensor's latest completed scan (at the last period boundary at or before now), as JSON text.
        Made in the serializer thread, once per scan: clients polling faster than the sensor scans get
        the same text, and the loop never encodes a scan."""
        spec = self.spec(name)
        assert spec is not None
        period = configured_period_s(spec)
        time_s = max(0, math.floor(self._daemon.clock.now() / period + 1e-9)) * period
        computed = await self._scan(spec, time_s)
        served = self._served.get(name)
        if served is None or served[0] is not computed or served[1] != time_s:
            scan = _stamped(computed, time_s)
            text = await asyncio.get_running_loop().run_in_executor(self._serializer, _scan_text, scan, period)
            self._served[name] = served = (computed, time_s, text)
        return served[2]

    async def _scan(self, spec: SensorSpec, time_s: float) -> Scan:
        """The cache's scan for `time_s` (its own stamp may differ: see `_stamped`), computed again if a
        live change replaced it while it was computed."""
        cache: ScanCache = self._daemon.scan_caches[spec.name]
        request = configured_request(spec)
        while True:
            future = cache.request(time_s, **request)
            scan = await asyncio.wrap_future(future)
            if cache.holds(time_s, future, **request):
                return scan

    def subscribe(self, name: str, subscriber: Subscriber) -> None:
        self._subscribers.setdefault(name, set()).add(subscriber)
        if name not in self._tasks or self._tasks[name].done():
            self._tasks[name] = asyncio.get_running_loop().create_task(self._feed(name))

    def unsubscribe(self, subscriber: Subscriber) -> None:
        for name, subscribers in self._subscribers.items():
            subscribers.discard(subscriber)

    def close(self) -> None:
        for task in self._tasks.values():
            task.cancel()

    async def _feed(self, name: str) -> None:
        """Each scan of the sensor as it completes in simulated time, while anyone subscribes."""
        spec = self.spec(name)
        assert spec is not None
        period = configured_period_s(spec)
        clock = self._daemon.clock
        index = math.floor(clock.now() / period + 1e-9) + 1
        loop = asyncio.get_running_loop()
        while self._subscribers.get(name):
            time_s = index * period
            delay = clock.wall_delay(time_s - clock.now())
            if delay > 0:
                self._clock_changed.clear()
                try:
                    await asyncio.wait_for(self._clock_changed.wait(), None if math.isinf(delay) else delay)
                    continue  # the clock changed: the wait is measured again
                except asyncio.TimeoutError:
                    pass
                if clock.now() < time_s - 1e-6:
                    continue
            scan = _stamped(await self._scan(spec, time_s), time_s)
            counters = self._daemon.sensor_counters().get(name, {})
            behind = {key: counters[key] for key in ("late", "skipped") if key in counters}
            message = await loop.run_in_executor(self._serializer, _scan_message, scan, period, behind)
            for subscriber in list(self._subscribers.get(name, ())):
                subscriber(message)
            index = max(index + 1, math.floor(clock.now() / period + 1e-9))  # a late feed skips, never bursts


def _scan_message(scan: Scan, period_s: float, behind: dict[str, int]) -> str:
    """The scan, and the sensor's counts of scans its devices sent late or skipped so far (the daemon was behind)."""
    return json.dumps({"type": "scan", **scan_json(scan, None, period_s), **behind})


def _stamped(scan: Scan, time_s: float) -> Scan:
    """The scan stamped `time_s` (the instant asked for, if the cache's scan carries another)."""
    return scan if scan.time_s == time_s else dataclasses.replace(scan, time_s=time_s)
