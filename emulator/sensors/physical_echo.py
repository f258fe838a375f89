"""Echo powers and the two receivers' decisions, on numpy arrays (pure math).

All powers are relative to the reference target (white paper, 2.5 m, normal
incidence) in clear air. A solid surface returns

    a = (rho / rho_ref) · cos_factor · G(R) · exp(-2 k OP(R))

where k = density_to_extinction and G is the range law normalised to 1 at
the reference range. A smoke slab [u, u + du] returns
beta · k·d(u) · exp(-2 k OP(u)) · G(u) du; integrated over a bin this is exact
in the extinction: beta/2 · (exp(-2k OP_a) - exp(-2k OP_b)) · G(mid).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from emulator.sensors.physical_params import SPEED_OF_LIGHT_M_S, LmsReceiver, PhysicalParams, ReceiverOptics, UrgReceiver


def range_law(range_m: np.ndarray, receiver: ReceiverOptics, params: PhysicalParams) -> np.ndarray:
    """G(u): inverse-square spreading × transmitter/receiver overlap × gain ramp, 1 at the reference range."""
    overlap_m, gain_ramp_m = receiver.overlap_m, receiver.gain_ramp_m
    return _spreading(range_m, overlap_m, gain_ramp_m) / _reference_spreading(params.reference_range_m, overlap_m, gain_ramp_m)


def _spreading(range_m: np.ndarray | float, overlap_m: float, gain_ramp_m: float) -> np.ndarray:
    u = np.asarray(range_m, dtype=float)
    spreading = u * u / (u * u + overlap_m**2) ** 2
    if gain_ramp_m > 0:
        spreading = spreading * np.minimum(u / gain_ramp_m, 1.0) ** 2
    return spreading


@functools.lru_cache(maxsize=16)
def _reference_spreading(reference_range_m: float, overlap_m: float, gain_ramp_m: float) -> float:
    """The range law's normaliser: the same for every scan, so computed once."""
    return float(_spreading(reference_range_m, overlap_m, gain_ramp_m))


def log_threshold(receiver: ReceiverOptics, params: PhysicalParams, extinction_per_density: float) -> float:
    """ln of the weakest detectable echo.

    "reference": the reference target seen through exactly the penetration
    power, exp(-2 k P) — derived from the paper, not tuned. A (reflectivity,
    range) pair: that target in clear air (a datasheet's range at a given
    remission).
    """
    if receiver.detection == "reference":
        return -2.0 * extinction_per_density * params.penetration_power
    reflectivity, range_m = receiver.detection
    return float(np.log(reflectivity / params.reference_reflectivity) + np.log(range_law(range_m, receiver, params)))


def log_target_echo(
    reflectivity: np.ndarray,
    cos_factor: np.ndarray,
    range_m: np.ndarray,
    optical_path: np.ndarray,
    extinction_per_density: float,
    receiver: ReceiverOptics,
    params: PhysicalParams,
) -> np.ndarray:
    """ln a per surface hit (-inf where there is no surface)."""
    clear_air = log_clear_air_echo(reflectivity, cos_factor, range_m, receiver, params)
    return np.where(echoing(reflectivity, cos_factor, range_m), clear_air - 2.0 * extinction_per_density * optical_path, -np.inf)


def log_clear_air_echo(
    reflectivity: np.ndarray, cos_factor: np.ndarray, range_m: np.ndarray, receiver: ReceiverOptics, params: PhysicalParams
) -> np.ndarray:
    """ln a of each surface hit without smoke (meaningful where `echoing`): fixed for a fixed surface."""
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.log(reflectivity / params.reference_reflectivity) + np.log(cos_factor) + np.log(range_law(range_m, receiver, params))


def echoing(reflectivity: np.ndarray, cos_factor: np.ndarray, range_m: np.ndarray) -> np.ndarray:
    """Surface hits that can return an echo at all."""
    return np.isfinite(range_m) & (reflectivity > 0) & (cos_factor > 0)


def smoke_bin_echo(
    transmission_edges: np.ndarray,
    backscatter_share: np.ndarray,
    mid_m: np.ndarray,
    receiver: ReceiverOptics,
    params: PhysicalParams,
) -> np.ndarray:
    """Backscattered power per range bin (N, M) from two-way transmissions at the bin edges (N, M+1)."""
    extinguished = transmission_edges[:, :-1] - transmission_edges[:, 1:]
    return 0.5 * backscatter_share * extinguished * range_law(mid_m, receiver, params)


