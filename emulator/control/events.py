"""Live events: from request bodies and event-log lines, checked by the scene loader's rules.

A change arrives as an operation, a name and a body (`PATCH
/api/smoke/regions/room {"density": 0.004}`, or the same over the WebSocket
with "op" and "name" keys); it becomes a `LiveEvent` (scene/live.py) stamped
with the simulated instant the daemon applies it. The event log holds one
JSON object per line, `{"t": time_s, "op": ..., "name": ..., ...}` with the
body's keys, and reads back into the same events, so a session can be
replayed scan for scan.

Values are checked by the scene loader's own rules, limits and words
(`checked_values`): a density the loader would refuse in a scene file is
refused here with the same message, e.g.
`smoke.regions[room].density: must be <= 1000, got 1e+300`. What depends on
the changes before (the particle budget across every plume, a live body's
speed) is checked by the session's `LiveLimits` (scene/live_limits.py): a
plume's rate that could make more particles alive at once than a scene file
may have is refused, naming the budget. A log (`--events-in`) is read
through the same checks in its order, so a log no live session could have
made is refused at load.
"""

from __future__ import annotations

import json
import math
import os
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterable, TextIO

from emulator.daemon.clock import MAX_SPEED, MIN_SPEED
from emulator.errors import SceneError, UserError
from emulator.scene.drive import Twist
from emulator.scene.live import ClockChange, LiveEvent, PlumeChange, PoseChange, RegionChange, TwistChange, event_record
from emulator.scene.bodies import Live
from emulator.scene.live_limits import LiveLimits
from emulator.scene.loader import MAX_DENSITY, MAX_EXTENT_M, MAX_PLUME_RATE, checked_values
from emulator.scene.model import Pose, Scene
from emulator.sensors.scan import TICKS_PER_S

OPS = ("region", "plume", "pose", "twist", "clock")
PLUME_KEYS = ("emitting", "rate", "wind")
POSE_KEYS = ("position", "rotation_deg", "yaw_deg")
TWIST_KEYS = ("vx", "vy", "wz")
RESOLVED_KEYS = ("until",)  # what the daemon adds to a twist when it applies it: not part of the log
CLOCK_KEYS = ("speed", "paused")
TIME_DECIMALS = 6  # event times are on the µs grid
MAX_EVENT_TIME_S = 1e9  # an event's time (31 years): within it a float still holds the µs grid (a JSON integer of 10**400 did not fit one)


@dataclass
class ControlError(Exception):
    """A change the API refuses: HTTP `status`, a one-line `message` and the `key` it concerns."""

    status: int
    message: str
    key: str = ""

    def __str__(self) -> str:
        return self.message

    def json(self) -> dict[str, str]:
        return {"error": self.message, "key": self.key}


def change_instant(now_s: float) -> float:
    """The µs tick a change made at simulated time `now_s` takes effect: the first one after `now_s`,
    so no scan already measured (at or before now) could have seen it."""
    return (math.floor(now_s * TICKS_PER_S) + 1) / TICKS_PER_S


def live_bodies(scene: Scene) -> dict[str, Any]:
    """The scene's bodies whose pose comes from the control API (`trajectory = "live"`), by name."""
    return {body.name: body for body in scene.bodies if isinstance(body.trajectory, Live)}


def change(scene: Scene, op: Any, name: Any, body: Any, time_s: float, limits: LiveLimits) -> LiveEvent:
    """The event a change request makes at `time_s` after the changes `limits` has seen; ControlError
    (404 unknown name, 400 a refused value or a limit it would break, 409 a change the resource does
    not allow) otherwise. `limits` is not told of it: `record` does that once it is applied."""
    if op not in OPS:
        raise ControlError(400, f"op: must be one of {', '.join(OPS)}, got {_short(op)}", "op")
    if op == "clock":
        return _clock_change(body, time_s, "clock")
    if not isinstance(name, str):
        raise ControlError(400, f"name: expected a string, got {_short(name)}", "name")
    if op == "region":
        where = f"smoke.regions[{name}]"
        _known(name, [region.name for region in scene.regions], "smoke region", where)
        values = _values(where, body, ("density",))
        return RegionChange(time_s, name, _read(values.number, "density", at_least=0, at_most=MAX_DENSITY))
    if op == "plume":
        where = f"smoke.plumes[{name}]"
        _known(name, [plume.name for plume in scene.plumes], "plume", where)
        values = _values(where, body, PLUME_KEYS)
        _at_least_one(values, PLUME_KEYS, where)
        rate = _read(values.number, "rate", above=0, at_most=MAX_PLUME_RATE) if "rate" in values else None
        if rate is not None and (why := limits.particles.refusal(name, time_s, rate)) is not None:
            raise ControlError(400, f"{where}.rate: {why}", f"{where}.rate")
        return PlumeChange(
            time_s,
            name,
            emitting=_read(values.boolean, "emitting") if "emitting" in values else None,
            rate=rate,
            wind=_read(values.vec3, "wind") if "wind" in values else None,
        )
    where = f"bodies[{name}]"
    bodies = [body.name for body in scene.bodies]
    _known(name, bodies, "body", where)
    if name not in live_bodies(scene):
        what = "pose is not set" if op == "pose" else "motion is not driven"
        raise ControlError(409, f'{where}: its trajectory is not "live": its {what} from outside', where)
    if op == "twist":
        return TwistChange(time_s, name, _twist(where, body, scene.body(name).drive))
    pose = _pose(where, body)
    if (why := limits.speed_refusal(name, time_s, pose.position)) is not None:
        raise ControlError(400, f"{where}.position: {why}", f"{where}.position")
    return PoseChange(time_s, name, pose)


