"""Comparing an estimated 2-D path with the ground truth: rigid alignment and absolute trajectory error.

A SLAM system reports its path in its own frame (icp-slam: the first scan's),
so the estimate is first moved onto the truth by the rotation and translation
that minimise the summed squared position error (Umeyama 1991 / Horn 1987,
without scale: a laser measures metres); the absolute trajectory error (ATE)
is then the RMS of the remaining position differences, as TUM's and evo's
`ape` tools compute it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class RigidTransform2D:
    """x' = rotation @ x + translation."""

    rotation: np.ndarray  # (2, 2)
    translation: np.ndarray  # (2,)

    @property
    def angle_rad(self) -> float:
        return float(np.arctan2(self.rotation[1, 0], self.rotation[0, 0]))

    def apply(self, poses: np.ndarray) -> np.ndarray:
        """Poses (n, 3) of x, y, yaw moved by this transform (yaw wrapped to (-pi, pi])."""
        moved = np.array(poses, dtype=float, copy=True)
        moved[:, :2] = poses[:, :2] @ self.rotation.T + self.translation
        moved[:, 2] = wrap_angle(poses[:, 2] + self.angle_rad)
        return moved


def wrap_angle(angles: np.ndarray) -> np.ndarray:
    """Angles in radians wrapped to (-pi, pi]."""
    return np.pi - np.mod(np.pi - np.asarray(angles, dtype=float), 2 * np.pi)


def align_rigid_2d(estimate_xy: np.ndarray, truth_xy: np.ndarray) -> RigidTransform2D:
    """The rotation and translation carrying `estimate_xy` (n, 2) closest to `truth_xy` (n, 2) in the
    least-squares sense (Umeyama's SVD solution, reflection excluded)."""
    estimate_xy = np.asarray(estimate_xy, dtype=float)
    truth_xy = np.asarray(truth_xy, dtype=float)
    if estimate_xy.shape != truth_xy.shape or estimate_xy.ndim != 2 or estimate_xy.shape[1] != 2:
        raise ValueError(f"expected two (n, 2) arrays, got {estimate_xy.shape} and {truth_xy.shape}")
    if len(estimate_xy) < 2:
        raise ValueError("alignment needs at least two poses")
    mean_estimate, mean_truth = estimate_xy.mean(axis=0), truth_xy.mean(axis=0)
    covariance = (truth_xy - mean_truth).T @ (estimate_xy - mean_estimate) / len(estimate_xy)
    u, _, vt = np.linalg.svd(covariance)
    sign = np.diag([1.0, np.sign(np.linalg.det(u @ vt)) or 1.0])
    rotation = u @ sign @ vt
    return RigidTransform2D(rotation, mean_truth - rotation @ mean_estimate)


@dataclass(frozen=True)
class TrajectoryError:
    """ATE after alignment: RMS and maximum position error (m), RMS heading error (rad)."""

    rmse_m: float
    max_m: float
    heading_rmse_rad: float
    aligned: np.ndarray  # (n, 3) the estimate in the truth's frame
    transform: RigidTransform2D


def absolute_trajectory_error(estimate: np.ndarray, truth: np.ndarray) -> TrajectoryError:
    """Align `estimate` (n, 3: x, y, yaw) onto `truth` (n, 3) and measure what remains."""
    estimate, truth = np.asarray(estimate, dtype=float), np.asarray(truth, dtype=float)
    transform = align_rigid_2d(estimate[:, :2], truth[:, :2])
    aligned = transform.apply(estimate)
    distances = np.linalg.norm(aligned[:, :2] - truth[:, :2], axis=1)
    headings = wrap_angle(aligned[:, 2] - truth[:, 2])
    return TrajectoryError(
        float(np.sqrt(np.mean(distances**2))), float(distances.max()),
        float(np.sqrt(np.mean(headings**2))), aligned, transform,
    )
