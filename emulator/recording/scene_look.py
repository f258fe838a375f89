"""How the scene looks in a viewer (Foxglove, the browser view): colours, smoke opacity, quaternions.

Scene materials carry only a reflectivity at the laser's wavelength, so a
material's colour is made up, but stable: its hue from its name, its
lightness from its reflectivity (a dark surface returns little light).
A smoke volume is as opaque as the light it stops across its own thickness,
1 − exp(−density · density_to_extinction · thickness), so a haze the sensors
see through stays faint and a region they cannot see through looks dense.
"""

from __future__ import annotations

import colorsys
import zlib

import numpy as np

from emulator.scene.model import Box, Cylinder, Scene, Shape, Sphere

RGB = tuple[float, float, float]
SMOKE_RGB: RGB = (0.55, 0.55, 0.58)
MAX_SMOKE_ALPHA = 0.85
MIN_VISIBLE_ALPHA = 0.04  # a region with any smoke at all stays visible


def material_rgb(scene: Scene, material: str) -> RGB:
    """A stable colour for the material: hue from its name, lightness from its reflectivity."""
    found = scene.materials.get(material)
    reflectivity = found.reflectivity if found is not None else 0.5
    hue = (zlib.crc32(material.encode()) % 360) / 360.0
    return colorsys.hls_to_rgb(hue, 0.2 + 0.55 * reflectivity, 0.22)


def thickness_m(shape: Shape) -> float:
    """A volume's smallest extent: the path light takes across it."""
    if isinstance(shape, Box):
        return float(min(shape.size))
    if isinstance(shape, Sphere):
        return 2.0 * shape.radius
    if isinstance(shape, Cylinder):
        return float(min(2.0 * shape.radius, shape.height))
    return 1.0


def smoke_alpha(density: float | np.ndarray, extinction_per_density: float, thickness: float | np.ndarray) -> np.ndarray:
    """Opacity of smoke of `density` across `thickness` metres (module docstring)."""
    density = np.maximum(np.asarray(density, dtype=float), 0.0)
    alpha = MAX_SMOKE_ALPHA * (1.0 - np.exp(-density * extinction_per_density * np.asarray(thickness)))
    return np.where(density > 0.0, np.maximum(alpha, MIN_VISIBLE_ALPHA), 0.0)


def quaternion_xyzw(rotation_deg: tuple[float, float, float]) -> tuple[float, float, float, float]:
    """Roll, pitch, yaw (degrees; R = Rz·Ry·Rx, as `Pose`) as a unit quaternion (x, y, z, w)."""
    roll, pitch, yaw = np.radians(rotation_deg) / 2.0
    cr, sr, cp, sp, cy, sy = np.cos(roll), np.sin(roll), np.cos(pitch), np.sin(pitch), np.cos(yaw), np.sin(yaw)
    return (
        float(sr * cp * cy - cr * sp * sy),
        float(cr * sp * cy + sr * cp * sy),
        float(cr * cp * sy - sr * sp * cy),
        float(cr * cp * cy + sr * sp * sy),
    )


def range_rgb(ranges_m: np.ndarray, max_range_m: float) -> np.ndarray:
    """(N, 3) uint8 colours for finite ranges: near yellow through green to far blue."""
    fraction = np.clip(np.asarray(ranges_m, dtype=float) / max(max_range_m, 1e-9), 0.0, 1.0)[:, None]
    near, far = np.array([255.0, 220.0, 0.0]), np.array([40.0, 90.0, 255.0])
    return (near + (far - near) * fraction).astype(np.uint8)
