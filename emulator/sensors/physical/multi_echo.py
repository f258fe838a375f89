"""Multi-echo pulsed receivers: every return of a beam above the unit's threshold, nearest first.

The multi-echo Hokuyos (UTM-30LX-EW, UST-10LX/20LX) and SICKs (LMS1xx, LMS5xx;
the TiMs and the UTM-30LX with one echo) time each return of their laser
pulse. From the `physical` model's beam physics (`beams.beam_physics_at`: the
surfaces in each beam's footprint, the smoke's backscatter on a range grid),
a beam's returns are

- each surface sub-ray of the footprint (two surfaces in one footprint: a
  mixed pixel gives two returns), with its echo power and range;
- the smoke: the signal at range u is the backscatter of the last pulse
  length before it, [u - `separation_m`, u]; each stretch of the beam where
  that reaches the threshold is one return, placed where it first does, with
  the stretch's strongest signal as its power.

Returns closer than `separation_m` merge into one echo (powers add, the range
is their power-weighted mean). Echoes weaker than the threshold — raised by
`fog_filter_gain` nearer than `fog_filter_m` when the fog filter is on — are
not seen. A unit keeping E echoes reports the first E it receives, the
nearest: the first echo is the nearest return, the last the farthest kept.
Powers are in reference units (white paper at 2.5 m in clear air = 1);
`intensities` puts them on the unit's scale.

Every function works on whole arrays: beams × candidates, and a batch of
instants stacked as `beams.Instants` rows (`echo_lists_at`, as the preset's
`*_values_at`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from emulator.optics import BeamHits
from emulator.sensors.physical.beams import (
    PUFFS_PER_PASS,
    Instants,
    SmokeEchoes,
    beam_physics_at,
    instant_passes,
)
from emulator.sensors.physical.echo import log_threshold
from emulator.sensors.physical.noise import scan_normals
from emulator.sensors.physical.params import DEFAULT_PARAMS, PhysicalParams, PulsedReceiver
from emulator.sensors.response import Beams

FIRST, LAST = "first", "last"


@dataclass(frozen=True)
class EchoLists:
    """Each beam's echoes nearest first, (..., E): ranges in metres (NaN past a beam's `count`),
    powers in reference units (0 past `count`); `count` (...,) how many each beam has."""

    ranges_m: np.ndarray
    powers: np.ndarray
    count: np.ndarray

    @property
    def max_echoes(self) -> int:
        return self.ranges_m.shape[-1]

    def echo(self, which: str) -> tuple[np.ndarray, np.ndarray]:
        """(range_m, power) of each beam's `FIRST` or `LAST` echo; NaN / 0 for a beam without one."""
        if which == FIRST:
            return self.ranges_m[..., 0], self.powers[..., 0]
        if which != LAST:
            raise ValueError(f"which echo: {FIRST!r} or {LAST!r}, not {which!r}")
        index = np.maximum(self.count - 1, 0)[..., None]
        return np.take_along_axis(self.ranges_m, index, -1)[..., 0], np.take_along_axis(self.powers, index, -1)[..., 0]

    def intensities(self, receiver: PulsedReceiver) -> np.ndarray:
        """The powers on the unit's intensity scale (int64, saturating at `intensity_max`; 0 past `count`)."""
        return intensity_of(self.powers, receiver)


def intensity_of(powers: np.ndarray, receiver: PulsedReceiver) -> np.ndarray:
    """Received power (reference units) → the unit's intensity: linear, saturating at `intensity_max`."""
    return np.minimum(np.rint(powers * receiver.intensity_reference), receiver.intensity_max).astype(np.int64)


def dynamic_range(receiver: PulsedReceiver, params: PhysicalParams = DEFAULT_PARAMS, extinction_per_density: float = 250.0) -> float:
    """The reference target's echo over the faintest detected one (the threshold's inverse)."""
    return float(np.exp(-log_threshold(receiver, params, extinction_per_density)))


