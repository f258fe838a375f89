"""Live changes to a scene, and the scene's state at any instant under them.

While `serve` runs, the control API changes the world: a smoke region's
density, a plume's emission (on/off, rate, wind), a live body's pose, the
clock. Each change is an event stamped with the simulated instant it takes
effect. The world at time t stays a pure function of (scene, seed, events,
t): an event changes nothing before its instant, so a scan at t depends only
on the events stamped at or before t, and caching, batching and prefetching
stay correct as long as scans at or after a new event's instant are
recomputed (the daemon's scan caches drop them).

`LiveState` holds the events applied so far, per region and plume (a live
body's poses and twists go to its `BodyPoses`, scene/bodies.py), and answers
"what holds at t". A twist is resolved when it is applied: it holds until the
body's watchdog or, earlier, until the body's footprint touches a solid
(scene/obstacles.py); the resolved event carries that instant (`until_s`), so
worker processes given it move their copies of the body without the solids. Events of one item normally arrive in time order; a density or plume
change stamped before that item's later changes (a log replayed ahead, then a
change made by hand) replaces them, as a density change drops the scene's
keyframes after it; live poses only move forward.

Only what can still matter is kept in memory. The daemon computes no instant
before its horizon (`LIVE_KEEP_S` simulated seconds before now, longer at a
fast clock: daemon/service.py); `prune(horizon)` then drops each item's
events superseded before the horizon (keeping the one holding at it), a
plume's changes whose particles have all died by then (their emission state
carried on, so particle indices and cadence stay the same), and a live
body's events before the one holding at it. Every instant at or after the
horizon evaluates bit for bit as without pruning; an instant before it, or a
change stamped before it, is a ValueError. The event log file keeps every
event (control/events.py).

`event_record` / `event_from_record` turn events into plain dicts and back,
for the event log and for worker processes (daemon/workers.py), which apply
the same events to their own worlds.
"""

from __future__ import annotations

import bisect
import dataclasses
import functools
import threading
from dataclasses import dataclass, field
from typing import Union

from typing import Any

import numpy as np
from emulator.scene.bodies import BodyPoses
from emulator.scene.drive import Drive, Twist
from emulator.scene.obstacles import Obstacles
from emulator.scene.model import Plume, Pose, Scene, Vec3
from emulator.scene.plumes import EmissionSegment, scene_emission


@dataclass(frozen=True)
class RegionChange:
    """From `time_s` on, smoke region `name` holds `density` (its keyframes after that are dropped)."""

    time_s: float
    name: str
    density: float

    op = "region"


@dataclass(frozen=True)
class PlumeChange:
    """From `time_s` on, plume `name`'s particles are born with what is given (None: unchanged).

    `emitting` overrides the scene's start/stop schedule from then on; particles
    already alive keep the rate and wind of their birth.
    """

    time_s: float
    name: str
    emitting: bool | None = None
    rate: float | None = None
    wind: Vec3 | None = None

    op = "plume"


@dataclass(frozen=True)
class PoseChange:
    """From `time_s` on, live body `name` stands at `pose` (until its next pose)."""

    time_s: float
    name: str
    pose: Pose

    op = "pose"


@dataclass(frozen=True)
class TwistChange:
    """From `time_s` on, live body `name` moves by `twist` (its frame) from where it then is, until
    `until_s`: its watchdog, or a solid it touches (None until the event is resolved by `LiveState`)."""

    time_s: float
    name: str
    twist: Twist
    until_s: float | None = None

    op = "twist"


@dataclass(frozen=True)
class ClockChange:
    """At `time_s` the clock's speed and/or pause changed; scans do not depend on it (logged for the record)."""

    time_s: float
    speed: float | None = None
    paused: bool | None = None

    op = "clock"
    name = ""


LiveEvent = Union[RegionChange, PlumeChange, PoseChange, TwistChange, ClockChange]
WorldEvent = Union[RegionChange, PlumeChange, PoseChange, TwistChange]


LIVE_KEEP_S = 60.0  # simulated seconds of live history kept before now (x the clock's speed when faster)


def live_horizon(now_s: float, speed: float = 1.0) -> float:
    """The earliest instant the daemon may still compute at `now_s`: `LIVE_KEEP_S` simulated seconds
    before now, or that many wall seconds at a clock faster than real time."""
    return now_s - LIVE_KEEP_S * max(1.0, speed)


