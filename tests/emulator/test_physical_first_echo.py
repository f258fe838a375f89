"""The LMS first-echo search skips work (rows without smoke energy, rows whose smoke can never
reach the threshold); it must give exactly what the direct search over every row's whole grid gives."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from emulator.sensors.physical.beams import bin_fractions
from emulator.sensors.physical.echo import lms_first_echo, log_threshold
from emulator.sensors.physical.params import DEFAULT_PARAMS, LmsReceiver

K = 250.0


def _energy_at(cumulative: np.ndarray, edges: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Cumulative energy at `points` of one row, linear in each bin (np.interp, no shortcuts)."""
    return np.interp(np.where(np.isfinite(points), points, edges[-1]), edges, cumulative)


def _direct_first_echo(target_amp, target_range_m, smoke_amp, edges_m, threshold, receiver: LmsReceiver):
    """Row by row: window energy at every bin edge and surface, first crossing, sharpness."""
    echo, clean = np.full(len(target_amp), np.inf), np.ones(len(target_amp), dtype=bool)
    for row in range(len(target_amp)):
        cumulative = np.concatenate([[0.0], np.cumsum(smoke_amp[row])])
        edges = edges_m[row]

        def window(points: np.ndarray) -> np.ndarray:
            if not cumulative.any():
                return np.zeros(len(points))
            return _energy_at(cumulative, edges, points) - _energy_at(cumulative, edges, points - receiver.window_m)

        at_edges = window(edges)
        reached = np.flatnonzero(at_edges >= threshold)
        smoke_at = np.inf
        if len(reached):
            i = reached[0]
            if i == 0:
                smoke_at = edges[0]
            else:
                low, high = at_edges[i - 1], at_edges[i]
                smoke_at = edges[i - 1] + min(max((threshold - low) / (high - low), 0.0), 1.0) * (edges[i] - edges[i - 1])
        order = np.argsort(np.where(target_amp[row] > 0, target_range_m[row], np.inf))
        ranges, amps = target_range_m[row][order], target_amp[row][order]
        energy = window(ranges) + np.cumsum(amps)
        hit = np.flatnonzero((energy >= threshold) & (amps > 0))
        target_at = ranges[hit[0]] if len(hit) else np.inf
        echo[row] = min(smoke_at, target_at)
        if np.isfinite(echo[row]):
            at_echo = threshold if smoke_at < target_at else energy[hit[0]]
            before = echo[row] - receiver.max_rise_m
            gained = at_echo - window(np.array([before]))[0] - amps[ranges <= before].sum()
            clean[row] = gained >= receiver.sharp_fraction * threshold
    return echo, clean


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(1, 12))
def test_the_shortcut_search_equals_the_direct_search(seed: int, rows: int):
    receiver = DEFAULT_PARAMS.lms
    log_level = log_threshold(receiver, DEFAULT_PARAMS, K)
    threshold = float(np.exp(log_level))
    rng = np.random.default_rng(seed)
    fractions = bin_fractions(DEFAULT_PARAMS)
    start, length = rng.uniform(0.0, 8.0, rows), rng.uniform(0.05, 12.0, rows)
    edges = start[:, None] + length[:, None] * fractions
    shape = rng.uniform(0.0, 1.0, (rows, len(fractions) - 1)) ** 4
    # totals from none to a few thresholds, many just either side of it (the skipped rows' bound)
    totals = threshold * rng.choice([0.0, 0.3, 1.0 - 1e-6, 1.0 + 1e-6, 1.5, 4.0], rows)
    smoke = shape / shape.sum(axis=1, keepdims=True) * totals[:, None]
    target_amp = threshold * rng.choice([0.0, 0.2, 0.6, 1.5], (rows, 3))
    target_range = np.where(target_amp > 0, rng.uniform(0.1, 20.0, (rows, 3)), np.inf)
    smoke_rows = np.flatnonzero(totals > 0)  # the others reach the receiver without a range grid
    echo, _, clean = lms_first_echo(target_amp, target_range, smoke[smoke_rows], edges[smoke_rows], log_level, receiver, smoke_rows)
    expected_echo, expected_clean = _direct_first_echo(target_amp, target_range, smoke, edges, threshold, receiver)
    np.testing.assert_allclose(echo, expected_echo, rtol=1e-9, atol=1e-12)
    seen = np.isfinite(echo)
    assert np.array_equal(clean[seen], expected_clean[seen])