def echo_lists(hits: BeamHits, beams: Beams, receiver: PulsedReceiver, params: PhysicalParams = DEFAULT_PARAMS,
               *, fog_filter: bool = False) -> EchoLists:
    """One scan's echo lists, (N, E) with E = `receiver.max_echoes`."""
    lists = echo_lists_at((hits,), (beams,), receiver, params, fog_filter=fog_filter)
    return EchoLists(lists.ranges_m[0], lists.powers[0], lists.count[0])


def echo_lists_at(hits: Sequence[BeamHits], beams: Sequence[Beams], receiver: PulsedReceiver,
                  params: PhysicalParams = DEFAULT_PARAMS, *, fog_filter: bool = False) -> EchoLists:
    """The echo lists of the same sensor's beams at K instants, (K, N, E), computed together (a dense
    plume's batch a few instants at a time, as the preset's); each instant's equal to computing it alone.
    With `params.noise`, each echo's range gets the unit's clear-air noise (seeded by scene, sensor, time)."""
    passes = instant_passes(beams, PUFFS_PER_PASS)
    if len(passes) > 1:
        parts = [echo_lists_at(hits[part], beams[part], receiver, params, fog_filter=fog_filter) for part in passes]
        return EchoLists(*(np.concatenate([getattr(p, name) for p in parts]) for name in ("ranges_m", "powers", "count")))
    instants = Instants.of(hits, beams)
    scene = instants.beams.scene
    threshold = float(np.exp(log_threshold(receiver, params, scene.density_to_extinction)))
    physics = beam_physics_at(instants, receiver, params)
    surfaces = physics.surfaces
    smoke_ranges, smoke_powers = smoke_returns(physics.smoke, receiver, threshold, fog_filter)
    rows = len(surfaces.amp)
    ranges = np.where(surfaces.amp > 0, surfaces.range_m, np.inf)
    powers = surfaces.amp
    if smoke_ranges.shape[1]:
        extra_ranges = np.full((rows, smoke_ranges.shape[1]), np.inf)
        extra_powers = np.zeros((rows, smoke_ranges.shape[1]))
        extra_ranges[physics.smoke.rows], extra_powers[physics.smoke.rows] = smoke_ranges, smoke_powers
        ranges, powers = np.concatenate([ranges, extra_ranges], axis=1), np.concatenate([powers, extra_powers], axis=1)
    lists = select_echoes(ranges, powers, threshold, receiver, fog_filter=fog_filter)
    if params.noise and receiver.range_sigma_m > 0:
        per_scan = instants.beam_count * receiver.max_echoes
        normals = scan_normals(scene.seed, instants.beams.sensor.name, instants.times_s, per_scan).reshape(lists.ranges_m.shape)
        lists = EchoLists(lists.ranges_m + normals * receiver.range_sigma_m, lists.powers, lists.count)
    shape = (instants.count, instants.beam_count, receiver.max_echoes)
    return EchoLists(lists.ranges_m.reshape(shape), lists.powers.reshape(shape), lists.count.reshape(shape[:2]))


def detection_level(ranges_m: np.ndarray, threshold: float, receiver: PulsedReceiver, fog_filter: bool) -> np.ndarray | float:
    """The weakest echo seen at each range: the threshold, raised near the unit when its fog filter is on."""
    if not fog_filter or receiver.fog_filter_m <= 0:
        return threshold
    return np.where(ranges_m < receiver.fog_filter_m, threshold * receiver.fog_filter_gain, threshold)


