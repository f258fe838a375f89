"""The first particle box each beam enters, with exact slab tests only on the boxes that can come first.

A dense plume puts hundreds of candidate boxes on a beam (railway with
10 000 particles: ~360 on each beam that meets the plume), and the
`formsma2011` preset needs only the nearest. A box lies inside its bounding
sphere, so a beam cannot enter it before `along - radius` (the sphere
centre's distance along the beam minus the sphere's radius). Pass 1 tests
each beam's nearest candidates exactly (bounds within FRONT_DEPTH_M of the
beam's nearest bound); the first entry it finds bounds the rest, and pass 2
tests only candidates whose bound does not lie past it. A candidate dropped
can neither be a beam's first box nor tie with it, and the ones kept are
reduced in their original order, so the ranges and densities are those of
testing every candidate (a tie goes to the last listed, as it always did).
"""

from __future__ import annotations

from typing import Callable

import numpy as np

FRONT_DEPTH_M = 0.2  # pass 1: candidates starting within this of each beam's nearest one (speed only, never the result)
BOUND_MARGIN_M = 1e-6  # far above the rounding of `along - radius` and of an entry; keeps every candidate that could tie

Intervals = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]  # candidate positions → their boxes' entry and exit


def first_boxes(
    beam: np.ndarray,
    box: np.ndarray,
    lower_bound_m: np.ndarray,
    intervals: Intervals,
    beam_end_m: np.ndarray,
    box_density: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Entry distance (inf if none) and density of the first box before each beam's end, from candidate
    pairs (`beam`, `box`) with `lower_bound_m` below any entry of the pair; `intervals` runs the exact test."""
    first_range = np.full(len(beam_end_m), np.inf)
    first_density = np.zeros(len(beam_end_m))
    if len(beam) == 0:
        return first_range, first_density
    nearest = np.full(len(beam_end_m), np.inf)
    np.minimum.at(nearest, beam, lower_bound_m)
    front = lower_bound_m <= nearest.take(beam) + FRONT_DEPTH_M
    front_pairs = front.nonzero()[0]
    entry = np.full(len(beam), np.inf)  # per candidate: its entry where its box is met, inf elsewhere
    entry[front_pairs] = _met_entries(front_pairs, beam, intervals, beam_end_m)
    bound = np.full(len(beam_end_m), np.inf)
    np.minimum.at(bound, beam.take(front_pairs), entry.take(front_pairs))
    rest = ~front
    rest &= lower_bound_m <= bound.take(beam) + BOUND_MARGIN_M
    rest_pairs = rest.nonzero()[0]
    entry[rest_pairs] = _met_entries(rest_pairs, beam, intervals, beam_end_m)
    met = np.isfinite(entry).nonzero()[0]  # the candidates met, in their original order
    beam, box, entry = beam.take(met), box.take(met), entry.take(met)
    np.minimum.at(first_range, beam, entry)
    first = entry == first_range.take(beam)  # each beam's first box (of a tie, the last listed)
    first_density[beam[first]] = box_density.take(box[first])
    return first_range, first_density


def _met_entries(pairs: np.ndarray, beam: np.ndarray, intervals: Intervals, beam_end_m: np.ndarray) -> np.ndarray:
    """Entry (clipped to the origin) of each of the candidates `pairs` whose box its beam meets before
    its end; inf for the others."""
    if len(pairs) == 0:
        return np.zeros(0)
    entry, exit_ = intervals(pairs)
    entry = np.maximum(entry, 0.0)
    met = (exit_ >= entry) & (entry < beam_end_m.take(beam.take(pairs)))
    return np.where(met, entry, np.inf)
