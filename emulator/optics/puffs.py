"""Plume particles as Gaussian puffs, integrated analytically along beams.

The `physical` model replaces each particle's hard collision box (edge L,
density D) by a Gaussian puff with the same peak density D and

    sigma = L / sqrt(2 pi)

which keeps the particle's smoke mass (D L^3) and its central column
(D L, the box's chord through its centre) while smoothing its edges. Along a
beam the line integral of a Gaussian is analytic: a puff whose centre lies at
distance `along_m` on the beam and `miss_m` off it contributes

    column = D sqrt(2 pi) sigma exp(-miss^2 / (2 sigma^2))

spread along the beam as a normal distribution of standard deviation sigma,
so the optical path from the origin to any distance s is column times
(Phi((s - along)/sigma) - Phi(-along/sigma)), summed over the (beam, puff)
pairs by compiled loops (`puff_kernels`). Puffs are summed out to a reach
(`reach_sigmas`) chosen per instant so that all the puffs left out add at most
TRUNCATION_BUDGET to any beam: the paths equal the untruncated integral to
within that. See docs/physical-model.md, "Plumes at scale".
"""

from __future__ import annotations

from dataclasses import dataclass, field
from types import ModuleType

import numpy as np

from emulator.optics.fans import beam_segments, dot_rows
from emulator.scene.plumes import Particles

SIGMA_PER_EDGE = 1.0 / np.sqrt(2.0 * np.pi)
REACH_SIGMAS = 3.0  # where a beam's smoke starts and ends (its range bins span this around each near puff)
BINS_SIGMAS = 4.0  # a fan's pairs kept for the range bins (and every limit); fainter ones count only to the beam's end
TRUNCATION_BUDGET = 8e-5  # d·m: the most the puffs left out may add to any beam's optical path


def reach_sigmas(central_columns: np.ndarray) -> float:
    """How far from a beam (in sigmas, at least REACH_SIGMAS) an instant's puffs are still summed.

    A puff whose centre lies r sigma from every point of a beam segment adds at most
    column × exp(−r²/2) to it (off the line, behind the origin or past the end alike),
    so leaving out every puff farther than R sigma costs at most exp(−R²/2) × Σ columns:
    R = sqrt(2 ln(Σ columns / TRUNCATION_BUDGET)) keeps that within the budget.
    """
    total = float(central_columns.sum()) if len(central_columns) else 0.0
    if total <= TRUNCATION_BUDGET:
        return REACH_SIGMAS
    return max(REACH_SIGMAS, float(np.sqrt(2.0 * np.log(total / TRUNCATION_BUDGET))))


@dataclass(frozen=True)
class Puffs:
    """Gaussian puffs: centres (P, 3), standard deviations (P,), peak densities (P,)."""

    centers: np.ndarray
    sigma: np.ndarray
    peak_density: np.ndarray

    def __len__(self) -> int:
        return len(self.sigma)

    @property
    def central_column(self) -> np.ndarray:
        """Each puff's line integral along a line through its centre (d·m)."""
        return self.peak_density * _SQRT_2PI * self.sigma

    @staticmethod
    def from_particles(particles: Particles) -> Puffs:
        edge = 2.0 * particles.half_sizes
        return Puffs(particles.centers, edge * SIGMA_PER_EDGE, particles.density)

    @staticmethod
    def concatenate(parts: list[Puffs]) -> Puffs:
        if len(parts) == 1:
            return parts[0]
        return Puffs(
            np.concatenate([p.centers for p in parts]).reshape(-1, 3),
            np.concatenate([p.sigma for p in parts]),
            np.concatenate([p.peak_density for p in parts]),
        )


