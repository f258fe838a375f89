"""What the `physical` model knows about each beam before a receiver decides.

From the optics' `BeamHits` and the beams' geometry: the smoke along each
beam as cumulative optical paths on a per-beam grid of range bins (smoke
regions exactly from their entry/exit distances, plume puffs analytically),
the fluctuation factor scaling each beam's smoke, and the surfaces the beam's
footprint meets (sub-rays at depth edges), each with its optical path.
A sensor's beams at several instants are computed together (`Instants`).
"""

from __future__ import annotations

import dataclasses
import functools
import weakref
from dataclasses import dataclass
from typing import Iterator, Sequence

import numpy as np

from emulator.optics import BeamHits, World
from emulator.optics.hits import RegionCrossing
from emulator.optics.instant_puffs import cross_instants
from emulator.optics.kept import KeptPerArrays
from emulator.optics.puffs import BeamPuffCrossings, Puffs, cross_beams
from emulator.scene.material_optics import optics_for, patch_values
from emulator.sensors.beam_geometry import scan_plane_rays
from emulator.sensors.physical.echo import echoing, log_clear_air_echo, reference_spreading
from emulator.sensors.physical.noise import fluctuation_factor
from emulator.sensors.physical.params import PhysicalParams, ReceiverOptics
from emulator.sensors.response import Beams


@dataclass(frozen=True)
class Surfaces:
    """The surfaces in each beam's footprint, (N, S): S sub-rays, unused ones with amp 0.

    `log_each` is ln of each sub-ray's echo, `amp` its share of the echo
    power; `range_m` the range each would report (material range stretch
    included); `single` marks beams with one sub-ray.
    """

    log_each: np.ndarray
    amp: np.ndarray
    range_m: np.ndarray
    present: np.ndarray
    single: np.ndarray

    @functools.cached_property
    def log_echo(self) -> np.ndarray:
        """ln of each footprint's summed echo (N,), exact for a beam with one surface."""
        with np.errstate(divide="ignore"):
            return np.where(self.single, self.log_each[:, 0], np.log(self.amp.sum(axis=1)))


@dataclass(frozen=True)
class SmokeEchoes:
    """Smoke backscatter per range bin for the R beams `rows` that meet smoke:
    power (R, M), bin centres (R, M), bin edges (R, M+1), which lie at the same
    `fractions` (M+1,) of each beam's smoke extent."""

    rows: np.ndarray
    amp: np.ndarray
    mid_m: np.ndarray
    edges_m: np.ndarray
    fractions: np.ndarray


@dataclass(frozen=True)
class BeamPhysics:
    """Everything a receiver needs, per beam."""

    surfaces: Surfaces
    smoke: SmokeEchoes
    optical_path_to_end: np.ndarray  # fluctuation included


