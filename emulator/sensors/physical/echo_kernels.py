"""Compiled per-beam walks of the `physical` model: the smoke bins' backscattered power (`beams`), and
for the multi-echo receiver (`multi_echo`) the smoke's returns along each beam's range grid, the
merging and keeping of each beam's returns, and the packing of the echoes a unit sends.

Each beam's walk is a short sequential scan (a cumulative sum, a merge of two sorted sample lists,
runs above a level, a sort of a handful of candidates). In numpy every step is a pass over
(beams × samples) temporaries with gathers and sorts; compiled, it is one pass per beam
(docs/performance.md gives the figures). The arithmetic is the numpy formulation's, operation for
operation, so the values are the same to the last bit.

Compiled on first use and cached on disk (`cache=True`): a fresh process with a warm cache loads them
in well under a second; the first process after an install compiles them (seconds: docs/performance.md).
"""

from __future__ import annotations

import numpy as np
from numba import njit

# error_model="numpy": a division by zero gives inf / NaN as numpy does, instead of raising
_COMPILE = {"cache": True, "nogil": True, "error_model": "numpy"}


@njit(**_COMPILE)
def _is_strong(amp: np.ndarray, edges_m: np.ndarray, r: int, separation_m: float, threshold: float) -> bool:
    """Whether row `r`'s densest bin holds the threshold within a pulse length (no other row returns anything:
    the cumulative is linear within bins)."""
    densest = 0.0  # numpy's max(..., initial=0.0): a NaN anywhere makes the maximum NaN
    for i in range(amp.shape[1]):
        density = amp[r, i] / (edges_m[r, i + 1] - edges_m[r, i])
        if density != density or densest != densest:
            densest = np.nan
        elif density > densest:
            densest = density
    return densest * separation_m >= threshold * (1.0 - 1e-9)


@njit(**_COMPILE)
def _windows(cumulative: np.ndarray, fractions: np.ndarray, reach: float, ending: np.ndarray, past: np.ndarray) -> None:
    """The energy of the pulse length ending at each edge (`ending`) and ending `reach` (a fraction of the
    extent) past it (`past`): the cumulative (M+1,), given at `fractions` and linear between, at each
    edge ± reach clipped to the extent. The points rise with the edge, so each one's bin (numpy's
    `searchsorted(..., side="right") - 1`, at most the last bin) is found by walking on from the last."""
    edges = len(fractions)
    bins = edges - 1
    below = 0
    beyond = 0
    for j in range(edges):
        along = min(max(fractions[j] - reach, 0.0), 1.0)
        while below < bins and fractions[below + 1] <= along:
            below += 1
        index = min(below, bins - 1)
        part = (along - fractions[index]) / (fractions[index + 1] - fractions[index])
        low = cumulative[index]
        ending[j] = -(((cumulative[index + 1] - low) * part + low) - cumulative[j])
        along = min(max(fractions[j] + reach, 0.0), 1.0)
        while beyond < bins and fractions[beyond + 1] <= along:
            beyond += 1
        index = min(beyond, bins - 1)
        part = (along - fractions[index]) / (fractions[index + 1] - fractions[index])
        low = cumulative[index]
        past[j] = ((cumulative[index + 1] - low) * part + low) - cumulative[j]


