"""Puff crossings of several instants of a moving sensor in one pass (`cross_instants`) against
`cross_beams` one instant at a time: each beam's pairs the same and in the same order, every field
bit for bit (the sums downstream run per beam, in pair order), including instants whose beams share
one origin (a body standing still: `cross_beams`' fan path, the same fan at several instants),
instants without puffs and beams that reach nowhere."""

from __future__ import annotations

import numpy as np
import pytest

from emulator.optics.instant_puffs import cross_instants
from emulator.optics.puffs import BeamPuffCrossings, Puffs, cross_beams

FIELDS = ("beam", "along_m", "sigma", "column", "before_origin", "near")


def _by_beam(crossings: BeamPuffCrossings) -> list[np.ndarray]:
    """The fields with the pairs ordered by beam, each beam's pairs in their own order."""
    order = np.argsort(crossings.beam, kind="stable")
    return [getattr(crossings, name)[order] for name in FIELDS]


def _scan(rng: np.random.Generator, n: int, still: bool) -> tuple[np.ndarray, np.ndarray]:
    """A moving-like scan: a fan whose origin drifts beam by beam (or stays put: a fan)."""
    start = rng.normal(size=3)
    drift = np.zeros((n, 3)) if still else np.linspace(0.0, 1.0, n)[:, None] * rng.normal(size=3) * 0.05
    angles = np.linspace(-2.0, 2.0, n) + rng.normal() * 0.01
    directions = np.stack([np.cos(angles), np.sin(angles), np.zeros(n)], axis=1)
    if rng.random() < 0.3:  # tilted: directions off the plane
        directions[:, 2] = rng.normal(size=n) * 0.1
        directions /= np.linalg.norm(directions, axis=1)[:, None]
    return start + drift, directions


def _puffs(rng: np.random.Generator, count: int) -> Puffs:
    return Puffs(rng.uniform(-6, 6, (count, 3)) * [1, 1, 0.2], rng.uniform(0.05, 1.2, count), rng.uniform(0, 3, count))


def _one_at_a_time(parts: list[Puffs], origins: np.ndarray, directions: np.ndarray, end: np.ndarray) -> BeamPuffCrossings:
    n = len(origins) // len(parts)
    crossed = [cross_beams(p, origins[k * n : (k + 1) * n], directions[k * n : (k + 1) * n], end[k * n : (k + 1) * n]) for k, p in enumerate(parts)]
    return BeamPuffCrossings(
        np.concatenate([c.beam + k * n for k, c in enumerate(crossed)]), *(np.concatenate([getattr(c, f) for c in crossed]) for f in FIELDS[1:])
    )


@pytest.mark.filterwarnings("error")  # an endless beam: never 0 × inf
@pytest.mark.parametrize("seed", range(6))
def test_several_instants_in_one_pass_cross_exactly_as_one_instant_at_a_time(seed: int) -> None:
    rng = np.random.default_rng(seed)
    crossed = grouped = 0
    for _ in range(40):
        count, n = int(rng.integers(1, 9)), int(rng.choice([5, 16, 17, 181, 361]))
        scans = [_scan(rng, n, still=rng.random() < 0.25) for _ in range(count)]
        if rng.random() < 0.3:  # a body at rest: the same fan at several instants
            scans = [scans[0]] * count
        origins = np.concatenate([s[0] for s in scans])
        directions = np.concatenate([s[1] for s in scans])
        end = rng.uniform(0.1, 8.0, count * n)
        if scans[0] is scans[-1] and rng.random() < 0.7:
            end = np.tile(end[:n], count)  # and the same solids: one call for every instant
        if rng.random() < 0.1:
            end[int(rng.integers(len(end)))] = np.inf  # a beam that meets nothing: its instant takes cross_beams' path
        parts = [_puffs(rng, int(rng.choice([0, 3, 45, 120]))) for _ in range(count)]
        together = cross_instants(parts, origins, directions, end)
        alone = _one_at_a_time(parts, origins, directions, end)
        for name, mine, theirs in zip(FIELDS, _by_beam(together), _by_beam(alone)):
            np.testing.assert_array_equal(mine, theirs, err_msg=name)
            assert mine.dtype == theirs.dtype
        crossed += len(alone)
        grouped += count > 1 and scans[0] is scans[-1] and bool((end[:n] == end[-n:]).all())
    assert crossed > 5000  # the cases do cross
    assert grouped >= 3  # and the same fan stands at several instants
