"""Which beam–particle pairs can meet: a cheap superset for the exact slab test.

Each particle's cube is bounded by a sphere (radius = half edge × √3). Only
spheres touching the box around all beam segments take part; a fan of beams
picks each sphere's beams by angle (`fans.py`, shared with the puffs), other
beam sets test every sphere against every beam, in chunks of bounded size.
"""

from __future__ import annotations

import numpy as np

from emulator.optics.fans import beam_segments, dot_columns, fan_pairs

PAIRS_PER_CHUNK = 250_000  # beams × particles tested at once by the general test (bounds temporaries)


def candidate_pairs(
    origins: np.ndarray, directions: np.ndarray, beam_end: np.ndarray, centers: np.ndarray, radius: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(beam, particle) index arrays of every pair whose bounding sphere the beam may cross before its
    end, and each pair's sphere centre's distance along the beam."""
    nothing = np.zeros(0, dtype=np.int64)
    if len(origins) == 0 or len(centers) == 0:
        return nothing, nothing, np.zeros(0)
    segments = beam_segments(origins, directions, beam_end)
    far = segments.far_from(centers, radius)
    if segments.fan is not None:
        offset = np.subtract(centers.T, origins[0][:, None], order="C")  # (3, P): a row per axis
        beam, particle = fan_pairs(segments.fan, offset, radius, far)
        along = dot_columns(offset, particle, segments.fan.directions_by_axis, beam)
        in_reach = along - radius.take(particle) <= beam_end.take(beam)
        return beam[in_reach], particle[in_reach], along[in_reach]
    near = (~far).nonzero()[0]
    step = max(1, PAIRS_PER_CHUNK // len(origins))
    beams, particles, alongs = [nothing], [nothing], [np.zeros(0)]
    for start in range(0, len(near), step):
        chunk = near[start : start + step]
        beam, particle, along = _sphere_pairs(origins, directions, beam_end, centers[chunk], radius[chunk])
        beams.append(beam)
        particles.append(chunk[particle])
        alongs.append(along)
    return np.concatenate(beams), np.concatenate(particles), np.concatenate(alongs)


def _sphere_pairs(
    origins: np.ndarray, directions: np.ndarray, beam_end: np.ndarray, centers: np.ndarray, radius: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every beam against every sphere: the perpendicular distance and the extent along the beam."""
    origin_along = np.einsum("ij,ij->i", origins, directions)
    along = directions @ centers.T - origin_along[:, None]
    distance_squared = (
        np.einsum("ij,ij->i", centers, centers)[None, :]
        - 2.0 * (origins @ centers.T)
        + np.einsum("ij,ij->i", origins, origins)[:, None]
    )
    beam, sphere = np.nonzero(
        (distance_squared - along * along <= (radius * radius)[None, :] + 1e-9)
        & (along >= -radius[None, :])
        & (along <= beam_end[:, None] + radius[None, :])
    )
    return beam, sphere, along[beam, sphere]
