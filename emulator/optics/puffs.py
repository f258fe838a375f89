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
(Phi((s - along)/sigma) - Phi(-along/sigma)). Everything is vectorised over
beams x puffs; only (beam, puff) pairs within `REACH_SIGMAS` are kept.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from emulator.optics.fans import beam_segments, dot_columns, dot_rows, fan_pairs
from emulator.scene.plumes import Particles

SIGMA_PER_EDGE = 1.0 / np.sqrt(2.0 * np.pi)
REACH_SIGMAS = 3.0  # a puff farther than this from a beam adds < 1.2 % of its central column


def erf(x: np.ndarray) -> np.ndarray:
    """Error function, Abramowitz & Stegun 7.1.26 (|error| < 1.5e-7), vectorised.

    numpy has no erf and scipy is not a dependency.
    """
    x = np.asarray(x, dtype=float)
    t = 1.0 / (1.0 + 0.3275911 * np.abs(x))
    poly = t * (0.254829592 + t * (-0.284496736 + t * (1.421413741 + t * (-1.453152027 + t * 1.061405429))))
    return np.sign(x) * (1.0 - poly * np.exp(-x * x))


_CDF_LIMIT = 6.0  # beyond ±6 sigma the CDF is 0 or 1 to within 1e-9
_CDF_STEP = 1e-3
_CDF_TABLE = 0.5 * (1.0 + erf(np.arange(-_CDF_LIMIT, _CDF_LIMIT + 2 * _CDF_STEP, _CDF_STEP) / np.sqrt(2.0)))
_CDF_SLOPE = np.diff(_CDF_TABLE)
_CDF_LAST = len(_CDF_SLOPE) - 1e-9
_CDF_ROWS = np.stack([_CDF_SLOPE, _CDF_TABLE[:-1]], axis=1)  # one cache line serves both: random reads halve


def normal_cdf(x: np.ndarray) -> np.ndarray:
    """Standard normal CDF: linear interpolation in a uniform table of `erf` (|error| < 2e-7).

    Indexing a uniform table costs a few cheap in-place passes over the
    array, where evaluating erf itself needs an exp and a division per element.
    """
    position = np.multiply(x, 1.0 / _CDF_STEP)
    position += _CDF_LIMIT / _CDF_STEP
    np.maximum(position, 0.0, out=position)  # np.clip's Python wrapper costs more than these two ufuncs
    np.minimum(position, _CDF_LAST, out=position)
    index = position.astype(np.intp)
    position -= index
    row = _CDF_ROWS.take(index, axis=0)
    position *= row[..., 0]
    position += row[..., 1]
    return position


_CDF_HEAD, _CDF_TAIL = normal_cdf(np.array([-2 * _CDF_LIMIT, 2 * _CDF_LIMIT]))  # the table's values beyond ±6