@dataclass(frozen=True)
class BeamPuffCrossings:
    """The (beam, puff) pairs that matter, flat arrays of length Q.

    `beam`: index of the beam; `along_m`: the puff centre's distance along the
    beam; `sigma`: the puff's standard deviation; `column`: its line integral
    over the whole line (d·m); `before_origin`: the share of it behind the
    origin (Phi(-along/sigma)), which the beam never sees; `near`: the pair
    lies within REACH_SIGMAS (it sets where the beam's smoke starts and ends;
    the others only add their faint tails to the paths).

    Per beam index, `pooled_column` sums what a fan's faint pairs (beyond
    BINS_SIGMAS, not kept) add from the origin to the beam's end
    `pooled_end_m`; it counts for limits from that end on. A nearer limit, as
    a footprint's nearer surface may be, and the range bins leave them out
    (each under 0.04 % of its puff's column).
    """

    beam: np.ndarray
    along_m: np.ndarray
    sigma: np.ndarray
    column: np.ndarray
    before_origin: np.ndarray
    near: np.ndarray
    pooled_column: np.ndarray = field(default_factory=lambda: np.zeros(0))
    pooled_end_m: np.ndarray = field(default_factory=lambda: np.zeros(0))

    def __len__(self) -> int:
        return len(self.beam)

    def optical_path_to(self, limits_m: np.ndarray, rows: np.ndarray | None = None) -> np.ndarray:
        """Puff optical path from each beam's origin to `limits_m` (>= 0; inf or NaN: the whole way).

        `limits_m` is (N,) or (N, M): one or M distances per beam; the result
        has its shape. With `rows`, `limits_m` holds only those beams' limits.
        A limit of 0 gives exactly 0; each beam's sum runs over its pairs in
        their order, whatever the other beams or limits.
        """
        limits = np.asarray(limits_m, dtype=float)
        if limits.size == 0 or (len(self) == 0 and not self.pooled_column.any()):
            return np.zeros(limits.shape)
        per_beam = np.ascontiguousarray(limits.reshape(len(limits), -1))
        position = self._positions(len(per_beam) if rows is None else None, rows)
        path = _kernels().path_to(
            per_beam, position, self.beam, self.along_m, self.sigma, self.column, self.before_origin, self.pooled_column, self.pooled_end_m
        )
        return path.reshape(limits.shape)

    def optical_path_on_grid(self, rows: np.ndarray, start_m: np.ndarray, length_m: np.ndarray, fractions: np.ndarray) -> np.ndarray:
        """The kept pairs' `optical_path_to` at the distances start + length × fractions (R, F) of beams
        `rows`; `fractions` ascend. The range bins' smoke: a fan's pairs fainter than BINS_SIGMAS, summed
        into each path to its beam's end, are left out of the bins (a grid point each costs a CDF)."""
        if len(rows) == 0 or len(self) == 0:
            return np.zeros((len(rows), len(fractions)))
        position = self._positions(None, rows)
        return _kernels().path_on_grid(
            np.ascontiguousarray(start_m, dtype=float), np.ascontiguousarray(length_m, dtype=float), np.ascontiguousarray(fractions, dtype=float),
            position, self.beam, self.along_m, self.sigma, self.column, self.before_origin,
        )

    def extent_m(self, n_beams: int) -> tuple[np.ndarray, np.ndarray]:
        """Per beam, where puff smoke starts and ends (REACH_SIGMAS around the near pairs' centres; inf/−inf if none)."""
        return _kernels().extent(n_beams, self.beam, self.along_m, self.sigma, self.near, REACH_SIGMAS)

    def _positions(self, count: int | None, rows: np.ndarray | None) -> np.ndarray:
        """Per beam index, its line in the caller's arrays (−1: not asked for)."""
        size = max(int(self.beam.max(initial=-1)) + 1, count or 0, int(rows.max()) + 1 if rows is not None and len(rows) else 0)
        if rows is None:
            position = np.full(size, -1, dtype=np.int64)
            position[:count] = np.arange(count)
            return position
        position = np.full(size, -1, dtype=np.int64)
        position[rows] = np.arange(len(rows))
        return position