def smoke_returns(smoke: SmokeEchoes, receiver: PulsedReceiver, threshold: float, fog_filter: bool = False
                  ) -> tuple[np.ndarray, np.ndarray]:
    """The smoke's returns of the beams `smoke.rows`, (R, J) ranges (inf where none) and powers (0).

    The signal at range u is the backscatter of the last pulse length, [u - separation_m, u]
    (as a surface at R is seen from R on). It is sampled at the grid points and one pulse length past
    each (so a homogeneous stretch's strongest window, the one starting where the smoke starts, is
    among them); each run of samples at or above the detection level is a return, placed where the
    signal first reaches it (linear between samples) with the run's strongest sample as its power.
    """
    rows = len(smoke.amp)
    # a pulse length holds at most the densest bin's energy per metre times its length (the cumulative is
    # linear within bins): only rows where that reaches the threshold can return anything
    densest = (smoke.amp / np.diff(smoke.edges_m, axis=1)).max(axis=1, initial=0.0)
    strong = np.flatnonzero(densest * receiver.separation_m >= threshold * (1.0 - 1e-9))
    if len(strong) == 0:
        return np.full((rows, 0), np.inf), np.zeros((rows, 0))
    ranges, powers = _strong_smoke_returns(smoke.amp[strong], smoke.edges_m[strong], smoke.fractions, receiver, threshold, fog_filter)
    all_ranges, all_powers = np.full((rows, ranges.shape[1]), np.inf), np.zeros((rows, ranges.shape[1]))
    all_ranges[strong], all_powers[strong] = ranges, powers
    return all_ranges, all_powers


def _strong_smoke_returns(amp: np.ndarray, edges_m: np.ndarray, fractions: np.ndarray, receiver: PulsedReceiver,
                          threshold: float, fog_filter: bool) -> tuple[np.ndarray, np.ndarray]:
    """`smoke_returns` of rows whose smoke may hold the threshold within a pulse length."""
    rows, edges = edges_m.shape
    cumulative = np.zeros((rows, edges))
    np.cumsum(amp, axis=1, out=cumulative[:, 1:])
    length = edges_m[:, -1:] - edges_m[:, :1]
    reach = receiver.separation_m / length
    at = _cumulative_at(cumulative, fractions, np.concatenate([fractions - reach, fractions + reach], axis=1))
    at[:, :edges] -= cumulative
    at[:, edges:] -= cumulative
    at[:, :edges] *= -1.0  # the windows ending at the grid points, then those ending a pulse length on
    points = np.concatenate([edges_m, edges_m + receiver.separation_m], axis=1)
    order = np.argsort(points, axis=1, kind="stable")
    order += (np.arange(rows) * (2 * edges))[:, None]  # row-major flat positions: `take` beats 2-D indexing
    points = points.take(order)
    signal = at.take(order)
    level = detection_level(points, threshold, receiver, fog_filter)
    above = signal >= level
    starts = above.copy()
    starts[:, 1:] &= ~above[:, :-1]
    run = np.cumsum(starts, axis=1)  # 1 + each sample's return while above
    most = int(run[:, -1].max())
    if most == 0:
        return np.full((rows, 0), np.inf), np.zeros((rows, 0))
    run[~above] = 0
    powers = np.stack([np.where(run == j + 1, signal, 0.0).max(axis=1) for j in range(most)], axis=1)  # J returns, J small
    ranges = np.full(rows * most, np.inf)
    ranges[(np.arange(rows)[:, None] * most + run - 1)[starts]] = _crossings(signal, level, points, starts)
    return ranges.reshape(rows, most), powers


def _cumulative_at(cumulative: np.ndarray, fractions: np.ndarray, along: np.ndarray) -> np.ndarray:
    """The cumulative energy (R, M+1), given at the shared `fractions` of each row's extent and linear
    between them, at fractions `along` (R, P) (clipped to the extent)."""
    along = np.clip(along, 0.0, 1.0)
    bins = len(fractions) - 1
    index = np.minimum(np.searchsorted(fractions, along, side="right") - 1, bins - 1)
    part = (along - fractions.take(index)) / (fractions.take(index + 1) - fractions.take(index))
    index += (np.arange(len(cumulative)) * cumulative.shape[1])[:, None]
    low = cumulative.take(index)
    high = cumulative.take(index + 1)
    high -= low
    high *= part
    high += low
    return high