@dataclass(frozen=True)
class Instants:
    """One sensor's beams at K instants, stacked: row k·N + b is beam b at instant k.

    Beams that stay put (a fixed sensor among fixed solids): `hits` and `beams`
    are the first instant's, whose fixed arrays (N,) serve every instant.
    Beams that move (a sensor on a moving body, or solids that move): each
    instant has its own, and `hits` / `beams` hold them all stacked (K·N rows;
    `beams.angles_rad` stays (N,)), `per_instant` each instant's own.
    What changes with time is held per row: each region's density (K·N,) and
    the regions' optical path to each beam's end.
    """

    hits: BeamHits
    beams: Beams
    times_s: tuple[float, ...]
    region_density: tuple[np.ndarray, ...]
    region_optical_path: np.ndarray
    per_instant: tuple[tuple[BeamHits, Beams], ...] | None = None

    @staticmethod
    def of(hits: Sequence[BeamHits], beams: Sequence[Beams]) -> Instants:
        """The instants of `hits` / `beams` (one entry per instant)."""
        n = len(hits[0])
        densities = np.array([[region.density for region in h.regions] for h in hits]).reshape(len(hits), -1)
        region_density = tuple(np.repeat(column, n) for column in densities.T)
        path = hits[0].region_optical_path if len(hits) == 1 else np.concatenate([h.region_optical_path for h in hits])
        times = tuple(b.time_s for b in beams)
        if _same_beams(hits, beams):
            return Instants(hits[0], beams[0], times, region_density, path)
        return Instants(_stacked_hits(hits), _stacked_beams(beams), times, region_density, path, tuple(zip(hits, beams)))

    @property
    def count(self) -> int:
        return len(self.times_s)

    @property
    def beam_count(self) -> int:
        """N: beams per instant."""
        return len(self.beams.angles_rad)

    def beam_rows(self, rows: np.ndarray) -> np.ndarray:
        """The rows of `hits`' arrays that hold the stacked `rows`."""
        return rows if self.count == 1 or self.per_instant is not None else rows % self.beam_count

    def smoky_regions(self) -> Iterator[tuple[RegionCrossing, np.ndarray]]:
        """Each region with density at some instant, with its density per row."""
        for region, density in zip(self.hits.regions, self.region_density):
            if density.max() > 0:
                yield region, density

    def crossings(self) -> BeamPuffCrossings:
        """Every instant's puffs against the beams in one pass; pairs name stacked rows."""
        world, n = self.beams.world, self.beam_count
        parts = [Puffs.from_particles(world.particles_at(time_s)) for time_s in self.times_s]
        if self.per_instant is not None:  # each instant's own beams (a moving sensor): all instants in one pass
            return cross_instants(parts, self.beams.origins, self.beams.directions, self.hits.beam_end_m)
        offsets = np.repeat(np.arange(self.count) * n, [len(part) for part in parts]) if self.count > 1 else None
        return cross_beams(Puffs.concatenate(parts), self.beams.origins, self.beams.directions, self.hits.beam_end_m, offsets)

    def surface_geometry(self, receiver: ReceiverOptics, params: PhysicalParams) -> _SurfaceGeometry:
        """The surfaces in the beams' footprints, stacked for the instants."""
        if self.per_instant is None:
            return _surface_geometry(self.hits, self.beams, receiver, params).stacked(self.count)
        return _footprint_surfaces(self.hits, self.beams, receiver, params, block=self.beam_count)  # all instants in one pass


def _same_beams(hits: Sequence[BeamHits], beams: Sequence[Beams]) -> bool:
    """Whether every instant casts the same beams against the same solids (they may then share them)."""
    return all(
        h.solid_range_m is hits[0].solid_range_m and b.origins is beams[0].origins and b.directions is beams[0].directions
        for h, b in zip(hits, beams)
    )


def _stacked_hits(hits: Sequence[BeamHits]) -> BeamHits:
    """The instants' hits as one (K·N) set of rows; each region's intervals padded to the widest instant."""

    def stack(name: str) -> np.ndarray:
        return np.concatenate([getattr(h, name) for h in hits])

    def padded(arrays: list[np.ndarray]) -> np.ndarray:
        width = max(array.shape[1] for array in arrays)
        if all(array.shape[1] == width for array in arrays):
            return np.concatenate(arrays)
        return np.concatenate([np.pad(a, ((0, 0), (0, width - a.shape[1])), constant_values=np.inf) for a in arrays])

    regions = tuple(
        RegionCrossing(i, hits[0].regions[i].density, padded([h.regions[i].entry_m for h in hits]), padded([h.regions[i].exit_m for h in hits]))
        for i in range(len(hits[0].regions))
    )
    return dataclasses.replace(
        hits[0],
        solid_range_m=stack("solid_range_m"),
        object_index=stack("object_index"),
        reflectivity=stack("reflectivity"),
        cos_incidence=stack("cos_incidence"),
        beam_end_m=stack("beam_end_m"),
        region_optical_path=stack("region_optical_path"),
        regions=regions,
        first_particle=_no_first_particle,
    )


