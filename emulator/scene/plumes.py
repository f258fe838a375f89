"""Plume particles as analytic functions of (seed, plume, particle index, t).

The paper's "local smoke" (section 4.2): a point source emits particles at a
fixed rate; each lives `lifetime` seconds and carries an axis-aligned
collision box that follows it. Nothing here steps through history: the
particles alive at any instant are computed directly, so any time can be
evaluated in any order and the result depends only on the scene's seed.

Particle i of a plume is born at t_i = start + i / rate (only while
t_i < stop) and is alive while t_i <= t < t_i + lifetime. With age a = t - t_i:

    centre    = source + (velocity + offset_i + wind) * a
    edge      = size + growth * a

`offset_i` is the particle's random velocity offset: three independent normal
draws with standard deviation `spread` (m/s per axis), derived from a
counter-based SplitMix64 hash of (seed, plume index, i) so that it is the same
whenever the particle is evaluated and needs no per-particle state.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from emulator.scene.model import Plume

_GAMMA = np.uint64(0x9E3779B97F4A7C15)
_MIX1 = np.uint64(0xBF58476D1CE4E5B9)
_MIX2 = np.uint64(0x94D049BB133111EB)
_DRAWS_PER_PARTICLE = 4  # four uniforms → four normals by Box–Muller; three are used


@dataclass(frozen=True)
class Particles:
    """The particles alive at one instant: collision-box centres (N, 3), half
    edge lengths (N,), smoke density inside each box (N,) and particle index (N,)."""

    centers: np.ndarray
    half_sizes: np.ndarray
    density: np.ndarray
    index: np.ndarray

    def __len__(self) -> int:
        return len(self.index)

    @staticmethod
    def empty() -> Particles:
        return Particles(np.zeros((0, 3)), np.zeros(0), np.zeros(0), np.zeros(0, dtype=np.int64))

    @staticmethod
    def concatenate(parts: list[Particles]) -> Particles:
        if len(parts) <= 1:
            return parts[0] if parts else Particles.empty()
        return Particles(
            np.concatenate([p.centers for p in parts]),
            np.concatenate([p.half_sizes for p in parts]),
            np.concatenate([p.density for p in parts]),
            np.concatenate([p.index for p in parts]),
        )


def splitmix64(counters: np.ndarray) -> np.ndarray:
    """SplitMix64's output function applied to uint64 counters (wrapping arithmetic)."""
    with np.errstate(over="ignore"):
        z = counters * _GAMMA + _GAMMA
        z = (z ^ (z >> np.uint64(30))) * _MIX1
        z = (z ^ (z >> np.uint64(27))) * _MIX2
    return z ^ (z >> np.uint64(31))


@functools.lru_cache(maxsize=256)
def _stream_key(seed: int, plume_index: int) -> np.uint64:
    """A 64-bit key per (seed, plume): distinct keys give unrelated streams."""
    seed_hash = splitmix64(np.array([seed % 2**64], dtype=np.uint64))
    key = splitmix64(seed_hash ^ np.array([plume_index % 2**64], dtype=np.uint64))
    return key[0]


def uniforms(seed: int, plume_index: int, particle_index: np.ndarray, draws: int) -> np.ndarray:
    """(N, draws) uniforms in [0, 1), a pure function of (seed, plume, particle, draw)."""
    key = _stream_key(seed, plume_index)
    counters = particle_index.astype(np.uint64)[:, None] * np.uint64(draws) + np.arange(draws, dtype=np.uint64)
    with np.errstate(over="ignore"):
        bits = splitmix64(counters + key)
    return (bits >> np.uint64(11)).astype(np.float64) * 2.0**-53


def velocity_offsets(seed: int, plume_index: int, particle_index: np.ndarray, spread: float) -> np.ndarray:
    """(N, 3) normal velocity offsets with standard deviation `spread` per axis."""
    u = uniforms(seed, plume_index, particle_index, _DRAWS_PER_PARTICLE)
    radius = np.sqrt(-2.0 * np.log1p(-u[:, 0::2]))  # 1 - u in (0, 1]: log is finite
    angle = 2.0 * np.pi * u[:, 1::2]
    normals = np.concatenate([radius * np.cos(angle), radius * np.sin(angle)], axis=1)
    return spread * normals[:, :3]


_OFFSET_BLOCK = 1024  # particles per cached block of velocity offsets
_OFFSET_BLOCKS_KEPT = 256  # ≈ 262 000 particles' offsets (6 MB at most): a window of live particles wider than
# the cache draws every block again at every instant (100 000 live particles: 33 ms an instant with 64 kept, 10.5 ms now)


