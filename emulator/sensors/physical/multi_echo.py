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


def nearest_first(seen: np.ndarray, values: np.ndarray, intensities: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The echoes a unit sends, (..., E): those `seen` (in its range), nearest first, -1 after them (one out
    of range leaves no gap); `values` and `intensities` (..., E) int64 in the echo lists' order."""
    from emulator.sensors.physical import echo_kernels  # numba loads with the first `physical` scan

    shape = seen.shape
    packed = echo_kernels.packed_nearest_first(
        np.ascontiguousarray(seen).reshape(-1, shape[-1]),
        np.ascontiguousarray(values, dtype=np.int64).reshape(-1, shape[-1]),
        np.ascontiguousarray(intensities, dtype=np.int64).reshape(-1, shape[-1]),
    )
    return packed[0].reshape(shape), packed[1].reshape(shape)


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
    surfaces, smoke = physics.surfaces, physics.smoke
    smoke_ranges, smoke_powers = smoke_returns(smoke, receiver, threshold, fog_filter)
    smoke_of = np.full(len(surfaces.amp), -1, dtype=np.intp)  # each row's row of the smoke's returns
    smoke_of[smoke.rows] = np.arange(len(smoke.rows))
    lists = _selected(surfaces.range_m, surfaces.amp, smoke_of, smoke_ranges, smoke_powers, threshold, receiver, fog_filter)
    if params.noise and receiver.range_sigma_m > 0:
        per_scan = instants.beam_count * receiver.max_echoes
        normals = scan_normals(scene.seed, instants.beams.sensor.name, instants.times_s, per_scan).reshape(lists.ranges_m.shape)
        lists = EchoLists(lists.ranges_m + normals * receiver.range_sigma_m, lists.powers, lists.count)
    shape = (instants.count, instants.beam_count, receiver.max_echoes)
    return EchoLists(lists.ranges_m.reshape(shape), lists.powers.reshape(shape), lists.count.reshape(shape[:2]))


def _near_level(threshold: float, receiver: PulsedReceiver, fog_filter: bool) -> tuple[float, float]:
    """The weakest echo seen: the threshold, raised near the unit when its fog filter is on; as
    (the range below which it is raised, the raised level)."""
    if not fog_filter or receiver.fog_filter_m <= 0:
        return -np.inf, threshold
    return receiver.fog_filter_m, threshold * receiver.fog_filter_gain


def smoke_returns(smoke: SmokeEchoes, receiver: PulsedReceiver, threshold: float, fog_filter: bool = False
                  ) -> tuple[np.ndarray, np.ndarray]:
    """The smoke's returns of the beams `smoke.rows`, (R, J) ranges (inf where none) and powers (0).

    The signal at range u is the backscatter of the last pulse length, [u - separation_m, u]
    (as a surface at R is seen from R on). It is sampled at the grid points and one pulse length past
    each (so a homogeneous stretch's strongest window, the one starting where the smoke starts, is
    among them); each run of samples at or above the detection level is a return, placed where the
    signal first reaches it (linear between samples) with the run's strongest sample as its power.
    """
    from emulator.sensors.physical import echo_kernels  # numba loads with the first `physical` scan

    near_m, near_threshold = _near_level(threshold, receiver, fog_filter)
    # only rows whose densest bin holds the threshold within a pulse length can return anything (the
    # cumulative is linear within bins)
    return echo_kernels.smoke_runs(
        smoke.amp, smoke.edges_m, smoke.fractions, receiver.separation_m, threshold, near_m, near_threshold
    )


def select_echoes(ranges_m: np.ndarray, powers: np.ndarray, threshold: float, receiver: PulsedReceiver,
                  *, fog_filter: bool = False) -> EchoLists:
    """The echo lists (N, E) of N beams' candidate returns (N, C) in any order (absent ones: range inf,
    power 0): returns closer than `separation_m` merge, those below the detection level are dropped,
    and of the rest a unit keeping E echoes reports the first E it receives (the nearest)."""
    no_smoke = np.full(len(ranges_m), -1, dtype=np.intp)
    return _selected(ranges_m, powers, no_smoke, np.zeros((0, 0)), np.zeros((0, 0)), threshold, receiver, fog_filter)


def _selected(ranges_m: np.ndarray, powers: np.ndarray, smoke_of: np.ndarray, smoke_ranges_m: np.ndarray,
              smoke_powers: np.ndarray, threshold: float, receiver: PulsedReceiver, fog_filter: bool) -> EchoLists:
    """`select_echoes` of each row's candidates (N, C) followed by its row `smoke_of` (-1: none) of the
    smoke's returns (R, J), without building the (N, C + J) candidates."""
    from emulator.sensors.physical import echo_kernels  # numba loads with the first `physical` scan

    near_m, near_threshold = _near_level(threshold, receiver, fog_filter)
    return EchoLists(*echo_kernels.kept_echoes(
        np.ascontiguousarray(ranges_m, dtype=float), np.ascontiguousarray(powers, dtype=float), smoke_of,
        smoke_ranges_m, smoke_powers, receiver.separation_m, threshold, near_m, near_threshold, receiver.max_echoes,
    ))