def _no_first_particle() -> tuple[np.ndarray, np.ndarray]:
    raise NotImplementedError("stacked hits of several instants have no single instant's particles")


def _stacked_beams(beams: Sequence[Beams]) -> Beams:
    def stack(name: str) -> np.ndarray | None:
        arrays = [getattr(b, name) for b in beams]
        return None if arrays[0] is None else np.concatenate(arrays)

    return dataclasses.replace(
        beams[0],
        origins=stack("origins"),
        directions=stack("directions"),
        rotations=stack("rotations"),
        beam_times_s=stack("beam_times_s"),
    )


PUFFS_PER_PASS = 10_000  # the puffs of the instants computed in one pass, together (at least one instant a pass)


def instant_passes(beams: Sequence[Beams], puffs_per_pass: int) -> list[slice]:
    """The instants computed together, consecutive: all of them unless their puffs together pass
    `puffs_per_pass`. A pass's arrays grow with its pairs and grid points, and past a few million they
    cost more per scan than smaller passes (railway with 10 000 live particles, `physical` URG-04LX:
    38 ms a scan in passes of 8 instants, 23 ms one at a time; with 500 particles 8 at a time is
    fastest). Each instant's values are those of computing it alone, whatever the passes."""
    if len(beams) == 1:
        return [slice(0, 1)]
    world = beams[0].world
    most = max(len(world.particles_at(b.time_s)) for b in beams)  # kept by the world for the crossing
    per_pass = max(1, puffs_per_pass // most) if most else len(beams)
    return [slice(start, start + per_pass) for start in range(0, len(beams), per_pass)]


def beam_physics_at(instants: Instants, receiver: ReceiverOptics, params: PhysicalParams) -> BeamPhysics:
    """Surfaces and smoke echoes of the beams at K instants as `receiver` sees them, rows stacked as
    in `instants`: each pass's numpy calls are shared by all K, per scan far cheaper than one at a time."""
    beams = instants.beams
    scene = beams.scene
    extinction = scene.density_to_extinction
    crossings = instants.crossings()
    geometry = instants.surface_geometry(receiver, params)
    puff_to_end_and_surfaces = crossings.optical_path_to(geometry.end_and_surfaces_m)  # one pass for every limit
    column = instants.region_optical_path + puff_to_end_and_surfaces[:, 0]
    smoke_start, smoke_end = _smoke_extent(instants, crossings, geometry)
    with np.errstate(invalid="ignore"):
        smoke_distance = np.where(np.isfinite(smoke_start), 0.5 * (smoke_start + smoke_end), 1.0)
    factor = fluctuation_factor(scene.seed, beams.sensor.name, beams.angles_rad, instants.times_s, column, smoke_distance, params)
    surfaces = _surfaces(instants, geometry, puff_to_end_and_surfaces[:, 1:], factor, extinction)
    far_end = np.where(geometry.any_present, np.maximum.reduce(np.where(surfaces.present, surfaces.range_m, 0.0).T), geometry.beam_end_m)
    smoke = _smoke_echoes(instants, crossings, factor, smoke_start, np.minimum(smoke_end, far_end), extinction, receiver, params)
    return BeamPhysics(surfaces, smoke, factor * column)


def _smoke_extent(instants: Instants, crossings: BeamPuffCrossings, geometry: _SurfaceGeometry) -> tuple[np.ndarray, np.ndarray]:
    start, end = crossings.extent_m(len(geometry.beam_end_m))
    for (entered_at, left_at), density in zip(geometry.region_extents, instants.region_density):
        if density.min() > 0:
            np.minimum(start, entered_at, out=start)
            np.maximum(end, left_at, out=end)
        elif density.max() > 0:  # smoke at some instants only
            smoky = density > 0
            np.minimum(start, np.where(smoky, entered_at, np.inf), out=start)
            np.maximum(end, np.where(smoky, left_at, -np.inf), out=end)
    return start, np.minimum(end, geometry.beam_end_m)


def _region_extents(hits: BeamHits) -> tuple[tuple[np.ndarray, np.ndarray], ...]:
    """Per region, where each beam first enters it before the beam's end and last leaves it (inf / -inf if never)."""
    extents = []
    for region in hits.regions:
        entered = np.isfinite(region.entry_m) & (region.entry_m < hits.beam_end_m[:, None])
        extents.append((np.where(entered, region.entry_m, np.inf).min(axis=1), np.where(entered, region.exit_m, -np.inf).max(axis=1)))
    return tuple(extents)


def _region_path_to(instants: Instants, rows: np.ndarray, limits: np.ndarray) -> np.ndarray:
    """Region optical path from the origin to `limits` (len(rows), S), ascending along each row, for
    stacked rows `rows`. Rows that enter a region only past their last limit gain exactly 0 from it:
    where they are most, only the others are summed."""
    total = np.zeros(limits.shape)
    beams = instants.beam_rows(rows)
    for region, density in instants.smoky_regions():
        entry, exit_ = region.entry_m.take(beams, axis=0), region.exit_m.take(beams, axis=0)  # take: cheaper than 2-D indexing
        reached = (entry.min(axis=1) if entry.shape[1] > 1 else entry[:, 0]) < limits[:, -1]
        if not reached.any():
            continue
        if reached.mean() > 0.5:
            total += _chords_to(entry, exit_, limits, density.take(rows))
        else:
            some = reached.nonzero()[0]
            total[some] += _chords_to(entry.take(some, axis=0), exit_.take(some, axis=0), limits.take(some, axis=0), density.take(rows.take(some)))
    return total


def _chords_to(entry: np.ndarray, exit_: np.ndarray, limits: np.ndarray, density: np.ndarray) -> np.ndarray:
    """Optical path (R, S) inside intervals [entry, exit) (R, K) before each of `limits` (R, S), at `density` (R,)."""
    if entry.shape[1] == 1:  # one interval per beam (a convex region): no sum over intervals
        inside = np.minimum(exit_, limits)
        inside -= np.minimum(entry, limits)
    else:
        limit = limits[:, :, None]
        inside = (np.minimum(exit_[:, None, :], limit) - np.minimum(entry[:, None, :], limit)).sum(axis=2)
    inside *= density[:, None]
    return inside


def _depth_edges(hits: BeamHits, params: PhysicalParams, block: int | None = None) -> np.ndarray:
    """Beams whose neighbour meets another object or a range differing by more than `edge_jump`
    (with `block`, rows are scans of `block` beams stacked: the last beam of one and the first of
    the next are no neighbours)."""
    ranges = np.where(np.isfinite(hits.solid_range_m), hits.solid_range_m, 0.0)
    objects = hits.object_index
    edge = np.zeros(len(ranges), dtype=bool)
    jump = (objects[1:] != objects[:-1]) | (np.abs(ranges[1:] - ranges[:-1]) > params.edge_jump * np.maximum(ranges[1:], ranges[:-1]))
    if block is not None:
        jump[block - 1 :: block] = False
    edge[1:] |= jump
    edge[:-1] |= jump
    return edge


@dataclass(frozen=True)
class _SurfaceGeometry:
    """What each beam's footprint meets of the fixed objects (N, S): unused sub-rays have range inf.

    Material effects are applied (patchy reflectivity, cos^n); only the smoke
    in front of these surfaces changes from scan to scan.
    """

    ranges: np.ndarray
    stretch_per_path: np.ndarray  # material range stretch × 2 k: apparent range = range × (1 + this × optical path)
    shares: np.ndarray  # (N, 1): sub-rays used per beam, which share its echo power
    edge_rows: np.ndarray
    present: np.ndarray  # used, with a surface in reach
    any_present: np.ndarray  # (N,)
    end_and_surfaces_m: np.ndarray  # (N, 1 + S): each beam's end and each present surface's range (0 elsewhere: adds exactly 0)
    log_clear_air: np.ndarray  # ln of each sub-ray's echo without smoke; -inf where it cannot echo at all
    inverse_shares: np.ndarray  # (N, 1)
    edge_region_lengths: tuple[np.ndarray, ...]  # per region, chord length (E, S) before each edge row's sub-rays
    cast_is_central: np.ndarray  # (N,) 1.0 where the first sub-ray is the cast beam itself, 0.0 on edge rows
    edge_positions: np.ndarray  # row-major flat positions of the edge rows' sub-rays in an (N, S) array
    region_extents: tuple[tuple[np.ndarray, np.ndarray], ...]  # `_region_extents`
    beam_end_m: np.ndarray  # (N,) as BeamHits.beam_end_m

    def stacked(self, count: int) -> _SurfaceGeometry:
        """This geometry for `count` instants stacked row after row (`Instants`); kept per count."""
        if count == 1:
            return self
        return _STACKED.get((self.ranges,), count, lambda: self._tiled(count))

    def _tiled(self, count: int) -> _SurfaceGeometry:
        n, sub_rays = self.ranges.shape

        def tile(array: np.ndarray) -> np.ndarray:
            return np.tile(array, (count,) + (1,) * (array.ndim - 1))

        edge_rows = (self.edge_rows + n * np.arange(count)[:, None]).ravel()
        geometry = _SurfaceGeometry(
            tile(self.ranges),
            tile(self.stretch_per_path),
            tile(self.shares),
            edge_rows,
            tile(self.present),
            tile(self.any_present),
            tile(self.end_and_surfaces_m),
            tile(self.log_clear_air),
            tile(self.inverse_shares),
            tuple(tile(chords) for chords in self.edge_region_lengths),
            tile(self.cast_is_central),
            (edge_rows[:, None] * sub_rays + np.arange(sub_rays)).ravel(),
            tuple((tile(entered), tile(left)) for entered, left in self.region_extents),
            tile(self.beam_end_m),
        )
        _lock(tuple(getattr(geometry, field.name) for field in dataclasses.fields(geometry)))
        return geometry


_STACKED = KeptPerArrays(64)  # ≈ 0.6 MB per (sensor, count), and tiling again is cheap


_GEOMETRIES = KeptPerArrays()


def _surface_geometry(hits: BeamHits, beams: Beams, receiver: ReceiverOptics, params: PhysicalParams) -> _SurfaceGeometry:
    """`_footprint_surfaces`, kept for a sensor's prepared beams (`World.prepare`: read-only arrays
    reused by every scan), since objects never move."""
    return _GEOMETRIES.get(
        (hits.solid_range_m, beams.angles_rad, hits.beam_end_m),
        (receiver, params, beams.scene.seed, beams.scene.density_to_extinction),
        lambda: _footprint_surfaces(hits, beams, receiver, params),
    )


def _footprint_surfaces(
    hits: BeamHits, beams: Beams, receiver: ReceiverOptics, params: PhysicalParams, block: int | None = None
) -> _SurfaceGeometry:
    """The footprints' surfaces of `hits`; with `block`, of several scans' beams stacked (`Instants`)."""
    n = len(hits)
    sub_rays = params.sub_rays if params.mixed_pixels else 1
    ranges = np.full((n, sub_rays), np.inf)
    ranges[:, 0] = hits.solid_range_m
    objects = np.full((n, sub_rays), -1, dtype=np.int64)
    objects[:, 0] = hits.object_index
    reflectivity = np.zeros((n, sub_rays))
    reflectivity[:, 0] = hits.reflectivity
    cosine = np.zeros((n, sub_rays))
    cosine[:, 0] = hits.cos_incidence
    used = np.zeros((n, sub_rays), dtype=bool)
    used[:, 0] = True
    edge_rows = np.flatnonzero(_depth_edges(hits, params, block)) if sub_rays > 1 else np.zeros(0, dtype=np.int64)
    if len(edge_rows):
        offsets = ((np.arange(sub_rays) + 0.5) / sub_rays - 0.5) * receiver.footprint_rad
        angles = beams.angles_rad[edge_rows if block is None else edge_rows % block][:, None] + offsets
        solids = _sub_ray_solids(beams, edge_rows, angles, hits.max_range_m)
        ranges[edge_rows], objects[edge_rows], reflectivity[edge_rows], cosine[edge_rows] = solids
        used[edge_rows] = True
    present = used & np.isfinite(ranges)
    angle_exponent, stretch, patchiness = _material_arrays(beams, objects, params)
    patchy = np.nonzero(present & (patchiness > 0))
    if len(patchy[0]):
        points = beams.origins[patchy[0]] + beams.directions[patchy[0]] * ranges[patchy][:, None]
        reflectivity[patchy] *= np.exp(patchiness[patchy] * patch_values(points, beams.scene.seed))
    limits = np.where(present, ranges, 0.0)
    cos_factor = cosine.copy()
    steeper = np.nonzero(angle_exponent != 1.0)  # cos^1 is cos: the power only where a material differs (few)
    cos_factor[steeper] **= angle_exponent[steeper]
    shares = used.sum(axis=1, keepdims=True)
    can_echo = present & echoing(reflectivity, cos_factor, ranges)
    log_clear_air = np.full((n, sub_rays), -np.inf)
    echoes = np.nonzero(can_echo)  # the logs only where a sub-ray can echo (most beams use one sub-ray)
    log_clear_air[echoes] = log_clear_air_echo(reflectivity[echoes], cos_factor[echoes], ranges[echoes], receiver, params)
    edge_limits = np.minimum(ranges[edge_rows], hits.max_range_m)
    cast_is_central = np.ones(n)
    cast_is_central[edge_rows] = 0.0
    geometry = _SurfaceGeometry(
        ranges,
        stretch * 2.0 * beams.scene.density_to_extinction,
        shares,
        edge_rows,
        present,
        np.logical_or.reduce(present.T),  # over the few sub-rays, a whole column at a time
        np.concatenate([hits.beam_end_m[:, None], limits], axis=1),
        log_clear_air,
        1.0 / shares,
        tuple(_chords_before(region, edge_rows, edge_limits) for region in hits.regions),
        cast_is_central,
        (edge_rows[:, None] * sub_rays + np.arange(sub_rays)).ravel(),
        _region_extents(hits),
        hits.beam_end_m,
    )
    _lock(tuple(getattr(geometry, field.name) for field in dataclasses.fields(geometry)))
    return geometry


def _lock(values: np.ndarray | tuple) -> None:
    """Make the arrays in (nested tuples of) `values` read-only: they are kept and shared by later scans."""
    if isinstance(values, tuple):
        for value in values:
            _lock(value)
    else:
        values.flags.writeable = False


def _chords_before(region: RegionCrossing, rows: np.ndarray, limits: np.ndarray) -> np.ndarray:
    """Chord length (R, S) of beams `rows` inside `region` before `limits` (R, S)."""
    entry, exit_, limit = region.entry_m[rows][:, None, :], region.exit_m[rows][:, None, :], limits[:, :, None]
    return (np.minimum(exit_, limit) - np.minimum(entry, limit)).sum(axis=2)


def _surfaces(instants: Instants, geometry: _SurfaceGeometry, puff_to_surfaces: np.ndarray, factor: np.ndarray, extinction: float) -> Surfaces:
    """`geometry`'s surfaces (stacked for the instants) seen through their smoke; `puff_to_surfaces`
    (K·N, S) is the puffs' optical path to each sub-ray's surface (0 for unused sub-rays)."""
    optical_path = puff_to_surfaces.copy()
    optical_path[:, 0] += instants.region_optical_path * geometry.cast_is_central  # an edge row's sub-rays all differ from the cast beam
    edge_rows = geometry.edge_rows
    if len(edge_rows):
        region_path = np.zeros((len(edge_rows), optical_path.shape[1]))
        for chords, density in zip(geometry.edge_region_lengths, instants.region_density):
            if density.max() > 0:
                region_path += density.take(edge_rows)[:, None] * chords
        optical_path.ravel()[geometry.edge_positions] += region_path.ravel()  # 1-D: cheaper than 2-D row indexing
    optical_path *= factor[:, None]
    log_each = optical_path * (-2.0 * extinction)
    log_each += geometry.log_clear_air
    amp = np.exp(log_each)
    amp *= geometry.inverse_shares
    apparent = geometry.stretch_per_path * optical_path
    apparent += 1.0
    apparent *= geometry.ranges  # inf where no surface is present
    return Surfaces(log_each, amp, apparent, geometry.present, geometry.shares[:, 0] == 1)


_SubRaySolids = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]
_SUB_RAY_CACHE: weakref.WeakKeyDictionary[World, dict[tuple, _SubRaySolids]] = weakref.WeakKeyDictionary()
_SUB_RAY_CACHE_SIZE = 64


