"""Small scenes around the paper's reference geometry (section 3.1), for the
`physical` model's tests and validation figures: a sensor 0.3 m above the
floor, a panel `distance_m` ahead, a room of homogeneous smoke."""

from __future__ import annotations

import numpy as np

from emulator.optics import BeamHits, World
from emulator.scene.materials import BUILTIN_MATERIALS
from emulator.scene.model import (
    Box,
    Density,
    Material,
    Plume,
    Pose,
    Scene,
    SceneObject,
    SensorSpec,
    SmokeRegion,
)
from emulator.sensors import lms200, urg04lx
from emulator.sensors.beam_geometry import scan_plane_rays
from emulator.sensors.response import Beams

SENSOR_HEIGHT_M = 0.3
URG_FRONT = urg04lx.FRONT_STEP - urg04lx.FIRST_VALID_STEP  # index of the straight-ahead beam among the valid ones


def panel(name: str, distance_m: float, material: str, yaw_deg: float = 0.0, width_m: float = 1.2) -> SceneObject:
    """A thin vertical panel whose front face is `distance_m` ahead of the sensor (when yaw is 0)."""
    return SceneObject(name, Box((0.05, width_m, 1.0)), Pose((distance_m + 0.025, 0.0, 0.5), (0.0, 0.0, yaw_deg)), material)


def room(density: float, size_m: float = 12.0) -> SmokeRegion:
    """Homogeneous smoke around the sensor and everything within size_m / 2."""
    return SmokeRegion("room", Box((size_m, size_m, 3.0)), Pose((0.0, 0.0, 1.5)), Density(((0.0, float(density)),)))


def reference_scene(
    objects: tuple[SceneObject, ...] = (),
    regions: tuple[SmokeRegion, ...] = (),
    plumes: tuple[Plume, ...] = (),
    seed: int = 7,
    materials: dict[str, Material] | None = None,
    density_to_extinction: float = 250.0,
) -> Scene:
    """A `physical` scene with a URG-04LX named "urg" and an LMS200 named "lms" at the origin."""
    pose = Pose((0.0, 0.0, SENSOR_HEIGHT_M))
    return Scene(
        path=None,
        name="reference",
        description="",
        seed=seed,
        model="physical",
        density_to_extinction=density_to_extinction,
        materials={**BUILTIN_MATERIALS, **(materials or {})},
        objects=objects,
        regions=regions,
        plumes=plumes,
        sensors=(SensorSpec("urg", urg04lx.MODEL, pose, ()), SensorSpec("lms", lms200.MODEL, pose, ())),
    )


def cast_beams(scene: Scene, sensor: str, angles_rad: np.ndarray, time_s: float, world: World | None = None) -> tuple[BeamHits, Beams]:
    """Cast `angles_rad` (sensor frame) of `sensor` at `time_s`: what a response model receives."""
    world = world if world is not None else World(scene)
    spec = scene.sensor(sensor)
    origins, directions = scan_plane_rays(spec.pose, np.asarray(angles_rad, dtype=float))
    reach = urg04lx.MAX_RANGE_M if spec.model == urg04lx.MODEL else lms200.REACH_M
    hits = world.cast(origins, directions, reach, time_s)
    return hits, Beams(scene, spec, world, time_s, np.asarray(angles_rad, dtype=float), origins, directions)