@dataclass
class _Track:
    """One item's events, ascending in time: parallel lists so `bisect` finds the one holding at t."""

    times: list[float] = field(default_factory=list)
    events: list = field(default_factory=list)

    def add(self, time_s: float, event: object) -> None:
        """Append, dropping this item's events stamped after `time_s` (the new one replaces them)."""
        keep = bisect.bisect_right(self.times, time_s)
        if keep < len(self.times):
            del self.times[keep:], self.events[keep:]
        self.events.append(event)
        self.times.append(time_s)

    def holding(self, time_s: float):
        """The last event stamped at or before `time_s`, or None."""
        position = bisect.bisect_right(self.times, time_s)
        return self.events[position - 1] if position else None

    def drop_before(self, count: int) -> None:
        """Forget the first `count` events."""
        if count > 0:
            del self.times[:count], self.events[:count]

    def superseded(self, time_s: float) -> int:
        """How many leading events are superseded at `time_s` (all before the one holding then)."""
        return max(bisect.bisect_right(self.times, time_s) - 1, 0)


@dataclass(frozen=True)
class _Emission:
    """A plume's emission state where its kept changes begin (those before were pruned): what is
    emitting then (None: the scene's schedule), rate, wind, the next particle index, the last birth."""

    emitting: bool | None
    rate: float
    wind: Vec3
    next_index: int
    last_birth: float | None


