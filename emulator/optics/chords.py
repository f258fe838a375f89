"""Exact intervals along rays inside closed shapes, vectorised over rays.

Each function takes ray origins (N, 3) and unit directions (N, 3) in the
shape's local frame and returns `(entry, exit)` arrays of shape (N, K): the
distances along each ray where it enters and leaves the shape. Convex shapes
give K = 1; a mesh gives as many intervals as the ray needs. Missing
intervals are `entry = exit = inf`. Intervals are not clipped: entries may be
negative when the origin is inside (the caller clips to the beam).
"""

from __future__ import annotations

from typing import Iterable

import numpy as np
import trimesh

from emulator.scene.geometry import shape_mesh
from emulator.scene.model import Box, Cylinder, MeshFile, Shape, Sphere

NO_HIT = np.inf
_CROSSING_CHUNK = 2_000_000  # rays × triangles per Möller–Trumbore batch
_SAME_CROSSING_M = 1e-9  # crossings closer than this with the same orientation are one (a shared edge)


def _empty_where(entry: np.ndarray, exit_: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mark empty intervals (exit < entry or NaN) as missing."""
    missing = ~(exit_ >= entry)
    return np.where(missing, NO_HIT, entry), np.where(missing, NO_HIT, exit_)


def _slab(
    origins: np.ndarray, directions: np.ndarray, lower: np.ndarray, upper: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Slab test of rays against axis-aligned boxes → near, far.

    Arguments broadcast against each other; their last axis holds the axes
    tested. The ray is inside the box for near < t < far (empty when
    far < near). A direction component of exactly 0 keeps the ray inside
    that axis's slab for all t when its origin lies within it, and outside
    otherwise (so does one so small that 1/d overflows).
    """
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):  # d may be 0 or subnormal
        inverse = 1.0 / directions
        t_lower = (lower - origins) * inverse
        t_upper = (upper - origins) * inverse
    near = np.minimum(t_lower, t_upper)
    far = np.maximum(t_lower, t_upper)
    parallel = np.broadcast_to(~np.isfinite(inverse), near.shape)  # d is 0 or so small that 1/d overflows
    if parallel.any():
        inside = (lower <= origins) & (origins <= upper)
        near = np.where(parallel, np.where(inside, -np.inf, np.inf), near)
        far = np.where(parallel, np.where(inside, np.inf, -np.inf), far)
    return _across_last_axis(np.maximum, near), _across_last_axis(np.minimum, far)


def _across_last_axis(combine: np.ufunc, values: np.ndarray) -> np.ndarray:
    """`combine` folded over the (short) last axis, one whole-array pass per axis: a reduction along a
    length-3 axis pays numpy's per-row set-up on every ray, several times this cost."""
    result = values[..., 0]
    for axis in range(1, values.shape[-1]):
        result = combine(result, values[..., axis])
    return result


