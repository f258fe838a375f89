"""World.cast: solid hits, exact smoke chords for every shape, keyframes, particles."""

from __future__ import annotations

import math

import numpy as np
import pytest
import trimesh
from hypothesis import given, settings
from hypothesis import strategies as st

from emulator.optics import World
from emulator.optics.chords import slab_intervals
from emulator.scene.model import (
    Box,
    Cylinder,
    Density,
    Material,
    MeshFile,
    Plume,
    Pose,
    Scene,
    SceneObject,
    SmokeRegion,
    Sphere,
)

MATERIALS = {"default": Material("default", 0.5), "white": Material("white", 0.9)}


def scene(objects=(), regions=(), plumes=(), seed=1) -> Scene:
    return Scene(None, "test", "", seed, "formsma2011", 250.0, MATERIALS, tuple(objects), tuple(regions), tuple(plumes), ())


def region(shape, position=(0.0, 0.0, 0.0), rotation=(0.0, 0.0, 0.0), density=0.001) -> SmokeRegion:
    keyframes = density if isinstance(density, Density) else Density(((0.0, density),))
    return SmokeRegion("smoke", shape, Pose(position, rotation), keyframes)


def parked_particle(center, edge, density=0.05) -> Plume:
    """A plume whose particles all sit still at the source: one fixed box."""
    return Plume("parked", tuple(center), 1.0, 1e6, edge, 0.0, (0.0, 0.0, 0.0), 0.0, (0.0, 0.0, 0.0), density)


def rays(origins, directions):
    origins = np.atleast_2d(np.asarray(origins, dtype=float))
    directions = np.atleast_2d(np.asarray(directions, dtype=float))
    directions = directions / np.linalg.norm(directions, axis=1, keepdims=True)
    return np.broadcast_to(origins, directions.shape).copy(), directions


def chord(world: World, origins, directions, max_range=100.0, time_s=0.0) -> np.ndarray:
    o, d = rays(origins, directions)
    hits = world.cast(o, d, max_range, time_s)
    (crossing,) = hits.regions
    return crossing.length_before(np.full(len(o), max_range))


# --- solids -------------------------------------------------------------------------------------


def test_solid_range_object_reflectivity_and_incidence():
    wall = SceneObject("wall", Box((0.2, 4.0, 2.0)), Pose((3.1, 0.0, 0.0), (0.0, 0.0, 30.0)), "white")
    post = SceneObject("post", Cylinder(0.1, 2.0), Pose((0.0, 2.0, 0.0)), "default")
    world = World(scene([wall, post]))
    o, d = rays([0.0, 0.0, 0.0], [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, -1.0, 0.0]])
    hits = world.cast(o, d, 10.0, 0.0)
    # the wall's near face is 0.1 m in front of its centre along its normal (cos 30° from +x)
    expected = (3.1 * math.cos(math.radians(30.0)) - 0.1) / math.cos(math.radians(30.0))
    assert hits.solid_range_m[0] == pytest.approx(expected, abs=1e-12)
    assert hits.object_index.tolist() == [0, 1, -1]
    assert hits.reflectivity.tolist() == [0.9, 0.5, 0.0]
    assert hits.cos_incidence[0] == pytest.approx(math.cos(math.radians(30.0)), abs=1e-9)
    assert hits.solid_range_m[1] == pytest.approx(1.9, abs=2e-3)  # faceted cylinder
    assert hits.solid_range_m[2] == np.inf


def test_a_solid_beyond_the_maximum_range_is_not_hit():
    wall = SceneObject("wall", Box((0.2, 4.0, 2.0)), Pose((5.7, 0.0, 0.0)), "white")
    hits = World(scene([wall])).cast(*rays([0, 0, 0], [1, 0, 0]), 5.6, 0.0)
    assert hits.solid_range_m[0] == np.inf and hits.object_index[0] == -1


# --- exact chords -------------------------------------------------------------------------------


@pytest.mark.parametrize("offset", [0.0, 0.2, -0.5, 0.69])
def test_rotated_box_chord_is_exact(offset):
    """A unit cube turned 45° about z: a ray at lateral offset h crosses 2·(1/√2 − |h|)."""
    world = World(scene(regions=[region(Box((1.0, 1.0, 1.0)), (3.0, 0.0, 0.0), (0.0, 0.0, 45.0))]))
    got = chord(world, [0.0, offset, 0.0], [1.0, 0.0, 0.0])
    assert got[0] == pytest.approx(2.0 * (1.0 / math.sqrt(2.0) - abs(offset)), abs=1e-12)