@njit(**_COMPILE)
def smoke_runs(
    amp: np.ndarray,
    edges_m: np.ndarray,
    fractions: np.ndarray,
    separation_m: float,
    threshold: float,
    near_m: float,
    near_threshold: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Each row's smoke returns: ranges (R, J) inf past its last, powers (R, J) 0 past it; J = the most of a row.

    The signal (backscatter of the last pulse length) is sampled at the grid's edges and a pulse length
    past each, in range order (ties: the edge first); each run of samples at or above the level
    (`near_threshold` nearer than `near_m`, else `threshold`) is a return placed where the signal first
    reaches the level (linear between samples), with the run's strongest sample as its power.
    """
    rows, edges = edges_m.shape
    samples = 2 * edges
    # each row's returns in turn (a row's runs alternate with gaps between its 2 (M+1) samples: at most M+1)
    found_ranges = np.empty(rows * edges)
    found_powers = np.empty(rows * edges)
    first = np.zeros(rows + 1, dtype=np.intp)
    found = 0
    cumulative = np.empty(edges)
    ending = np.empty(edges)  # the window ending at each edge
    past = np.empty(edges)  # the window ending a pulse length past each edge
    points = np.empty(samples)  # both in range order
    signals = np.empty(samples)
    most = 0
    lowest = min(threshold, near_threshold)
    for r in range(rows):
        first[r] = found
        if not _is_strong(amp, edges_m, r, separation_m, threshold):
            continue
        cumulative[0] = 0.0
        for i in range(edges - 1):
            cumulative[i + 1] = cumulative[i] + amp[r, i]
        _windows(cumulative, fractions, separation_m / (edges_m[r, edges - 1] - edges_m[r, 0]), ending, past)
        if max(ending.max(), past.max()) < lowest:
            continue  # no sample reaches the level: no return
        # the samples in range order, ties the edge first (numpy's stable sort of the edges, then the points past them)
        later = 0
        for j in range(edges):
            while later < edges and edges_m[r, later] + separation_m < edges_m[r, j]:
                later += 1
            points[j + later] = edges_m[r, j]
            signals[j + later] = ending[j]
        earlier = 0
        for j in range(edges):
            point = edges_m[r, j] + separation_m
            while earlier < edges and edges_m[r, earlier] <= point:
                earlier += 1
            points[j + earlier] = point
            signals[j + earlier] = past[j]
        strongest = 0.0
        was_above = False
        for k in range(samples):
            signal = signals[k]
            level = near_threshold if points[k] < near_m else threshold
            above = signal >= level
            if above and not was_above:
                if found > first[r]:
                    found_powers[found - 1] = strongest
                strongest = signal
                if k == 0:
                    found_ranges[found] = points[0] + 0.0 * (points[0] - points[0])
                else:
                    part = min(max((level - signals[k - 1]) / (signal - signals[k - 1]), 0.0), 1.0)
                    found_ranges[found] = points[k - 1] + part * (points[k] - points[k - 1])
                found += 1
            elif above and signal > strongest:
                strongest = signal
            was_above = above
        if found > first[r]:
            found_powers[found - 1] = strongest
            most = max(most, found - first[r])
    first[rows] = found
    ranges = np.full((rows, most), np.inf)
    powers = np.zeros((rows, most))
    for r in range(rows):
        for j in range(first[r + 1] - first[r]):
            ranges[r, j] = found_ranges[first[r] + j]
            powers[r, j] = found_powers[first[r] + j]
    return ranges, powers


@njit(**_COMPILE)
def kept_echoes(
    ranges_m: np.ndarray,
    powers: np.ndarray,
    smoke_of: np.ndarray,
    smoke_ranges_m: np.ndarray,
    smoke_powers: np.ndarray,
    separation_m: float,
    threshold: float,
    near_m: float,
    near_threshold: float,
    max_echoes: int,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The echo lists of rows' candidate returns in any order (absent: power 0): each row's (N, S) and,
    for a row r with `smoke_of[r]` ≥ 0, that row of the smoke's (R, J), after them. Sorted by range,
    merged where closer than `separation_m` (powers add, range their power-weighted mean; a lone return
    keeps its own range), those below the level dropped, the first `max_echoes` kept.
    Returns ranges (N, E) NaN past each row's count, powers (N, E) 0 past it, count (N,)."""
    n, own = ranges_m.shape
    candidates = own + smoke_ranges_m.shape[1]
    row_ranges = np.empty(candidates)
    row_powers = np.empty(candidates)
    out_ranges = np.full((n, max_echoes), np.nan)
    out_powers = np.zeros((n, max_echoes))
    count = np.zeros(n, dtype=np.int64)
    order = np.empty(candidates, dtype=np.intp)
    keys = np.empty(candidates)
    merged = np.empty(candidates)
    power = np.empty(candidates)
    for r in range(n):
        smoke = smoke_of[r]
        for c in range(candidates):
            if c < own:
                row_ranges[c] = ranges_m[r, c]
                row_powers[c] = powers[r, c]
            elif smoke >= 0:
                row_ranges[c] = smoke_ranges_m[smoke, c - own]
                row_powers[c] = smoke_powers[smoke, c - own]
            else:
                row_ranges[c] = np.inf
                row_powers[c] = 0.0
        present = 0
        only = 0
        for c in range(candidates):
            if row_powers[c] > 0:
                if present == 0:
                    only = c
                present += 1
        groups = 1
        if present <= 1:
            merged[0] = row_ranges[only] if present else np.inf
            power[0] = row_powers[only] if present else 0.0
        else:
            for c in range(candidates):  # a stable insertion sort by range, absent returns last
                key = row_ranges[c] if row_powers[c] > 0 else np.inf
                k = c
                while k > 0 and keys[k - 1] > key:
                    keys[k] = keys[k - 1]
                    order[k] = order[k - 1]
                    k -= 1
                keys[k] = key
                order[k] = c
            groups = 0
            members = 0
            moment = 0.0
            last = 0.0
            for k in range(candidates):
                amp = row_powers[order[k]]
                here = amp > 0
                amp = amp if here else 0.0
                range_here = row_ranges[order[k]] if here else np.inf
                if k == 0 or not (range_here - last < separation_m):
                    if groups and members > 1:
                        merged[groups - 1] = moment / power[groups - 1]
                    groups += 1
                    merged[groups - 1] = range_here
                    power[groups - 1] = 0.0
                    members = 0
                    moment = 0.0
                power[groups - 1] += amp
                moment += amp * (range_here if here else 0.0)
                members += 1 if here else 0
                last = range_here
            if members > 1:
                merged[groups - 1] = moment / power[groups - 1]
        seen = 0
        for g in range(groups):
            level = near_threshold if merged[g] < near_m else threshold
            if power[g] > 0 and power[g] >= level:
                if seen < max_echoes:
                    out_ranges[r, seen] = merged[g]
                    out_powers[r, seen] = power[g]
                seen += 1
        count[r] = min(seen, max_echoes)
    return out_ranges, out_powers, count


@njit(**_COMPILE)
def smoke_bin_powers(
    path: np.ndarray,
    transmission: np.ndarray,
    low_m: np.ndarray,
    length_m: np.ndarray,
    scattering_per_path: np.ndarray,
    middles: np.ndarray,
    share_gain: float,
    overlap_squared: float,
    gain_ramp_m: float,
    reference_spreading: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Each smoke bin's backscattered power and its middle's range, (R, M), from the optical path and
    two-way transmission at the bin edges (R, M+1), as `beams._smoke_echoes` and `echo.smoke_bin_echo`
    define them: the share (1 + mean extinction³ · `scattering_per_path` per bin) × `share_gain`, half
    the power extinguished in the bin, the range law at its middle."""
    rows, edges = path.shape
    bins = edges - 1
    powers = np.empty((rows, bins))
    mid_m = np.empty((rows, bins))
    for r in range(rows):
        per_length = 1.0 / length_m[r]
        for i in range(bins):
            scattering = (path[r, i + 1] - path[r, i]) * scattering_per_path[i] * per_length
            share = (scattering * scattering * scattering + 1.0) * share_gain
            u = low_m[r] + length_m[r] * middles[i]
            mid_m[r, i] = u
            spreading = u * u
            spreading /= (spreading + overlap_squared) * (spreading + overlap_squared)
            if gain_ramp_m > 0:
                ramp = min(u / gain_ramp_m, 1.0)
                spreading *= ramp * ramp
            powers[r, i] = 0.5 * share * (transmission[r, i] - transmission[r, i + 1]) * (spreading / reference_spreading)
    return powers, mid_m


@njit(**_COMPILE)
def packed_nearest_first(seen: np.ndarray, values: np.ndarray, intensities: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each row's (N, E) seen echoes moved to the front in their order, -1 after them (values and intensities)."""
    rows, echoes = seen.shape
    packed_values = np.full((rows, echoes), -1, dtype=np.int64)
    packed_intensities = np.full((rows, echoes), -1, dtype=np.int64)
    for r in range(rows):
        kept = 0
        for e in range(echoes):
            if seen[r, e]:
                packed_values[r, kept] = values[r, e]
                packed_intensities[r, kept] = intensities[r, e]
                kept += 1
    return packed_values, packed_intensities
