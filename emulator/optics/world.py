"""`World`: a scene prepared for casting beams, and `cast` at any time t.

The only module that talks to Embree (embreex). Solid objects are merged into
one Embree triangle mesh with a per-triangle object id; Embree finds each
beam's first triangle and the distance is then recomputed in float64 from that
triangle's plane (Embree works in float32). Smoke regions use exact analytic
chords (`chords.py`); plume particles are axis-aligned boxes met by a
vectorised slab test over beams × particles.

Fixed objects (and those on bodies without a trajectory) and region shapes
never move: what a fixed set of beams meets of them is computed once by
`prepare` (a sensor keeps it), and `cast_prepared` adds what changes with
time (region densities, particles, and the objects riding on moving bodies,
`moving.py`, each beam at its own instant). Only the first particle per beam
is computed on demand, as the `physical` preset never asks for it.
`World.bodies` holds every body's pose source; a live body's poses are fed in
through `World.bodies.add_live_pose`. Live changes from the control API enter
through `World.apply` (`scene/live.py`): densities and plume emissions from
`World.live`, poses into `World.bodies`, each from its instant on.
"""

from __future__ import annotations

from collections import OrderedDict

import numpy as np
import trimesh
from embreex.mesh_construction import TriangleMesh
from embreex.rtcore_scene import EmbreeScene

from emulator.errors import SceneError
from emulator.optics.candidates import candidate_pairs
from emulator.optics.fans import beam_segments
from emulator.optics.first_boxes import first_boxes
from emulator.optics.chords import NO_HIT, gathered_cube_intervals, paired_cube_intervals_by_axis, shape_intervals
from emulator.optics.hits import BeamHits, PreparedBeams, RegionCrossing
from emulator.optics.moving import MovingSolids, Solids, exact_hits, triangle_planes
from emulator.scene.bodies import BodyPoses, mounted_matrix
from emulator.scene.geometry import shape_mesh, world_mesh, world_to_local
from emulator.scene.live import LiveState, WorldEvent
from emulator.scene.model import MeshFile, Scene, SceneObject
from emulator.scene.plumes import Particles, particles_at


PARTICLE_INSTANTS_KEPT = 16  # two batches of scans (daemon/scan_cache.py SCAN_BATCH = 8)