@dataclass(frozen=True)
class Puffs:
    """Gaussian puffs: centres (P, 3), standard deviations (P,), peak densities (P,)."""

    centers: np.ndarray
    sigma: np.ndarray
    peak_density: np.ndarray

    def __len__(self) -> int:
        return len(self.sigma)

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
    origin (Phi(-along/sigma)), which the beam never sees.
    """

    beam: np.ndarray
    along_m: np.ndarray
    sigma: np.ndarray
    column: np.ndarray
    before_origin: np.ndarray

    def __len__(self) -> int:
        return len(self.beam)

    def optical_path_to(self, limits_m: np.ndarray, rows: np.ndarray | None = None) -> np.ndarray:
        """Puff optical path from each beam's origin to `limits_m` (>= 0; inf or NaN: the whole way).

        `limits_m` is (N,) or (N, M): one or M distances per beam; the result
        has its shape. With `rows`, `limits_m` holds only those beams' limits.
        Of M limits, the first is evaluated for every beam, a later one only
        where it is neither 0 (a path of exactly 0) nor the first (the same
        sum): the pairs' CDFs are most of the cost, and a beam's footprint
        limits are mostly its end again or unused (0). Bit-identical to
        evaluating every limit: each sum adds the same terms in the same order.
        """
        limits = np.asarray(limits_m, dtype=float)
        if limits.size == 0 or len(self) == 0:
            return np.zeros(limits.shape)
        per_beam = limits.reshape(len(limits), -1)
        pairs = self._in_rows(rows) if rows is not None else self._all_pairs
        first = _path_to(per_beam[:, :1], *pairs)
        if per_beam.shape[1] == 1:
            return first.reshape(limits.shape)
        later = per_beam[:, 1:]
        same = later == per_beam[:, :1]
        result = np.empty(per_beam.shape)
        result[:, :1] = first
        result[:, 1:] = np.where(same, first, 0.0)
        own = (later != 0.0) & ~same
        own_rows = own.any(axis=1).nonzero()[0]
        if len(own_rows):
            own_path = _path_to(later.take(own_rows, axis=0), *_pairs_in_rows(pairs, own_rows))
            result[own_rows, 1:] = np.where(own.take(own_rows, axis=0), own_path, result.take(own_rows, axis=0)[:, 1:])
        return result.reshape(limits.shape)

    def optical_path_on_grid(self, rows: np.ndarray, start_m: np.ndarray, length_m: np.ndarray, fractions: np.ndarray) -> np.ndarray:
        """`optical_path_to` at the distances start + length × fractions (R, F) of beams `rows`.

        `fractions` ascend, so the distances of each beam do too: a puff adds
        its nearly 0 head (the table's value at -6 sigma) before its window of
        ±6 sigma and its nearly full column after it, and only the few grid
        points inside that window need the CDF. Lengths must be positive.
        Work runs on the grid transposed (F, R), so each step's sum runs along a contiguous row.
        """
        if len(rows) == 0 or len(self) == 0:
            return np.zeros((len(rows), len(fractions)))
        beam, along, sigma, before, column = self._in_rows(rows)
        if len(beam) == 0:
            return np.zeros((len(rows), len(fractions)))
        start, length = start_m.take(beam), length_m.take(beam)
        window = _CDF_LIMIT * sigma
        first = fractions.searchsorted((along - window - start) / length, side="right")
        past = np.maximum(first, fractions.searchsorted((along + window - start) / length, side="left"))
        count, width = len(rows), len(fractions)
        # every grid point sees the head; from `past` on, the rest of the column (a step, summed row after row)
        head = np.bincount(beam, weights=column * (_CDF_HEAD - before), minlength=count)
        result = np.bincount(past * count + beam, weights=column * (_CDF_TAIL - _CDF_HEAD), minlength=(width + 1) * count)
        result = result[:-count].reshape(width, count)
        grid_rows = list(result)  # views: a running sum over the F rows, in place (np.cumsum on short columns is slower)
        for previous, current in zip(grid_rows, grid_rows[1:]):
            current += previous
        result += head
        grid = start_m + fractions[:, None] * length_m  # (F, R): the grid once, not per pair
        inside = past - first
        for low, high in _row_chunks(beam, inside, count):
            if low == 0 and high == count:
                result += _window_sums(grid, beam, first, inside, along, sigma, column)
                break
            chunk = ((beam >= low) & (beam < high)).nonzero()[0]
            result[:, low:high] += _window_sums(
                np.ascontiguousarray(grid[:, low:high]), beam.take(chunk) - low, first.take(chunk), inside.take(chunk),
                along.take(chunk), sigma.take(chunk), column.take(chunk),
            )
        return np.ascontiguousarray(result.T)

    def extent_m(self, n_beams: int) -> tuple[np.ndarray, np.ndarray]:
        """Per beam, where puff smoke starts and ends (REACH_SIGMAS around the centres; inf/−inf if none)."""
        start = np.full(n_beams, np.inf)
        end = np.full(n_beams, -np.inf)
        reach = REACH_SIGMAS * self.sigma
        np.minimum.at(start, self.beam, np.maximum(self.along_m - reach, 0.0))
        np.maximum.at(end, self.beam, self.along_m + reach)
        return start, end

    @property
    def _all_pairs(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        return self.beam, self.along_m, self.sigma, self.before_origin, self.column

    def _in_rows(self, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The pairs whose beam is in `rows`, their beam given as its position in `rows`."""
        return _pairs_in_rows(self._all_pairs, rows)


_Pairs = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]  # beam, along, sigma, before origin, column


