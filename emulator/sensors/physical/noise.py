"""Deterministic randomness of the `physical` model: density fluctuations and range noise.

Every draw derives from (scene seed, sensor name) and, for per-scan noise,
the scan time, so a scan is reproducible from the scene alone.
"""

from __future__ import annotations

import functools
import zlib
from typing import Sequence

import numpy as np

from emulator.optics.kept import KEPT_VALUES, KeptPerArrays
from emulator.scene.plumes import splitmix64
from emulator.sensors.physical.params import (
    LMS_SIGMA_M,
    LMS_SYSTEMATIC_M,
    PhysicalParams,
    urg_noise_sigma_m,
)

_FLUCTUATION_STREAM = 0xF1
_NOISE_STREAM = 0x4E
_BIAS_STREAM = 0xB1


def _sensor_key(seed: int, sensor: str) -> list[int]:
    return [seed % 2**63, zlib.crc32(sensor.encode())]


def scan_rng(seed: int, sensor: str, time_s: float) -> np.random.Generator:
    """The generator for one scan's noise: a pure function of (seed, sensor, scan time in µs)."""
    return np.random.default_rng(_sensor_key(seed, sensor) + [_NOISE_STREAM, int(round(time_s * 1e6)) % 2**63])


def fluctuation_field(seed: int, sensor: str, angles_rad: np.ndarray, times_s: Sequence[float], params: PhysicalParams) -> np.ndarray:
    """A smooth field in (beam angle, time) with zero median and unit variance, (K, N) at K times.

    A sum of random travelling cosines (random wavenumbers, frequencies and
    phases fixed per seed and sensor): correlated over about
    `fluctuation_angle_deg` and `fluctuation_time_s`, so neighbouring beams and consecutive scans flicker
    together.
    """
    wavenumber, frequency, phase = _fluctuation_modes(
        seed, sensor, params.fluctuation_modes, params.fluctuation_angle_deg, params.fluctuation_time_s
    )
    # cos(k a + w t + p) = cos(k a) cos(w t + p) - sin(k a) sin(w t + p): the angle part is fixed per sensor
    along_angle = _FIELD_ANGLES.get((angles_rad, wavenumber), params.fluctuation_modes, lambda: _angle_modes(angles_rad, wavenumber))
    in_time = frequency * np.asarray(times_s, dtype=float)[:, None] + phase
    in_time = np.concatenate([np.cos(in_time), np.sin(in_time)], axis=1)
    return np.stack([along_angle @ row for row in in_time])  # one product per instant: a matrix product rounds differently


def _angle_modes(angles_rad: np.ndarray, wavenumber: np.ndarray) -> np.ndarray:
    """sqrt(2 / modes) × [cos(k a), -sin(k a)] (N, 2 modes): the field's angle part, kept per sensor."""
    argument = np.outer(angles_rad, wavenumber)
    return _read_only(np.sqrt(2.0 / len(wavenumber)) * np.concatenate([np.cos(argument), -np.sin(argument)], axis=1))


@functools.lru_cache(maxsize=KEPT_VALUES)  # one per sensor of a fleet: its wavenumbers key `_FIELD_ANGLES`
def _fluctuation_modes(seed: int, sensor: str, modes: int, angle_deg: float, time_s: float) -> tuple[np.ndarray, ...]:
    """The field's random wavenumbers, frequencies and phases: fixed per seed and sensor, so drawn once."""
    rng = np.random.default_rng(_sensor_key(seed, sensor) + [_FLUCTUATION_STREAM])
    wavenumber = rng.normal(0.0, 1.0 / np.radians(angle_deg), modes)
    frequency = rng.normal(0.0, 2.0 * np.pi / time_s, modes)
    phase = rng.uniform(0.0, 2.0 * np.pi, modes)
    for array in (wavenumber, frequency, phase):
        array.flags.writeable = False
    return wavenumber, frequency, phase


def edge_strength(column: np.ndarray, angles_rad: np.ndarray, smoke_distance_m: np.ndarray, length_m: float) -> np.ndarray:
    """How much a beam lies on a smoke edge, 0..1: the column's relative lateral gradient × length_m.

    The gradient is taken between neighbouring beams (lateral spacing =
    angle step × distance to the smoke), so homogeneous smoke gives 0 and a
    plume's flank close to 1. Arrays are (N,) or (K, N): K instants of the same beams.
    """
    if column.shape[-1] < 3:
        return np.zeros(column.shape)
    padded = np.concatenate([column[..., :1], column, column[..., -1:]], axis=-1)
    spacing = _BEAM_SPACINGS.get((angles_rad,), None, lambda: _beam_spacing_rad(angles_rad)) * np.maximum(smoke_distance_m, 0.1)
    with np.errstate(divide="ignore", invalid="ignore"):
        relative = np.abs(padded[..., 2:] - padded[..., :-2]) / (spacing * column)
    strength = relative * length_m
    strength[np.isnan(strength)] = 0.0  # no smoke on either side
    return np.minimum(np.maximum(strength, 0.0), 1.0)  # +inf (smoke only on one side) → 1


