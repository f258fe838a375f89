"""Puff crossings of a moving sensor's scans: several instants' beams, each with its own puffs, in one pass.

A sensor on a moving body casts new beams every scan, each from the pose at its
own instant, so its beams have many origins and no fan; and each scan meets the
puffs alive at its own time. `cross_beams` would be called once per scan, paying
its few dozen numpy calls each time. `cross_instants` crosses K such scans
(N beams each, stacked) with their K puff sets at once, applying `cross_beams`'
own cuts per instant: the box bounding the instant's segments, then boxes of
BEAMS_PER_BLOCK consecutive beams, then the same exact tests on the pairs left.
Its crossings are those of the K calls, bit for bit and in the same order, their
beams numbered as stacked rows (instant k's beam b is row k·N + b).
"""

from __future__ import annotations

import dataclasses
from typing import Sequence

import numpy as np

from emulator.optics.fans import dot_rows
from emulator.optics.puffs import (
    _BLOCK_MARGIN,
    BEAMS_PER_BLOCK,
    BeamPuffCrossings,
    Puffs,
    cross_beams,
    crossings_of_candidates,
    reach_sigmas,
)


def cross_instants(
    parts: Sequence[Puffs], origins: np.ndarray, directions: np.ndarray, beam_end_m: np.ndarray
) -> BeamPuffCrossings:
    """Instant k's puffs `parts[k]` against its beams, rows k·N .. (k + 1)·N of `origins`, unit
    `directions` (K·N, 3) and `beam_end_m` (K·N,): each pair's beam its stacked row, each row's pairs
    those `cross_beams` gives that instant, in its order (rows may interleave: what follows sums per row).

    Instants for which `cross_beams` takes another path (their beams share one origin: perhaps a fan,
    as when the body stands still; too few beams for blocks; a segment without an end) are crossed by
    it, those with the very same beams in one call (their puffs' pairs offset to their rows, as a fixed
    sensor's instants are); all the others together here.
    """
    count = len(parts)
    n = len(origins) // count if count else 0
    if n == 0:
        empty = np.zeros(0)
        return BeamPuffCrossings(np.zeros(0, dtype=np.int64), empty, empty, empty, empty, np.zeros(0, dtype=bool))
    finite_end = np.isfinite(beam_end_m)  # an instant with an endless beam is crossed alone; its ends are not used
    ends = origins + directions * np.where(finite_end, beam_end_m, 0.0)[:, None]  # never 0 × inf
    several_origins = (origins.reshape(count, n, 3) != origins[::n][:, None, :]).any(axis=(1, 2))
    together = several_origins & finite_end.reshape(count, n).all(axis=1) & (n > BEAMS_PER_BLOCK)
    if together.all():
        return _cross_together(parts, origins, directions, beam_end_m, ends, n)
    pieces: list[BeamPuffCrossings] = []
    if together.any():
        batched = _cross_together(  # renumbered as if these instants were stacked alone
            [part for part, joins in zip(parts, together) if joins],
            *(array.reshape(count, n, 3)[together].reshape(-1, 3) for array in (origins, directions)),
            beam_end_m.reshape(count, n)[together].ravel(),
            ends.reshape(count, n, 3)[together].reshape(-1, 3),
            n,
        )
        joined = together.nonzero()[0]
        per_instant = np.diff(batched.beam.searchsorted(np.arange(len(joined) + 1) * n))  # its pairs are instant-major
        pieces.append(dataclasses.replace(batched, beam=batched.beam + ((joined - np.arange(len(joined))) * n).repeat(per_instant)))
    for group in _same_beams(origins, directions, beam_end_m, n, (~together).nonzero()[0]):  # per instant, not per beam
        rows = slice(group[0] * n, (group[0] + 1) * n)
        offsets = np.array(group).repeat([len(parts[k]) for k in group]) * n
        pieces.append(cross_beams(Puffs.concatenate([parts[k] for k in group]), origins[rows], directions[rows], beam_end_m[rows], offsets))
    rows = max((len(piece.pooled_column) for piece in pieces), default=0)
    pooled = np.zeros(rows)
    end = np.zeros(rows)
    for piece in pieces:  # each row's pooled pairs come from one piece (its instant's)
        pooled[: len(piece.pooled_column)] += piece.pooled_column
        np.maximum(end[: len(piece.pooled_end_m)], piece.pooled_end_m, out=end[: len(piece.pooled_end_m)])
    return BeamPuffCrossings(*(np.concatenate([getattr(piece, name) for piece in pieces]) for name in _FIELDS), pooled, end)


_FIELDS = ("beam", "along_m", "sigma", "column", "before_origin", "near")


def _same_beams(origins: np.ndarray, directions: np.ndarray, beam_end_m: np.ndarray, n: int, instants: np.ndarray) -> list[list[int]]:
    """`instants` grouped by equal beams (origins, directions and ends alike, bit for bit)."""
    groups: list[list[int]] = []
    for k in instants:
        rows = slice(k * n, (k + 1) * n)
        for group in groups:
            first = slice(group[0] * n, (group[0] + 1) * n)
            if all(np.array_equal(a[rows], a[first]) for a in (origins, directions, beam_end_m)):
                group.append(int(k))
                break
        else:
            groups.append([int(k)])
    return groups


