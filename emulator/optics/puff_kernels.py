"""Compiled loops over (beam, puff) pairs: finding a fan's pairs and summing their Gaussian integrals.

Each pair's share of its puff's column up to a distance s along the beam is
column × (Phi((s − along)/sigma) − Phi(−along/sigma)), evaluated here with the
C library's erfc (exact to rounding) and summed per beam in the pairs' order,
so a beam's sums do not depend on which other beams or instants share the call.
Plain loops compiled by numba (cached on disk after the first process): numpy
would need a temporary per step over every pair, and the pairs of a dense plume
number in the hundreds of thousands per scan.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

SATURATED = 8.3  # |z| beyond this: Phi is 0 or 1 to within 1e-16
WINDOW = 6.0  # range bins: beyond this Phi is taken as 0 or 1
WINDOW_ERROR = 1e-9  # Phi(-WINDOW) = 9.9e-10: what that costs, per pair, in units of its column
_STEPS_PER_SIGMA = 64
_NODES = np.arange(-SATURATED, SATURATED + 2.0 / _STEPS_PER_SIGMA, 1.0 / _STEPS_PER_SIGMA)
# per node: Phi and its slope phi times the step, side by side (17 KB: stays in the first-level cache)
_TABLE = np.stack([
    0.5 * np.array([math.erfc(-z * math.sqrt(0.5)) for z in _NODES]),
    np.exp(-0.5 * _NODES * _NODES) / math.sqrt(2.0 * math.pi) / _STEPS_PER_SIGMA,
], axis=1)
CDF_ERROR = 1e-9  # cubic Hermite interpolation: at most step^4 / 384 x max |4th derivative of Phi| (< 1e-10), plus rounding


@njit(cache=True, error_model="numpy")
def _cdf(z: float) -> float:
    """Phi(z) by cubic Hermite interpolation between nodes 1/64 sigma apart holding Phi and its slope
    (|error| < CDF_ERROR): erfc itself costs several times more, and pairs × grid points call it
    millions of times a scan."""
    if z <= -SATURATED:
        return 0.0
    if z >= SATURATED:
        return 1.0
    position = (z + SATURATED) * _STEPS_PER_SIGMA
    index = int(position)
    t = position - index
    low, high = _TABLE[index, 0], _TABLE[index + 1, 0]
    slope_low, slope_high = _TABLE[index, 1], _TABLE[index + 1, 1]
    difference = high - low
    a = 3.0 * difference - 2.0 * slope_low - slope_high
    b = slope_low + slope_high - 2.0 * difference
    return low + t * (slope_low + t * (a + t * b))


@njit(cache=True, error_model="numpy")
def fan_crossings(
    offsets: np.ndarray, sigma: np.ndarray, central_column: np.ndarray, reach_sigmas: np.ndarray, row_offset: np.ndarray,
    axes: np.ndarray, beam_angle: np.ndarray, directions: np.ndarray, beam_end: np.ndarray, near_sigmas: float, kept_sigmas: float,
    rows: int,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The (beam, puff) pairs of a fan of beams from one origin: puff p's centre lies at `offsets[p]`
    from the origin; it pairs with every beam that passes within `reach_sigmas[p]` × sigma of its
    centre before the beam's end + that reach (and not wholly behind the origin). `axes` rows: the
    fan's normal, first and second in-plane axes; `beam_angle` ascending. Pairs come puff by puff,
    beams ascending; a pair's row is its beam + `row_offset[p]`. Returns row, along, sigma, column,
    Phi(−along/sigma) and whether the pair lies within `near_sigmas`, for the pairs within
    `kept_sigmas` only; then per row (`rows` of them) the summed share of its faint pairs (beyond `kept_sigmas`) from the origin
    to the beam's end, and that end: most pairs of a dense plume are faint, and what they add is
    needed only there (the range bins read the near pairs), so they are summed here, not kept."""
    count = len(sigma)
    n = len(beam_angle)
    low = np.zeros((count, 3), dtype=np.int64)
    high = np.zeros((count, 3), dtype=np.int64)
    total = 0
    for p in range(count):
        reach = reach_sigmas[p] * sigma[p]
        ox, oy, oz = offsets[p, 0], offsets[p, 1], offsets[p, 2]
        height = ox * axes[0, 0] + oy * axes[0, 1] + oz * axes[0, 2]
        if abs(height) >= reach:
            continue
        x = ox * axes[1, 0] + oy * axes[1, 1] + oz * axes[1, 2]
        y = ox * axes[2, 0] + oy * axes[2, 1] + oz * axes[2, 2]
        in_plane = math.sqrt(max(reach * reach - height * height, 0.0))
        distance = math.hypot(x, y)
        if distance <= in_plane:
            high[p, 1] = n
            total += n
            continue
        half = math.asin(in_plane / distance)
        centre = math.atan2(y, x)
        for turn in range(3):
            shift = (turn - 1) * 2.0 * math.pi
            if turn != 1 and not (beam_angle[0] <= centre + shift + half and centre + shift - half <= beam_angle[n - 1]):
                continue  # an interval one turn away meets no beam (the usual case): no search
            lo = np.searchsorted(beam_angle, centre + shift - half, side="left")
            hi = np.searchsorted(beam_angle, centre + shift + half, side="right")
            if hi > lo:
                low[p, turn], high[p, turn] = lo, hi
                total += hi - lo
    row = np.empty(total, dtype=np.int64)
    along_of = np.empty(total)
    sigma_of = np.empty(total)
    column_of = np.empty(total)
    before_of = np.empty(total)
    near_of = np.empty(total, dtype=np.bool_)
    pooled_column = np.zeros(rows)
    pooled_end = np.zeros(rows)
    kept = 0
    for p in range(count):
        s = sigma[p]
        reach = reach_sigmas[p] * s
        reach_sq = reach * reach
        near = near_sigmas * s
        near_sq = near * near
        close = kept_sigmas * s
        close_sq = close * close
        ox, oy, oz = offsets[p, 0], offsets[p, 1], offsets[p, 2]
        distance_sq = ox * ox + oy * oy + oz * oz
        inverse_two_var = 1.0 / (2.0 * s * s)
        for turn in range(3):
            for b in range(low[p, turn], high[p, turn]):
                along = ox * directions[b, 0] + oy * directions[b, 1] + oz * directions[b, 2]
                if along >= beam_end[b] + reach:
                    continue
                miss_sq = max(distance_sq - along * along, 0.0)
                if miss_sq >= reach_sq or not (along > 0.0 or distance_sq < reach_sq):
                    continue
                is_near = miss_sq < near_sq and along < beam_end[b] + near and (along > 0.0 or distance_sq < near_sq)
                column = central_column[p] * math.exp(-miss_sq * inverse_two_var)
                before = _cdf(-along / s) if along < SATURATED * s else 0.0
                r = b + row_offset[p]
                if not (miss_sq < close_sq and along < beam_end[b] + close and (along > 0.0 or distance_sq < close_sq)):
                    to_end = (beam_end[b] - along) / s if beam_end[b] < 1e12 else SATURATED
                    pooled_column[r] += column * (_cdf(to_end) - before)
                    pooled_end[r] = beam_end[b]
                    continue
                row[kept] = r
                along_of[kept] = along
                sigma_of[kept] = s
                column_of[kept] = column
                before_of[kept] = before
                near_of[kept] = is_near
                kept += 1
    return row[:kept], along_of[:kept], sigma_of[:kept], column_of[:kept], before_of[:kept], near_of[:kept], pooled_column, pooled_end