def cross_beams(
    puffs: Puffs, origins: np.ndarray, directions: np.ndarray, beam_end_m: np.ndarray, row_offset: np.ndarray | None = None
) -> BeamPuffCrossings:
    """The puffs each beam passes within their instant's reach (`reach_sigmas`), before its end.

    With `row_offset` (P,), ascending, a puff's pairs name the row beam + its offset:
    the puffs of K instants, each offset by its instant × N, cross the same N
    beams in one pass, and each pair lands on that instant's rows (each instant's
    reach from its own puffs; pairs of one row keep the order a single instant's call gives them).

    `directions` must be unit vectors. A scanner's beams usually form a fan
    (one origin, directions in one plane, ordered by angle): then each puff
    picks its beams by angle with a binary search, in compiled code, so the cost
    grows with the pairs that matter rather than with beams x puffs.
    """
    if len(puffs) == 0 or len(origins) == 0:
        return _no_crossings()
    reach = _reach_per_puff(puffs, row_offset)
    reach_of_puff = reach * puffs.sigma
    segments = beam_segments(origins, directions, beam_end_m)
    fan = segments.fan
    if fan is not None:  # a fan has one origin: its pairs found and measured in one compiled pass
        far = segments.far_from(puffs.centers, reach_of_puff)
        if far.all():
            return _no_crossings()
        live = (~far).nonzero()[0]
        offsets = puffs.centers.take(live, axis=0) - origins[0]
        offset_of_row = np.zeros(len(live), dtype=np.int64) if row_offset is None else row_offset.take(live).astype(np.int64)
        rows = len(origins) + (int(row_offset.max()) if row_offset is not None else 0)
        return BeamPuffCrossings(*_kernels().fan_crossings(
            *map(_read_only, (offsets, puffs.sigma.take(live), puffs.central_column.take(live), reach.take(live),
                              offset_of_row, fan.axes_by_row[:, :, 0].T.copy(), fan.beam_angle, directions, beam_end_m)),
            REACH_SIGMAS, BINS_SIGMAS, rows,
        ))
    far = segments.far_from(puffs.centers, reach_of_puff)
    if far.all():
        return _no_crossings()
    near = (~far).nonzero()[0]
    beam, puff = _block_pairs(origins, directions, beam_end_m, puffs.centers.take(near, axis=0), reach_of_puff.take(near))
    puff = near.take(puff)
    offset = (puffs.centers.take(puff, axis=0) - origins.take(beam, axis=0)).T
    distance_sq = dot_rows(offset, offset)
    along = dot_rows(offset, directions.take(beam, axis=0).T)
    return crossings_of_candidates(puffs, reach_of_puff, beam_end_m, beam, puff, along, distance_sq, row_offset)


def _reach_per_puff(puffs: Puffs, row_offset: np.ndarray | None) -> np.ndarray:
    """Each puff's reach in sigmas: its instant's (`reach_sigmas` of that instant's puffs; with
    `row_offset`, the puffs of one instant share an offset and follow each other)."""
    columns = puffs.central_column
    if row_offset is None:
        return np.full(len(puffs), reach_sigmas(columns))
    firsts = np.concatenate([[0], (np.diff(row_offset) != 0).nonzero()[0] + 1])
    counts = np.diff(np.append(firsts, len(puffs)))
    return np.repeat([reach_sigmas(columns[first:first + count]) for first, count in zip(firsts, counts)], counts)


def crossings_of_candidates(
    puffs: Puffs, reach_of_puff: np.ndarray, beam_end_m: np.ndarray, beam: np.ndarray, puff: np.ndarray,
    along: np.ndarray, distance_sq: np.ndarray, row_offset: np.ndarray | None = None,
) -> BeamPuffCrossings:
    """`cross_beams`' exact tests on candidate (beam, puff) pairs, given each pair's puff centre's distance
    along the beam and squared distance from its origin, and each puff's reach (m); the pairs kept keep their order."""
    reach = reach_of_puff.take(puff)
    before_end = along < beam_end_m.take(beam) + reach  # the test that culls: first, on every candidate
    if not before_end.all():
        before_end = before_end.nonzero()[0]
        beam, puff, along, distance_sq, reach = beam.take(before_end), puff.take(before_end), along.take(before_end), distance_sq.take(before_end), reach.take(before_end)
    reach_sq = reach * reach
    miss_sq = np.maximum(distance_sq - along * along, 0.0)
    ahead = (along > 0) | (distance_sq < reach_sq)  # a puff behind the origin and out of reach adds < its budget share
    kept = (miss_sq < reach_sq) & ahead
    if not kept.all():
        kept = kept.nonzero()[0]
        beam, puff, along, miss_sq, distance_sq = beam.take(kept), puff.take(kept), along.take(kept), miss_sq.take(kept), distance_sq.take(kept)
    sigma = puffs.sigma.take(puff)
    column = puffs.central_column.take(puff) * np.exp(-miss_sq / (2.0 * sigma * sigma))
    near_reach = REACH_SIGMAS * sigma
    near_sq = near_reach * near_reach
    near = (miss_sq < near_sq) & (along < beam_end_m.take(beam) + near_reach) & ((along > 0) | (distance_sq < near_sq))
    if row_offset is not None:
        beam = beam + row_offset.take(puff)
    return BeamPuffCrossings(beam, along, sigma, column, _kernels().normal_cdf(-along / sigma), near)


