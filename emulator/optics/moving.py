"""Solids riding on moving bodies: each body's objects in their own Embree scene, in the body's frame.

Built once per world. A cast transforms every beam into the body's frame at
that beam's own instant (`BodyPoses.frames`, vectorised over beams), asks
Embree for the first triangle, recomputes the distance in float64 from the
triangle's plane (as the static scene does) and keeps, per beam, whichever of
the static or moving hits is nearer. Only beams passing within the sphere that
bounds the body's objects around its origin (at the beam's instant) are
transformed and cast: the others cannot meet them. No scene is rebuilt per scan
and no Python loop runs per beam: the loop is over moving bodies.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from embreex.mesh_construction import TriangleMesh
from embreex.rtcore_scene import EmbreeScene

from emulator.scene.bodies import BodyPoses
from emulator.scene.geometry import world_mesh
from emulator.scene.model import Scene


@dataclass(frozen=True)
class Solids:
    """First solid hit per beam (N,): range (inf if none), object index (-1), reflectivity and |cos incidence| (0)."""

    range_m: np.ndarray
    object_index: np.ndarray
    reflectivity: np.ndarray
    cos_incidence: np.ndarray


def triangle_planes(triangles: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """Per triangle: unit normal n and offset n·v0 (T, 4), so a hit's range is (n·v0 − n·o) / (n·d)."""
    return np.concatenate([normals, np.einsum("ij,ij->i", normals, triangles[:, 0])[:, None]], axis=1).astype(np.float64)


def exact_hits(
    triangle: np.ndarray,
    planes: np.ndarray,
    triangle_object: np.ndarray,
    object_reflectivity: np.ndarray,
    origins: np.ndarray,
    directions: np.ndarray,
    max_range_m: float,
) -> Solids:
    """Embree's first `triangle` per ray (-1 for none) turned into float64 ranges from the triangle's plane."""
    picked = planes.take(triangle, axis=0, mode="clip")  # -1 (no hit) reads row 0, masked below
    facing = np.einsum("ij,ij->i", picked[:, :3], directions)
    with np.errstate(divide="ignore", invalid="ignore"):
        exact_range = (picked[:, 3] - np.einsum("ij,ij->i", picked[:, :3], origins)) / facing
    hit = (triangle >= 0) & (exact_range <= max_range_m)
    objects = np.where(hit, triangle_object.take(triangle, mode="clip"), -1)
    return Solids(
        np.where(hit, exact_range, np.inf),
        objects,
        np.where(hit, object_reflectivity.take(objects, mode="clip"), 0.0),
        np.where(hit, np.abs(facing), 0.0),
    )


@dataclass(frozen=True)
class _BodySolids:
    body: str
    embree: EmbreeScene
    planes: np.ndarray
    triangle_object: np.ndarray
    reach_m: float  # every vertex lies within this of the body's origin, with a margin for Embree's float32 rays


_REACH_MARGIN_M = 1e-3  # float32 rays stray by ~1e-5 m at 80 m: a hit Embree reports lies far within this


def _passing_within(centers: np.ndarray, radius: float, origins: np.ndarray, directions: np.ndarray, length_m: float) -> np.ndarray:
    """Which beams (segments of `length_m` from `origins` along unit `directions`) pass within `radius`
    of their `centers` (N, 3) (or one centre broadcast)."""
    offset = centers - origins
    along = np.clip(np.einsum("ij,ij->i", offset, directions), 0.0, length_m)
    offset -= along[:, None] * directions
    return np.einsum("ij,ij->i", offset, offset) <= radius * radius


class MovingSolids:
    """The objects of every moving body (a body with a trajectory), cast in their body's frame."""

    def __init__(self, scene: Scene, poses: BodyPoses, object_reflectivity: np.ndarray) -> None:
        self._poses = poses
        self._object_reflectivity = object_reflectivity
        self._bodies: list[_BodySolids] = []
        for body in scene.bodies:
            if not body.moving:
                continue
            carried = [(index, obj) for index, obj in enumerate(scene.objects) if obj.body == body.name]
            if not carried:
                continue
            meshes = [world_mesh(obj.shape, obj.pose) for _, obj in carried]  # in the body's frame
            triangles = np.concatenate([mesh.triangles for mesh in meshes])
            normals = np.concatenate([mesh.face_normals for mesh in meshes])
            embree = EmbreeScene()
            TriangleMesh(embree, triangles.astype(np.float32))
            owner = np.concatenate([np.full(len(mesh.faces), index, dtype=np.int64) for (index, _), mesh in zip(carried, meshes)])
            reach = float(np.sqrt((triangles * triangles).sum(axis=2).max())) + _REACH_MARGIN_M
            self._bodies.append(_BodySolids(body.name, embree, triangle_planes(triangles, normals), owner, reach))

    def __bool__(self) -> bool:
        return bool(self._bodies)

    def nearest(self, solids: Solids, origins: np.ndarray, directions: np.ndarray, max_range_m: float, times_s: np.ndarray) -> Solids:
        """`solids` with each beam's hit replaced where a moving body's surface is nearer at the beam's instant
        (fresh arrays: `solids`' may be shared)."""
        best = Solids(solids.range_m.copy(), solids.object_index.copy(), solids.reflectivity.copy(), solids.cos_incidence.copy())
        for body in self._bodies:  # fresh arrays, as each beam's nearer hits replace its own
            frames = self._poses.frames(body.body, times_s)
            rows = _passing_within(frames.positions, body.reach_m, origins, directions, max_range_m * (1.0 + 1e-6)).nonzero()[0]
            if len(rows) == 0:
                continue
            rotations, positions = frames.rotations.take(rows, axis=0), frames.positions.take(rows, axis=0)
            # world → body frame: R^T (o − p), R^T d (each row's bits whatever rows are transformed with it)
            local_origins = np.einsum("nji,nj->ni", rotations, origins.take(rows, axis=0) - positions)
            local_directions = np.einsum("nji,nj->ni", rotations, directions.take(rows, axis=0))
            limits = np.full(len(rows), max_range_m, dtype=np.float32)
            triangle = body.embree.run(
                np.ascontiguousarray(local_origins, dtype=np.float32),
                np.ascontiguousarray(local_directions, dtype=np.float32),
                dists=limits,
            )
            hits = exact_hits(
                triangle, body.planes, body.triangle_object, self._object_reflectivity, local_origins, local_directions, max_range_m
            )
            nearer = hits.range_m < best.range_m.take(rows)
            replaced = rows[nearer]
            best.range_m[replaced] = hits.range_m[nearer]
            best.object_index[replaced] = hits.object_index[nearer]
            best.reflectivity[replaced] = hits.reflectivity[nearer]
            best.cos_incidence[replaced] = hits.cos_incidence[nearer]
        return best
