"""`LiveSession`: the one place live changes enter a running daemon, and its event log.

Every front end (HTTP, WebSocket, `serve --events-in`) hands its changes to
`LiveSession.request` or `apply`; the session stamps them with the simulated
instant they take effect, applies them to the daemon (world, scan caches,
clock), appends them to the event log (and `--events FILE`), and tells its
listeners (the WebSocket clients' state messages). In memory it keeps the
last `EVENTS_SHOWN` events (`GET /api/events`), each also as its JSON text,
made once when it is applied: building the JSON of 10 000 events took the
loop 34 ms a request, every other client's scans waiting meanwhile; joining
the texts takes 0.5 ms. The file keeps them all.
"""

from __future__ import annotations

import collections
import dataclasses
import functools
import json
import math
from pathlib import Path
from typing import Any, Callable, Mapping

import numpy as np

from emulator.control.events import ControlError, EventWriter, change, change_instant, event_json, record
from emulator.daemon.service import Daemon
from emulator.scene.live import LiveEvent
from emulator.scene.live_limits import LiveLimits
from emulator.scene.model import Pose, Scene

Listener = Callable[[LiveEvent], None]

EVENTS_SHOWN = 10_000  # the last events applied, kept for `GET /api/events` (the --events file keeps every one)


class LiveSession:
    """Live changes to `daemon`, logged; `writer` (serve --events) gets each one as it is applied."""

    def __init__(self, daemon: Daemon, writer: EventWriter | None = None) -> None:
        self.daemon = daemon
        self.scene: Scene = daemon.scene
        self._shown: collections.deque[tuple[LiveEvent, str]] = collections.deque(maxlen=EVENTS_SHOWN)  # each with its JSON
        self.applied = 0  # events applied in all
        self.limits = LiveLimits(self.scene)  # the scene file's limits, for every change in turn
        self._writer = writer
        self._listeners: list[Listener] = []

    def listen(self, listener: Listener) -> Callable[[], None]:
        """Call `listener(event)` after each applied change; returns what stops it."""
        self._listeners.append(listener)
        return lambda: self._listeners.remove(listener) if listener in self._listeners else None

    def request(self, op: Any, name: Any, body: Any) -> LiveEvent:
        """A change asked for now: checked (ControlError), stamped with the next µs tick, applied."""
        if self.daemon.live is None and op != "clock":
            raise ControlError(409, "this daemon serves recorded scans: its world cannot change", "op")
        event = change(self.scene, op, name, body, change_instant(self.daemon.clock.now()), self.limits)
        return self.apply(event)

    def apply(self, event: LiveEvent) -> LiveEvent:
        """Apply an event (checked already, e.g. read from a log) and record it; the event as applied
        (a twist with where it stops). ControlError 409 for a live pose or twist stamped before the
        body's last one (a log replayed ahead of now)."""
        try:
            event = self.daemon.apply(event)
        except ValueError as error:
            raise ControlError(409, str(error), f"bodies[{event.name}]") from None
        self._shown.append((event, json.dumps(event_json(event))))
        self.applied += 1
        record(self.limits, event)
        if self.daemon.live is not None:
            self.limits.particles.prune(self.daemon.live.horizon)
        if self._writer is not None:
            self._writer.write(event)
        for listener in list(self._listeners):
            listener(event)
        return event

    def close(self) -> None:
        if self._writer is not None:
            self._writer.close()

    # ----------------------------------------------------------------------- what the API shows

    @property
    def events(self) -> list[LiveEvent]:
        """The last EVENTS_SHOWN events applied, oldest first."""
        return [event for event, _ in self._shown]

    def event_log_text(self) -> str:
        """`GET /api/events`: the events kept, as one JSON array."""
        return "[" + ", ".join(text for _, text in self._shown) + "]"

    def state(self) -> dict[str, Any]:
        """`GET /api/state`: the clock, and what holds now of every live quantity."""
        clock = self.daemon.clock
        now = clock.now()
        live = self.daemon.live
        state: dict[str, Any] = {
            "time_s": round(now, 6),
            "speed": clock.speed,
            "paused": bool(getattr(clock, "paused", False)),
            "bodies": {},
            "regions": {},
            "plumes": {},
            "sensors": {},
        }
        if live is not None:
            for body in self.scene.bodies:
                state["bodies"][body.name] = pose_json(live.body_pose(body.name, now))
                if body.name in live.bodies.live_names:
                    state["bodies"][body.name]["twist"] = dataclasses.asdict(live.body_twist(body.name, now))
            for index, region in enumerate(self.scene.regions):
                state["regions"][region.name] = {"density": live.region_density(index, now)}
            for plume in self.scene.plumes:
                state["plumes"][plume.name] = live.plume_state(plume.name, now)
        counters = self.daemon.sensor_counters()
        clients = self.daemon.client_counts()
        for spec in self.scene.sensors:
            state["sensors"][spec.name] = {"pose": pose_json(spec.pose), "clients": clients[spec.name]}
            if spec.name in counters:  # behind: scans sent after a fresher one was due, and never sent
                state["sensors"][spec.name] |= {key: counters[spec.name][key] for key in ("late", "skipped")}
        return state

    def live_poses(self) -> dict[str, Any]:
        """The live bodies' poses and twists now: `{"time_s", "bodies": {name: {"position", "rotation_deg", "twist"}}}`."""
        now = self.daemon.clock.now()
        live = self.daemon.live
        bodies = {}
        for name in live.bodies.live_names if live is not None else ():
            bodies[name] = {**pose_json(live.body_pose(name, now)), "twist": dataclasses.asdict(live.body_twist(name, now))}
        return {"time_s": round(now, 6), "bodies": bodies}

    @functools.cached_property
    def scene_text(self) -> str:
        """`GET /api/scene`: the loaded scene as JSON text, made once (rescue's takes 8 ms: per request,
        a client polling it would hold the loop from every device)."""
        return json.dumps(plain(self.scene))


def pose_json(pose: Pose) -> dict[str, list[float]]:
    return {"position": list(pose.position), "rotation_deg": list(pose.rotation_deg)}


def plain(value: Any) -> Any:
    """A scene's dataclasses as JSON-ready values; a shape says its kind (`{"kind": "box", ...}`)."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        fields = {field.name: plain(getattr(value, field.name)) for field in dataclasses.fields(value)}
        if type(value).__name__ in ("Box", "Sphere", "Cylinder", "MeshFile"):
            return {"kind": type(value).__name__.lower().replace("meshfile", "mesh"), **fields}
        return fields
    if isinstance(value, Mapping):
        return {str(key): plain(item) for key, item in value.items()}
    if isinstance(value, (list, tuple)):
        return [plain(item) for item in value]
    if isinstance(value, Path):
        return str(value)
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, (np.integer, np.floating)):
        return value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value