class LiveState:
    """The live events applied to one scene, and what they make of it at any instant.

    `apply` runs on the daemon's loop thread while scans read on the scan
    thread: a lock keeps each read consistent. `generation` counts applied
    world events, so a cache of anything computed from this state can tell
    when it is stale.
    """

    def __init__(self, scene: Scene, bodies: BodyPoses | None = None) -> None:
        self.scene = scene
        self.bodies = bodies if bodies is not None else BodyPoses(scene.bodies)
        self.generation = 0
        self._lock = threading.Lock()
        self._changing = threading.RLock()  # a whole apply or prune: `export` sees none half done
        self._regions = {region.name: _Track() for region in scene.regions}
        self._plumes = {plume.name: _Track() for plume in scene.plumes}
        self._segments: dict[str, tuple[EmissionSegment, ...] | None] = {plume.name: None for plume in scene.plumes}
        self._carried: dict[str, _Emission | None] = {plume.name: None for plume in scene.plumes}
        # per plume, for a change appended after the others: the segments before its last change, the
        # state then, and that change (so appending recomputes two changes' parts, not all of them)
        self._before_last: dict[str, tuple[list[EmissionSegment], _Emission, PlumeChange] | None] = {
            plume.name: None for plume in scene.plumes}
        self._plume_by_name = {plume.name: plume for plume in scene.plumes}
        self.horizon = float("-inf")  # no instant before it is kept (`prune`)
        # from which instant the world changed by the last change applied (inf: it changed nothing)
        self.changed_from_s = float("inf")

    def apply(self, event: WorldEvent) -> WorldEvent:
        """Take `event` into account from its instant on (validated by the caller: names exist); the
        event as applied (a twist resolved). ValueError for a pose or twist stamped before the body's last one,
        or any change stamped before the horizon (`prune`)."""
        with self._changing:
            return self._apply(event)

    def _apply(self, event: WorldEvent) -> WorldEvent:
        if event.time_s < self.horizon:
            raise ValueError(f"live {event.op} at {event.time_s} s is before the kept history's horizon ({self.horizon} s)")
        self.changed_from_s = event.time_s
        if isinstance(event, (PoseChange, TwistChange)):
            if isinstance(event, PoseChange):
                self.bodies.add_live_pose(event.name, event.time_s, event.pose)
            else:
                event = self.resolved(event)
                self.changed_from_s = self.bodies.add_live_twist(event.name, event.time_s, event.twist, event.until_s)
            with self._lock:
                self.generation += 1
            return event
        with self._lock:
            if isinstance(event, RegionChange):
                self._regions[event.name].add(event.time_s, event)
            elif isinstance(event, PlumeChange):
                track = self._plumes[event.name]
                track.add(event.time_s, event)
                plume = self._plume_by_name[event.name]
                self._segments[event.name] = self._emission_after(plume, track)
            else:
                raise TypeError(f"not a world event: {event!r}")
            self.generation += 1
        return event

    def _emission_after(self, plume: Plume, track: _Track) -> tuple[EmissionSegment, ...]:
        """The plume's segments once `track`'s last change was added (lock held): from the last change's
        part on when it was appended after the one before, else from the first kept change."""
        name, events, before = plume.name, track.events, self._before_last[plume.name]
        if before is not None and len(events) >= 2 and events[-2] is before[2]:
            prefix, state, last = before
            parts, state = _emission(plume, [last], state, events[-1].time_s)
            prefix.extend(parts)
        else:
            prefix_parts, state = _emission(plume, events[:-1], self._carried[name], events[-1].time_s)
            prefix = list(prefix_parts)
        self._before_last[name] = (prefix, state, events[-1])
        return (*prefix, *_emission(plume, events[-1:], state, float("inf"))[0])

    def prune(self, horizon_s: float) -> None:
        """Forget what no instant at or after `horizon_s` depends on (module docstring); later changes
        must be stamped at or after it. Amortised: an item's history is cut once half of it is droppable."""
        with self._changing:
            self._prune(horizon_s)

    def export(self) -> dict[str, Any]:
        """What this state holds, picklable (a restarted worker `restore`s it rather than replaying every change)."""
        with self._changing, self._lock:
            return {
                "generation": self.generation, "horizon": self.horizon,
                "regions": {name: list(track.events) for name, track in self._regions.items()},
                "plumes": {name: (list(track.events), self._carried[name], self._segments[name]) for name, track in self._plumes.items()},
                "bodies": {name: self.bodies.live_events(name) for name in self.bodies.live_names},
            }

    def restore(self, exported: dict[str, Any]) -> None:
        """Hold what `export` gave (another state of the same scene), in place of what this one held."""
        with self._changing, self._lock:
            self.generation, self.horizon = exported["generation"], exported["horizon"]
            for name, events in exported["regions"].items():
                self._regions[name] = _Track([event.time_s for event in events], list(events))
            for name, (events, carried, segments) in exported["plumes"].items():
                self._plumes[name] = _Track([event.time_s for event in events], list(events))
                self._carried[name], self._segments[name], self._before_last[name] = carried, segments, None
            self.bodies.restore(exported["bodies"], exported["horizon"])

    def _prune(self, horizon_s: float) -> None:
        with self._lock:
            if horizon_s <= self.horizon:
                return
            self.horizon = horizon_s
            for track in self._regions.values():
                count = track.superseded(horizon_s)
                if count and 2 * count >= len(track.times):
                    track.drop_before(count)
            for name, track in self._plumes.items():
                plume = self._plume_by_name[name]
                # a change's particles are born before the next change and all dead `lifetime` after it
                dead_by = horizon_s - plume.lifetime
                count = track.superseded(dead_by)
                if count and 2 * count >= len(track.times):
                    _, self._carried[name] = _emission(plume, track.events[:count], self._carried[name], track.times[count])
                    track.drop_before(count)
                    self._before_last[name] = None  # rebuilt from the kept changes at the next one
                    segments = self._segments[name]
                    self._segments[name] = tuple(s for s in segments or () if s.end + plume.lifetime > horizon_s)
        self.bodies.prune(horizon_s)

    def held(self) -> int:
        """How many live events are held in memory (regions, plumes and live bodies)."""
        with self._lock:
            count = sum(len(track.times) for track in (*self._regions.values(), *self._plumes.values()))
        return count + sum(len(self.bodies.live_events(name).times) for name in self.bodies.live_names)

    def resolved(self, event: TwistChange) -> TwistChange:
        """The twist with the instant it stops: its watchdog, or the first contact with a solid before.
        ValueError when it is stamped before the body's last event."""
        if event.until_s is not None:
            return event
        last_s = self.bodies.last_event_s(event.name)
        if event.time_s < last_s:
            raise ValueError(f"live twist at {event.time_s} s is earlier than the body's last event ({last_s} s)")
        drive = self.bodies.body(event.name).drive
        twist = np.array([event.twist.vx, event.twist.vy, event.twist.wz])
        until_s = self._continued_until(event, drive, twist, last_s)
        if until_s is not None:
            return dataclasses.replace(event, until_s=until_s)
        position, quaternion = self.bodies.live_pose(event.name, event.time_s)
        moving_s = self.obstacles.travel_time(drive, position, quaternion, twist, drive.watchdog_s)
        return dataclasses.replace(event, until_s=event.time_s + moving_s)

    def _continued_until(self, event: TwistChange, drive: Drive, twist: np.ndarray, last_s: float) -> float | None:
        """Where the same twist again, while the last one still moves the body, stops (None if it is not
        such a twist). Its path up to the old stop was searched already: a stop short of the last
        twist's watchdog was a solid, which the same path meets at the same instant; otherwise only
        the path on from the old stop is searched, up to this twist's watchdog."""
        old_until = self.bodies.moving_by(event.name, event.time_s, twist)
        if old_until is None:
            return None
        if old_until != last_s + drive.watchdog_s:
            return old_until  # stopped by a solid
        remaining_s = event.time_s + drive.watchdog_s - old_until
        position, quaternion = self.bodies.live_pose(event.name, old_until)
        moving_s = self.obstacles.travel_time(drive, position, quaternion, twist, remaining_s)
        return event.time_s + drive.watchdog_s if moving_s >= remaining_s else old_until + moving_s

    @functools.cached_property
    def obstacles(self) -> Obstacles:
        """The solids that stop driven bodies (built at the first twist, or by `prepare_obstacles`)."""
        return Obstacles(self.scene)

    def prepare_obstacles(self) -> None:
        """Cut the solids for every live body's footprint at its scene height now, not at its first twist."""
        for body in self.scene.bodies:
            if body.name in self.bodies.live_names:
                z = body.pose.position[2]
                self.obstacles.outlines(z + body.drive.clearance, z + body.drive.height)

    def body_twist(self, name: str, time_s: float) -> Twist:
        """The twist moving live body `name` at `time_s` (zero when it stands)."""
        return self.bodies.live_twist(name, time_s)

    def region_density(self, index: int, time_s: float) -> float:
        """Region `index`'s density at `time_s`: its last live change, else the scene's keyframes."""
        region = self.scene.regions[index]
        with self._lock:
            change = self._regions[region.name].holding(time_s)
        return change.density if change is not None else float(region.density.at(time_s))

    def plume_segments(self, index: int) -> tuple[EmissionSegment, ...] | None:
        """Plume `index`'s emission segments, or None while no live change touched it (the scene's emission)."""
        with self._lock:
            return self._segments[self.scene.plumes[index].name]

    def plume_state(self, name: str, time_s: float) -> dict:
        """What plume `name` emits at `time_s`: {"emitting", "rate", "wind"} (for the control API's state)."""
        plume = self._plume_by_name[name]
        if time_s < self.horizon:
            raise ValueError(f"plume state at {time_s} s is before the kept history's horizon ({self.horizon} s)")
        with self._lock:
            segments = self._segments[name]
            segments = (scene_emission(plume),) if segments is None else segments
            changes = [event for event in self._plumes[name].events if event.time_s <= time_s]
            carried = self._carried[name]
        rate, wind = (plume.rate, plume.wind) if carried is None else (carried.rate, carried.wind)
        for change in changes:
            rate = change.rate if change.rate is not None else rate
            wind = change.wind if change.wind is not None else wind
        emitting = any(segment.first_birth <= time_s < segment.end for segment in segments)
        return {"emitting": emitting, "rate": rate, "wind": list(wind)}

    def body_pose(self, name: str, time_s: float) -> Pose:
        """Body `name`'s pose at `time_s` (its trajectory, or a live body's last pose)."""
        return self.bodies.frames(name, [time_s]).at(0)


