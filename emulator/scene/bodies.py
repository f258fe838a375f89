"""Bodies (docs/scene-format.md, "Bodies"): rigid frames that move, and their poses as pure functions of t.

A body's pose at any instant comes from its trajectory alone (plus, for a live
body, the pose events recorded so far), so a scan evaluates it directly for
every beam's own instant: `BodyPoses.frames(body, times)` takes an array of
times and returns positions (T, 3) and rotations (T, 3, 3), body → world, in
one vectorised pass (no per-beam Python).

- `Keyframes`: rows (t, position, quaternion). Between rows the position is
  linear and the rotation follows the shortest arc (slerp); before the first
  and after the last row the pose is held; two rows at one time are a jump
  (the later row holds from that instant on).
- `LIVE`: the pose is driven from outside while `serve` runs. The seams for the
  control API are `BodyPoses.add_live_pose(body, time_s, pose)` and
  `add_live_twist(body, time_s, twist, until_s)`: each appends one event to
  the body's ordered event list (times must not decrease): a pose, and the
  velocity (vx, vy, wz) that moves it from there until `until_s` (zero for a
  pose; for a twist, when its watchdog or a solid stops it: scene/obstacles.py).
  The same twist again while the last one still moves the body (a cmd_vel
  bridge repeating it) moves that event's `until_s` on instead: the path up
  to the old stop stays the very same, bit for bit, and what was computed
  for those instants stays valid. A twist that cannot move a standing body
  (zero, or pushing against the solid that stopped it) adds no event.
  `live_frames(times, events, initial)` is the pure function that turns that
  list into poses: from each event's time until the next event's, its pose
  moved along its twist's closed-form arc (scene/drive.py) for the time
  elapsed, up to `until_s`; the body's scene pose before the first. Evaluating
  instant t never looks at events after t, so replaying the same event log
  gives the same scans. Nor does it look at events before the one holding at
  t (each event carries its pose): `BodyPoses.prune(horizon)` forgets those
  before the one holding at the horizon, and instants before it are refused.

Quaternions are (x, y, z, w) as in TUM files; rotations compose as
R = Rz(yaw) · Ry(pitch) · Rx(roll), as `Pose.rotation_matrix`.
"""

from __future__ import annotations

import functools
import threading
from dataclasses import dataclass, field
from typing import Union

import numpy as np

from emulator.scene.drive import Drive, Twist, planar_motion
from emulator.scene.model import Pose

_SLERP_LINEAR_BELOW = 1e-9  # sin of the arc under which slerp falls back to a normalised lerp


# --------------------------------------------------------------------------- quaternions (x, y, z, w)


def euler_quaternion(rotation_deg: np.ndarray) -> np.ndarray:
    """Quaternions (..., 4) of roll, pitch, yaw in degrees (..., 3): q = qz(yaw) · qy(pitch) · qx(roll)."""
    half = np.radians(np.asarray(rotation_deg, dtype=float)) * 0.5
    cr, sr = np.cos(half[..., 0]), np.sin(half[..., 0])
    cp, sp = np.cos(half[..., 1]), np.sin(half[..., 1])
    cy, sy = np.cos(half[..., 2]), np.sin(half[..., 2])
    return np.stack(
        [
            sr * cp * cy - cr * sp * sy,
            cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy,
            cr * cp * cy + sr * sp * sy,
        ],
        axis=-1,
    )


# Each rotation matrix entry (row-major) is the identity's plus w1 q_i q_j + w2 q_k q_l with w = ±2, for a unit quaternion.
_MATRIX_TERMS = (
    ((1, 1, -2), (2, 2, -2)), ((0, 1, 2), (2, 3, -2)), ((0, 2, 2), (1, 3, 2)),
    ((0, 1, 2), (2, 3, 2)), ((0, 0, -2), (2, 2, -2)), ((1, 2, 2), (0, 3, -2)),
    ((0, 2, 2), (1, 3, -2)), ((1, 2, 2), (0, 3, 2)), ((0, 0, -2), (1, 1, -2)),
)
_TERM_LEFT = np.array([terms[k][0] for k in range(2) for terms in _MATRIX_TERMS])  # (18,): the 9 first terms, then the 9 second
_TERM_RIGHT = np.array([terms[k][1] for k in range(2) for terms in _MATRIX_TERMS])
_TERM_WEIGHT = np.array([float(terms[k][2]) for k in range(2) for terms in _MATRIX_TERMS])[:, None]
_IDENTITY_ROWS = np.eye(3).reshape(9, 1)


