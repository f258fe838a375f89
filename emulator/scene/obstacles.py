"""What stops a driven body: the scene's solids as segments in the plane, and where a twist meets them.

A driven body's footprint is a vertical cylinder (scene/drive.py `Drive`):
`radius` about the body's origin, from `clearance` to `height` above it.
`Outlines` are the solids that stay (no body, or a body without a
trajectory) cut to that slab of heights and seen from above: every triangle
edge clipped to the slab and every cut of a triangle by the slab's two
planes, projected to (x, y) segments. The footprint meets a solid exactly
where its centre comes within `radius` of one of those segments (the
centre moves continuously from outside, so it meets an outline before it
could be inside one). Solids on moving bodies (a door, another robot) do
not stop it.

`travel_time` follows the centre along a twist's arc every `STEP_M` of
path (a rotation in place never moves the centre of a round footprint, so
only the path matters; the spans of path that cannot reach a solid are
screened out first, every `COARSE_STEPS` samples), finds the first sample
closer than `radius` and still closing in, and narrows the contact between it and the
last free sample by bisection on the exact arc. The body therefore stops
touching the solid (its clearance `radius`, to a few nm), never inside it;
closing in by less than `CONTACT_TOLERANCE_M` is not a collision, so a body
touching a wall may drive along it or away. A body already closer than
`radius` (put there by a pose) may move, but not closer.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
import trimesh

from emulator.scene.drive import Drive, planar_motion
from emulator.scene.geometry import world_mesh
from emulator.scene.model import Scene

STEP_M = 0.001  # path between two samples of the centre: a grazed corner is missed by at most ~0.4 µm
CONTACT_TOLERANCE_M = 1e-6  # a centre this much inside `radius` still counts as touching, not hitting
COARSE_STEPS = 20  # the path is screened every 20 samples (2 cm); only the spans that may touch are sampled finely
SAMPLES_PER_PASS = 256  # centre samples compared with the outlines in the first pass: a blocked twist ends early
MAX_SAMPLES_PER_PASS = 4096  # later passes double up to this (a long path along a wall: fewer, larger passes)
MAX_SLABS = 16  # slabs of heights whose outlines are kept (one per live body and height it was posed at)
REFINEMENTS = 4  # rounds narrowing the contact between the last free and the first blocked sample
REFINE_SAMPLES = 32  # intervals each round splits into


@dataclass(frozen=True, eq=False)
class Outlines:
    """Solids seen from above within a slab of heights: segments `starts` (M, 2) → `ends` (M, 2)."""

    starts: np.ndarray
    ends: np.ndarray

    def near(self, low: np.ndarray, high: np.ndarray) -> Outlines:
        """The segments whose bounding boxes meet the box [low, high] (2,)."""
        min_x, min_y, max_x, max_y = self._boxes
        keep = (min_x <= high[0]) & (min_y <= high[1]) & (max_x >= low[0]) & (max_y >= low[1])
        return Outlines(self.starts[keep], self.ends[keep])

    @functools.cached_property
    def _boxes(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Each segment's bounding box as four contiguous columns, made once: a twist asks `near` of
        the same outlines several times, and each pass over (M, 2) minima and maxima cost 0.17 ms."""
        lower, upper = np.minimum(self.starts, self.ends), np.maximum(self.starts, self.ends)
        return (*(np.ascontiguousarray(column) for column in lower.T), *(np.ascontiguousarray(column) for column in upper.T))

    def clearance(self, points: np.ndarray) -> np.ndarray:
        """(K,): each point's distance to the nearest segment (inf with none)."""
        if not len(self.starts):
            return np.full(len(points), np.inf)
        along = self.ends - self.starts  # (M, 2)
        length2 = np.einsum("ij,ij->i", along, along)
        offset = points[:, None, :] - self.starts[None, :, :]  # (K, M, 2)
        with np.errstate(divide="ignore", invalid="ignore"):
            fraction = np.where(length2 > 0, (offset[..., 0] * along[:, 0] + offset[..., 1] * along[:, 1]) / length2, 0.0)
        fraction = np.clip(fraction, 0.0, 1.0)
        dx = offset[..., 0] - fraction * along[:, 0]
        dy = offset[..., 1] - fraction * along[:, 1]
        return np.sqrt(dx * dx + dy * dy).min(axis=1)