_BEAM_SPACINGS = KeptPerArrays()
_FIELD_ANGLES = KeptPerArrays()


def _beam_spacing_rad(angles_rad: np.ndarray) -> np.ndarray:
    """Angle between each beam's two neighbours (the ends extrapolated); kept for a sensor's read-only angles."""
    angles = np.concatenate([angles_rad[:1] - (angles_rad[1] - angles_rad[0]), angles_rad, angles_rad[-1:] + (angles_rad[-1] - angles_rad[-2])])
    return _read_only(np.abs(angles[2:] - angles[:-2]))


def _read_only(array: np.ndarray) -> np.ndarray:
    """`array`, locked: kept values are shared by every later scan."""
    array.flags.writeable = False
    return array


def fluctuation_factor(
    seed: int,
    sensor: str,
    angles_rad: np.ndarray,
    times_s: Sequence[float],
    column: np.ndarray,
    smoke_distance_m: np.ndarray,
    params: PhysicalParams,
) -> np.ndarray:
    """Per beam and instant (K·N, stacked as `Instants`), the factor scaling all its smoke's density:
    exp(amplitude × field), median 1."""
    if not params.fluctuation:
        return np.ones(len(column))
    shape = (len(times_s), len(angles_rad))
    edges = edge_strength(column.reshape(shape), angles_rad, smoke_distance_m.reshape(shape), params.fluctuation_length_m)
    amplitude = params.fluctuation_bulk + params.fluctuation_edge * edges
    return np.exp(amplitude * fluctuation_field(seed, sensor, angles_rad, times_s, params)).ravel()


def scan_normals(seed: int, sensor: str, times_s: Sequence[float], per_scan: int) -> np.ndarray:
    """`per_scan` standard normal draws for each scan at `times_s`, stacked (K·per_scan,): each
    scan's from its own generator (`scan_rng`), so a scan draws the same alone or with others."""
    draws = [scan_rng(seed, sensor, time_s).standard_normal(per_scan) for time_s in times_s]
    return draws[0] if len(draws) == 1 else np.concatenate(draws)


def urg_range_noise_m(normal: np.ndarray, range_m: np.ndarray) -> np.ndarray:
    """Random clear-air error of the URG-04LX (datasheet accuracy read as a 2σ bound), from standard normal draws."""
    return normal * urg_noise_sigma_m(np.where(np.isfinite(range_m), range_m, 0.0))


def lms_range_error_m(normal: np.ndarray, seed: int, sensor: str, angles_rad: np.ndarray) -> np.ndarray:
    """LMS200 error at sensor-frame `angles_rad` (N,) for K scans' standard normal draws (K·N,):
    a fixed systematic offset per beam direction (uniform in ±15 mm) plus σ = 5 mm noise."""
    systematic = _SYSTEMATIC.get((angles_rad,), (seed, sensor), lambda: _lms_systematic_m(seed, sensor, np.degrees(angles_rad) + 90.0))
    return (systematic + normal.reshape(-1, len(angles_rad)) * LMS_SIGMA_M).ravel()


_SYSTEMATIC = KeptPerArrays()


def _lms_systematic_m(seed: int, sensor: str, device_angles_deg: np.ndarray) -> np.ndarray:
    """The fixed offset per device angle (quarter degrees), kept for a sensor's read-only angles."""
    quarter_degrees = np.rint(np.asarray(device_angles_deg) * 4.0).astype(np.int64).astype(np.uint64)
    key = np.uint64(zlib.crc32(sensor.encode()) ^ (seed % 2**32) << 32) ^ np.uint64(_BIAS_STREAM)
    with np.errstate(over="ignore"):
        bits = splitmix64(quarter_degrees ^ key)
    uniform = (bits >> np.uint64(11)).astype(np.float64) * 2.0**-53
    systematic = LMS_SYSTEMATIC_M * (2.0 * uniform - 1.0)
    systematic.flags.writeable = False
    return systematic
