"""A live body driven by velocity: its limits and footprint, and the closed-form motion of a twist.

A twist (vx, vy, wz) is a planar velocity in the body's frame, as a mobile
base takes it: vx forward along the body's heading (its yaw), vy to its left
(m/s), wz about the vertical (rad/s, counter-clockwise). Held constant from
an instant on, it moves the body along an exact arc (a straight line when wz
is 0): after dt the heading has turned by a = wz·dt and the body has moved,
in its starting heading's frame,

    dt · (S·vx − C·vy,  C·vx + S·vy),   S = sin(a)/a,  C = (1 − cos a)/a

(S → 1, C → 0 as a → 0). z, roll and pitch stay. `planar_motion` evaluates
this for many instants at once, elementwise (no BLAS), so a pose never
depends on which other instants are evaluated with it.

`Drive` holds what the scene says of such a body (`[bodies.drive]`,
docs/scene-format.md): its collision footprint (a vertical cylinder of
`radius` from `clearance` to `height` above the body's origin), its speed
limits and its watchdog: a twist holds for `watchdog_s` after the command
that set it, then the body stops, as a real base stops when its commands
stop.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

DEFAULT_RADIUS_M = 0.25
DEFAULT_HEIGHT_M = 0.5
DEFAULT_CLEARANCE_M = 0.02
DEFAULT_MAX_SPEED = 1.0  # m/s
DEFAULT_MAX_TURN_RATE = 2.0  # rad/s
DEFAULT_WATCHDOG_S = 0.5
MAX_WATCHDOG_S = 2  # bounds the path one command can cover (max_speed × 2 s) and the work of finding where it stops
MAX_BODY_SPEED = 10  # m/s: the bound a scene's max_speed may reach
MAX_BODY_TURN_RATE = 20  # rad/s


@dataclass(frozen=True)
class Drive:
    """How a live body takes twists: footprint (m), limits (m/s, rad/s) and watchdog (s)."""

    radius: float = DEFAULT_RADIUS_M
    height: float = DEFAULT_HEIGHT_M
    clearance: float = DEFAULT_CLEARANCE_M
    max_speed: float = DEFAULT_MAX_SPEED
    max_turn_rate: float = DEFAULT_MAX_TURN_RATE
    watchdog_s: float = DEFAULT_WATCHDOG_S


@dataclass(frozen=True)
class Twist:
    """A planar velocity in the body's frame: vx forward, vy left (m/s), wz counter-clockwise (rad/s)."""

    vx: float = 0.0
    vy: float = 0.0
    wz: float = 0.0

    @property
    def still(self) -> bool:
        return self.vx == 0.0 and self.vy == 0.0 and self.wz == 0.0


def heading(quaternions: np.ndarray) -> np.ndarray:
    """The yaw (rad) of each rotation (..., 4) (x, y, z, w): the direction its x axis points in the plane."""
    x, y, z, w = (quaternions[..., k] for k in range(4))
    return np.arctan2(2.0 * (x * y + w * z), 1.0 - 2.0 * (y * y + z * z))


def planar_motion(
    positions: np.ndarray, quaternions: np.ndarray, twists: np.ndarray, durations: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Where twists (T, 3) of (vx, vy, wz) take poses (T, 3) / (T, 4) in `durations` (T,) seconds:
    the closed-form arc (module docstring). Rows with a zero duration come back bit for bit."""
    dt = np.asarray(durations, dtype=float)
    vx, vy, wz = twists[:, 0], twists[:, 1], twists[:, 2]
    turn = wz * dt
    half = 0.5 * turn
    s = np.sinc(turn / np.pi)  # sin(a)/a
    c = np.sin(half) * np.sinc(half / np.pi)  # (1 - cos a)/a = sin(a/2) · sin(a/2)/(a/2)
    forward = dt * (s * vx - c * vy)
    left = dt * (c * vx + s * vy)
    yaw = heading(quaternions)
    cos_yaw, sin_yaw = np.cos(yaw), np.sin(yaw)
    moved = positions.copy()
    moved[:, 0] += cos_yaw * forward - sin_yaw * left
    moved[:, 1] += sin_yaw * forward + cos_yaw * left
    # turn about the world's vertical: q' = qz(a) ⊗ q, qz(a) = (0, 0, sin(a/2), cos(a/2))
    sz, cz = np.sin(half), np.cos(half)
    x, y, z, w = (quaternions[:, k] for k in range(4))
    turned = np.stack([cz * x - sz * y, cz * y + sz * x, cz * z + sz * w, cz * w - sz * z], axis=1)
    still = (dt == 0.0)[:, None]
    return np.where(still, positions, moved), np.where(still, quaternions, turned)