def _pairs_in_rows(pairs: _Pairs, rows: np.ndarray) -> _Pairs:
    """The `pairs` whose beam is in `rows`, in their order, their beam given as its position in `rows`."""
    beam, along, sigma, before, column = pairs
    if len(beam) == 0:
        return pairs
    position = np.full(max(int(beam.max()), int(rows.max())) + 1, -1)
    position[rows] = np.arange(len(rows))
    position = position.take(beam)
    if position.min() >= 0:
        return position, along, sigma, before, column
    kept = (position >= 0).nonzero()[0]
    return position.take(kept), along.take(kept), sigma.take(kept), before.take(kept), column.take(kept)


def _path_to(per_beam: np.ndarray, beam: np.ndarray, along: np.ndarray, sigma: np.ndarray, before: np.ndarray, column: np.ndarray) -> np.ndarray:
    """Every pair's share of its puff's column up to its beam's limits `per_beam` (N, M), summed per beam → (N, M)."""
    standard = np.fmin(per_beam, 1e12).take(beam, axis=0)  # 1e12: past every puff, whatever the limit
    standard -= along[:, None]
    standard /= sigma[:, None]
    contribution = normal_cdf(standard)
    contribution -= before[:, None]  # limits >= 0: the share is never below it
    contribution *= column[:, None]
    columns = per_beam.shape[1]
    flat_index = (beam[:, None] * columns + np.arange(columns)).ravel() if columns > 1 else beam
    return np.bincount(flat_index, weights=contribution.ravel(), minlength=per_beam.size).reshape(per_beam.shape)


POINTS_PER_CHUNK = 1 << 20  # grid points inside puff windows evaluated at once (see _row_chunks)


def _row_chunks(beam: np.ndarray, inside: np.ndarray, count: int) -> list[tuple[int, int]]:
    """Consecutive ranges of the `count` rows, each holding about POINTS_PER_CHUNK of the pairs' window
    points (`inside` per pair): a dense plume has millions, and temporaries that large are mapped
    afresh by the allocator (page faults on every scan) where 8 MiB ones are reused. A row's points
    all fall in one range, summed in the pairs' order, so the sums are those of one pass."""
    total = int(inside.sum())
    if total <= POINTS_PER_CHUNK:
        return [(0, count)]
    ends = np.bincount(beam, weights=inside, minlength=count).cumsum()
    cuts = np.unique(ends.searchsorted(np.arange(POINTS_PER_CHUNK, total, POINTS_PER_CHUNK), side="right"))
    bounds = [0, *(int(cut) for cut in cuts if 0 < cut < count), count]
    return list(zip(bounds[:-1], bounds[1:]))


def _window_sums(
    grid: np.ndarray, beam: np.ndarray, first: np.ndarray, inside: np.ndarray, along: np.ndarray, sigma: np.ndarray, column: np.ndarray
) -> np.ndarray:
    """Each pair's CDF share minus its head at the `inside` grid points from `first` on, summed per point of
    `grid` (F, R) in the pairs' order → (F, R)."""
    width, count = grid.shape
    ends = inside.cumsum()
    if len(ends) == 0 or ends[-1] == 0:
        return np.zeros((width, count))
    point = (beam + (first - ends + inside) * count).repeat(inside) + np.arange(0, ends[-1] * count, count)
    standard = grid.ravel().take(point)
    standard -= along.repeat(inside)
    standard /= sigma.repeat(inside)
    contribution = normal_cdf(standard)
    contribution -= _CDF_HEAD
    contribution *= column.repeat(inside)
    return np.bincount(point, weights=contribution, minlength=count * width).reshape(width, count)


