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

from emulator.optics.kept import KeptPerArrays
from emulator.sensors.physical.params import (
    SPEED_OF_LIGHT_M_S,
    LmsReceiver,
    PhysicalParams,
    ReceiverOptics,
    UrgReceiver,
)


def range_law(range_m: np.ndarray, receiver: ReceiverOptics, params: PhysicalParams) -> np.ndarray:
    """G(u): inverse-square spreading × transmitter/receiver overlap × gain ramp, 1 at the reference range."""
    overlap_m, gain_ramp_m = receiver.overlap_m, receiver.gain_ramp_m
    return _spreading(range_m, overlap_m, gain_ramp_m) / reference_spreading(params.reference_range_m, overlap_m, gain_ramp_m)


def _spreading(range_m: np.ndarray | float, overlap_m: float, gain_ramp_m: float) -> np.ndarray:
    u = np.asarray(range_m, dtype=float)
    spreading = u * u / (u * u + overlap_m**2) ** 2
    if gain_ramp_m > 0:
        spreading = spreading * np.minimum(u / gain_ramp_m, 1.0) ** 2
    return spreading


@functools.lru_cache(maxsize=16)
def reference_spreading(reference_range_m: float, overlap_m: float, gain_ramp_m: float) -> float:
    """The range law's normaliser: the same for every scan, so computed once."""
    return float(_spreading(reference_range_m, overlap_m, gain_ramp_m))


@functools.lru_cache(maxsize=64)
def log_threshold(receiver: ReceiverOptics, params: PhysicalParams, extinction_per_density: float) -> float:
    """ln of the weakest detectable echo (the same for every scan, so computed once).

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
    """Backscattered power per range bin (N, M) from two-way transmissions at the bin edges (N, M+1).
    The scans run it compiled, fused with the share (`echo_kernels.smoke_bin_powers`, tested equal)."""
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


def _crossing_on_grid(energy: np.ndarray, edges_m: np.ndarray, level: float) -> np.ndarray:
    """First distance where an energy (N, M+1) given at bin edges, linear in between, reaches `level` (inf if never)."""
    reached = energy >= level
    first = np.argmax(reached, axis=1)  # the first True, or 0 when there is none
    index = first + np.arange(0, energy.size, energy.shape[1])  # row-major flat positions (1-D take beats 2-D indexing)
    previous = np.where(first > 0, index - 1, index)
    low, high = energy.take(previous), energy.take(index)
    with np.errstate(divide="ignore", invalid="ignore"):
        fraction = np.fmin(np.fmax((level - low) / (high - low), 0.0), 1.0)  # fmax: NaN (high == low, only at index 0) → 0
    below = edges_m.take(previous)
    below += fraction * (edges_m.take(index) - below)
    return np.where(reached.take(index), below, np.inf)


@dataclass(frozen=True)
class _EdgeLookup:
    """Finds the bin of a fraction of a beam's extent with two table look-ups instead of a binary search.

    `cell_bin` gives the bin at the start of each of `cells` equal cells, each narrower than any bin,
    so a point's bin is that or the next one; `next_edge` and `inverse_width` are indexed by bin.
    """

    fractions: np.ndarray
    cells: int
    cell_bin: np.ndarray
    next_edge: np.ndarray
    inverse_width: np.ndarray

    @staticmethod
    def of(fractions: np.ndarray) -> _EdgeLookup:
        bins = len(fractions) - 1
        widths = np.diff(fractions)
        cells = int(np.ceil(2.0 / widths.min())) + 1
        cell_bin = np.minimum(np.searchsorted(fractions, np.arange(cells) / cells, side="right") - 1, bins - 1)
        next_edge = np.append(fractions[1:bins], np.inf)  # the last bin takes everything up to 1
        return _EdgeLookup(fractions, cells, cell_bin, next_edge, 1.0 / widths)

    def interpolate(self, values: np.ndarray, rows: np.ndarray, along: np.ndarray) -> np.ndarray:
        """`values` (N, M+1) at bin edges, linear within each bin, for `rows` (R,) at fractions `along` (R, K) in [0, 1]."""
        index = self.cell_bin.take((along * (self.cells * (1.0 - 1e-12))).astype(np.intp))
        index += along >= self.next_edge.take(index)
        fraction = along - self.fractions.take(index)
        fraction *= self.inverse_width.take(index)
        index += (rows * values.shape[1])[:, None]  # row-major flat positions
        flat = values.ravel()
        low = flat.take(index)
        high = flat.take(index + 1)
        high -= low
        high *= fraction
        high += low
        return high


_LOOKUPS = KeptPerArrays()


def _edge_lookup(edges_m: np.ndarray, fractions: np.ndarray | None) -> _EdgeLookup:
    """The look-up for `fractions` (kept when they are a read-only array), or for the fractions
    that every row's edges share, read off the widest row."""
    if fractions is not None:
        return _LOOKUPS.get((fractions,), None, lambda: _EdgeLookup.of(fractions))
    length = edges_m[:, -1] - edges_m[:, 0]
    widest = int(np.argmax(length)) if len(length) else 0
    if len(length) and length[widest] > 0:
        return _EdgeLookup.of((edges_m[widest] - edges_m[widest, 0]) / length[widest])
    return _EdgeLookup.of(np.linspace(0.0, 1.0, edges_m.shape[1]))