def _crossings(signal: np.ndarray, level: np.ndarray | float, points_m: np.ndarray, starts: np.ndarray) -> np.ndarray:
    """Where the signal first reaches the level at each run start (row-major order of `starts`):
    linear between the sample before and the start; a run starting at the first sample starts there."""
    row, column = np.nonzero(starts)
    before = np.maximum(column - 1, 0)
    low, high = signal[row, before], signal[row, column]
    level_here = level[row, column] if isinstance(level, np.ndarray) else level
    with np.errstate(divide="ignore", invalid="ignore"):
        part = np.where(column > 0, np.clip((level_here - low) / (high - low), 0.0, 1.0), 0.0)
    return points_m[row, before] + part * (points_m[row, column] - points_m[row, before])


def select_echoes(ranges_m: np.ndarray, powers: np.ndarray, threshold: float, receiver: PulsedReceiver,
                  *, fog_filter: bool = False) -> EchoLists:
    """The echo lists (N, E) of N beams' candidate returns (N, C) in any order (absent ones: range inf,
    power 0): returns closer than `separation_m` merge, those below the detection level are dropped,
    and of the rest a unit keeping E echoes reports the first E it receives (the nearest)."""
    n, candidates = ranges_m.shape
    present = powers > 0
    several = np.flatnonzero(np.count_nonzero(present, axis=1) > 1)  # most beams have one return: nothing to sort
    merged = np.full((n, candidates), np.inf)
    power = np.zeros((n, candidates))
    only = np.argmax(present, axis=1) + np.arange(0, n * candidates, candidates)
    merged[:, 0] = np.where(present.ravel().take(only), ranges_m.ravel().take(only), np.inf)
    power[:, 0] = np.where(present.ravel().take(only), powers.ravel().take(only), 0.0)
    if len(several):
        merged[several], power[several] = _merged(ranges_m[several], np.where(present[several], powers[several], 0.0), receiver.separation_m)
    seen = (power > 0) & (power >= detection_level(merged, threshold, receiver, fog_filter))
    return _kept(merged, power, seen, receiver.max_echoes)


def _merged(ranges_m: np.ndarray, powers: np.ndarray, separation_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Rows' returns (R, C) sorted by range and merged where closer than `separation_m`: (range, power)
    of each merged echo nearest first, then inf / 0. A lone return keeps its own range exactly."""
    n, candidates = ranges_m.shape
    positions = np.argsort(np.where(powers > 0, ranges_m, np.inf), axis=1, kind="stable")
    positions += np.arange(0, n * candidates, candidates)[:, None]
    amps = powers.take(positions)
    present = amps > 0
    ranges = np.where(present, ranges_m.take(positions), np.inf)
    new_group = np.ones((n, candidates), dtype=bool)
    with np.errstate(invalid="ignore"):
        new_group[:, 1:] = ~(ranges[:, 1:] - ranges[:, :-1] < separation_m)
    flat = (np.cumsum(new_group, axis=1) - 1 + np.arange(0, n * candidates, candidates)[:, None]).ravel()
    size = n * candidates
    power = np.bincount(flat, weights=amps.ravel(), minlength=size)
    moment = np.bincount(flat, weights=(amps * np.where(present, ranges, 0.0)).ravel(), minlength=size)
    members = np.bincount(flat, weights=present.ravel(), minlength=size)
    first_range = np.full(size, np.inf)
    first_range[flat[new_group.ravel()]] = ranges[new_group]
    with np.errstate(divide="ignore", invalid="ignore"):
        merged = np.where(members > 1, moment / power, first_range)
    return merged.reshape(n, candidates), power.reshape(n, candidates)


def _kept(ranges: np.ndarray, powers: np.ndarray, seen: np.ndarray, max_echoes: int) -> EchoLists:
    """Pack each row's seen echoes (in range order) into E slots: the first E received, the nearest."""
    n = len(ranges)
    rank = np.cumsum(seen, axis=1) - 1
    kept = seen & (rank < max_echoes)
    out_ranges, out_powers = np.full((n, max_echoes), np.nan), np.zeros((n, max_echoes))
    target = (np.arange(n)[:, None] * max_echoes + rank)[kept]
    out_ranges.ravel()[target] = ranges[kept]
    out_powers.ravel()[target] = powers[kept]
    return EchoLists(out_ranges, out_powers, np.minimum(seen.sum(axis=1), max_echoes))