@njit(cache=True, error_model="numpy")
def path_to(
    limits: np.ndarray, position: np.ndarray, row: np.ndarray, along: np.ndarray, sigma: np.ndarray, column: np.ndarray,
    before: np.ndarray, pooled_column: np.ndarray, pooled_end: np.ndarray,
) -> np.ndarray:
    """Optical path from each beam's origin to its `limits` (R, M) (inf or NaN: the whole way), for the
    rows whose `position[row]` ≥ 0 (their line in `limits`); a limit of 0 gives exactly 0. A row's
    pooled share (see fan_crossings) counts for its limits from its beam's end on. A later limit equal
    to the row's first is not summed again but copied (the same terms in the same order)."""
    count, width = limits.shape
    result = np.zeros((count, width))
    for q in range(len(row)):
        r = position[row[q]]
        if r < 0:
            continue
        a, inverse, c, b = along[q], 1.0 / sigma[q], column[q], before[q]
        for m in range(width):
            limit = limits[r, m]
            if limit == 0.0 or (m > 0 and limit == limits[r, 0]):
                continue
            z = (limit - a) * inverse if limit < 1e12 else SATURATED + 1.0  # inf and NaN: past every puff
            if z >= SATURATED:
                result[r, m] += c * (1.0 - b)
            elif z > -SATURATED:
                result[r, m] += c * (_cdf(z) - b)
    for i in range(min(len(position), len(pooled_column))):
        r = position[i]
        if r < 0 or pooled_column[i] == 0.0:
            continue
        for m in range(width):
            limit = limits[r, m]
            if limit != 0.0 and not limit < pooled_end[i]:  # NaN: the whole way
                result[r, m] += pooled_column[i]
    for r in range(count):
        for m in range(1, width):
            if limits[r, m] == limits[r, 0]:
                result[r, m] = result[r, 0]
    return result