def _by_range(amp: np.ndarray, range_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each row's echoing targets (N, S) nearest first. Only rows with an echo past the first
    column need sorting: in the others the later columns hold no energy, wherever they lie."""
    several = np.flatnonzero(amp[:, 1:].any(axis=1))
    if len(several) == 0:
        return range_m, amp
    ranges, amps = range_m.copy(), amp.copy()
    order = np.argsort(np.where(amp[several] > 0, range_m[several], np.inf), axis=1)
    order += (several * amp.shape[1])[:, None]  # row-major flat positions
    ranges[several], amps[several] = range_m.ravel().take(order), amp.ravel().take(order)
    return ranges, amps


def lms_first_echo(
    target_amp: np.ndarray,
    target_range_m: np.ndarray,
    smoke_amp: np.ndarray,
    edges_m: np.ndarray,
    log_threshold_value: float,
    receiver: LmsReceiver,
    smoke_rows: np.ndarray | None = None,
    fractions: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The pulsed receiver: (range_m, from_smoke, clean) per beam; range inf = no echo (and `clean` then means nothing).

    The receiver integrates the echo energy over the last `window_m` of range
    (smoke bins, and the surfaces met so far) and stops at the first distance
    where it reaches the threshold. The echo is clean when `sharp_fraction`
    of the threshold arrived within the last `max_rise_m`. `smoke_amp` and
    `edges_m` hold the beams `smoke_rows` (default: all); the others have no
    smoke. Every row's edges lie at the same `fractions` of its extent
    (default: read off the edges).
    """
    threshold = float(np.exp(log_threshold_value))
    smoke_rows = np.arange(len(target_amp)) if smoke_rows is None else smoke_rows
    bins, window = smoke_amp.shape[1], receiver.window_m
    cumulative = np.zeros((len(smoke_amp), bins + 1))
    np.cumsum(smoke_amp, axis=1, out=cumulative[:, 1:])
    total = cumulative[:, bins]  # bins hold no negative energy, so the cumulative never falls: this bounds every window
    holding = np.flatnonzero(total > 0)  # every other row's windows hold exactly 0
    lookup = _edge_lookup(edges_m, fractions)
    start, length = edges_m[:, 0], edges_m[:, bins] - edges_m[:, 0]

    def energy_at(rows: np.ndarray, points_m: np.ndarray, starts: np.ndarray, scales: np.ndarray) -> np.ndarray:
        """Cumulative smoke energy of `rows` at points (R, K), given each row's start and 1 / length (R, 1);
        inf points take the whole smoke."""
        along = points_m - starts
        along *= scales
        np.maximum(along, 0.0, out=along)
        np.minimum(along, 1.0, out=along)
        return lookup.interpolate(cumulative, rows, along)

    holding_start, holding_scale = start.take(holding)[:, None], 1.0 / length.take(holding)[:, None]

    def smoke_window(points_m: np.ndarray) -> np.ndarray:
        """Smoke energy of the rows `holding` within the window ending at each point (H, K)."""
        at = energy_at(holding, np.concatenate([points_m, points_m - window], axis=1), holding_start, holding_scale)
        return at[:, : points_m.shape[1]] - at[:, points_m.shape[1] :]

    ranges, amps = _by_range(target_amp, target_range_m)
    targets = ranges.shape[1]
    beams = smoke_rows.take(holding)

    smoke_at = np.full(len(ranges), np.inf)
    # only these rows' windows can reach the threshold (to within a few ulps of the window sums)
    reachable = np.flatnonzero(total >= threshold * (1.0 - 1e-9))
    if len(reachable):
        # at a bin edge the cumulative is exact; the window's far end lies before the smoke (adding 0)
        # unless the smoke is longer than the window
        at_edges = cumulative.take(reachable, axis=0)
        reachable_edges = edges_m.take(reachable, axis=0)
        long = np.flatnonzero(length.take(reachable) > window)
        if len(long):
            long_rows = reachable.take(long)
            far_ends = energy_at(
                long_rows, reachable_edges.take(long, axis=0) - window, start.take(long_rows)[:, None], 1.0 / length.take(long_rows)[:, None]
            )
            long_edges = (long[:, None] * (bins + 1) + np.arange(bins + 1)).ravel()
            at_edges.ravel()[long_edges] -= far_ends.ravel()
        smoke_at[smoke_rows.take(reachable)] = _crossing_on_grid(at_edges, reachable_edges, threshold)

    # one interpolation for the smoky rows' windows at every surface and before every candidate echo
    # (each surface and the smoke's own), whichever the receiver then stops at
    energy_at_target = np.cumsum(amps, axis=1)
    rise = receiver.max_rise_m
    if len(holding):
        smoke_ranges = ranges.take(beams, axis=0)
        smoke_echo = smoke_at.take(beams)[:, None]
        windows = smoke_window(np.concatenate([smoke_ranges, smoke_ranges - rise, np.where(np.isfinite(smoke_echo), smoke_echo - rise, 0.0)], axis=1))
        beam_targets = (beams[:, None] * targets + np.arange(targets)).ravel()  # 1-D: cheaper than 2-D row indexing
        energy_at_target.ravel()[beam_targets] += windows[:, :targets].ravel()
    reached = (energy_at_target >= threshold) & (amps > 0)
    first_target = np.argmax(reached, axis=1)
    first_position = first_target + np.arange(0, reached.size, targets)  # row-major flat positions
    target_at = np.where(reached.take(first_position), ranges.take(first_position), np.inf)
    from_smoke = smoke_at < target_at
    echo_m = np.minimum(smoke_at, target_at)
    energy_at_echo = np.where(from_smoke, threshold, energy_at_target.take(first_position))
    before = echo_m - rise
    targets_before = ((ranges <= before[:, None]) * amps).sum(axis=1)  # absent targets (range inf) have amp 0
    gained = energy_at_echo - targets_before
    if len(holding):
        # the window before the echo: the smoke's own column, or that of the surface that stopped the receiver
        candidate = np.where(from_smoke.take(beams), 2 * targets, targets + first_target.take(beams))
        gained[beams] -= windows.take(candidate + np.arange(0, windows.size, windows.shape[1]))
    clean = gained >= receiver.sharp_fraction * threshold
    return echo_m, from_smoke, clean