def emission_segments(
    plume: Plume, changes: list[PlumeChange], carried: _Emission | None = None
) -> tuple[EmissionSegment, ...]:
    """The plume's emission split at each change, each part with the rate and wind then in force.

    Before the first change the scene's schedule holds (births from `start`,
    before `stop`); a change with `emitting` set replaces that schedule from
    its instant on. A part that starts while the plume was emitting continues
    its cadence (the next birth one new interval after the last one, not
    before the change), so changing only the wind adds no extra particle.
    `carried`: the state where `changes` begin when earlier ones were pruned
    (`LiveState.prune`): then no part comes before the first change.
    """
    return _emission(plume, changes, carried, float("inf"))[0]


def _emission(
    plume: Plume, changes: list[PlumeChange], carried: _Emission | None, last_end: float
) -> tuple[tuple[EmissionSegment, ...], _Emission]:
    """`emission_segments` with the last change's part ending at `last_end`, and the state after it."""
    segments: list[EmissionSegment] = []
    if carried is None:
        emitting: bool | None = None  # None: the scene's start/stop schedule
        rate, wind, next_index, last_birth = plume.rate, plume.wind, 0, None
        starts: list[PlumeChange | None] = [None, *changes]
        ends = [change.time_s for change in changes] + [last_end]
    else:
        emitting, rate, wind, next_index, last_birth = (
            carried.emitting, carried.rate, carried.wind, carried.next_index, carried.last_birth)
        starts = list(changes)
        ends = [change.time_s for change in changes[1:]] + [last_end]
    begin = float("-inf")
    for change, end in zip(starts, ends):
        if change is not None:
            begin = change.time_s
            emitting = change.emitting if change.emitting is not None else emitting
            rate = change.rate if change.rate is not None else rate
            wind = change.wind if change.wind is not None else wind
        window_begin, window_end = (max(begin, plume.start), min(end, plume.stop)) if emitting is None else (begin, end)
        if emitting is False or not window_begin < window_end:
            last_birth = None
            continue
        if change is None:
            first_birth = plume.start  # the scene's own cadence: particle indices as without changes
        elif last_birth is not None and begin == window_begin:
            first_birth = max(window_begin, last_birth + 1.0 / rate)
        else:
            first_birth = window_begin
        segment = EmissionSegment(first_birth, window_end, rate, wind, next_index)
        count = segment.births_before(window_end) if window_end != float("inf") else 0
        if count:
            next_index += count
            last_birth = first_birth + (count - 1) / rate
            segments.append(segment)
        elif window_end == float("inf"):
            segments.append(segment)
        else:
            last_birth = None
    return tuple(segments), _Emission(emitting, rate, wind, next_index, last_birth)