def cross_beams(
    puffs: Puffs, origins: np.ndarray, directions: np.ndarray, beam_end_m: np.ndarray, row_offset: np.ndarray | None = None
) -> BeamPuffCrossings:
    """The puffs each beam passes within REACH_SIGMAS of, before its end.

    With `row_offset` (P,), a puff's pairs name the row beam + its offset:
    the puffs of K instants, each offset by its instant × N, cross the same N
    beams in one pass, and each pair lands on that instant's rows (pairs of one
    row keep the order a single instant's call gives them).

    `directions` must be unit vectors. A scanner's beams usually form a fan
    (one origin, directions in one plane, ordered by angle): then each puff
    picks its beams by angle with a binary search, so the cost grows with the
    pairs that matter rather than with beams x puffs.
    """
    if len(puffs) == 0 or len(origins) == 0:
        return _no_crossings()
    reach_of_puff = REACH_SIGMAS * puffs.sigma
    segments = beam_segments(origins, directions, beam_end_m)
    far = segments.far_from(puffs.centers, reach_of_puff)
    if far.all():
        return _no_crossings()
    fan = segments.fan
    if fan is not None:  # a fan has one origin: each puff's offset and distance once, not once per pair
        offset = np.subtract(puffs.centers.T, origins[0][:, None], order="C")  # (3, P): a row per axis
        beam, puff = fan_pairs(fan, offset, reach_of_puff, far)
        distance_sq = dot_rows(offset, offset).take(puff)
        along = dot_columns(offset, puff, fan.directions_by_axis, beam)
    else:
        near = (~far).nonzero()[0]
        beam, puff = _block_pairs(origins, directions, beam_end_m, puffs.centers.take(near, axis=0), reach_of_puff.take(near))
        puff = near.take(puff)
        offset = (puffs.centers.take(puff, axis=0) - origins.take(beam, axis=0)).T
        distance_sq = dot_rows(offset, offset)
        along = dot_rows(offset, directions.take(beam, axis=0).T)
    return crossings_of_candidates(puffs, reach_of_puff, beam_end_m, beam, puff, along, distance_sq, row_offset)


def crossings_of_candidates(
    puffs: Puffs, reach_of_puff: np.ndarray, beam_end_m: np.ndarray, beam: np.ndarray, puff: np.ndarray,
    along: np.ndarray, distance_sq: np.ndarray, row_offset: np.ndarray | None = None,
) -> BeamPuffCrossings:
    """`cross_beams`' exact tests on candidate (beam, puff) pairs, given each pair's puff centre's distance
    along the beam and squared distance from its origin; the pairs kept keep their order."""
    reach = reach_of_puff.take(puff)
    before_end = along < beam_end_m.take(beam) + reach  # the test that culls: first, on every candidate
    if not before_end.all():  # often every candidate does (a plume in front of the solids): nothing to take
        before_end = before_end.nonzero()[0]
        beam, puff, along, distance_sq, reach = beam.take(before_end), puff.take(before_end), along.take(before_end), distance_sq.take(before_end), reach.take(before_end)
    reach_sq = reach * reach
    miss_sq = np.maximum(distance_sq - along * along, 0.0)
    ahead = (along > 0) | (distance_sq < reach_sq)  # a puff behind the origin and out of reach adds < 0.2 %
    near = (miss_sq < reach_sq) & ahead  # a fan's angular reach nearly implies both; all pairs need them
    if not near.all():
        near = near.nonzero()[0]
        beam, puff, along, miss_sq = beam.take(near), puff.take(near), along.take(near), miss_sq.take(near)
    sigma = puffs.sigma.take(puff)
    central_column = puffs.peak_density * _SQRT_2PI * puffs.sigma  # per puff, then per pair: the same products
    column = central_column.take(puff) * np.exp(-miss_sq / (2.0 * puffs.sigma * puffs.sigma).take(puff))
    if row_offset is not None:
        beam = beam + row_offset.take(puff)
    return BeamPuffCrossings(beam, along, sigma, column, normal_cdf(-along / sigma))


_SQRT_2PI = np.sqrt(2.0 * np.pi)


def _no_crossings() -> BeamPuffCrossings:
    empty = np.zeros(0)
    return BeamPuffCrossings(np.zeros(0, dtype=np.int64), empty, empty, empty, empty)


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
    ends = origins + directions * beam_end_m[:, None]
    if n_beams <= BEAMS_PER_BLOCK or not np.isfinite(ends).all():
        return _all_pairs(n_beams, n_puffs)
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
