"""The parsed scene: immutable, validated data (docs/scene-format.md).

Everything here is plain data. Loading and validation live in `loader.py`;
geometry (meshes in the world frame) in `geometry.py`; plume particles as
functions of time in `plumes.py`. Time-varying things are functions of t so
any instant can be evaluated directly and reproducibly from the seed.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Mapping, Union

import numpy as np

if TYPE_CHECKING:
    from emulator.scene.bodies import Body

Vec3 = tuple[float, float, float]


@dataclass(frozen=True)
class Box:
    size: Vec3


@dataclass(frozen=True)
class Sphere:
    radius: float


@dataclass(frozen=True)
class Cylinder:
    """A cylinder along the local z axis, centred on the origin."""

    radius: float
    height: float


@dataclass(frozen=True)
class MeshFile:
    """A mesh file (glb, gltf, obj, stl, ply); `path` is absolute."""

    path: Path


Shape = Union[Box, Sphere, Cylinder, MeshFile]


@dataclass(frozen=True)
class Pose:
    """Position (m) and roll, pitch, yaw (degrees) of a local frame in the world."""

    position: Vec3 = (0.0, 0.0, 0.0)
    rotation_deg: Vec3 = (0.0, 0.0, 0.0)

    def rotation_matrix(self) -> np.ndarray:
        """3x3 rotation R = Rz(yaw) @ Ry(pitch) @ Rx(roll): local → world."""
        roll, pitch, yaw = np.radians(self.rotation_deg)
        cr, sr = np.cos(roll), np.sin(roll)
        cp, sp = np.cos(pitch), np.sin(pitch)
        cy, sy = np.cos(yaw), np.sin(yaw)
        rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
        ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
        rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
        return rz @ ry @ rx

    def matrix(self) -> np.ndarray:
        """4x4 homogeneous transform local → world."""
        m = np.eye(4)
        m[:3, :3] = self.rotation_matrix()
        m[:3, 3] = self.position
        return m


@dataclass(frozen=True)
class Material:
    """Surface optics at the laser wavelength.

    `reflectivity` is the diffuse reflectance (0..1). Further fields used only
    by the `physical` model carry defaults so `formsma2011` scenes never need them.
    """

    name: str
    reflectivity: float = 0.8
    retroreflective: bool = False  # returns light towards its source: the LMS200 flags it as a reflector


@dataclass(frozen=True)
class SceneObject:
    name: str
    shape: Shape
    pose: Pose
    material: str
    body: str | None = None  # riding on this body: `pose` is then relative to the body's frame


@dataclass(frozen=True)
class Density:
    """Smoke density as a piecewise-linear function of time (the paper's Kismet curves).

    A constant density is one keyframe. Before the first and after the last
    keyframe the density holds the end value. Times do not decrease; two
    keyframes at one time are a step (the later one holds from that instant on).
    """

    keyframes: tuple[tuple[float, float], ...]

    @functools.cached_property
    def _table(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Times, values and the rows that start a step (each step's later row), built once."""
        times = np.array([k[0] for k in self.keyframes], dtype=float)
        values = np.array([k[1] for k in self.keyframes], dtype=float)
        return times, values, np.flatnonzero(np.diff(times) == 0) + 1

    def at(self, time_s: float | np.ndarray) -> float | np.ndarray:
        times, values, steps = self._table
        if not len(steps):
            result = np.interp(time_s, times, values)
        else:  # interpolate within the run of rows between steps that holds t
            query = np.asarray(time_s, dtype=float)
            run = np.searchsorted(times[steps], query, side="right")
            bounds = np.concatenate([[0], steps, [len(times)]])
            result = np.zeros(query.shape)
            for index, (low, high) in enumerate(zip(bounds[:-1], bounds[1:])):
                inside = run == index
                result = np.where(inside, np.interp(query, times[low:high], values[low:high]), result)
        return float(result) if np.ndim(result) == 0 else result


@dataclass(frozen=True)
class SmokeRegion:
    """The paper's "smoke area": homogeneous smoke filling a closed shape."""

    name: str
    shape: Shape
    pose: Pose
    density: Density


@dataclass(frozen=True)
class Plume:
    """The paper's "local smoke": particles emitted from a point source."""

    name: str
    source: Vec3
    rate: float
    lifetime: float
    size: float
    growth: float
    velocity: Vec3
    spread: float
    wind: Vec3
    density: float
    start: float = 0.0
    stop: float = 1e9


@dataclass(frozen=True)
class SensorSpec:
    """A sensor in the scene. `options` holds the validated model options
    (docs/scene-format.md), every one filled with the real device's default."""

    name: str
    model: str  # "urg-04lx" | "lms200"
    pose: Pose
    endpoints: tuple[str, ...]
    options: Mapping[str, Any] = field(default_factory=dict)
    body: str | None = None  # riding on this body: `pose` is then relative to the body's frame


@dataclass(frozen=True)
class Scene:
    path: Path | None
    name: str
    description: str
    seed: int
    model: str  # "formsma2011" | "physical"
    density_to_extinction: float
    materials: Mapping[str, Material]
    objects: tuple[SceneObject, ...]
    regions: tuple[SmokeRegion, ...]
    plumes: tuple[Plume, ...]
    sensors: tuple[SensorSpec, ...]
    bodies: tuple[Body, ...] = ()
    camera_reference: bool = False  # a camera watched a reference target in the run (plots add its saturation)

    def body(self, name: str) -> Body:
        for body in self.bodies:
            if body.name == name:
                return body
        raise KeyError(f"no body named {name!r}")

    def sensor(self, name: str) -> SensorSpec:
        for spec in self.sensors:
            if spec.name == name:
                return spec
        known = ", ".join(s.name for s in self.sensors) or "none"
        raise KeyError(f"no sensor named {name!r} (known: {known})")