@dataclass(frozen=True)
class SmokeReturn:
    """Per beam (N,): the smoke's total echo power, its power-weighted range sum and its phasor."""

    power: np.ndarray
    range_moment: np.ndarray
    phasor: np.ndarray


def modulation_wavenumber(receiver: UrgReceiver) -> float:
    """Phase per metre of range (out and back) at the modulation frequency."""
    return 4.0 * np.pi * receiver.modulation_hz / SPEED_OF_LIGHT_M_S


def smoke_return(rows: np.ndarray, amp: np.ndarray, mid_m: np.ndarray, n_beams: int, receiver: UrgReceiver) -> SmokeReturn:
    """Sum the smoke bins of `rows` as the AMCW receiver sees them."""
    power, moment, phasor = np.zeros(n_beams), np.zeros(n_beams), np.zeros(n_beams, dtype=complex)
    power[rows] = amp.sum(axis=1)
    moment[rows] = (amp * mid_m).sum(axis=1)
    phasor[rows] = (amp * np.exp(1j * modulation_wavenumber(receiver) * mid_m)).sum(axis=1)
    return SmokeReturn(power, moment, phasor)


def urg_decision(
    log_target: np.ndarray,
    target_amp: np.ndarray,
    target_range_m: np.ndarray,
    smoke: SmokeReturn,
    log_threshold_value: float,
    receiver: UrgReceiver,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The AMCW receiver: (detected, coherent, range_m) per beam.

    The phase sees the sum of all returns as phasors at the modulation
    wavenumber; the reported range is their power-weighted mean range, so
    smoke pulls it toward the sensor. `log_target` is ln of the surfaces'
    summed echo, compared in the log domain so that with no smoke return the
    decision is exactly 'two-way optical depth within the budget'.
    Surfaces are (N, S) arrays (S sub-rays).
    """
    target_total = target_amp.sum(axis=1)
    total = target_total + smoke.power
    detected = (log_target >= log_threshold_value) | ((smoke.power > 0) & (total >= np.exp(log_threshold_value)))
    target_range = np.where(target_amp > 0, target_range_m, 0.0)
    phasor = (target_amp * np.exp(1j * modulation_wavenumber(receiver) * target_range)).sum(axis=1) + smoke.phasor
    positive = np.where(total > 0, total, 1.0)
    coherence = np.where(total > 0, np.abs(phasor) / positive, 1.0)
    mean_range = ((target_amp * target_range).sum(axis=1) + smoke.range_moment) / positive
    single_target = (smoke.power == 0) & (np.count_nonzero(target_amp, axis=1) <= 1)
    mean_range = np.where(single_target, target_range.max(axis=1), mean_range)  # exact, no rounding through the mean
    coherent = single_target | (coherence >= receiver.min_coherence)
    return detected, coherent, mean_range


def _crossing_on_grid(cumulative: np.ndarray, edges_m: np.ndarray, level: float) -> np.ndarray:
    """First distance where a cumulative energy (N, M+1) at bin edges reaches `level` (inf if never)."""
    reached = cumulative >= level
    index = np.argmax(reached, axis=1)
    any_reached = reached.any(axis=1)
    rows = np.arange(len(cumulative))
    previous = np.maximum(index - 1, 0)
    low, high = cumulative[rows, previous], cumulative[rows, index]
    with np.errstate(divide="ignore", invalid="ignore"):
        fraction = np.where(high > low, (level - low) / (high - low), 1.0)
    at = edges_m[rows, previous] + np.minimum(np.maximum(fraction, 0.0), 1.0) * (edges_m[rows, index] - edges_m[rows, previous])
    return np.where(any_reached, np.where(index == 0, edges_m[:, 0], at), np.inf)


def _edge_fractions(edges_m: np.ndarray) -> np.ndarray:
    """The bin edges as fractions of a beam's extent, read off the widest beam.

    Every row's bin edges are the same fractions of its own extent (only the
    start and length differ), so one binary search on those fractions serves all rows.
    """
    length = edges_m[:, -1] - edges_m[:, 0]
    widest = int(np.argmax(length)) if len(length) else 0
    if len(length) and length[widest] > 0:
        return (edges_m[widest] - edges_m[widest, :1]) / length[widest : widest + 1]
    return np.linspace(0.0, 1.0, edges_m.shape[1])


def _cumulative_at(cumulative: np.ndarray, edges_m: np.ndarray, fractions: np.ndarray, points_m: np.ndarray) -> np.ndarray:
    """Cumulative smoke energy at `points_m` (N, S), linear within each bin (edges at `fractions` of each extent)."""
    start, stop = edges_m[:, :1], edges_m[:, -1:]
    length = stop - start
    bins = cumulative.shape[1] - 1
    along = (np.where(np.isfinite(points_m), points_m, stop) - start) / np.where(length > 0, length, 1.0)
    along = np.minimum(np.maximum(along, 0.0), 1.0)
    index = np.searchsorted(fractions, along, side="right") - 1
    index = np.minimum(np.maximum(index, 0), bins - 1)
    fraction = (along - fractions[index]) / (fractions[index + 1] - fractions[index])
    flat = index + (np.arange(len(cumulative)) * cumulative.shape[1])[:, None]  # row-major (N, bins + 1)
    values = cumulative.ravel()
    low, high = values[flat], values[flat + 1]
    return low + fraction * (high - low)


def lms_first_echo(
    target_amp: np.ndarray,
    target_range_m: np.ndarray,
    smoke_amp: np.ndarray,
    edges_m: np.ndarray,
    log_threshold_value: float,
    receiver: LmsReceiver,
    smoke_rows: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The pulsed receiver: (range_m, from_smoke, clean) per beam; range inf = no echo.

    The receiver integrates the echo energy over the last `window_m` of range
    (smoke bins, and the surfaces met so far) and stops at the first distance
    where it reaches the threshold. The echo is clean when `sharp_fraction`
    of the threshold arrived within the last `max_rise_m`. `smoke_amp` and
    `edges_m` hold the beams `smoke_rows` (default: all); the others have no smoke.
    """
    threshold = float(np.exp(log_threshold_value))
    smoke_rows = np.arange(len(target_amp)) if smoke_rows is None else smoke_rows
    cumulative = np.concatenate([np.zeros((len(smoke_amp), 1)), np.cumsum(smoke_amp, axis=1)], axis=1)

    span = cumulative.max(axis=1) - cumulative.min(axis=1)  # cumulative starts at 0: span 0 means no smoke energy
    holding = np.flatnonzero(span > 0)  # every other beam's windows hold exactly 0
    # a window holds at most the span (to within a few ulps): only these can trigger on smoke
    reachable = np.flatnonzero(span >= threshold * (1.0 - 1e-9))
    fractions = _edge_fractions(edges_m)

    def rows_window(rows: np.ndarray, points_m: np.ndarray) -> np.ndarray:
        """Smoke energy within the window ending at each point (R, K) of smoke `rows`: one interpolation for both ends."""
        at = _cumulative_at(cumulative[rows], edges_m[rows], fractions, np.concatenate([points_m, points_m - receiver.window_m], axis=1))
        return at[:, : points_m.shape[1]] - at[:, points_m.shape[1] :]

    def smoke_window(points_m: np.ndarray) -> np.ndarray:
        """The same for every beam's points (N, K)."""
        windows = np.zeros(points_m.shape)
        if len(holding):
            beams = smoke_rows[holding]
            windows[beams] = rows_window(holding, points_m[beams])
        return windows

    order = np.argsort(np.where(target_amp > 0, target_range_m, np.inf), axis=1)
    order += (np.arange(len(order)) * order.shape[1])[:, None]  # row-major flat positions
    ranges, amps = target_range_m.ravel()[order], target_amp.ravel()[order]
    smoke_at = np.full(len(ranges), np.inf)
    if len(reachable):
        smoke_at[smoke_rows[reachable]] = _crossing_on_grid(rows_window(reachable, edges_m[reachable]), edges_m[reachable], threshold)
    energy_at_target = smoke_window(ranges) + np.cumsum(amps, axis=1)
    reached = (energy_at_target >= threshold) & (amps > 0)
    rows = np.arange(len(ranges))
    first_target = np.argmax(reached, axis=1)
    target_at = np.where(reached.any(axis=1), ranges[rows, first_target], np.inf)
    from_smoke = smoke_at < target_at
    echo_m = np.minimum(smoke_at, target_at)
    energy_at_echo = np.where(from_smoke, threshold, energy_at_target[rows, first_target])
    before = echo_m[:, None] - receiver.max_rise_m
    with np.errstate(invalid="ignore"):
        targets_before = np.where(ranges <= before, amps, 0.0).sum(axis=1)
        gained = energy_at_echo - smoke_window(np.where(np.isfinite(before), before, 0.0))[:, 0] - targets_before
    clean = gained >= receiver.sharp_fraction * threshold
    return echo_m, from_smoke, clean
