"""The cheap cuts before any exact beam–sphere test, shared by plume boxes and puffs.

A sphere (a particle's bounding sphere, a puff's reach) can only meet beam
segments if it touches the box bounding them all. A scanner's beams share one
origin and lie in one plane (a fan): a sphere then covers one interval of
beam angles, found by binary search, so the cost grows with beams + spheres +
pairs rather than with their product. Both cuts are kept per beam arrays, so
a sensor's fixed beams pay for them once.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from emulator.optics.kept import KeptPerArrays


@dataclass(frozen=True)
class Fan:
    """A fan's plane (`first`, `second` in it, `normal`) and its beams' angles in it, ascending;
    `axes_by_row` (3, 3, 1) holds (normal, first, second) as columns, to project (3, P) offsets in one pass;
    `directions_by_axis` (3, N) the beams' directions, one contiguous row per axis, and
    `inverse_directions_by_axis` (3, N) their reciprocals (inf where a component is 0), as the slab test needs."""

    first: np.ndarray
    second: np.ndarray
    normal: np.ndarray
    beam_angle: np.ndarray
    axes_by_row: np.ndarray
    directions_by_axis: np.ndarray
    inverse_directions_by_axis: np.ndarray


@dataclass(frozen=True)
class Segments:
    """What culling needs of fixed beam segments: the corners of the box bounding them, and their fan if any."""

    lower: np.ndarray
    upper: np.ndarray
    fan: Fan | None

    def far_from(self, centers: np.ndarray, radius: np.ndarray) -> np.ndarray:
        """Which spheres lie wholly outside the box bounding all beam segments (an axis at a time:
        a reduction across the (P, 3) array's short rows costs several times more)."""
        far = np.zeros(len(radius), dtype=bool)
        for axis in range(3):
            center = centers[:, axis]
            far |= center + radius < self.lower[axis]
            far |= center - radius > self.upper[axis]
        return far


_SEGMENTS = KeptPerArrays()


def beam_segments(origins: np.ndarray, directions: np.ndarray, beam_end_m: np.ndarray) -> Segments:
    """Kept for a sensor's read-only beam arrays: one look-up a scan."""
    return _SEGMENTS.get(
        (origins, directions, beam_end_m),
        None,
        lambda: Segments(*_segments_box(origins, directions, beam_end_m), _fan_geometry(origins, directions)),
    )


def fan_pairs(fan: Fan, offset: np.ndarray, radius: np.ndarray, skip: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Candidate (beam, sphere) pairs of a fan of beams, given each sphere's `offset` (3, P) from the
    origin and `radius` (P,): the beams within each sphere's angular reach, grouped by sphere,
    ascending; none for spheres in `skip`. Whether a sphere starts before a beam's end is left to the caller."""
    beam_angle, axes = fan.beam_angle, fan.axes_by_row
    # each row as _dot computes it: o0·a0 + o1·a1 + o2·a2; the angles only for spheres the plane cuts
    height = offset[0] * axes[0, 0] + offset[1] * axes[1, 0] + offset[2] * axes[2, 0]
    cut = np.abs(height) < radius
    cut &= ~skip
    live = cut.nonzero()[0]
    if len(live) < len(radius):
        offset, radius, height = offset.take(live, axis=1), radius.take(live), height.take(live)
    x = offset[0] * axes[0, 1] + offset[1] * axes[1, 1] + offset[2] * axes[2, 1]
    y = offset[0] * axes[0, 2] + offset[1] * axes[1, 2] + offset[2] * axes[2, 2]
    in_plane = np.sqrt(np.maximum(radius * radius - height * height, 0.0))
    distance = np.hypot(x, y)
    around_origin = distance <= in_plane  # every beam's angle: set below, whatever half_width says
    half_width = np.arcsin(np.minimum(in_plane, distance) / np.maximum(distance, _TINIEST))  # never 0 / 0
    centre = np.arctan2(y, x)
    lower_edge, upper_edge = centre - half_width, centre + half_width
    # an interval reaching past ±pi may hold beams one turn away (checked with a margin: a needless turn adds no pairs)
    wraps = len(live) > 0 and (
        upper_edge.max() > beam_angle[0] + (2.0 * np.pi - 1e-9) or lower_edge.min() < beam_angle[-1] - (2.0 * np.pi - 1e-9)
    )
    beams, sphere_of = [], []
    for turn in (-2.0 * np.pi, 0.0, 2.0 * np.pi) if wraps else (0.0,):
        low = beam_angle.searchsorted(centre + turn - half_width if turn else lower_edge, side="left")
        high = beam_angle.searchsorted(centre + turn + half_width if turn else upper_edge, side="right")
        if turn:
            high[around_origin] = low[around_origin]
        else:
            low[around_origin], high[around_origin] = 0, len(beam_angle)
        counts = high - low
        sphere_of.append(live.repeat(counts))
        beams.append((low + counts - counts.cumsum()).repeat(counts) + np.arange(len(sphere_of[-1])))
    if len(beams) == 1:
        return beams[0], sphere_of[0]
    return np.concatenate(beams), np.concatenate(sphere_of)


def dot_rows(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Dot products of the columns of (3, n) arrays, summed in einsum's order ((x + z) + y): the same bits."""
    product = a * b
    total = product[0] + product[2]
    total += product[1]
    return total


def dot_columns(a: np.ndarray, a_index: np.ndarray, b: np.ndarray, b_index: np.ndarray) -> np.ndarray:
    """`dot_rows(a.take(a_index, axis=1), b.take(b_index, axis=1))`, the same bits, a row at a time:
    for a million pairs the (3, Q) temporaries are large enough for the allocator to map them
    afresh (page faults every scan); rows of Q are reused."""
    total = a[0].take(a_index)
    total *= b[0].take(b_index)
    other = a[2].take(a_index)
    other *= b[2].take(b_index)
    total += other
    a[1].take(a_index, out=other)
    other *= b[1].take(b_index)
    total += other
    return total


_TINIEST = np.nextafter(0.0, 1.0)


def _fan_geometry(origins: np.ndarray, directions: np.ndarray) -> Fan | None:
    """The beams' fan, or None if they have several origins, span space or are not ordered by angle."""
    if len(origins) < 2 or (origins != origins[0]).any():  # cheaper than np.ptp, which reduces (N, 3) along N
        return None
    first = directions[len(directions) // 2]
    normal = _cross(directions[0], directions[-1])
    if np.linalg.norm(normal) < 1e-9:
        normal = _cross(directions[0], directions[1])
    normal /= np.linalg.norm(normal)
    second = _cross(normal, first)
    if np.abs(_dot(directions, normal)).max() > 1e-9:
        return None
    beam_angle = np.arctan2(_dot(directions, second), _dot(directions, first))
    if np.all(np.diff(beam_angle) < 0):
        second, beam_angle = -second, -beam_angle
    if np.any(np.diff(beam_angle) <= 0):
        return None
    axes_by_row = np.stack([normal, first, second], axis=1)[:, :, None]
    directions_by_axis = np.ascontiguousarray(directions.T)
    with np.errstate(divide="ignore", over="ignore"):  # a component of 0 or so small that 1/d overflows: inf
        inverse_directions_by_axis = np.divide(1.0, directions_by_axis)
    for array in (first, second, normal, beam_angle, axes_by_row, directions_by_axis, inverse_directions_by_axis):
        array.flags.writeable = False  # kept and shared by later scans
    return Fan(first, second, normal, beam_angle, axes_by_row, directions_by_axis, inverse_directions_by_axis)


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a × b of two 3-vectors (np.cross costs more in its set-up than in this arithmetic)."""
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


def _dot(vectors: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """(N, 3) · (3,) without BLAS (whose threads cost more than this work on small arrays)."""
    return vectors[:, 0] * axis[0] + vectors[:, 1] * axis[1] + vectors[:, 2] * axis[2]


def _segments_box(origins: np.ndarray, directions: np.ndarray, beam_end_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Lower and upper corner of the box bounding all beam segments (an infinite beam counts to its origin)."""
    ends = origins + directions * np.where(np.isfinite(beam_end_m), beam_end_m, 0.0)[:, None]
    # reduceat over one block: numpy's min/max along the long axis of an (N, 3) array cost several times more
    return np.minimum.reduceat(np.minimum(origins, ends), _FIRST, axis=0)[0], np.maximum.reduceat(np.maximum(origins, ends), _FIRST, axis=0)[0]


_FIRST = np.zeros(1, dtype=np.intp)
