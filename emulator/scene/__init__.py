"""The scene: loading and validating scene files, and the immutable data they become."""

from emulator.scene.loader import BundledScene, bundled_scenes, load_scene
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
    SensorSpec,
    Shape,
    SmokeRegion,
    Sphere,
    Vec3,
)

__all__ = [
    "Box",
    "BundledScene",
    "Cylinder",
    "Density",
    "Material",
    "MeshFile",
    "Plume",
    "Pose",
    "Scene",
    "SceneObject",
    "SensorSpec",
    "Shape",
    "SmokeRegion",
    "Sphere",
    "Vec3",
    "bundled_scenes",
    "load_scene",
]
