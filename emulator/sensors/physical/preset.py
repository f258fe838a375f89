"""Preset `physical`: one echo-power mechanism behind every smoke behaviour (docs/smoke-model.md §5).

Extinction σ = density_to_extinction × density attenuates each echo twice
(Beer–Lambert); a surface's echo ∝ reflectivity · cos^n / R² · T must reach a
threshold derived from the paper (white paper at 2.5 m fails at exactly
0.007 d·m); smoke backscatters and competes with the surface echo; density
fluctuations and datasheet noise make it flicker. The two receivers differ:

- URG-04LX (AMCW phase): all returns blend into one phase; the range is
  their power-weighted mean (pulled toward the sensor by smoke). Codes:
  1 too weak (0 when nothing solid is in reach and the smoke alone would not
  extinguish the reference target), 8 when the blend decoheres (two-wave
  intensity mismatch), 19 below 20 mm, 0 beyond 5600 mm.
- LMS200 (pulsed, first echo): the first distance where the integrated echo
  energy reaches its threshold; a dense plume front triggers it (smoke seen as
  an obstacle); a smeared rise at a plume edge gives 8187 (signal-to-noise
  too small); no echo 8191; beyond the unit's maximum 8183.

See docs/physical-model.md for every parameter and the validation figures.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from emulator.optics import BeamHits
from emulator.sensors import lms200, urg04lx
from emulator.sensors.physical.beams import (
    BeamPhysics,
    Instants,
    SmokeEchoes,
    PUFFS_PER_PASS,
    beam_physics_at,
    instant_passes,
)
from emulator.sensors.physical.echo import (
    lms_first_echo,
    log_threshold,
    smoke_return,
    urg_decision,
)
from emulator.sensors.physical.noise import (
    lms_range_error_m,
    scan_normals,
    urg_range_noise_m,
)
from emulator.sensors.physical.params import (
    DEFAULT_PARAMS,
    PhysicalParams,
    ReceiverOptics,
)
from emulator.sensors.response import Beams

URG_INCOHERENT = 8  # SCIP: intensity of the two waves do not match
URG_MAX_VALUE_MM = int(round(urg04lx.MAX_RANGE_M * 1000.0))
LMS_SIGNAL_TO_NOISE = 8187  # LMS2xx: signal-to-noise ratio too small


def urg_values(hits: BeamHits, beams: Beams, params: PhysicalParams = DEFAULT_PARAMS) -> np.ndarray:
    return urg_values_at((hits,), (beams,), params)[0]


def urg_values_at(hits: Sequence[BeamHits], beams: Sequence[Beams], params: PhysicalParams = DEFAULT_PARAMS) -> np.ndarray:
    """URG values (K, N) of the same beams at K instants, computed in one pass (or a few: `_passes`)."""
    passes = _passes(beams)
    if len(passes) > 1:
        return np.concatenate([urg_values_at(hits[part], beams[part], params) for part in passes])
    receiver = params.urg
    instants, physics, threshold = _physics(hits, beams, receiver, params)
    surfaces, smoke = physics.surfaces, physics.smoke
    smoke_echo = smoke_return(smoke.rows, smoke.amp, smoke.mid_m, len(surfaces.amp), receiver)
    detected, coherent, range_m = urg_decision(surfaces.log_echo, surfaces.amp, surfaces.range_m, smoke_echo, threshold, receiver)
    if params.noise:
        range_m = range_m + urg_range_noise_m(_scan_normals(instants), range_m)
    millimetres = np.rint(np.where(detected, range_m, 0.0) * 1000.0).astype(np.int64)
    values = np.where(millimetres < urg04lx.MIN_VALUE_MM, urg04lx.NON_MEASURABLE, millimetres)
    values = np.where(millimetres > URG_MAX_VALUE_MM, urg04lx.NO_ECHO, values)  # stretched or noisy past DMAX
    values = np.where(coherent, values, URG_INCOHERENT)
    has_surface = surfaces.present.any(axis=1)
    smoke_extinguishes = physics.optical_path_to_end > params.penetration_power
    weak = np.where(has_surface | smoke_extinguishes, urg04lx.LOW_INTENSITY, urg04lx.NO_ECHO)
    return np.where(detected, values, weak).reshape(instants.count, -1)


def lms_values(
    hits: BeamHits, beams: Beams, unit: str, params: PhysicalParams = DEFAULT_PARAMS, *, field_bits: int = 13
) -> np.ndarray:
    return lms_values_at((hits,), (beams,), unit, params, field_bits=field_bits)[0]


def lms_values_at(
    hits: Sequence[BeamHits], beams: Sequence[Beams], unit: str, params: PhysicalParams = DEFAULT_PARAMS,
    *, field_bits: int = 13,
) -> np.ndarray:
    """LMS200 values (K, N) of the same beams at K instants, computed in one pass (or a few: `_passes`);
    distances and error codes in a `field_bits` wide field (the measuring mode's range)."""
    passes = _passes(beams)
    if len(passes) > 1:
        return np.concatenate([lms_values_at(hits[part], beams[part], unit, params, field_bits=field_bits) for part in passes])
    receiver = params.lms
    instants, physics, threshold = _physics(hits, beams, receiver, params)
    surfaces, smoke = physics.surfaces, physics.smoke
    echo_m, clean = _lms_echo(surfaces.amp, surfaces.range_m, smoke, threshold, params)
    seen = np.isfinite(echo_m)
    if params.noise:
        scene, sensor = instants.beams.scene, instants.beams.sensor
        echo_m = echo_m + lms_range_error_m(_scan_normals(instants), scene.seed, sensor.name, instants.beams.angles_rad)
    counts = np.rint(np.where(seen, np.maximum(echo_m, 0.0), 0.0) * lms200.UNITS_PER_M[unit]).astype(np.int64)
    above_maximum = lms200.field_code(lms200.ABOVE_MAXIMUM, field_bits)
    values = np.where(counts >= above_maximum, above_maximum, counts)
    values = np.where(clean, values, lms200.field_code(LMS_SIGNAL_TO_NOISE, field_bits))
    return np.where(seen, values, lms200.field_code(lms200.NO_ECHO, field_bits)).reshape(instants.count, -1)


def _passes(beams: Sequence[Beams]) -> list[slice]:
    """The instants computed together (`instant_passes`, at most PUFFS_PER_PASS puffs a pass)."""
    return instant_passes(beams, PUFFS_PER_PASS)


def _physics(
    hits: Sequence[BeamHits], beams: Sequence[Beams], receiver: ReceiverOptics, params: PhysicalParams
) -> tuple[Instants, BeamPhysics, float]:
    """The instants, their beams' physics as `receiver` sees it, and its ln detection threshold."""
    instants = Instants.of(hits, beams)
    threshold = log_threshold(receiver, params, instants.beams.scene.density_to_extinction)
    return instants, beam_physics_at(instants, receiver, params), threshold


def _scan_normals(instants: Instants) -> np.ndarray:
    """Each scan's standard normal draws, one per beam, stacked as the instants' rows."""
    beams = instants.beams
    return scan_normals(beams.scene.seed, beams.sensor.name, instants.times_s, instants.beam_count)


def _lms_echo(
    target_amp: np.ndarray, target_range_m: np.ndarray, smoke: SmokeEchoes, threshold: float, params: PhysicalParams
) -> tuple[np.ndarray, np.ndarray]:
    """First echo of every beam; only the beams `smoke.rows` have a range grid."""
    echo_m, _, clean = lms_first_echo(target_amp, target_range_m, smoke.amp, smoke.edges_m, threshold, params.lms, smoke.rows, smoke.fractions)
    return echo_m, clean
