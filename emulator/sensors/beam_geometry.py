"""Beams of a planar scanner: sensor-frame angles → world origins and directions."""

from __future__ import annotations

import numpy as np

from emulator.scene.model import Pose


def scan_plane_rays(pose: Pose, angles_rad: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Origins and unit directions (N, 3) of beams in the sensor's xy-plane.

    Angle 0 is the sensor's +x, positive toward its +y (left). The arrays are
    read-only: sensors cache them and share them with every scan.
    """
    local = np.stack([np.cos(angles_rad), np.sin(angles_rad), np.zeros_like(angles_rad)], axis=1)
    directions = local @ pose.rotation_matrix().T
    origins = np.broadcast_to(np.asarray(pose.position, dtype=float), directions.shape).copy()
    origins.flags.writeable = directions.flags.writeable = False
    return origins, directions
