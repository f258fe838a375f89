"""`BeamHits`: what each beam of a cast met, as arrays (one entry per beam)."""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from typing import Callable

import numpy as np


@dataclass(frozen=True)
class RegionCrossing:
    """Where the beams run inside one smoke region.

    `entry_m` and `exit_m` are (N, K): K intervals per beam, clipped to
    [0, max_range_m]; a missing interval has entry = exit = inf. A beam whose
    origin is inside the region enters at 0. Intervals are not cut at the
    solid hit, so a model may look past it; `density` is the region's density
    at the cast's time.
    """

    region_index: int
    density: float
    entry_m: np.ndarray
    exit_m: np.ndarray

    def length_before(self, limit_m: np.ndarray) -> np.ndarray:
        """Chord length (N,) inside the region between the origin and `limit_m` (N,)."""
        limit = limit_m[:, None]
        inside = np.minimum(self.exit_m, limit) - np.minimum(self.entry_m, limit)
        return inside.sum(axis=1)


@dataclass(frozen=True)
class PreparedBeams:
    """Beams (N, 3) and what they meet of the scene's fixed geometry (`World.prepare`).

    Solids as in `BeamHits`; `region_intervals` holds each region's (entry,
    exit) as in `RegionCrossing`, `region_lengths` each region's chord length
    before the beam's end (N,). Objects and region shapes never move, so a
    sensor prepares its beams once and casts them at any time.
    """

    origins: np.ndarray
    directions: np.ndarray
    max_range_m: float
    solid_range_m: np.ndarray
    object_index: np.ndarray
    reflectivity: np.ndarray
    cos_incidence: np.ndarray
    region_intervals: tuple[tuple[np.ndarray, np.ndarray], ...]
    region_lengths: tuple[np.ndarray, ...]
    beam_end_m: np.ndarray  # as BeamHits.beam_end_m
    with_moving_solids: bool = False  # the moving bodies' solids are already in (`World.with_moving_solids`)

    def rows(self, start: int, stop: int) -> PreparedBeams:
        """Beams start..stop-1 (views): one scan's share of several scans prepared together."""
        part = slice(start, stop)
        return PreparedBeams(
            self.origins[part], self.directions[part], self.max_range_m, self.solid_range_m[part], self.object_index[part],
            self.reflectivity[part], self.cos_incidence[part],
            tuple((entry[part], exit_[part]) for entry, exit_ in self.region_intervals),
            tuple(length[part] for length in self.region_lengths), self.beam_end_m[part], self.with_moving_solids,
        )


@dataclass(frozen=True)
class BeamHits:
    """Per-beam physics of one cast at `time_s`, arrays of length N.

    solid_range_m: distance to the first solid surface, inf if none within
        max_range_m; object_index: its object (index into scene.objects), -1 if
        none; reflectivity: its material's reflectivity (0 if none);
        cos_incidence: |cos| of the angle between beam and surface normal (0 if none).
    beam_end_m: where each beam stops: the solid hit, or max_range_m when
        nothing solid is in reach.
    region_optical_path: ∫ density ds over all smoke regions from the origin
        up to the solid hit, or to max_range_m when there is none (d·m);
        overlapping regions add. `regions` holds each region's intervals.
    plume_hit_range_m: entry distance into the first plume particle box met
        before the solid hit and within max_range_m (0 when the origin is in a
        box), inf if none; plume_hit_density: that particle's density (0 if none).
        Both come from `first_particle`, called on first use only.
    """

    time_s: float
    max_range_m: float
    solid_range_m: np.ndarray
    object_index: np.ndarray
    reflectivity: np.ndarray
    cos_incidence: np.ndarray
    beam_end_m: np.ndarray
    region_optical_path: np.ndarray
    regions: tuple[RegionCrossing, ...]
    first_particle: Callable[[], tuple[np.ndarray, np.ndarray]] = field(repr=False, compare=False)

    def __len__(self) -> int:
        return len(self.solid_range_m)

    @cached_property
    def _first_particle_hits(self) -> tuple[np.ndarray, np.ndarray]:
        return self.first_particle()

    @property
    def plume_hit_range_m(self) -> np.ndarray:
        return self._first_particle_hits[0]

    @property
    def plume_hit_density(self) -> np.ndarray:
        return self._first_particle_hits[1]