def _cached_velocity_offsets(seed: int, plume_index: int, particle_index: np.ndarray, spread: float) -> np.ndarray:
    """`velocity_offsets`, drawn once per block of consecutive particles: every scan of a
    particle's lifetime needs its offset again, and the alive particles are a sliding window."""
    if len(particle_index) == 0:
        return np.zeros((0, 3))
    first, last = int(particle_index[0]) // _OFFSET_BLOCK, int(particle_index[-1]) // _OFFSET_BLOCK
    if first == last:
        blocks = _offset_block(seed, plume_index, first, spread)
    else:
        blocks = np.concatenate([_offset_block(seed, plume_index, block, spread) for block in range(first, last + 1)])
    return blocks.take(particle_index - first * _OFFSET_BLOCK, axis=0)  # take: cheaper than 2-D fancy indexing


@functools.lru_cache(maxsize=_OFFSET_BLOCKS_KEPT)
def _offset_block(seed: int, plume_index: int, block: int, spread: float) -> np.ndarray:
    offsets = velocity_offsets(seed, plume_index, np.arange(block * _OFFSET_BLOCK, (block + 1) * _OFFSET_BLOCK), spread)
    offsets.flags.writeable = False
    return offsets


@dataclass(frozen=True)
class EmissionSegment:
    """A stretch of a plume's emission with one rate and wind (live changes split the scene's one).

    Births run at `first_birth + j / rate` for j >= 0 while before `end`;
    the j-th of them is the plume's particle `first_index + j`, so every
    particle keeps one index, one random offset and the wind of its birth.
    """

    first_birth: float
    end: float
    rate: float
    wind: tuple[float, float, float]
    first_index: int

    def births_before(self, time_s: float) -> int:
        """How many of the segment's births come before `time_s` (its count, for time_s = end)."""
        if time_s <= self.first_birth:
            return 0
        count = int(np.ceil((time_s - self.first_birth) * self.rate))
        while count > 0 and self.first_birth + (count - 1) / self.rate >= time_s:
            count -= 1
        while self.first_birth + count / self.rate < time_s:
            count += 1
        return count


def scene_emission(plume: Plume) -> EmissionSegment:
    """The scene's own emission: from `start` to `stop` at `rate`, in `wind`."""
    return EmissionSegment(plume.start, plume.stop, plume.rate, plume.wind, 0)


def alive_indices(plume: Plume, time_s: float, segment: EmissionSegment | None = None) -> np.ndarray:
    """Indices i of the segment's particles (default: the scene's emission) alive at `time_s`, ascending."""
    segment = segment or scene_emission(plume)
    if time_s < segment.first_birth:
        return np.zeros(0, dtype=np.int64)
    start, rate = segment.first_birth, segment.rate
    newest = np.floor((time_s - start) * rate) + 1
    emitted = np.ceil((segment.end - start) * rate) + 1
    oldest = np.floor((time_s - plume.lifetime - start) * rate) - 1
    first, last = int(max(oldest, 0)), int(min(newest, emitted))
    candidates = np.arange(first, last + 1, dtype=np.int64)
    birth = start + candidates / rate
    alive = (birth <= time_s) & (time_s < birth + plume.lifetime) & (birth < segment.end)
    return candidates[alive] + segment.first_index


def particles_at(
    plume: Plume, seed: int, plume_index: int, time_s: float, segments: tuple[EmissionSegment, ...] | None = None
) -> Particles:
    """The plume's particles alive at `time_s`, vectorised over particles.

    `segments` (ascending, from `emission_segments`) replace the scene's one
    emission when live changes have split it; only those that can still
    have a particle alive are evaluated.
    """
    if segments is None:
        return _segment_particles(plume, seed, plume_index, time_s, scene_emission(plume))
    parts = [
        _segment_particles(plume, seed, plume_index, time_s, segment)
        for segment in segments
        if segment.end + plume.lifetime > time_s >= segment.first_birth
    ]
    return Particles.concatenate(parts)


def _segment_particles(plume: Plume, seed: int, plume_index: int, time_s: float, segment: EmissionSegment) -> Particles:
    index = alive_indices(plume, time_s, segment)
    age = time_s - (segment.first_birth + (index - segment.first_index) / segment.rate)
    velocity = np.asarray(plume.velocity, dtype=float) + np.asarray(segment.wind, dtype=float)
    offsets = _cached_velocity_offsets(seed, plume_index, index, plume.spread)
    centers = np.asarray(plume.source, dtype=float) + (velocity + offsets) * age[:, None]
    half_sizes = 0.5 * (plume.size + plume.growth * age)
    density = np.full(len(index), float(plume.density))
    return Particles(centers, half_sizes, density, index)
