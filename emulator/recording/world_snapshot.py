"""What a viewer draws of the world at one instant: smoke densities, plume particles, poses.

`SceneSnapshots` evaluates the scene (its keyframes, its plumes, its bodies'
trajectories) under the live changes a `LiveState` holds: a running daemon's
(so the view shows a density the control API just set), or none for a
recording of the scene alone (a live body then stays at its scene pose).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Mapping

import numpy as np

from emulator.scene.bodies import BodyPoses
from emulator.scene.live import LiveState
from emulator.scene.model import Pose, Scene
from emulator.scene.plumes import Particles, particles_at


@dataclass(frozen=True)
class WorldSnapshot:
    """The world at `time_s` as a viewer draws it: sensor and body poses in the world frame."""

    time_s: float
    densities: Mapping[str, float]
    particles: Mapping[str, Particles]
    sensor_poses: Mapping[str, Pose]
    body_poses: Mapping[str, Pose] = field(default_factory=dict)


class SceneSnapshots:
    """`snapshots(t)`: the scene at `t` under `live`'s changes (none: the scene alone)."""

    def __init__(self, scene: Scene, live: LiveState | None = None) -> None:
        self.scene = scene
        self._live = live
        self._poses = live.bodies if live is not None else BodyPoses(scene.bodies)

    def __call__(self, time_s: float) -> WorldSnapshot:
        scene, live, instant = self.scene, self._live, np.array([time_s])
        frames = {body.name: self._poses.frames(body.name, instant) for body in scene.bodies}
        return WorldSnapshot(
            time_s=time_s,
            densities={
                region.name: live.region_density(index, time_s) if live is not None else float(region.density.at(time_s))
                for index, region in enumerate(scene.regions)
            },
            particles={
                plume.name: particles_at(plume, scene.seed, index, time_s,
                                         live.plume_segments(index) if live is not None else None)
                for index, plume in enumerate(scene.plumes)
            },
            sensor_poses={
                spec.name: spec.pose if spec.body is None else frames[spec.body].then(spec.pose).at(0)
                for spec in scene.sensors
            },
            body_poses={name: frame.at(0) for name, frame in frames.items()},
        )

    def trajectory(self, body: str, start_s: float, end_s: float, step_s: float = 0.1) -> np.ndarray:
        """(N, 3) positions of `body` from `start_s` to `end_s`: its path, for drawing."""
        times = np.arange(start_s, end_s + step_s / 2, step_s)
        return np.asarray(self._poses.frames(body, times).positions)