def static_solids(scene: Scene) -> list[trimesh.Trimesh]:
    """The world meshes of the solids that never move (their own pose, or on a body that stays)."""
    staying = {body.name for body in scene.bodies if not body.moving}
    meshes = []
    for item in scene.objects:
        if item.body is None:
            meshes.append(world_mesh(item.shape, item.pose))
        elif item.body in staying:
            mesh = world_mesh(item.shape, item.pose)
            mesh.apply_transform(scene.body(item.body).pose.matrix())
            meshes.append(mesh)
    return meshes


def slab_outlines(meshes: list[trimesh.Trimesh], low_z: float, high_z: float) -> Outlines:
    """The meshes within heights [low_z, high_z], seen from above (module docstring)."""
    starts, ends = [np.zeros((0, 2))], [np.zeros((0, 2))]
    for mesh in meshes:
        lowest, highest = mesh.bounds[:, 2]
        if highest < low_z or lowest > high_z:
            continue
        edges = mesh.vertices[mesh.edges_unique]  # (E, 2, 3)
        a, b = edges[:, 0], edges[:, 1]
        rise = b[:, 2] - a[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            at_low = np.where(rise != 0, (low_z - a[:, 2]) / rise, -np.inf)
            at_high = np.where(rise != 0, (high_z - a[:, 2]) / rise, np.inf)
        flat_inside = (rise == 0) & (a[:, 2] >= low_z) & (a[:, 2] <= high_z)
        first = np.where(rise == 0, np.where(flat_inside, 0.0, 1.0), np.maximum(0.0, np.minimum(at_low, at_high)))
        last = np.where(rise == 0, np.where(flat_inside, 1.0, 0.0), np.minimum(1.0, np.maximum(at_low, at_high)))
        kept = first <= last
        starts.append((a + first[:, None] * (b - a))[kept][:, :2])
        ends.append((a + last[:, None] * (b - a))[kept][:, :2])
        for height in (low_z, high_z):
            if lowest <= height <= highest:
                cuts = trimesh.intersections.mesh_plane(mesh, [0.0, 0.0, 1.0], [0.0, 0.0, height])
                if len(cuts):
                    starts.append(np.asarray(cuts)[:, 0, :2])
                    ends.append(np.asarray(cuts)[:, 1, :2])
    return Outlines(np.concatenate(starts), np.concatenate(ends))


class Obstacles:
    """The scene's staying solids, cut into outlines per slab of heights as driven bodies need them."""

    def __init__(self, scene: Scene) -> None:
        self._scene = scene
        self._outlines: dict[tuple[float, float], Outlines] = {}

    @functools.cached_property
    def _meshes(self) -> list[trimesh.Trimesh]:
        return static_solids(self._scene)

    def outlines(self, low_z: float, high_z: float) -> Outlines:
        """The solids within heights [low_z, high_z] seen from above, cut once per slab (a body's
        height changes only by a pose; at most MAX_SLABS kept)."""
        key = (low_z, high_z)
        if key not in self._outlines:
            if len(self._outlines) >= MAX_SLABS:
                self._outlines.pop(next(iter(self._outlines)))
            self._outlines[key] = slab_outlines(self._meshes, low_z, high_z)
        return self._outlines[key]

    def travel_time(self, drive: Drive, position: np.ndarray, quaternion: np.ndarray, twist: np.ndarray,
                    horizon_s: float) -> float:
        """How long (s, at most `horizon_s`) the twist (3,) moves the body from the pose before its
        footprint touches a solid (module docstring)."""
        speed = float(np.hypot(twist[0], twist[1]))
        if speed == 0.0 or horizon_s <= 0.0:
            return horizon_s
        z = float(position[2])
        outlines = self.outlines(z + drive.clearance, z + drive.height)
        if not len(outlines.starts):
            return horizon_s
        step_s = STEP_M / speed
        count = int(np.ceil(horizon_s / step_s))
        nearby, samples = self._samples_near_solids(drive.radius, position, quaternion, twist, count, step_s, horizon_s, outlines)
        previous: tuple[float, float] | None = None  # (time, clearance) of the last sample
        first, size = 0, SAMPLES_PER_PASS
        while first < len(samples):
            times = np.minimum(samples[first:first + size] * step_s, horizon_s)
            first, size = first + size, min(2 * size, MAX_SAMPLES_PER_PASS)
            centres = _centres(position, quaternion, twist, times)
            reach = drive.radius + STEP_M
            local = nearby.near(centres.min(axis=0) - reach, centres.max(axis=0) + reach)  # along a long path: few
            clearances = local.clearance(centres)
            before = np.concatenate([[previous[1] if previous else -np.inf], clearances[:-1]])
            blocked = np.flatnonzero((clearances < drive.radius - CONTACT_TOLERANCE_M) & (clearances < before))
            if len(blocked):
                index = int(blocked[0])
                free_time, free_clearance = (float(times[index - 1]), float(before[index])) if index else previous
                if free_clearance < drive.radius - CONTACT_TOLERANCE_M:
                    return free_time  # already closer than the radius, and now closing in: stop here
                return _contact(local, drive.radius, position, quaternion, twist, free_time, float(times[index]))
            previous = (float(times[-1]), float(clearances[-1]))
        return horizon_s

    @staticmethod
    def _samples_near_solids(radius: float, position: np.ndarray, quaternion: np.ndarray, twist: np.ndarray,
                             count: int, step_s: float, horizon_s: float, outlines: Outlines) -> tuple[Outlines, np.ndarray]:
        """The outlines near the path, and which of its samples 0..count (every STEP_M) can meet them.

        The clearance changes no faster than the centre moves, so between two coarse samples L of path
        apart (COARSE_STEPS samples) with clearances d1, d2 it stays above (d1 + d2 - L) / 2: where
        that is at least the radius, the samples in between cannot touch anything and are skipped.
        """
        every = COARSE_STEPS
        coarse = np.append(np.arange(0, count, every), count)
        centres = _centres(position, quaternion, twist, np.minimum(coarse * step_s, horizon_s))
        reach = radius + every * STEP_M
        nearby = outlines.near(centres.min(axis=0) - reach, centres.max(axis=0) + reach)
        clearance = np.minimum(nearby.clearance(centres), reach)  # a far outline left out: at most reach away
        spans = np.diff(coarse) * STEP_M
        lowest = (clearance[:-1] + clearance[1:] - spans) / 2
        unsafe = np.flatnonzero(lowest < radius)
        if not len(unsafe):
            return nearby, np.zeros(0, dtype=np.int64)
        ranges = [np.arange(coarse[i], coarse[i + 1] + 1) for i in unsafe]
        return nearby, np.unique(np.concatenate(ranges))


def _centres(position: np.ndarray, quaternion: np.ndarray, twist: np.ndarray, times: np.ndarray) -> np.ndarray:
    """(K, 2): where the body's origin is `times` seconds into the twist."""
    count = len(times)
    moved, _ = planar_motion(
        np.broadcast_to(position, (count, 3)).copy(), np.broadcast_to(quaternion, (count, 4)).copy(),
        np.broadcast_to(twist, (count, 3)), times,
    )
    return moved[:, :2]


def _contact(outlines: Outlines, radius: float, position: np.ndarray, quaternion: np.ndarray, twist: np.ndarray,
             free_s: float, blocked_s: float) -> float:
    """The latest instant in [free_s, blocked_s] found clear (the centre at least `radius` from every
    outline): the footprint touching, not inside. Each round samples the interval and keeps the part
    where it turns from clear to blocked: REFINEMENTS rounds narrow 1 mm of path to about 1 nm."""
    for _ in range(REFINEMENTS):
        times = np.linspace(free_s, blocked_s, REFINE_SAMPLES + 1)
        clear = outlines.clearance(_centres(position, quaternion, twist, times)) >= radius
        clear[0] = True  # free_s was found clear before (its sample may have been taken elsewhere)
        first_blocked = int(np.argmin(clear)) if not clear.all() else len(times) - 1
        free_s, blocked_s = float(times[first_blocked - 1]), float(times[first_blocked])
    return free_s