def _sub_ray_solids(beams: Beams, rows: np.ndarray, angles_rad: np.ndarray, max_range_m: float) -> _SubRaySolids:
    """Range, object, reflectivity and |cos incidence| (R, S) of sub-rays of beams `rows` at sensor-frame
    `angles_rad` (R, S).

    When nothing moves, the result depends only on the world, the sensor's pose
    and the angles: it is cast once and kept per world. A moving sensor casts
    each beam's sub-rays from its pose at the beam's instant, and moving solids
    are met at that instant: cast afresh.
    """
    if beams.rotations is not None or beams.world.moving:
        return _moving_sub_ray_solids(beams, rows, angles_rad, max_range_m)
    cache = _SUB_RAY_CACHE.setdefault(beams.world, {})
    key = (beams.sensor.pose, angles_rad.tobytes(), angles_rad.shape, max_range_m)
    if key not in cache:
        origins, directions = scan_plane_rays(beams.sensor.pose, angles_rad.ravel())
        hits = beams.world.cast(origins, directions, max_range_m, beams.time_s)
        shape = angles_rad.shape
        if len(cache) >= _SUB_RAY_CACHE_SIZE:
            cache.clear()
        cache[key] = (
            hits.solid_range_m.reshape(shape),
            hits.object_index.reshape(shape),
            hits.reflectivity.reshape(shape),
            hits.cos_incidence.reshape(shape),
        )
    return cache[key]