def test_tilted_box_chord_is_exact():
    """A slab 0.5 m thick pitched by 60°: a horizontal ray crosses 0.5 / cos(60°)."""
    world = World(scene(regions=[region(Box((0.5, 10.0, 10.0)), (4.0, 0.0, 0.0), (0.0, 60.0, 0.0))]))
    assert chord(world, [0, 0, 0], [1, 0, 0])[0] == pytest.approx(1.0, abs=1e-12)


@pytest.mark.parametrize("offset", [0.0, 0.3, 0.99])
def test_sphere_chord_is_exact(offset):
    world = World(scene(regions=[region(Sphere(1.0), (5.0, 0.0, 0.0))]))
    assert chord(world, [0.0, 0.0, offset], [1, 0, 0])[0] == pytest.approx(2 * math.sqrt(1 - offset**2), abs=1e-12)


def test_sphere_chord_from_inside_counts_from_the_origin():
    world = World(scene(regions=[region(Sphere(2.0), (0.5, 0.0, 0.0))]))
    assert chord(world, [0, 0, 0], [[1, 0, 0], [-1, 0, 0]]).tolist() == pytest.approx([2.5, 1.5], abs=1e-12)


def test_cylinder_chords_through_side_caps_and_axis():
    world = World(scene(regions=[region(Cylinder(0.5, 2.0), (4.0, 0.0, 0.0))]))
    # perpendicular to the axis at height offset 0.7 (within the caps): the circle's chord
    assert chord(world, [0.0, 0.2, 0.7], [1, 0, 0])[0] == pytest.approx(2 * math.sqrt(0.25 - 0.04), abs=1e-12)
    # along the axis from below: the height
    assert chord(world, [4.0, 0.1, -3.0], [0, 0, 1])[0] == pytest.approx(2.0, abs=1e-12)
    # through the centre at 10° from the axis: enters and leaves through the caps
    theta = math.radians(10.0)
    direction = [math.sin(theta), 0.0, math.cos(theta)]
    start = np.array([4.0, 0.0, 0.0]) - 3.0 * np.array(direction)
    assert chord(world, start, direction)[0] == pytest.approx(2.0 / math.cos(theta), abs=1e-12)
    # through the centre at 80° from the axis: through the side
    theta = math.radians(80.0)
    direction = [math.sin(theta), 0.0, math.cos(theta)]
    start = np.array([4.0, 0.0, 0.0]) - 3.0 * np.array(direction)
    assert chord(world, start, direction)[0] == pytest.approx(1.0 / math.sin(theta), abs=1e-12)


def test_rotated_cylinder_lying_across_the_beam():
    world = World(scene(regions=[region(Cylinder(0.3, 1.0), (2.0, 0.0, 0.0), (90.0, 0.0, 0.0))]))
    assert chord(world, [0.0, 0.0, 0.1], [1, 0, 0])[0] == pytest.approx(2 * math.sqrt(0.09 - 0.01), abs=1e-12)
    assert chord(world, [0.0, 0.6, 0.0], [1, 0, 0])[0] == 0.0  # beyond the cap


def mesh_region(tmp_path, mesh: trimesh.Trimesh, name: str, **pose) -> SmokeRegion:
    path = tmp_path / f"{name}.ply"  # binary PLY keeps float64 vertices (STL rounds to float32)
    mesh.export(path)
    return region(MeshFile(path), **pose)


def test_mesh_box_chords_match_the_analytic_box(tmp_path):
    box = trimesh.creation.box(extents=(1.0, 2.0, 0.5))
    world = World(scene(regions=[mesh_region(tmp_path, box, "box", position=(3.0, 0.0, 0.0), rotation=(0.0, 0.0, 20.0))]))
    analytic = World(scene(regions=[region(Box((1.0, 2.0, 0.5)), (3.0, 0.0, 0.0), (0.0, 0.0, 20.0))]))
    angles = np.radians(np.linspace(-30, 30, 241))
    directions = np.stack([np.cos(angles), np.sin(angles), np.full_like(angles, 0.01)], axis=1)
    assert np.any(chord(analytic, [0, 0, 0], directions) > 0)
    np.testing.assert_allclose(chord(world, [0, 0, 0], directions), chord(analytic, [0, 0, 0], directions), atol=1e-9)


