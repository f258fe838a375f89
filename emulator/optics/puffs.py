"""Plume particles as Gaussian puffs, integrated analytically along beams.

The `physical` model replaces each particle's hard collision box (edge L,
density D) by a Gaussian puff with the same peak density D and

    sigma = L / sqrt(2 pi)

which keeps the particle's smoke mass (D L^3) and its central column
(D L, the box's chord through its centre) while smoothing its edges. Along a
beam the line integral of a Gaussian is analytic: a puff whose centre lies at
distance `along_m` on the beam and `miss_m` off it contributes

    column = D sqrt(2 pi) sigma exp(-miss^2 / (2 sigma^2))

spread along the beam as a normal distribution of standard deviation sigma,
so the optical path from the origin to any distance s is column times
(Phi((s - along)/sigma) - Phi(-along/sigma)). Everything is vectorised over
beams x puffs; only (beam, puff) pairs within `REACH_SIGMAS` are kept.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from emulator.scene.plumes import Particles

SIGMA_PER_EDGE = 1.0 / np.sqrt(2.0 * np.pi)
REACH_SIGMAS = 4.0  # a puff farther than this from a beam adds < 4e-4 of its column


def erf(x: np.ndarray) -> np.ndarray:
    """Error function, Abramowitz & Stegun 7.1.26 (|error| < 1.5e-7), vectorised.

    numpy has no erf and scipy is not a dependency.
    """
    x = np.asarray(x, dtype=float)
    t = 1.0 / (1.0 + 0.3275911 * np.abs(x))
    poly = t * (0.254829592 + t * (-0.284496736 + t * (1.421413741 + t * (-1.453152027 + t * 1.061405429))))
    return np.sign(x) * (1.0 - poly * np.exp(-x * x))


def normal_cdf(x: np.ndarray) -> np.ndarray:
    return 0.5 * (1.0 + erf(np.asarray(x) / np.sqrt(2.0)))


@dataclass(frozen=True)
class Puffs:
    """Gaussian puffs: centres (P, 3), standard deviations (P,), peak densities (P,)."""

    centers: np.ndarray
    sigma: np.ndarray
    peak_density: np.ndarray

    def __len__(self) -> int:
        return len(self.sigma)

    @staticmethod
    def from_particles(particles: Particles) -> Puffs:
        edge = 2.0 * particles.half_sizes
        return Puffs(particles.centers, edge * SIGMA_PER_EDGE, particles.density)


@dataclass(frozen=True)
class BeamPuffCrossings:
    """The (beam, puff) pairs that matter, flat arrays of length Q.

    `beam`: index of the beam; `along_m`: the puff centre's distance along the
    beam; `sigma`: the puff's standard deviation; `column`: its line integral
    over the whole line (d·m); `before_origin`: the share of it behind the
    origin (Phi(-along/sigma)), which the beam never sees.
    """

    beam: np.ndarray
    along_m: np.ndarray
    sigma: np.ndarray
    column: np.ndarray
    before_origin: np.ndarray

    def __len__(self) -> int:
        return len(self.beam)

    def optical_path_to(self, limits_m: np.ndarray) -> np.ndarray:
        """Puff optical path from each beam's origin to `limits_m`.

        `limits_m` is (N,) or (N, M): one or M distances per beam; the result has its shape.
        """
        limits = np.asarray(limits_m, dtype=float)
        result = np.zeros(limits.shape)
        if len(self) == 0:
            return result
        per_beam = limits.reshape(len(limits), -1)
        finite = np.where(np.isfinite(per_beam), per_beam, 1e12)
        share = normal_cdf((finite[self.beam] - self.along_m[:, None]) / self.sigma[:, None])
        contribution = self.column[:, None] * np.maximum(share - self.before_origin[:, None], 0.0)
        columns = per_beam.shape[1]
        flat_index = (self.beam[:, None] * columns + np.arange(columns)).ravel()
        totals = np.bincount(flat_index, weights=contribution.ravel(), minlength=per_beam.size)
        return totals.reshape(limits.shape)

    def extent_m(self, n_beams: int) -> tuple[np.ndarray, np.ndarray]:
        """Per beam, where puff smoke starts and ends (REACH_SIGMAS around the centres; inf/−inf if none)."""
        start = np.full(n_beams, np.inf)
        end = np.full(n_beams, -np.inf)
        np.minimum.at(start, self.beam, np.maximum(self.along_m - REACH_SIGMAS * self.sigma, 0.0))
        np.maximum.at(end, self.beam, self.along_m + REACH_SIGMAS * self.sigma)
        return start, end


def cross_beams(puffs: Puffs, origins: np.ndarray, directions: np.ndarray, beam_end_m: np.ndarray) -> BeamPuffCrossings:
    """The puffs each beam passes within REACH_SIGMAS of, before its end.

    `directions` must be unit vectors. Distances come from matrix products
    (beams x puffs), so the cost is a few array operations whatever the count.
    """
    if len(puffs) == 0 or len(origins) == 0:
        empty = np.zeros(0)
        return BeamPuffCrossings(np.zeros(0, dtype=np.int64), empty, empty, empty, empty)
    puffs = _near_segments(puffs, origins, directions, beam_end_m)
    offsets = [puffs.centers[None, :, axis] - origins[:, axis, None] for axis in range(3)]
    along = sum(offset * directions[:, axis, None] for axis, offset in enumerate(offsets))
    miss_sq = np.maximum(sum(offset * offset for offset in offsets) - along * along, 0.0)
    reach = REACH_SIGMAS * puffs.sigma[None, :]
    near = (miss_sq < reach * reach) & (along > -reach) & (along < beam_end_m[:, None] + reach)
    beam, puff = np.nonzero(near)
    sigma = puffs.sigma[puff]
    along_m = along[beam, puff]
    column = puffs.peak_density[puff] * np.sqrt(2.0 * np.pi) * sigma * np.exp(-miss_sq[beam, puff] / (2.0 * sigma * sigma))
    return BeamPuffCrossings(beam, along_m, sigma, column, normal_cdf(-along_m / sigma))


def _near_segments(puffs: Puffs, origins: np.ndarray, directions: np.ndarray, beam_end_m: np.ndarray) -> Puffs:
    """The puffs within reach of the box bounding all beam segments (a cheap first cut)."""
    ends = origins + directions * np.where(np.isfinite(beam_end_m), beam_end_m, 0.0)[:, None]
    lower = np.minimum(origins.min(axis=0), ends.min(axis=0))
    upper = np.maximum(origins.max(axis=0), ends.max(axis=0))
    reach = REACH_SIGMAS * puffs.sigma[:, None]
    keep = np.all((puffs.centers + reach >= lower) & (puffs.centers - reach <= upper), axis=1)
    return Puffs(puffs.centers[keep], puffs.sigma[keep], puffs.peak_density[keep])
