"""Which beam–particle pairs can meet: a cheap superset for the exact slab test.

Each particle's cube is bounded by a sphere (radius = half edge × √3). A
scanner's beams share one origin and lie in one plane (a fan): a sphere then
covers one interval of beam angles, found by binary search over the sorted
angles, so the cost grows with beams + particles + pairs. Other beam sets test
every sphere against every beam, in chunks of bounded size. Either way only
particles touching the bounding box of all beam segments take part.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from emulator.optics.kept import KeptPerArrays

PAIRS_PER_CHUNK = 250_000  # beams × particles tested at once by the general test (bounds temporaries)
_COPLANAR = 1e-9  # |d·n| below this: the beams lie in one plane
_ANGLE_MARGIN = 1e-9  # radians added to each side of a sphere's interval (rounding; the slab test decides)


def candidate_pairs(
    origins: np.ndarray, directions: np.ndarray, beam_end: np.ndarray, centers: np.ndarray, radius: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(beam, particle) index arrays: every pair whose bounding sphere the beam may cross before its end."""
    nothing = np.zeros(0, dtype=np.int64)
    if len(origins) == 0 or len(centers) == 0:
        return nothing, nothing
    near = np.flatnonzero(_touches_beam_box(origins, directions, beam_end, centers, radius))
    fan = _FANS.get((origins, directions), None, lambda: _fan_of(origins, directions))
    if fan is not None:
        beam, particle = _fan_pairs(fan, origins[0], directions, beam_end, centers[near], radius[near])
        return beam, near[particle]
    step = max(1, PAIRS_PER_CHUNK // len(origins))
    beams, particles = [nothing], [nothing]
    for start in range(0, len(near), step):
        chunk = near[start : start + step]
        beam, particle = _sphere_pairs(origins, directions, beam_end, centers[chunk], radius[chunk])
        beams.append(beam)
        particles.append(chunk[particle])
    return np.concatenate(beams), np.concatenate(particles)


def _touches_beam_box(
    origins: np.ndarray, directions: np.ndarray, beam_end: np.ndarray, centers: np.ndarray, radius: np.ndarray
) -> np.ndarray:
    """Mask of the spheres whose bounding cube touches the bounding box of all beam segments."""
    lower, upper = _BOXES.get((origins, directions, beam_end), None, lambda: _segments_box(origins, directions, beam_end))
    return np.all((centers + radius[:, None] >= lower) & (centers - radius[:, None] <= upper), axis=1)


_BOXES = KeptPerArrays()


def _segments_box(origins: np.ndarray, directions: np.ndarray, beam_end: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    ends = origins + directions * beam_end[:, None]
    return np.minimum(origins.min(axis=0), ends.min(axis=0)), np.maximum(origins.max(axis=0), ends.max(axis=0))


def _fan_normal(directions: np.ndarray) -> np.ndarray | None:
    """The unit normal of the plane holding every direction, or None if they span space (or a line)."""
    crosses = np.cross(directions[0], directions)
    widest = int(np.argmax(np.einsum("ij,ij->i", crosses, crosses)))
    length = np.linalg.norm(crosses[widest])
    if length < 1e-6:
        return None
    normal = crosses[widest] / length
    return normal if np.abs(directions @ normal).max() <= _COPLANAR else None


@dataclass(frozen=True)
class _Fan:
    """Beams from one origin in one plane: its unit `normal`, two axes in it, and the beams
    sorted by angle (`order`) with their sorted angles three times (−2π, 0, +2π)."""

    normal: np.ndarray
    first: np.ndarray
    second: np.ndarray
    order: np.ndarray
    angles: np.ndarray


_FANS = KeptPerArrays()


def _fan_of(origins: np.ndarray, directions: np.ndarray) -> _Fan | None:
    """The beams' fan, or None if they have several origins or span space."""
    if not np.all(origins == origins[0]):
        return None
    normal = _fan_normal(directions)
    if normal is None:
        return None
    first = directions[0]
    second = np.cross(normal, first)
    beam_angle = np.arctan2(directions @ second, directions @ first)
    order = np.argsort(beam_angle, kind="stable")
    # the sorted angles three times so an interval that wraps around ±π is one slice
    angles = np.concatenate([beam_angle[order] - 2 * np.pi, beam_angle[order], beam_angle[order] + 2 * np.pi])
    for array in (normal, second, order, angles):
        array.flags.writeable = False  # kept and shared by later scans
    return _Fan(normal, first, second, order, angles)


def _fan_pairs(
    fan: _Fan,
    origin: np.ndarray,
    directions: np.ndarray,
    beam_end: np.ndarray,
    centers: np.ndarray,
    radius: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Beams from one origin in one plane: each sphere's circle in that plane covers an interval of
    angles; of those pairs, the ones whose sphere starts before the beam's end."""
    normal, first, second, order, angles = fan.normal, fan.first, fan.second, fan.order, fan.angles
    count = len(order)
    offset = centers - origin
    height = offset @ normal
    circle_squared = radius * radius - height * height  # the sphere's circle in the beams' plane
    in_plane = offset - height[:, None] * normal
    distance = np.sqrt(np.einsum("ij,ij->i", in_plane, in_plane))
    with np.errstate(divide="ignore", invalid="ignore"):
        half_width = np.arcsin(np.clip(np.sqrt(np.maximum(circle_squared, 0.0)) / distance, 0.0, 1.0))
    centre_angle = np.arctan2(in_plane @ second, in_plane @ first)
    low = np.searchsorted(angles, centre_angle - half_width - _ANGLE_MARGIN, side="left")
    high = np.searchsorted(angles, centre_angle + half_width + _ANGLE_MARGIN, side="right")
    surrounds_origin = distance * distance <= circle_squared
    low = np.where(surrounds_origin, count, low)  # the origin is inside the circle: every beam
    high = np.where(surrounds_origin, 2 * count, high)
    counts = np.where(circle_squared >= 0.0, high - low, 0)

    particle = np.repeat(np.arange(len(centers)), counts)
    starts = np.repeat(low - (np.cumsum(counts) - counts), counts)
    position = starts + np.arange(len(particle))
    beam = order[position % count]
    along = np.einsum("ij,ij->i", offset[particle], directions[beam])
    in_reach = along - radius[particle] <= beam_end[beam]
    return beam[in_reach], particle[in_reach]


def _sphere_pairs(
    origins: np.ndarray, directions: np.ndarray, beam_end: np.ndarray, centers: np.ndarray, radius: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Every beam against every sphere: the perpendicular distance and the extent along the beam."""
    origin_along = np.einsum("ij,ij->i", origins, directions)
    along = directions @ centers.T - origin_along[:, None]
    distance_squared = (
        np.einsum("ij,ij->i", centers, centers)[None, :]
        - 2.0 * (origins @ centers.T)
        + np.einsum("ij,ij->i", origins, origins)[:, None]
    )
    return np.nonzero(
        (distance_squared - along * along <= (radius * radius)[None, :] + 1e-9)
        & (along >= -radius[None, :])
        & (along <= beam_end[:, None] + radius[None, :])
    )