def quaternion_matrix(quaternions: np.ndarray) -> np.ndarray:
    """Rotation matrices (..., 3, 3) of unit quaternions (..., 4), in one pass over all of them.

    Entry by entry: identity + (w1 q_i q_j + w2 q_k q_l), the products and sums elementwise (no BLAS, no
    reduction), so each matrix's bits never depend on how many are computed together. Worked on (18, T)
    rows, one contiguous row per term: far fewer, cheaper passes than a product table per quaternion.
    """
    q = np.asarray(quaternions, dtype=float)
    by_component = np.ascontiguousarray(q.reshape(-1, 4).T)
    terms = by_component[_TERM_LEFT] * by_component[_TERM_RIGHT]
    terms *= _TERM_WEIGHT  # ×±2: exact
    entries = terms[:9] + terms[9:]
    entries += _IDENTITY_ROWS
    return np.ascontiguousarray(entries.T).reshape(*q.shape[:-1], 3, 3)


def matrix_quaternion(rotation: np.ndarray) -> np.ndarray:
    """The unit quaternion (4,) of one rotation matrix (3, 3), with w >= 0 (Shepperd's method)."""
    m = np.asarray(rotation, dtype=float)
    trace = m[0, 0] + m[1, 1] + m[2, 2]
    if trace > 0:
        s = 2.0 * np.sqrt(1.0 + trace)
        q = [(m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s, 0.25 * s]
    elif m[0, 0] >= m[1, 1] and m[0, 0] >= m[2, 2]:
        s = 2.0 * np.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2])
        q = [0.25 * s, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s, (m[2, 1] - m[1, 2]) / s]
    elif m[1, 1] >= m[2, 2]:
        s = 2.0 * np.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2])
        q = [(m[0, 1] + m[1, 0]) / s, 0.25 * s, (m[1, 2] + m[2, 1]) / s, (m[0, 2] - m[2, 0]) / s]
    else:
        s = 2.0 * np.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1])
        q = [(m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, 0.25 * s, (m[1, 0] - m[0, 1]) / s]
    quaternion = np.array(q)
    quaternion /= np.linalg.norm(quaternion)
    return -quaternion if quaternion[3] < 0 else quaternion


def matrix_euler_deg(rotation: np.ndarray) -> tuple[float, float, float]:
    """Roll, pitch, yaw (degrees) of one rotation matrix, inverse of `Pose.rotation_matrix`."""
    m = np.asarray(rotation, dtype=float)
    pitch = np.arcsin(np.clip(-m[2, 0], -1.0, 1.0))
    if abs(m[2, 0]) < 1.0 - 1e-12:
        roll, yaw = np.arctan2(m[2, 1], m[2, 2]), np.arctan2(m[1, 0], m[0, 0])
    else:  # gimbal lock: only roll ± yaw is defined; report it all as yaw
        roll, yaw = 0.0, np.arctan2(-m[0, 1], m[1, 1])
    return float(np.degrees(roll)), float(np.degrees(pitch)), float(np.degrees(yaw))


def slerp(q0: np.ndarray, q1: np.ndarray, fraction: np.ndarray) -> np.ndarray:
    """Shortest-arc interpolation (T, 4) from q0 (T, 4) to q1 (T, 4) at `fraction` (T,) in [0, 1]."""
    return _slerp_along(q0, _arcs(q0, q1), fraction)


@dataclass(frozen=True)
class _Arcs:
    """What slerp from q0 to q1 needs before the fraction (T rows): q1 on q0's half of the sphere
    (`toward`), the arc between them, its sine, and where that is too small to divide by (`near`)."""

    toward: np.ndarray
    arc: np.ndarray
    sin_arc: np.ndarray
    near: np.ndarray

    def take(self, rows: np.ndarray) -> _Arcs:
        return _Arcs(self.toward.take(rows, axis=0), self.arc.take(rows), self.sin_arc.take(rows), self.near.take(rows))


def _arcs(q0: np.ndarray, q1: np.ndarray) -> _Arcs:
    dot = np.einsum("ij,ij->i", q0, q1)
    toward = np.where((dot < 0)[:, None], -q1, q1)
    dot = np.minimum(np.abs(dot), 1.0)
    arc = np.arccos(dot)
    sin_arc = np.sin(arc)
    return _Arcs(toward, arc, sin_arc, sin_arc < _SLERP_LINEAR_BELOW)


def _slerp_along(q0: np.ndarray, arcs: _Arcs, fraction: np.ndarray) -> np.ndarray:
    with np.errstate(divide="ignore", invalid="ignore"):
        w0 = np.where(arcs.near, 1.0 - fraction, np.sin((1.0 - fraction) * arcs.arc) / arcs.sin_arc)
        w1 = np.where(arcs.near, fraction, np.sin(fraction * arcs.arc) / arcs.sin_arc)
    result = w0[:, None] * q0 + w1[:, None] * arcs.toward
    return result / np.linalg.norm(result, axis=1, keepdims=True)


# --------------------------------------------------------------------------- trajectories


@dataclass(frozen=True, eq=False)
class Keyframes:
    """Poses at times: `times` (K,) non-decreasing, `positions` (K, 3), unit `quaternions` (K, 4)."""

    times: np.ndarray
    positions: np.ndarray
    quaternions: np.ndarray

    @functools.cached_property
    def still_after(self) -> np.ndarray:
        """(K,): whether the pose stays put from row k to row k + 1 (the last row: held for ever)."""
        same = np.all(self.positions[1:] == self.positions[:-1], axis=1) & np.all(self.quaternions[1:] == self.quaternions[:-1], axis=1)
        return np.append(same, True)

    @functools.cached_property
    def segments(self) -> _Segments:
        """What interpolating from each row to the next needs, computed once (the trajectory never changes)."""
        last = len(self.times) - 1
        start = np.arange(last + 1)
        end = np.minimum(start + 1, last)
        return _Segments(
            self.times[end] - self.times[start], self.positions[end] - self.positions[start], _arcs(self.quaternions[start], self.quaternions[end])
        )


@dataclass(frozen=True)
class _Segments:
    """Per keyframe row k, toward row k + 1 (the last row: toward itself): time span (K,), position
    change (K, 3) and the rotation's arc (`_Arcs`, K rows)."""

    span: np.ndarray
    delta: np.ndarray
    arcs: _Arcs


@dataclass(frozen=True)
class Live:
    """The pose comes from outside while `serve` runs (control API): see `BodyPoses.add_live_pose`."""


LIVE = Live()

Trajectory = Union[Keyframes, Live]


@dataclass(frozen=True, eq=False)
class Frames:
    """Poses of one frame at T instants: `positions` (T, 3), `rotations` (T, 3, 3) local → world."""

    positions: np.ndarray
    rotations: np.ndarray

    def then(self, local: Pose) -> Frames:
        """The frames of something mounted at `local` in these frames (a sensor on a body).

        The T rotations' rows as one (3T, 3) matrix: one BLAS product instead of T (numpy's stacked
        matmul calls BLAS once per matrix); each row is the same dot product either way (tested).
        """
        rows = np.reshape(self.rotations, (-1, 3))
        positions = self.positions + (rows @ np.asarray(local.position, dtype=float)).reshape(-1, 3)
        return Frames(positions, (rows @ local.rotation_matrix()).reshape(-1, 3, 3))

    def at(self, index: int) -> Pose:
        """Instant `index` as a `Pose` (position, roll/pitch/yaw in degrees)."""
        return Pose(tuple(float(v) for v in self.positions[index]), matrix_euler_deg(self.rotations[index]))  # type: ignore[arg-type]


def keyframe_frames(keyframes: Keyframes, times_s: np.ndarray) -> Frames:
    """The keyframed pose at each of `times_s` (T,): linear position, slerped rotation, held outside."""
    times = np.asarray(times_s, dtype=float).reshape(-1)
    last = len(keyframes.times) - 1
    still = _still_pose(keyframes, times)
    if still is not None:  # e.g. a door between its movements: one pose for every instant
        return Frames(np.broadcast_to(keyframes.positions[still], (len(times), 3)), np.broadcast_to(quaternion_matrix(keyframes.quaternions[still]), (len(times), 3, 3)))
    after = np.searchsorted(keyframes.times, times, side="right") - 1  # the last row at or before t: a jump's later row
    start = np.clip(after, 0, last)
    segments = keyframes.segments
    span = segments.span.take(start)
    with np.errstate(divide="ignore", invalid="ignore"):
        fraction = np.where(span > 0, (times - keyframes.times.take(start)) / span, 0.0)
    fraction = np.clip(np.where(after < 0, 0.0, fraction), 0.0, 1.0)
    p0 = keyframes.positions.take(start, axis=0)
    q0 = keyframes.quaternions.take(start, axis=0)
    # at a row, or where the body stands still, exactly the row's pose: the same bits as the shortcut above,
    # so an instant's pose never depends on which other instants are evaluated with it
    exact = ((fraction == 0.0) | keyframes.still_after.take(start))[:, None]
    positions = np.where(exact, p0, p0 + fraction[:, None] * segments.delta.take(start, axis=0))
    quaternions = np.where(exact, q0, _slerp_along(q0, segments.arcs.take(start), fraction))
    return Frames(positions, quaternion_matrix(quaternions))


def _still_pose(keyframes: Keyframes, times: np.ndarray) -> int | None:
    """The row whose pose holds at every one of `times` when the body does not move among them, else None."""
    if not len(times):
        return None
    first, last = np.searchsorted(keyframes.times, (times.min(), times.max()), side="right") - 1
    if last < 0:  # every instant before the first row: its pose is held
        return 0
    first = max(int(first), 0)  # before the first row the pose is row 0's
    if not keyframes.still_after[first:last].all():
        return None
    return first if keyframes.still_after[last] or times.max() == keyframes.times[last] else None


@dataclass(frozen=True, eq=False)
class LiveEvents:
    """An ordered list of live events: `times` (E,), the pose then, `positions` (E, 3) and
    `quaternions` (E, 4), the `twists` (E, 3) of (vx, vy, wz) moving it from there, and `until` (E,),
    the instant that motion ends (the event's own time for a pose)."""

    times: np.ndarray
    positions: np.ndarray
    quaternions: np.ndarray
    twists: np.ndarray
    until: np.ndarray

    @staticmethod
    def empty() -> LiveEvents:
        return LiveEvents(np.zeros(0), np.zeros((0, 3)), np.zeros((0, 4)), np.zeros((0, 3)), np.zeros(0))


def live_poses(events: LiveEvents, initial: Pose, times_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Positions (T, 3) and quaternions (T, 4) of the live body at each of `times_s` (module docstring)."""
    times = np.asarray(times_s, dtype=float).reshape(-1)
    index = np.searchsorted(events.times, times, side="right") - 1
    positions = np.broadcast_to(np.asarray(initial.position, dtype=float), (len(times), 3)).copy()
    quaternions = np.broadcast_to(euler_quaternion(initial.rotation_deg), (len(times), 4)).copy()
    seen = np.flatnonzero(index >= 0)
    if len(seen):
        rows = index[seen]
        elapsed = np.maximum(np.minimum(times[seen], events.until[rows]) - events.times[rows], 0.0)
        positions[seen], quaternions[seen] = planar_motion(
            events.positions[rows], events.quaternions[rows], events.twists[rows], elapsed
        )
    return positions, quaternions


def live_frames(events: LiveEvents, initial: Pose, times_s: np.ndarray) -> Frames:
    """The live pose at each of `times_s`: the last event's pose at or before t moved by its twist,
    `initial` before the first."""
    times = np.asarray(times_s, dtype=float).reshape(-1)
    index = np.searchsorted(events.times, times, side="right") - 1
    if not (index >= 0).any():
        return Frames(
            np.broadcast_to(np.asarray(initial.position, dtype=float), (len(times), 3)).copy(),
            np.broadcast_to(initial.rotation_matrix(), (len(times), 3, 3)).copy(),
        )
    positions, quaternions = live_poses(events, initial, times)
    rotations = quaternion_matrix(quaternions)
    rotations[index < 0] = initial.rotation_matrix()
    return Frames(positions, rotations)


# --------------------------------------------------------------------------- bodies


@dataclass(frozen=True)
class Body:
    """A rigid frame: `pose` when no trajectory applies; `trajectory` None (it stays), keyframes or LIVE.
    A live body also takes twists, with `drive`'s footprint, limits and watchdog."""

    name: str
    pose: Pose = Pose()
    trajectory: Trajectory | None = None
    drive: Drive = Drive()

    @property
    def moving(self) -> bool:
        return self.trajectory is not None


class _EventLog:
    """Append-only arrays with amortised O(1) appends; a snapshot never changes after it is taken."""

    _COLUMNS = {"times": (), "positions": (3,), "quaternions": (4,), "twists": (3,), "until": ()}

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._count = 0
        self._arrays = {name: np.zeros((16, *shape)) for name, shape in self._COLUMNS.items()}
        self.last_time_s = float("-inf")  # the latest event taken (a merged twist's, not its row's start)

    def append(self, time_s: float, position: np.ndarray, quaternion: np.ndarray,
               twist: np.ndarray | None = None, until_s: float | None = None) -> None:
        with self._lock:
            times = self._arrays["times"]
            if time_s < self.last_time_s:
                raise ValueError(f"live pose at {time_s} s is earlier than the last one ({self.last_time_s} s)")
            self.last_time_s = float(time_s)
            if self._count == len(times):  # grow into new arrays: earlier snapshots keep the old ones
                self._arrays = {name: np.concatenate([array, np.zeros_like(array)]) for name, array in self._arrays.items()}
            row = {"times": time_s, "positions": position, "quaternions": quaternion, "twists": 0.0 if twist is None else twist,
                   "until": time_s if until_s is None else until_s}
            for name, value in row.items():
                self._arrays[name][self._count] = value
            self._count += 1

    def continue_twist(self, time_s: float, twist: np.ndarray, until_s: float) -> float | None:
        """The same twist again while the last one still moves the body: its row moves on until
        `until_s` instead of a new row starting from where the body is (the path up to the old stop is
        the very same, to the last bit, so nothing computed before it changes). The instant from which
        the body's path changed (inf: not at all), or None if this is not such a twist."""
        with self._lock:
            row_until = self._moving_by(time_s, twist)
            if row_until is None:
                return None
            last = self._count - 1
            self.last_time_s = float(time_s)
            if until_s == row_until:
                return float("inf")
            until = self._arrays["until"].copy()  # earlier snapshots keep the old column
            until[last] = until_s
            self._arrays = {**self._arrays, "until": until}
            return min(row_until, float(until_s))

    def moving_by(self, time_s: float, twist: np.ndarray) -> float | None:
        """The last event's stop if `twist` (3,) is the one still moving the body at `time_s`, else None."""
        with self._lock:
            return self._moving_by(time_s, twist)

    def _moving_by(self, time_s: float, twist: np.ndarray) -> float | None:
        last = self._count - 1
        if last < 0 or time_s < self.last_time_s:
            return None
        row_until = float(self._arrays["until"][last])
        if not (self._arrays["times"][last] <= time_s < row_until) or not np.array_equal(self._arrays["twists"][last], twist):
            return None
        return row_until

    def keep_standing(self, time_s: float) -> bool:
        """Whether the body already stands at `time_s` (a twist that cannot move it then changes
        nothing: pushing against the solid that stopped it); if so, `time_s` is taken as an event's."""
        with self._lock:
            if time_s < self.last_time_s or (self._count and self._arrays["until"][self._count - 1] > time_s):
                return False
            self.last_time_s = float(time_s)
            return True

    def prune(self, horizon_s: float) -> None:
        """Forget the events before the one holding at `horizon_s`, once they are half of those held
        (amortised O(1) per event; earlier snapshots keep the old arrays)."""
        with self._lock:
            count = int(np.searchsorted(self._arrays["times"][: self._count], horizon_s, side="right")) - 1
            if count <= 0 or 2 * count < self._count:
                return
            kept = self._count - count
            size = max(16, 2 * kept)
            self._arrays = {name: np.concatenate([array[count:self._count], np.zeros((size - kept, *array.shape[1:]))])
                            for name, array in self._arrays.items()}
            self._count = kept

    def restore(self, events: LiveEvents) -> None:
        """Hold `events` in place of what was held."""
        with self._lock:
            self._count = len(events.times)
            self._arrays = {name: np.concatenate([getattr(events, name), np.zeros((max(16, self._count), *shape))])
                            for name, shape in self._COLUMNS.items()}
            # (a merged twist later than its row's start is not known here: only ordering checks use it)
            self.last_time_s = float(events.times[-1]) if self._count else float("-inf")

    def snapshot(self) -> LiveEvents:
        with self._lock:
            n = self._count
            return LiveEvents(**{name: array[:n] for name, array in self._arrays.items()})


@dataclass
class BodyPoses:
    """Every body's pose at any instants: the scene's trajectories plus the live bodies' events."""

    bodies: tuple[Body, ...]
    _live: dict[str, _EventLog] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.horizon = float("-inf")  # instants before it are no longer kept (`prune`)
        self._by_name = {body.name: body for body in self.bodies}
        self._live = {body.name: _EventLog() for body in self.bodies if isinstance(body.trajectory, Live)}

    def body(self, name: str) -> Body:
        return self._by_name[name]

    @property
    def live_names(self) -> tuple[str, ...]:
        return tuple(self._live)

    def frames(self, name: str, times_s: np.ndarray) -> Frames:
        """Body `name`'s pose at each of `times_s` (T,), vectorised."""
        body = self._by_name[name]
        times = np.asarray(times_s, dtype=float).reshape(-1)
        if isinstance(body.trajectory, Keyframes):
            return keyframe_frames(body.trajectory, times)
        if isinstance(body.trajectory, Live):
            if len(times) and times.min() < self.horizon:
                raise ValueError(f"body {name!r} at {times.min()} s: before the kept history's horizon ({self.horizon} s)")
            return live_frames(self._live[name].snapshot(), body.pose, times)
        return Frames(
            np.broadcast_to(np.asarray(body.pose.position, dtype=float), (len(times), 3)),
            np.broadcast_to(body.pose.rotation_matrix(), (len(times), 3, 3)),
        )

    def add_live_pose(self, name: str, time_s: float, pose: Pose) -> None:
        """Record that live body `name` is at `pose` from `time_s` on (times must not decrease)."""
        if name not in self._live:
            raise KeyError(f"no live body named {name!r} (live: {', '.join(self._live) or 'none'})")
        self._live[name].append(float(time_s), np.asarray(pose.position, dtype=float), euler_quaternion(pose.rotation_deg))

    def add_live_twist(self, name: str, time_s: float, twist: Twist, until_s: float) -> float:
        """Record that live body `name` moves by `twist` from where it is at `time_s` until `until_s`;
        the instant from which its path changed (inf: not at all). A cmd_vel bridge repeats the same
        twist 10-100 times a second: each repeat only moves the stop on, so the scans computed for
        the instants before the old stop stay valid."""
        log, velocity = self._live_log(name), np.array([twist.vx, twist.vy, twist.wz])
        changed_from = log.continue_twist(float(time_s), velocity, float(until_s))
        if changed_from is not None:
            return changed_from
        if (until_s <= time_s or not velocity.any()) and log.keep_standing(float(time_s)):
            return float("inf")  # it stands, and this twist cannot move it (a solid, or zero)
        position, quaternion = self.live_pose(name, time_s)
        log.append(float(time_s), position, quaternion, velocity, float(until_s))
        return float(time_s)

    def moving_by(self, name: str, time_s: float, twist: np.ndarray) -> float | None:
        """Where live body `name` stops if `twist` (vx, vy, wz) is the one still moving it at `time_s`,
        else None."""
        return self._live_log(name).moving_by(time_s, twist)

    def last_event_s(self, name: str) -> float:
        """The instant of live body `name`'s latest pose or twist (-inf before any)."""
        return self._live_log(name).last_time_s

    def live_pose(self, name: str, time_s: float) -> tuple[np.ndarray, np.ndarray]:
        """Live body `name`'s position (3,) and quaternion (4,) at `time_s`, from its events so far."""
        positions, quaternions = live_poses(self._live_log(name).snapshot(), self._by_name[name].pose, np.array([time_s]))
        return positions[0], quaternions[0]

    def live_twist(self, name: str, time_s: float) -> Twist:
        """The twist moving live body `name` at `time_s` (zero when it stands)."""
        events = self._live_log(name).snapshot()
        index = int(np.searchsorted(events.times, time_s, side="right")) - 1
        if index < 0 or time_s >= events.until[index]:
            return Twist()
        return Twist(*(float(value) for value in events.twists[index]))

    def _live_log(self, name: str) -> _EventLog:
        if name not in self._live:
            raise KeyError(f"no live body named {name!r} (live: {', '.join(self._live) or 'none'})")
        return self._live[name]

    def prune(self, horizon_s: float) -> None:
        """Forget the live events no instant at or after `horizon_s` depends on (module docstring)."""
        self.horizon = max(self.horizon, horizon_s)
        for log in self._live.values():
            log.prune(horizon_s)

    def restore(self, events: dict[str, LiveEvents], horizon_s: float) -> None:
        """Hold each live body's `events` (from `live_events`) in place of its own, and the horizon."""
        self.horizon = horizon_s
        for name, held in events.items():
            self._live_log(name).restore(held)

    def live_events(self, name: str) -> LiveEvents:
        """The events recorded for live body `name` so far."""
        return self._live[name].snapshot()


def mounted_matrix(body: Body | None, local: Pose) -> np.ndarray:
    """The 4x4 world transform of something at `local` on a body that stays (no trajectory), or on none."""
    return local.matrix() if body is None else body.pose.matrix() @ local.matrix()