def _moving_sub_ray_solids(beams: Beams, rows: np.ndarray, angles_rad: np.ndarray, max_range_m: float) -> _SubRaySolids:
    shape = angles_rad.shape
    flat = angles_rad.ravel()
    owner = np.repeat(rows, shape[1])  # the beam each sub-ray belongs to
    local = np.stack([np.cos(flat), np.sin(flat), np.zeros_like(flat)], axis=1)
    if beams.rotations is not None:
        directions = np.einsum("nij,nj->ni", beams.rotations[owner], local)
    else:
        directions = local @ beams.sensor.pose.rotation_matrix().T
    origins = beams.origins[owner]
    times = beams.beam_times_s[owner] if beams.beam_times_s is not None else None
    solids = beams.world.solids(origins, directions, max_range_m, beams.time_s, times)
    return (
        solids.range_m.reshape(shape),
        solids.object_index.reshape(shape),
        solids.reflectivity.reshape(shape),
        solids.cos_incidence.reshape(shape),
    )


_MATERIAL_TABLES: weakref.WeakKeyDictionary[World, tuple[object, np.ndarray]] = weakref.WeakKeyDictionary()


def _material_arrays(beams: Beams, objects: np.ndarray, params: PhysicalParams) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per sub-ray: angle exponent, range stretch and patchiness of the material hit."""
    if not params.material_effects or not beams.scene.objects:
        return np.ones(objects.shape), np.zeros(objects.shape), np.zeros(objects.shape)
    scene, table = _MATERIAL_TABLES.get(beams.world, (None, None))
    if scene is not beams.scene or table is None:  # per object, plus a last column for "nothing hit"; kept (moving beams ask every scan)
        materials = [optics_for(obj.material) for obj in beams.scene.objects]
        table = np.array([[m.angle_exponent, m.range_stretch, m.patchiness] for m in materials] + [[1.0, 0.0, 0.0]]).T.copy()
        _MATERIAL_TABLES[beams.world] = (beams.scene, table)
    index = np.where(objects >= 0, objects, table.shape[1] - 1)
    return table[0].take(index), table[1].take(index), table[2].take(index)  # a gather per column: cheaper than rows


def bin_fractions(params: PhysicalParams) -> np.ndarray:
    """Bin edges as fractions of a beam's smoke extent, each bin `bin_growth` times the previous:
    fine where the smoke begins, where a first echo forms in dense smoke. Read-only, computed once."""
    return _bin_fractions(params.bins, params.bin_growth)


@functools.lru_cache(maxsize=16)
def _bin_fractions(bins: int, growth: float) -> np.ndarray:
    widths = growth ** np.arange(bins)
    fractions = np.concatenate([[0.0], np.cumsum(widths) / widths.sum()])
    fractions.flags.writeable = False
    return fractions


def _smoke_echoes(
    instants: Instants,
    crossings: BeamPuffCrossings,
    factor: np.ndarray,
    start: np.ndarray,
    end: np.ndarray,
    extinction: float,
    receiver: ReceiverOptics,
    params: PhysicalParams,
) -> SmokeEchoes:
    from emulator.sensors.physical import echo_kernels  # numba loads with the first `physical` scan

    rows = np.flatnonzero(np.isfinite(start) & (end > start)) if params.backscatter else np.zeros(0, dtype=np.int64)
    low = start[rows]
    length = end[rows] - low
    grid = _smoke_grid(params)
    edges = low[:, None] + length[:, None] * grid.fractions
    path = _region_path_to(instants, rows, edges)
    path += crossings.optical_path_on_grid(rows, low, length, grid.fractions)
    path *= factor.take(rows)[:, None]
    transmission = path * (-2.0 * extinction)
    np.exp(transmission, out=transmission)
    overlap_m, gain_ramp_m = receiver.overlap_m, receiver.gain_ramp_m
    amp, mid = echo_kernels.smoke_bin_powers(
        path, transmission, low, length,
        grid.inverse_widths * (extinction / params.multiple_scattering_extinction),  # bin widths as fractions of the extent
        grid.middles,
        receiver.volume_gain * params.backscatter_ratio,  # raised by multiple scattering in dense smoke
        overlap_m**2, gain_ramp_m, reference_spreading(params.reference_range_m, overlap_m, gain_ramp_m),
    )
    return SmokeEchoes(rows, amp, mid, edges, grid.fractions)


@dataclass(frozen=True)
class _SmokeGrid:
    """The range bins along a beam's smoke as fractions of its extent: edges (M+1,), middles (M,),
    1 / widths (M,). Read-only, computed once per parameter set."""

    fractions: np.ndarray
    middles: np.ndarray
    inverse_widths: np.ndarray


@functools.lru_cache(maxsize=16)
def _smoke_grid_of(bins: int, growth: float) -> _SmokeGrid:
    fractions = _bin_fractions(bins, growth)
    grid = _SmokeGrid(fractions, 0.5 * (fractions[1:] + fractions[:-1]), 1.0 / np.diff(fractions))
    grid.middles.flags.writeable = False
    grid.inverse_widths.flags.writeable = False
    return grid


def _smoke_grid(params: PhysicalParams) -> _SmokeGrid:
    return _smoke_grid_of(params.bins, params.bin_growth)