def record(limits: LiveLimits, event: LiveEvent) -> None:
    """Tell `limits` of an applied event, so the next change is checked against it."""
    if isinstance(event, PlumeChange) and event.rate is not None:
        limits.particles.add(event.name, event.time_s, event.rate)
    elif isinstance(event, PoseChange):
        limits.add_pose(event.name, event.time_s, event.pose.position)


def _twist(where: str, body: Any, drive: Any) -> Twist:
    """(vx, vy, wz), each 0 when left out, within the body's `drive` limits (a 400 naming the limit)."""
    values = _values(f"{where}.twist", body, TWIST_KEYS)
    _at_least_one(values, TWIST_KEYS, f"{where}.twist")
    twist = Twist(*(_read(values.number, key, 0.0) for key in TWIST_KEYS))
    speed = math.hypot(twist.vx, twist.vy)
    if speed > drive.max_speed:
        raise ControlError(
            400, f"{where}.twist: speed {speed:g} m/s is over the body's limit {where}.drive.max_speed = {drive.max_speed:g} m/s",
            f"{where}.drive.max_speed",
        )
    if abs(twist.wz) > drive.max_turn_rate:
        raise ControlError(
            400, f"{where}.twist.wz: {twist.wz:g} rad/s is over the body's limit {where}.drive.max_turn_rate = "
            f"{drive.max_turn_rate:g} rad/s", f"{where}.drive.max_turn_rate",
        )
    return twist


def _clock_change(body: Any, time_s: float, where: str) -> ClockChange:
    values = _values(where, body, CLOCK_KEYS)
    _at_least_one(values, CLOCK_KEYS, where)
    return ClockChange(
        time_s,
        speed=_read(values.number, "speed", at_least=MIN_SPEED, at_most=MAX_SPEED) if "speed" in values else None,
        paused=_read(values.boolean, "paused") if "paused" in values else None,
    )


def _pose(where: str, body: Any) -> Pose:
    values = _values(where, body, POSE_KEYS)
    if "rotation_deg" in values and "yaw_deg" in values:
        raise ControlError(400, f"{where}.yaw_deg: give rotation_deg or yaw_deg, not both", f"{where}.yaw_deg")
    position = _read(values.vec3, "position")
    if "yaw_deg" in values:
        rotation = (0.0, 0.0, _read(values.number, "yaw_deg", at_least=-MAX_EXTENT_M, at_most=MAX_EXTENT_M))
    else:
        rotation = _read(values.vec3, "rotation_deg", (0.0, 0.0, 0.0))
    return Pose(position, rotation)


def _values(where: str, body: Any, allowed: tuple[str, ...]):
    try:
        return checked_values(where, body, allowed)
    except SceneError as error:
        raise ControlError(400, str(error), error.key) from None


def _read(reader, key: str, *args: Any, **bounds: float) -> Any:
    """A value read by the loader's rules; its SceneError becomes a 400 with the same words."""
    try:
        return reader(key, *args, **bounds)
    except SceneError as error:
        raise ControlError(400, str(error), error.key) from None


def _known(name: str, names: list[str], what: str, where: str) -> None:
    if name not in names:
        known = ", ".join(names) or "none"
        raise ControlError(404, f"no {what} named {_short(name)} (known: {known})", where)