def slab_intervals(
    origins: np.ndarray, directions: np.ndarray, lower: np.ndarray, upper: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Entry and exit of every ray (N, 3) through every axis-aligned box [lower, upper] (M, 3) → (N, M)."""
    return _empty_where(*_slab(origins[:, None, :], directions[:, None, :], lower[None], upper[None]))


def paired_cube_intervals(
    origins: np.ndarray, directions: np.ndarray, centers: np.ndarray, half_sizes: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Entry and exit of ray k (K, 3) through the axis-aligned cube k (centre (K, 3), half edge (K,)) → (K,)."""
    return paired_cube_intervals_by_axis(origins.T, directions.T, centers.T, half_sizes)


def paired_cube_intervals_by_axis(
    origins: np.ndarray, directions: np.ndarray, centers: np.ndarray, half_sizes: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """`paired_cube_intervals` of arrays laid out (3, K), one row per axis (→ (K,)).

    The slab test with few array operations (it runs on every candidate pair),
    an axis at a time on contiguous rows (a reduction across a (K, 3) array's
    short rows costs several times more): an axis the ray runs parallel to
    gives NaN or ±inf bounds, which fmax/fmin skip; such a ray misses when its
    origin lies outside that axis's slab. The bounds are combined in the order
    of the axes, so the result is the same whatever the layout.
    """
    with np.errstate(divide="ignore", over="ignore"):  # d is 0 or so small that 1/d overflows: inf
        per_axis = ((np.divide(1.0, directions[axis]), np.subtract(centers[axis], origins[axis])) for axis in range(3))
        return _cube_intervals(per_axis, half_sizes)


def gathered_cube_intervals(
    inverse_directions: np.ndarray, center_offsets: np.ndarray, half_sizes: np.ndarray, ray: np.ndarray, cube: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """`paired_cube_intervals_by_axis` of pairs (ray[k], cube[k]) of rays from one origin, given per ray
    1 / direction (3, N) and per cube its centre − the origin (3, M) and half edge (M,): the division
    and the subtraction once per ray and per cube instead of once per pair, the same values."""
    per_axis = ((inverse_directions[axis].take(ray), center_offsets[axis].take(cube)) for axis in range(3))
    return _cube_intervals(per_axis, half_sizes.take(cube))


def _cube_intervals(per_axis: Iterable[tuple[np.ndarray, np.ndarray]], half_sizes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The slab test from each axis's (1 / direction, centre − origin) per pair (see paired_cube_intervals_by_axis)."""
    near = far = outside = None
    with np.errstate(invalid="ignore", over="ignore"):
        for inverse, offset in per_axis:
            middle = offset * inverse
            spread = np.abs(inverse)
            spread *= half_sizes
            lower, upper = middle - spread, middle + spread
            near = lower if near is None else np.fmax(near, lower, out=near)
            far = upper if far is None else np.fmin(far, upper, out=far)
            parallel = ~np.isfinite(inverse)  # d is 0 or so small that 1/d overflows
            if parallel.any():
                away = parallel & (np.abs(offset) > half_sizes)
                outside = away if outside is None else outside | away
    if outside is not None and outside.any():
        near = np.where(outside, np.inf, near)
    return _empty_where(near, far)


def box_intervals(shape: Box, origins: np.ndarray, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    half = 0.5 * np.asarray(shape.size, dtype=float)[None, :]
    return slab_intervals(origins, directions, -half, half)


def sphere_intervals(shape: Sphere, origins: np.ndarray, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    b = np.einsum("ij,ij->i", origins, directions)
    c = np.einsum("ij,ij->i", origins, origins) - shape.radius**2
    with np.errstate(invalid="ignore"):
        root = np.sqrt(b * b - c)
    return _empty_where((-b - root)[:, None], (-b + root)[:, None])


def cylinder_intervals(shape: Cylinder, origins: np.ndarray, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The side (a quadratic in the xy-plane) intersected with the caps' slab in z."""
    ox, oy = origins[:, 0], origins[:, 1]
    dx, dy = directions[:, 0], directions[:, 1]
    a = dx * dx + dy * dy
    b = ox * dx + oy * dy
    c = ox * ox + oy * oy - shape.radius**2
    along_axis = a == 0.0
    with np.errstate(divide="ignore", invalid="ignore"):
        root = np.sqrt(b * b - a * c)
        side_near = np.where(along_axis, np.where(c <= 0, -np.inf, np.inf), (-b - root) / a)
        side_far = np.where(along_axis, np.where(c <= 0, np.inf, -np.inf), (-b + root) / a)
    half_height = np.array([0.5 * shape.height])
    cap_near, cap_far = _slab(origins[:, 2:], directions[:, 2:], -half_height, half_height)
    near = np.maximum(side_near, cap_near)
    far = np.minimum(side_far, cap_far)
    return _empty_where(near[:, None], far[:, None])


def _ray_triangle_crossings(
    origins: np.ndarray, directions: np.ndarray, triangles: np.ndarray, normals: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Möller–Trumbore against every triangle: distances t > 0 (N, T), inf where
    missed, and the crossing's orientation: +1 leaving (d·n > 0), -1 entering."""
    v0, edge1, edge2 = triangles[:, 0], triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0]
    p = np.cross(directions[:, None, :], edge2[None, :, :])
    det = np.einsum("ntk,tk->nt", p, edge1)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv_det = 1.0 / det
        s = origins[:, None, :] - v0[None, :, :]
        u = np.einsum("ntk,ntk->nt", s, p) * inv_det
        q = np.cross(s, edge1[None, :, :])
        v = np.einsum("nk,ntk->nt", directions, q) * inv_det
        t = np.einsum("tk,ntk->nt", edge2, q) * inv_det
        hit = (det != 0.0) & (u >= 0.0) & (v >= 0.0) & (u + v <= 1.0) & (t > 0.0)
    orientation = np.sign(directions @ normals.T)
    return np.where(hit, t, np.inf), np.where(hit, orientation, 0.0)


def mesh_intervals(
    mesh: trimesh.Trimesh, origins: np.ndarray, directions: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Every interval inside a closed mesh, from all ray/triangle crossings.

    The winding number at the origin is the sum of the orientations of all
    crossings ahead (a leaving crossing ahead means the origin is inside);
    walking along the ray each crossing changes it by its orientation, and
    the ray is inside wherever it is positive. Two crossings at the same
    distance with the same orientation are one crossing through a shared
    edge or vertex and are counted once.
    """
    triangles = np.asarray(mesh.triangles, dtype=float)
    normals = np.asarray(mesh.face_normals, dtype=float)
    rows = max(1, _CROSSING_CHUNK // max(1, len(triangles)))
    distance_parts, orientation_parts = [], []
    for start in range(0, len(origins), rows):
        chunk = slice(start, start + rows)
        t, sign = _ray_triangle_crossings(origins[chunk], directions[chunk], triangles, normals)
        distance_parts.append(t)
        orientation_parts.append(sign)
    distances = np.concatenate(distance_parts)
    orientations = np.concatenate(orientation_parts)
    order = np.argsort(distances, axis=1)
    distances = np.take_along_axis(distances, order, axis=1)
    orientations = np.take_along_axis(orientations, order, axis=1)
    duplicate = np.zeros_like(distances, dtype=bool)
    with np.errstate(invalid="ignore"):  # inf − inf between two misses
        duplicate[:, 1:] = (np.abs(np.diff(distances, axis=1)) < _SAME_CROSSING_M) & (
            orientations[:, 1:] == orientations[:, :-1]
        )
    orientations = np.where(duplicate, 0.0, orientations)
    most = int((orientations != 0).sum(axis=1).max(initial=0))
    keep = np.argsort(orientations == 0, axis=1, kind="stable")[:, :most]
    distances = np.take_along_axis(distances, keep, axis=1)
    orientations = np.take_along_axis(orientations, keep, axis=1)
    winding_at_origin = orientations.sum(axis=1)
    winding_after = winding_at_origin[:, None] - np.cumsum(orientations, axis=1)
    starts = np.concatenate([np.full((len(origins), 1), -np.inf), distances], axis=1)
    ends = np.concatenate([distances, np.full((len(origins), 1), np.inf)], axis=1)
    inside = np.concatenate([winding_at_origin[:, None], winding_after], axis=1) > 0
    inside &= ends > starts
    return np.where(inside, starts, NO_HIT), np.where(inside, ends, NO_HIT)


def shape_intervals(
    shape: Shape, origins: np.ndarray, directions: np.ndarray, mesh: trimesh.Trimesh | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Intervals inside `shape` for rays in its local frame (`mesh` caches a MeshFile's mesh)."""
    if isinstance(shape, Box):
        return box_intervals(shape, origins, directions)
    if isinstance(shape, Sphere):
        return sphere_intervals(shape, origins, directions)
    if isinstance(shape, Cylinder):
        return cylinder_intervals(shape, origins, directions)
    if isinstance(shape, MeshFile):
        return mesh_intervals(mesh if mesh is not None else shape_mesh(shape), origins, directions)
    raise TypeError(f"unknown shape {shape!r}")