def test_mesh_ray_through_a_shared_edge_is_counted_once(tmp_path):
    """The centre of a box face lies on the diagonal shared by its two triangles."""
    box = trimesh.creation.box(extents=(1.0, 1.0, 1.0))
    world = World(scene(regions=[mesh_region(tmp_path, box, "cube", position=(3.0, 0.0, 0.0))]))
    assert chord(world, [0, 0, 0], [1, 0, 0])[0] == pytest.approx(1.0, abs=1e-12)
    assert chord(world, [0, 0, 0], [1, 0, 0], max_range=3.0)[0] == pytest.approx(0.5, abs=1e-12)


def test_non_convex_mesh_gives_every_interval(tmp_path):
    ring = trimesh.creation.annulus(r_min=1.0, r_max=1.5, height=1.0, sections=512)
    world = World(scene(regions=[mesh_region(tmp_path, ring, "ring", position=(5.0, 0.0, 0.0))]))
    o, d = rays([0.0, 0.0, 0.0], [1, 0, 0])
    (crossing,) = world.cast(o, d, 100.0, 0.0).regions
    entries = np.sort(crossing.entry_m[0][np.isfinite(crossing.entry_m[0])])
    exits = np.sort(crossing.exit_m[0][np.isfinite(crossing.exit_m[0])])
    np.testing.assert_allclose(entries, [3.5, 6.0], atol=1e-12)
    np.testing.assert_allclose(exits, [4.0, 6.5], atol=1e-12)


def test_mesh_chord_from_inside_starts_at_the_origin(tmp_path):
    box = trimesh.creation.box(extents=(2.0, 2.0, 2.0))
    world = World(scene(regions=[mesh_region(tmp_path, box, "room", position=(0.3, 0.0, 0.0))]))
    assert chord(world, [0, 0, 0], [[1, 0, 0], [-1, 0, 0]]).tolist() == pytest.approx([1.3, 0.7], abs=1e-12)


finite = st.floats(-3.0, 3.0)