@njit(cache=True, error_model="numpy")
def path_on_grid(
    start: np.ndarray, length: np.ndarray, fractions: np.ndarray, position: np.ndarray, row: np.ndarray, along: np.ndarray,
    sigma: np.ndarray, column: np.ndarray, before: np.ndarray,
) -> np.ndarray:
    """Optical path of the pairs to start + length × fractions (R, F) of the rows whose
    `position[row]` ≥ 0; `fractions` ascend. Past a puff's window each later point gains its whole
    remaining column: added once, at the first such point, and carried along by a running sum."""
    count, width = len(start), len(fractions)
    inside = np.zeros((count, width))
    past = np.zeros((count, width + 1))
    for q in range(len(row)):
        r = position[row[q]]
        if r < 0:
            continue
        inverse = 1.0 / sigma[q]
        c, b = column[q], before[q]
        first = (start[r] - along[q]) * inverse
        step = length[r] * inverse
        for k in range(width):
            z = first + step * fractions[k]
            if z >= WINDOW:
                past[r, k] += c * (1.0 - b)
                break
            if z > -WINDOW:
                inside[r, k] += c * (_cdf(z) - b)
    for r in range(count):
        carried = 0.0
        for k in range(width):
            carried += past[r, k]
            inside[r, k] += carried
    return inside


@njit(cache=True, error_model="numpy")
def extent(count: int, row: np.ndarray, along: np.ndarray, sigma: np.ndarray, near: np.ndarray, reach_sigmas: float) -> tuple[np.ndarray, np.ndarray]:
    """Per row, where the near pairs' smoke starts and ends (`reach_sigmas` around their centres; inf / −inf if none)."""
    start = np.full(count, np.inf)
    end = np.full(count, -np.inf)
    for q in range(len(row)):
        if not near[q]:
            continue
        reach = reach_sigmas * sigma[q]
        r = row[q]
        start[r] = min(start[r], max(along[q] - reach, 0.0))
        end[r] = max(end[r], along[q] + reach)
    return start, end


@njit(cache=True, error_model="numpy")
def normal_cdf(z: np.ndarray) -> np.ndarray:
    """Standard normal CDF of every element (1-D), exact to rounding."""
    result = np.empty(len(z))
    for i in range(len(z)):
        result[i] = _cdf(z[i])
    return result