class World:
    """A scene ready for casting: build once per scene, cast at any time."""

    def __init__(self, scene: Scene) -> None:
        self.scene = scene
        self.bodies = BodyPoses(scene.bodies)
        fixed = [(i, self._fixed_mesh(obj)) for i, obj in enumerate(scene.objects) if not self._rides_moving_body(obj.body)]
        meshes = [mesh for _, mesh in fixed]
        triangles = np.concatenate([m.triangles for m in meshes]) if meshes else np.zeros((0, 3, 3))
        normals = np.concatenate([m.face_normals for m in meshes]) if meshes else np.zeros((0, 3))
        self._triangle_planes = triangle_planes(triangles, normals)
        self._triangle_object = np.concatenate(
            [np.full(len(m.faces), i, dtype=np.int64) for i, m in fixed] or [np.zeros(0, np.int64)]
        )
        self._object_reflectivity = np.array([self._reflectivity(obj.material) for obj in scene.objects], dtype=float)
        self.moving = MovingSolids(scene, self.bodies, self._object_reflectivity)
        self._embree: EmbreeScene | None = None
        if len(triangles):
            self._embree = EmbreeScene()
            TriangleMesh(self._embree, triangles.astype(np.float32))
        self._region_meshes: dict[int, trimesh.Trimesh] = {
            i: shape_mesh(region.shape) for i, region in enumerate(scene.regions) if isinstance(region.shape, MeshFile)
        }
        self.live = LiveState(scene, self.bodies)
        self._particles: OrderedDict[tuple[int, float], Particles] = OrderedDict()

    def apply(self, event: WorldEvent) -> WorldEvent:
        """A live change, in force from its instant on (scans at or after it must be recomputed); the
        event as applied (a twist resolved). ValueError for a pose or twist stamped before the body's
        last one (live bodies only move forward)."""
        return self.live.apply(event)

    def _rides_moving_body(self, body: str | None) -> bool:
        return body is not None and self.scene.body(body).moving

    def _fixed_mesh(self, obj: SceneObject) -> trimesh.Trimesh:
        """A fixed object's mesh in the world (on a body without a trajectory: placed by the body's pose)."""
        if obj.body is None:
            return world_mesh(obj.shape, obj.pose)
        mesh = shape_mesh(obj.shape).copy()
        mesh.apply_transform(mounted_matrix(self.scene.body(obj.body), obj.pose))
        return mesh

    def _reflectivity(self, material: str) -> float:
        if material not in self.scene.materials:
            raise SceneError(f"{self.scene.name}: unknown material {material!r}")
        return float(self.scene.materials[material].reflectivity)

    def particles_at(self, time_s: float) -> Particles:
        """All plumes' particles alive at `time_s` (the last PARTICLE_INSTANTS_KEPT instants' are kept:
        a scan asks twice, a batch of scans once to size its passes and once to cross them)."""
        key = (self.live.generation, time_s)  # a live change makes the kept particles stale
        kept = self._particles.get(key)
        if kept is not None:
            self._particles.move_to_end(key)
            return kept
        particles = Particles.concatenate(
            [
                particles_at(plume, self.scene.seed, i, time_s, self.live.plume_segments(i))
                for i, plume in enumerate(self.scene.plumes)
            ]
        )
        for array in (particles.centers, particles.half_sizes, particles.density, particles.index):
            array.flags.writeable = False  # shared by every caller at this instant
        self._particles[key] = particles
        if len(self._particles) > PARTICLE_INSTANTS_KEPT:
            self._particles.popitem(last=False)
        return particles

    def first_triangles(self, origins: np.ndarray, directions: np.ndarray, max_range_m: float) -> np.ndarray:
        """Embree's first triangle index per ray within max_range_m (-1 for none): the plain INTERSECT."""
        if self._embree is None:
            return np.full(len(origins), -1, dtype=np.int64)
        limits = np.full(len(origins), max_range_m, dtype=np.float32)
        return self._embree.run(
            np.ascontiguousarray(origins, dtype=np.float32),
            np.ascontiguousarray(directions, dtype=np.float32),
            dists=limits,
        )

    def cast(
        self, origins: np.ndarray, directions: np.ndarray, max_range_m: float, time_s: float, beam_times_s: np.ndarray | None = None
    ) -> BeamHits:
        """Cast beams from `origins` (N, 3) along unit `directions` (N, 3) at `time_s` (moving bodies'
        objects at each beam's own instant `beam_times_s` (N,) when given)."""
        return self.cast_prepared(self.prepare(origins, directions, max_range_m), time_s, beam_times_s)

    def solids(
        self, origins: np.ndarray, directions: np.ndarray, max_range_m: float, time_s: float, beam_times_s: np.ndarray | None = None
    ) -> Solids:
        """First solid hit per beam at `time_s` (moving bodies' solids at `beam_times_s`), without the smoke."""
        origins = np.asarray(origins, dtype=float)
        directions = np.asarray(directions, dtype=float)
        solids = Solids(*self._solids(origins, directions, max_range_m))
        if not self.moving:
            return solids
        times = np.full(len(origins), time_s) if beam_times_s is None else np.asarray(beam_times_s, dtype=float)
        return self.moving.nearest(solids, origins, directions, max_range_m, times)

    def prepare(self, origins: np.ndarray, directions: np.ndarray, max_range_m: float) -> PreparedBeams:
        """What the beams meet of the scene's fixed geometry: solids and region intervals."""
        origins = np.asarray(origins, dtype=float)
        directions = np.asarray(directions, dtype=float)
        solid_range, object_index, reflectivity, cos_incidence = self._solids(origins, directions, max_range_m)
        intervals = tuple(
            self._region_intervals(i, origins, directions, max_range_m) for i in range(len(self.scene.regions))
        )
        beam_end = np.minimum(solid_range, max_range_m)
        lengths = tuple(RegionCrossing(i, 0.0, *interval).length_before(beam_end) for i, interval in enumerate(intervals))
        shared = (solid_range, object_index, reflectivity, cos_incidence, beam_end, *lengths, *sum(intervals, ()))
        for array in shared:
            array.flags.writeable = False  # shared by every scan of these beams
        return PreparedBeams(
            origins, directions, max_range_m, solid_range, object_index, reflectivity, cos_incidence, intervals, lengths,
            beam_end,
        )

    def cast_prepared(self, prepared: PreparedBeams, time_s: float, beam_times_s: np.ndarray | None = None) -> BeamHits:
        """`cast` of prepared beams at `time_s`: the smoke, and the moving bodies' objects at each
        beam's instant in `beam_times_s` (N,) (all at `time_s` when None)."""
        if self.moving and not prepared.with_moving_solids:
            times = np.full(len(prepared.origins), time_s) if beam_times_s is None else beam_times_s
            prepared = self.with_moving_solids(prepared, times)
        regions = tuple(
            RegionCrossing(i, self.live.region_density(i, time_s), *prepared.region_intervals[i])
            for i in range(len(self.scene.regions))
        )
        optical_path = np.zeros(len(prepared.origins))
        for crossing, length in zip(regions, prepared.region_lengths):
            if crossing.density:
                optical_path += crossing.density * length
        beam_end = prepared.beam_end_m
        return BeamHits(
            time_s=time_s,
            max_range_m=prepared.max_range_m,
            solid_range_m=prepared.solid_range_m,
            object_index=prepared.object_index,
            reflectivity=prepared.reflectivity,
            cos_incidence=prepared.cos_incidence,
            beam_end_m=beam_end,
            region_optical_path=optical_path,
            regions=regions,
            first_particle=lambda: self._first_particle(prepared.origins, prepared.directions, beam_end, time_s),
        )

    def with_moving_solids(self, prepared: PreparedBeams, beam_times_s: np.ndarray) -> PreparedBeams:
        """`prepared` with the moving bodies' objects added where they are nearer at each beam's instant
        (fresh, writeable arrays: they hold for these instants only, so no cache keeps them). Several
        scans' beams can be done at once and cast one scan at a time (`PreparedBeams.rows`)."""
        if not self.moving:
            return prepared
        times = np.asarray(beam_times_s, dtype=float)
        fixed = Solids(prepared.solid_range_m, prepared.object_index, prepared.reflectivity, prepared.cos_incidence)
        solids = self.moving.nearest(fixed, prepared.origins, prepared.directions, prepared.max_range_m, times)
        beam_end = np.minimum(solids.range_m, prepared.max_range_m)
        lengths = tuple(
            RegionCrossing(i, 0.0, *interval).length_before(beam_end) for i, interval in enumerate(prepared.region_intervals)
        )
        return PreparedBeams(
            prepared.origins, prepared.directions, prepared.max_range_m, solids.range_m, solids.object_index,
            solids.reflectivity, solids.cos_incidence, prepared.region_intervals, lengths, beam_end, True,
        )

    def _solids(
        self, origins: np.ndarray, directions: np.ndarray, max_range_m: float
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """First solid hit per beam; the distance recomputed in float64 from the hit triangle's plane."""
        if self._embree is None:
            nothing = np.zeros(len(origins))
            return np.full(len(origins), np.inf), np.full(len(origins), -1, dtype=np.int64), nothing, nothing.copy()
        triangle = self.first_triangles(origins, directions, max_range_m)
        solids = exact_hits(
            triangle, self._triangle_planes, self._triangle_object, self._object_reflectivity, origins, directions, max_range_m
        )
        return solids.range_m, solids.object_index, solids.reflectivity, solids.cos_incidence

    def _region_intervals(
        self, index: int, origins: np.ndarray, directions: np.ndarray, max_range_m: float
    ) -> tuple[np.ndarray, np.ndarray]:
        """Entry and exit (N, K) of the beams in region `index`, clipped to [0, max_range_m]; inf where missing."""
        region = self.scene.regions[index]
        local_origins, local_directions = world_to_local(region.pose, origins, directions)
        entry, exit_ = shape_intervals(region.shape, local_origins, local_directions, self._region_meshes.get(index))
        entry = np.maximum(entry, 0.0)
        exit_ = np.minimum(exit_, max_range_m)
        missing = ~(exit_ > entry)
        return np.where(missing, NO_HIT, entry), np.where(missing, NO_HIT, exit_)

    def _first_particle(
        self, origins: np.ndarray, directions: np.ndarray, beam_end: np.ndarray, time_s: float
    ) -> tuple[np.ndarray, np.ndarray]:
        """Entry distance and density of the first particle box before each beam's end.

        The particles' bounding spheres pick candidate pairs (`candidates.py`);
        the exact slab test runs on those that can come first (`first_boxes.py`).
        """
        particles = self.particles_at(time_s)
        if len(particles) == 0 or len(origins) == 0:
            return np.full(len(origins), np.inf), np.zeros(len(origins))
        radius = particles.half_sizes * np.sqrt(3.0)
        beam, particle, along = candidate_pairs(origins, directions, beam_end, particles.centers, radius)
        fan = beam_segments(origins, directions, beam_end).fan  # kept: candidate_pairs just asked for it
        if fan is not None:  # one origin: each beam's 1/direction and each box's offset once, not per pair
            offsets = np.subtract(particles.centers.T, origins[0][:, None], order="C")

            def intervals(pairs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
                return gathered_cube_intervals(
                    fan.inverse_directions_by_axis, offsets, particles.half_sizes, beam.take(pairs), particle.take(pairs)
                )
        else:
            origins_by_axis, directions_by_axis = np.ascontiguousarray(origins.T), np.ascontiguousarray(directions.T)
            centers_by_axis = np.ascontiguousarray(particles.centers.T)

            def intervals(pairs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
                beams, boxes = beam.take(pairs), particle.take(pairs)
                return paired_cube_intervals_by_axis(
                    origins_by_axis.take(beams, axis=1), directions_by_axis.take(beams, axis=1),
                    centers_by_axis.take(boxes, axis=1), particles.half_sizes.take(boxes),
                )
        return first_boxes(beam, particle, along - radius.take(particle), intervals, beam_end, particles.density)