def _at_least_one(values: Any, keys: tuple[str, ...], where: str) -> None:
    if not any(key in values for key in keys):
        raise ControlError(400, f"{where}: expected at least one of: {', '.join(keys)}", where)


def _short(value: Any) -> str:
    text = json.dumps(value)[:60] if isinstance(value, (str, int, float, bool)) or value is None else type(value).__name__
    return text


# --------------------------------------------------------------------------- the event log


def event_json(event: LiveEvent) -> dict[str, Any]:
    """One line of the event log: {"t", "op", "name", ...the body's keys}, t on the µs grid (what the
    daemon derives when it applies a change, such as where a twist stops, is derived again on replay)."""
    record = {key: value for key, value in event_record(event).items() if key not in RESOLVED_KEYS}
    return {**record, "t": round(event.time_s, TIME_DECIMALS)}


def event_from_json(scene: Scene, data: Any, limits: LiveLimits) -> LiveEvent:
    """The event of one log line (a dict) after the lines `limits` has seen; ControlError if the scene
    or its limits would refuse it."""
    if not isinstance(data, dict):
        raise ControlError(400, f"expected a JSON object, got {_short(data)}")
    body = dict(data)
    time_value = body.pop("t", None)
    if isinstance(time_value, bool) or not isinstance(time_value, (int, float)) or not 0 <= time_value < MAX_EVENT_TIME_S:
        raise ControlError(400, f"t: expected a time in seconds, 0 <= t < {MAX_EVENT_TIME_S:g}, got {_short(time_value)}", "t")
    op, name = body.pop("op", None), body.pop("name", None)
    return change(scene, op, name, body, round(float(time_value), TIME_DECIMALS), limits)


def read_events(path: str | os.PathLike[str], scene: Scene) -> list[LiveEvent]:
    """Every event of a log file, in order, each checked after the ones before it (the particle budget,
    a body's speed); one UserError line naming the file, the line and the limit otherwise."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as error:
        raise UserError(f"{path}: cannot read the event log: {getattr(error, 'strerror', None) or error}") from None
    events = []
    limits = LiveLimits(scene)
    body_last_s: dict[str, float] = {}  # a body's live poses and twists come in time order
    for number, line in enumerate(text.splitlines(), start=1):
        if not line.strip():
            continue
        try:
            events.append(event_from_json(scene, json.loads(line), limits))
            record(limits, events[-1])
        except (ValueError, RecursionError):
            raise UserError(f"{path.name}: line {number}: not a JSON object") from None
        except ControlError as error:
            raise UserError(f"{path.name}: line {number}: {error.message}") from None
        event = events[-1]
        if isinstance(event, (PoseChange, TwistChange)):
            last_s = body_last_s.get(event.name, -math.inf)
            if event.time_s < last_s:
                raise UserError(f"{path.name}: line {number}: bodies[{event.name}]: a live {event.op} at {event.time_s:g} s, "
                                f"earlier than the body's last one ({last_s:g} s)")
            body_last_s[event.name] = event.time_s
    return events


def world_events(events: Iterable[LiveEvent]) -> list[LiveEvent]:
    """The events that change the world (not the clock): what `scan` and `record` apply."""
    return [event for event in events if not isinstance(event, ClockChange)]


class EventWriter:
    """`serve --events FILE`: each applied event appended as one JSON line, flushed at once.

    The file is created or truncated, never followed through a symlink.
    """

    def __init__(self, path: str | os.PathLike[str]) -> None:
        self.path = Path(path)
        try:
            fd = os.open(self.path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC | os.O_NOFOLLOW, 0o644)
        except OSError as error:
            raise UserError(f"--events {self.path}: cannot write: {error.strerror}") from None
        self._file: TextIO = os.fdopen(fd, "w", encoding="utf-8")
        self.error: str | None = None  # why the log stopped, once a write failed

    def write(self, event: LiveEvent) -> None:
        """Append the event; a write that fails (a full disk) ends the log with one line on stderr,
        and the change stands: the session goes on, unlogged from there."""
        if self.error is not None:
            return
        try:
            self._file.write(json.dumps(event_json(event)) + "\n")
            self._file.flush()
        except OSError as error:
            self.error = error.strerror or str(error)
            print(f"lrf-emulator: --events {self.path}: cannot write ({self.error}): changes from {event.time_s:g} s on are not logged",
                  file=sys.stderr, flush=True)
            self._close_quietly()

    def close(self) -> None:
        if self.error is None:
            self._close_quietly()

    def _close_quietly(self) -> None:
        try:
            self._file.close()
        except OSError:  # what the last flush left unwritten: already reported
            pass
