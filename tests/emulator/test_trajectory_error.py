"""Rigid 2-D alignment and absolute trajectory error (emulator/bench/trajectory.py)."""

from __future__ import annotations

import numpy as np
import pytest

from emulator.bench.trajectory import absolute_trajectory_error, align_rigid_2d, wrap_angle


def loop(count: int = 200) -> np.ndarray:
    """A closed 4 m × 2 m loop driven with the heading along the path."""
    angle = np.linspace(0, 2 * np.pi, count, endpoint=False)
    x, y = 2.0 * np.cos(angle), 1.0 * np.sin(angle)
    heading = np.arctan2(np.gradient(y), np.gradient(x))
    return np.column_stack([x, y, heading])


def moved(poses: np.ndarray, angle: float, shift: tuple[float, float]) -> np.ndarray:
    rotation = np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
    out = poses.copy()
    out[:, :2] = poses[:, :2] @ rotation.T + shift
    out[:, 2] = wrap_angle(poses[:, 2] + angle)
    return out


def test_a_moved_copy_aligns_back_exactly() -> None:
    truth = loop()
    estimate = moved(truth, -2.5, (7.0, -3.0))  # a SLAM frame: rotated and shifted
    error = absolute_trajectory_error(estimate, truth)
    assert error.rmse_m < 1e-9 and error.heading_rmse_rad < 1e-9
    assert error.transform.angle_rad == pytest.approx(2.5)
    np.testing.assert_allclose(error.aligned, truth, atol=1e-9)


def test_noise_is_what_remains() -> None:
    truth = loop(2000)
    noise = np.random.default_rng(1).normal(0.0, 0.05, (2000, 2))
    estimate = moved(truth, 0.7, (1.0, 2.0))
    estimate[:, :2] += noise
    error = absolute_trajectory_error(estimate, truth)
    assert error.rmse_m == pytest.approx(0.05 * np.sqrt(2), rel=0.05)


def test_a_mirrored_path_is_not_aligned_by_a_reflection() -> None:
    truth = loop()
    mirrored = truth * np.array([1.0, -1.0, -1.0])
    assert absolute_trajectory_error(mirrored, truth).rmse_m > 0.5


def test_shapes_are_checked() -> None:
    with pytest.raises(ValueError):
        align_rigid_2d(np.zeros((3, 2)), np.zeros((4, 2)))
    with pytest.raises(ValueError):
        align_rigid_2d(np.zeros((1, 2)), np.zeros((1, 2)))