_SQRT_2PI = np.sqrt(2.0 * np.pi)


def _read_only(array: np.ndarray) -> np.ndarray:
    """A read-only view: numba compiles a kernel once per argument type, and writability is part of the type;
    a fan's beams come cached (read-only) or fresh (a moving sensor's), and each new mix compiled for seconds
    in the middle of a stream."""
    view = array.view()
    view.flags.writeable = False
    return view


def _kernels() -> ModuleType:
    """The compiled loops, imported with the first crossing: numba loads only where puffs are crossed."""
    from emulator.optics import puff_kernels

    return puff_kernels


def _no_crossings() -> BeamPuffCrossings:
    empty = np.zeros(0)
    return BeamPuffCrossings(np.zeros(0, dtype=np.int64), empty, empty, empty, empty, np.zeros(0, dtype=bool))


BEAMS_PER_BLOCK = 16
_BLOCK_MARGIN = 1.5  # x reach: a kept pair's centre lies within sqrt(2) reach of its segment (past its end by < reach)


def _block_pairs(
    origins: np.ndarray, directions: np.ndarray, beam_end_m: np.ndarray, centers: np.ndarray, reach: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Candidate (beam, puff) pairs of beams with their own origins, beam-major and puffs ascending
    as all pairs would be: consecutive beams are taken in blocks, and a puff pairs only with the beams
    of blocks whose segments' bounding box it comes within _BLOCK_MARGIN reaches of. Every pair the
    exact tests in cross_beams keep survives this cut, so the crossings are the same, found cheaper."""
    n_beams, n_puffs = len(origins), len(centers)
    if n_beams <= BEAMS_PER_BLOCK or not np.isfinite(beam_end_m).all():  # an endless beam has no box (0 × inf: NaN)
        return _all_pairs(n_beams, n_puffs)
    ends = origins + directions * beam_end_m[:, None]
    blocks = -(-n_beams // BEAMS_PER_BLOCK)
    block_starts = np.arange(0, n_beams, BEAMS_PER_BLOCK)
    # reduceat: numpy's min/max along the long axis of an (N, 3) array cost several times more
    lower = np.minimum.reduceat(np.minimum(origins, ends), block_starts, axis=0).T  # (3, B): a row per axis
    upper = np.maximum.reduceat(np.maximum(origins, ends), block_starts, axis=0).T
    margin = _BLOCK_MARGIN * reach
    outside = np.zeros((blocks, n_puffs), dtype=bool)
    for center, low, high in zip(centers.T, lower, upper):  # per axis, (B, P): no reduction over a length-3 axis
        outside |= np.greater.outer(low, center + margin)
        outside |= np.less.outer(high, center - margin)
    block, puff = (~outside).nonzero()  # block-major, puffs ascending
    per_block = np.bincount(block, minlength=blocks)
    width = np.minimum(BEAMS_PER_BLOCK, n_beams - np.arange(blocks) * BEAMS_PER_BLOCK)
    sizes = width * per_block
    within = np.arange(int(sizes.sum())) - (sizes.cumsum() - sizes).repeat(sizes)
    count = per_block.repeat(sizes)
    beam = np.arange(blocks).repeat(sizes) * BEAMS_PER_BLOCK + within // count
    return beam, puff.take((per_block.cumsum() - per_block).repeat(sizes) + within % count)


def _all_pairs(n_beams: int, n_puffs: int) -> tuple[np.ndarray, np.ndarray]:
    beam, puff = np.meshgrid(np.arange(n_beams), np.arange(n_puffs), indexing="ij")
    return beam.ravel(), puff.ravel()