@settings(max_examples=60, deadline=None)
@given(
    size=st.tuples(*[st.floats(0.125, 3.0, width=32)] * 3),  # mesh files store float32 vertices
    position=st.tuples(finite, finite, finite),
    rotation=st.tuples(st.floats(-180, 180), st.floats(-90, 90), st.floats(-180, 180)),
    seed=st.integers(0, 2**32 - 1),
)
def test_box_slab_and_mesh_crossings_agree_for_any_pose(tmp_path_factory, size, position, rotation, seed):
    """Two independent exact methods (slab in the local frame, every triangle crossing) agree."""
    directory = tmp_path_factory.mktemp("mesh")
    mesh = mesh_region(directory, trimesh.creation.box(extents=size), "box", position=position, rotation=rotation)
    analytic = region(Box(size), position, rotation)
    generator = np.random.default_rng(seed)
    origins = generator.uniform(-4, 4, (64, 3))
    directions = generator.normal(size=(64, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    by_mesh = World(scene(regions=[mesh])).cast(origins, directions, 50.0, 0.0).regions[0]
    by_slab = World(scene(regions=[analytic])).cast(origins, directions, 50.0, 0.0).regions[0]
    limit = np.full(64, 50.0)
    np.testing.assert_allclose(by_mesh.length_before(limit), by_slab.length_before(limit), atol=1e-9)


# --- density in time, overlaps, the solid ----------------------------------------------------------


def test_keyframed_density_is_interpolated_into_the_optical_path():
    keyframes = Density(((0.0, 0.0), (10.0, 0.004), (20.0, 0.004), (30.0, 0.001)))
    world = World(scene(regions=[region(Box((2.0, 2.0, 2.0)), (3.0, 0.0, 0.0), density=keyframes)]))
    o, d = rays([0, 0, 0], [1, 0, 0])
    for time_s, density in [(0.0, 0.0), (5.0, 0.002), (15.0, 0.004), (25.0, 0.0025), (99.0, 0.001), (-5.0, 0.0)]:
        assert world.cast(o, d, 10.0, time_s).region_optical_path[0] == pytest.approx(2.0 * density, abs=1e-15)


def test_overlapping_regions_add_and_stop_at_the_solid():
    room = region(Box((20.0, 20.0, 4.0)), (0.0, 0.0, 0.0), density=0.001)
    cloud = region(Sphere(1.0), (3.0, 0.0, 0.0), density=0.002)
    behind = region(Sphere(0.5), (6.0, 0.0, 0.0), density=0.5)
    wall = SceneObject("wall", Box((0.2, 4.0, 4.0)), Pose((5.1, 0.0, 0.0)), "default")
    world = World(scene([wall], [room, cloud, behind]))
    hits = world.cast(*rays([0, 0, 0], [1, 0, 0]), 10.0, 0.0)
    assert hits.region_optical_path[0] == pytest.approx(0.001 * 5.0 + 0.002 * 2.0, abs=1e-15)
    assert hits.regions[2].entry_m[0, 0] == pytest.approx(5.5)  # reported past the solid, not counted


def test_nothing_solid_counts_smoke_up_to_the_maximum_range():
    world = World(scene(regions=[region(Box((100.0, 1.0, 1.0)), (0.0, 0.0, 0.0), density=0.001)]))
    hits = world.cast(*rays([0, 0, 0], [1, 0, 0]), 5.6, 0.0)
    assert hits.region_optical_path[0] == pytest.approx(0.0056, abs=1e-15)


# --- plume particles --------------------------------------------------------------------------------


def test_first_particle_before_the_solid():
    near = parked_particle((2.0, 0.0, 0.0), 0.4, density=0.07)
    far = parked_particle((3.0, 0.0, 0.0), 0.4, density=0.09)
    beyond = parked_particle((6.0, 1.0, 0.0), 0.4)
    wall = SceneObject("wall", Box((0.2, 4.0, 4.0)), Pose((5.1, 0.0, 0.0)), "default")
    world = World(scene([wall], plumes=[far, near, beyond]))
    o, d = rays([0, 0, 0], [[1, 0, 0], [5.0, 1.0, 0.0], [0, 1, 0], [1, 0.05, 0]])
    hits = world.cast(o, d, 10.0, 4.0)
    assert hits.plume_hit_range_m[0] == pytest.approx(1.8, abs=1e-12)
    assert hits.plume_hit_density[0] == 0.07
    assert hits.plume_hit_range_m[1] == np.inf  # that particle is behind the wall
    assert hits.plume_hit_range_m[2] == np.inf and hits.plume_hit_density[2] == 0.0
    assert hits.plume_hit_range_m[3] == pytest.approx(1.8 / 1.0, rel=2e-3)


def test_origin_inside_a_particle_box_meets_it_at_zero():
    world = World(scene(plumes=[parked_particle((0.1, 0.0, 0.0), 0.5)]))
    assert world.cast(*rays([0, 0, 0], [-1, 0, 0]), 5.0, 1.0).plume_hit_range_m[0] == 0.0


def test_particles_exist_only_once_emitted():
    world = World(scene(plumes=[Plume("p", (2.0, 0.0, 0.0), 1.0, 1e6, 0.4, 0.0, (0, 0, 0), 0.0, (0, 0, 0), 0.05, start=3.0)]))
    o, d = rays([0, 0, 0], [1, 0, 0])
    assert world.cast(o, d, 5.0, 2.9).plume_hit_range_m[0] == np.inf
    assert world.cast(o, d, 5.0, 3.0).plume_hit_range_m[0] == pytest.approx(1.8)


def brute_force_first_entry(world: World, origins, directions, max_range, time_s):
    particles = world.particles_at(time_s)
    half = particles.half_sizes[:, None]
    entry, exit_ = slab_intervals(origins, directions, particles.centers - half, particles.centers + half)
    entry = np.maximum(entry, 0.0)
    return np.where((exit_ >= entry) & (entry < max_range), entry, np.inf).min(axis=1)


def test_many_particles_match_a_brute_force_first_entry():
    """10 000 particles, beams from one origin (a fan) and from many origins (chunked general
    test): the first entry per beam equals a plain minimum over every particle box."""
    fire = Plume("fire", (3.0, 0.0, 0.0), 2000.0, 5.0, 0.05, 0.02, (0.0, 0.0, 0.05), 0.4, (0.0, 0.1, 0.0), 0.05)
    world = World(scene(plumes=[fire], seed=9))
    assert len(world.particles_at(5.0)) == 10_000
    angles = np.radians(np.linspace(-30, 30, 361))
    directions = np.stack([np.cos(angles), np.sin(angles), np.zeros_like(angles)], axis=1)
    spread_origins = np.column_stack([np.zeros(361), np.linspace(-0.5, 0.5, 361), np.zeros(361)])
    for origins in (np.zeros((361, 3)), spread_origins):
        expected = brute_force_first_entry(world, origins, directions, 10.0, 5.0)
        assert np.isfinite(expected).sum() > 100
        got = world.cast(origins, directions, 10.0, 5.0).plume_hit_range_m
        np.testing.assert_allclose(got, expected, rtol=1e-12, atol=1e-12)  # the same to rounding


@settings(max_examples=30, deadline=None)
@given(
    roll=st.floats(-180, 180), pitch=st.floats(-90, 90), yaw=st.floats(-180, 180),
    seed=st.integers(0, 2**32 - 1), beams=st.integers(2, 1024),
)
def test_a_tilted_full_circle_fan_finds_every_particle(roll, pitch, yaw, seed, beams):
    """Beams all around a tilted plane (the fan search wraps around ±180°) against particles
    scattered around and across the origin, compared with the brute-force minimum."""
    cloud = Plume("cloud", (0.0, 0.0, 0.0), 400.0, 5.0, 0.05, 0.05, (0.0, 0.0, 0.0), 0.8, (0.0, 0.0, 0.0), 0.05)
    world = World(scene(plumes=[cloud], seed=seed))
    angles = np.linspace(-np.pi, np.pi, beams, endpoint=False)
    local = np.stack([np.cos(angles), np.sin(angles), np.zeros_like(angles)], axis=1)
    directions = local @ Pose((0, 0, 0), (roll, pitch, yaw)).rotation_matrix().T
    origins = np.tile([0.6, -0.3, 0.02], (beams, 1))
    expected = brute_force_first_entry(world, origins, directions, 8.0, 5.0)
    got = world.cast(origins, directions, 8.0, 5.0).plume_hit_range_m
    np.testing.assert_allclose(got, expected, rtol=1e-12, atol=1e-12)  # the same to rounding
    if beams >= 256 and not np.all(expected == 0.0):  # unless the origin is in a box: particles and open air
        assert np.any((expected > 0) & np.isfinite(expected)) and np.any(np.isinf(expected))


def test_kept_values_follow_the_identity_of_read_only_arrays():
    from emulator.optics.kept import KeptPerArrays

    kept, calls = KeptPerArrays(), []

    def compute(array):
        calls.append(1)
        return float(array.sum())

    frozen = np.arange(4.0)
    frozen.flags.writeable = False
    assert kept.get((frozen,), "a", lambda: compute(frozen)) == 6.0
    assert kept.get((frozen,), "a", lambda: compute(frozen)) == 6.0 and len(calls) == 1
    assert kept.get((frozen,), "b", lambda: compute(frozen)) == 6.0 and len(calls) == 2  # another extra key
    twin = np.arange(4.0)
    twin.flags.writeable = False
    kept.get((twin,), "a", lambda: compute(twin))  # equal contents, another array: computed again
    assert len(calls) == 3
    writeable = np.ones(3)
    kept.get((writeable,), "a", lambda: compute(writeable))
    writeable[0] = 5.0  # never kept: a change is seen
    assert kept.get((writeable,), "a", lambda: compute(writeable)) == 7.0 and len(calls) == 5


def test_kept_values_outlast_a_fleet_round_and_go_with_their_arrays():
    """A worker computes every sensor of a fleet in turn: a store that holds fewer values than the
    fleet loses each one before its sensor comes round; when full it drops the oldest, and a value
    goes as soon as its arrays die."""
    from emulator.optics.kept import KEPT_VALUES, KeptPerArrays

    from emulator.sensors.physical.noise import _fluctuation_modes

    assert KEPT_VALUES >= 3 * 256  # a few values for every sensor of the largest scene
    assert _fluctuation_modes.cache_info().maxsize >= 256  # its arrays key a store: one per sensor
    kept, calls = KeptPerArrays(size=3), []
    fleet = [np.full(4, float(index)) for index in range(4)]
    for array in fleet:
        array.flags.writeable = False
    for round_ in range(2):
        for array in fleet[:3]:
            kept.get((array,), None, lambda: calls.append(1))
    assert len(calls) == 3  # the second round found all three
    kept.get((fleet[3],), None, lambda: calls.append(1))  # full: the oldest goes, not all
    kept.get((fleet[2],), None, lambda: calls.append(1))
    assert len(calls) == 4 and len(kept) == 3
    del fleet[3]
    assert len(kept) == 2  # its array died