def event_record(event: LiveEvent) -> dict[str, Any]:
    """A plain dict of the event: {"t", "op", "name", ...its values} (the event log's line)."""
    record: dict[str, Any] = {"t": event.time_s, "op": event.op}
    if isinstance(event, ClockChange):
        record.update({key: value for key, value in (("speed", event.speed), ("paused", event.paused)) if value is not None})
        return record
    record["name"] = event.name
    if isinstance(event, RegionChange):
        record["density"] = event.density
    elif isinstance(event, PlumeChange):
        for key in ("emitting", "rate", "wind"):
            value = getattr(event, key)
            if value is not None:
                record[key] = list(value) if key == "wind" else value
    elif isinstance(event, TwistChange):
        record.update(vx=event.twist.vx, vy=event.twist.vy, wz=event.twist.wz)
        if event.until_s is not None:
            record["until"] = event.until_s
    else:
        record["position"] = list(event.pose.position)
        record["rotation_deg"] = list(event.pose.rotation_deg)
    return record


def event_from_record(record: dict[str, Any]) -> LiveEvent:
    """The event of a record made by `event_record` (trusted: checked where it came from)."""
    time_s, op = float(record["t"]), record["op"]
    if op == "clock":
        return ClockChange(time_s, record.get("speed"), record.get("paused"))
    if op == "region":
        return RegionChange(time_s, record["name"], float(record["density"]))
    if op == "plume":
        wind = record.get("wind")
        return PlumeChange(time_s, record["name"], record.get("emitting"), record.get("rate"),
                           tuple(wind) if wind is not None else None)
    if op == "pose":
        return PoseChange(time_s, record["name"], Pose(tuple(record["position"]), tuple(record["rotation_deg"])))
    if op == "twist":
        return TwistChange(time_s, record["name"], Twist(record["vx"], record["vy"], record["wz"]), record.get("until"))
    raise ValueError(f"unknown live event op {op!r}")