def _cross_together(
    parts: Sequence[Puffs], origins: np.ndarray, directions: np.ndarray, beam_end_m: np.ndarray, ends: np.ndarray, n: int
) -> BeamPuffCrossings:
    """`cross_instants` of (at least one) instants whose beams have several origins and finite segments."""
    count = len(parts)
    puffs = Puffs.concatenate(list(parts))
    sizes = np.array([len(part) for part in parts], dtype=np.int64)
    instant_of_puff = np.arange(count).repeat(sizes)
    reach_of_puff = np.repeat([reach_sigmas(part.central_column) for part in parts], sizes) * puffs.sigma  # each instant's own
    low_ends, high_ends = np.minimum(origins, ends), np.maximum(origins, ends)
    # cross_beams' first cut, per instant: spheres wholly outside the box bounding all of its segments
    instant_starts = np.arange(0, count * n, n)
    lower = np.minimum.reduceat(low_ends, instant_starts, axis=0).take(instant_of_puff, axis=0)
    upper = np.maximum.reduceat(high_ends, instant_starts, axis=0).take(instant_of_puff, axis=0)
    reach = reach_of_puff[:, None]
    far = np.logical_or.reduce((puffs.centers + reach < lower) | (puffs.centers - reach > upper), axis=1)
    near = (~far).nonzero()[0]  # instant-major, puffs ascending
    beam, puff = _block_pairs(low_ends, high_ends, n, count, puffs.centers.take(near, axis=0), reach_of_puff.take(near), instant_of_puff.take(near))
    puff = near.take(puff)
    # (3, pairs) a contiguous row per axis: gathers and sums cheaper than on (pairs, 3), the same values
    offset = np.ascontiguousarray(puffs.centers.T).take(puff, axis=1) - np.ascontiguousarray(origins.T).take(beam, axis=1)
    along = dot_rows(offset, np.ascontiguousarray(directions.T).take(beam, axis=1))
    return crossings_of_candidates(puffs, reach_of_puff, beam_end_m, beam, puff, along, dot_rows(offset, offset))


def _block_pairs(
    low_ends: np.ndarray, high_ends: np.ndarray, n: int, count: int, centers: np.ndarray, reach: np.ndarray, instant: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """`puffs._block_pairs` of each instant, all at once: candidate (row, puff) pairs, instant-major, then
    beam-major and puffs (indices into `centers`, each an instant's, ascending) as one instant's call gives them.
    Blocks never span two instants; a puff is tested against its own instant's blocks only, laid out as
    (instant, block, puff slot) with each instant's puffs in its first slots."""
    blocks = -(-n // BEAMS_PER_BLOCK)
    block_starts = (np.arange(0, count * n, n)[:, None] + np.arange(0, n, BEAMS_PER_BLOCK)).ravel()  # each block's first row
    lower = np.minimum.reduceat(low_ends, block_starts, axis=0).T.reshape(3, count, blocks, 1)  # a row per axis
    upper = np.maximum.reduceat(high_ends, block_starts, axis=0).T.reshape(3, count, blocks, 1)
    per_instant = np.bincount(instant, minlength=count)
    first_of_instant = per_instant.cumsum() - per_instant
    slots = int(per_instant.max()) if len(instant) else 0
    slot = np.arange(len(instant)) - first_of_instant.take(instant)
    margin = _BLOCK_MARGIN * reach
    outside = np.ones((count, 1, slots), dtype=bool)
    outside[instant, 0, slot] = False  # an empty slot is outside every block
    outside = np.repeat(outside, blocks, axis=1)
    for center, low, high in zip(centers.T, lower, upper):  # per axis, as puffs._block_pairs compares
        high_side = np.zeros((count, 1, slots))
        high_side[instant, 0, slot] = center + margin
        low_side = np.zeros((count, 1, slots))
        low_side[instant, 0, slot] = center - margin
        outside |= low > high_side
        outside |= high < low_side
    pair_instant, pair_block, pair_slot = (~outside).nonzero()  # instant-major, block-major, puffs ascending
    per_block = np.bincount(pair_instant * blocks + pair_block, minlength=count * blocks)
    # every beam in turn (blocks tile the rows in order), each with all its block's puffs: no division
    widths = np.diff(np.append(block_starts, count * n))
    puffs_of_row = per_block.repeat(widths)
    beam = np.arange(count * n).repeat(puffs_of_row)
    first_pair = (per_block.cumsum() - per_block).repeat(widths)  # per row: its block's first pair
    within_row = np.arange(len(beam)) - (puffs_of_row.cumsum() - puffs_of_row).repeat(puffs_of_row)
    puff_of_pair = first_of_instant.take(pair_instant) + pair_slot
    return beam, puff_of_pair.take(first_pair.repeat(puffs_of_row) + within_row)
