"""Scenes built from the dataclasses for the `physical` model's tests."""

from __future__ import annotations

from emulator.scene.materials import BUILTIN_MATERIALS
from emulator.scene.model import Box, Density, Material, Plume, Pose, Scene, SceneObject, SensorSpec, SmokeRegion

SENSOR_HEIGHT_M = 0.3


def target(name: str, distance_m: float, material: str, yaw_deg: float = 0.0, width_m: float = 1.2) -> SceneObject:
    """A thin vertical panel whose front face is `distance_m` ahead of the sensor."""
    return SceneObject(name, Box((0.05, width_m, 1.0)), Pose((distance_m + 0.025, 0.0, 0.5), (0.0, 0.0, yaw_deg)), material)


def room(density: float | tuple[tuple[float, float], ...], size_m: float = 8.0) -> SmokeRegion:
    keyframes = density if isinstance(density, tuple) else ((0.0, float(density)),)
    return SmokeRegion("room", Box((size_m, size_m, 3.0)), Pose((0.0, 0.0, 1.5)), Density(keyframes))


def sensors(*models: str) -> tuple[SensorSpec, ...]:
    return tuple(SensorSpec(model[:3], model, Pose((0.0, 0.0, SENSOR_HEIGHT_M)), ()) for model in models)


def scene(
    objects: tuple[SceneObject, ...] = (),
    regions: tuple[SmokeRegion, ...] = (),
    plumes: tuple[Plume, ...] = (),
    models: tuple[str, ...] = ("urg-04lx", "lms200"),
    seed: int = 7,
    model: str = "physical",
    materials: dict[str, Material] | None = None,
) -> Scene:
    return Scene(
        path=None,
        name="test",
        description="",
        seed=seed,
        model=model,
        density_to_extinction=250.0,
        materials={**BUILTIN_MATERIALS, **(materials or {})},
        objects=objects,
        regions=regions,
        plumes=plumes,
        sensors=sensors(*models),
    )
