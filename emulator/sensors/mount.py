"""Where a sensor's beams start and point at each beam's own instant (docs/scene-format.md, "Bodies").

A sensor without a body, or on a body without a trajectory, stands still: its
beams are computed once (`fixed_rays`), exactly as a fixed sensor's. A sensor
on a moving body gets, for one scan, the body's pose at every beam's instant
in one vectorised pass (`moving_rays`): the beam that a turning robot fires
late in the revolution leaves from where the robot is by then. `cast_moving`
does that for several scans at once: one pose evaluation, one Embree pass and
one region pass over all their beams, then each scan's smoke.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from emulator.optics import BeamHits, World
from emulator.scene.bodies import BodyPoses, Frames, matrix_euler_deg, mounted_matrix
from emulator.scene.model import Pose, Scene, SensorSpec
from emulator.sensors.beam_geometry import scan_plane_rays
from emulator.sensors.response import Beams


@dataclasses.dataclass(frozen=True)
class MovingRays:
    """One scan's beams: origins and unit directions (N, 3), each beam's sensor → world rotation (N, 3, 3)."""

    origins: np.ndarray
    directions: np.ndarray
    rotations: np.ndarray


class SensorMount:
    """A sensor's place in the world: fixed, or riding on a moving body."""

    def __init__(self, scene: Scene, spec: SensorSpec, poses: BodyPoses) -> None:
        self._poses = poses
        self._local = spec.pose
        self._body = scene.body(spec.body) if spec.body is not None else None
        self.moving = self._body is not None and self._body.moving
        if self._body is None or self.moving:
            self.fixed_spec = spec
        else:  # on a body that stays: the sensor is fixed at the composed pose
            matrix = mounted_matrix(self._body, spec.pose)
            pose = Pose(tuple(float(v) for v in matrix[:3, 3]), matrix_euler_deg(matrix[:3, :3]))  # type: ignore[arg-type]
            self.fixed_spec = dataclasses.replace(spec, pose=pose, body=None)

    def fixed_rays(self, angles_rad: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Origins and directions of a sensor that does not move (read-only, shared by every scan)."""
        return scan_plane_rays(self.fixed_spec.pose, angles_rad)

    def frames(self, times_s: np.ndarray) -> Frames:
        """The sensor's pose (sensor → world) at each of `times_s`."""
        times = np.asarray(times_s, dtype=float).reshape(-1)
        if not self.moving:
            pose = self.fixed_spec.pose
            return Frames(
                np.broadcast_to(np.asarray(pose.position, dtype=float), (len(times), 3)),
                np.broadcast_to(pose.rotation_matrix(), (len(times), 3, 3)),
            )
        assert self._body is not None
        return self._poses.frames(self._body.name, times).then(self._local)

    def pose_at(self, time_s: float) -> tuple[np.ndarray, np.ndarray]:
        """Position (3,) and rotation (3, 3) of the sensor at `time_s`."""
        frames = self.frames(np.array([time_s]))
        return np.array(frames.positions[0]), np.array(frames.rotations[0])

    def moving_rays(self, angles_rad: np.ndarray, beam_times_s: np.ndarray) -> MovingRays:
        """Each beam (sensor-frame angle (N,)) cast from the sensor's pose at its instant: `beam_times_s`
        (K·N,) holds K scans of these beams, one after another."""
        frames = self.frames(beam_times_s)
        local = np.stack([np.cos(angles_rad), np.sin(angles_rad), np.zeros_like(angles_rad)], axis=1)
        local = np.tile(local, (len(frames.positions) // max(len(angles_rad), 1), 1))  # a scan's directions, once
        directions = np.einsum("nij,nj->ni", frames.rotations, local)
        return MovingRays(np.ascontiguousarray(frames.positions), directions, frames.rotations)


def cast_moving(
    world: World, scene: Scene, spec: SensorSpec, mount: SensorMount, angles_rad: np.ndarray, offsets_s: np.ndarray,
    times_s: list[float], max_range_m: float,
) -> list[tuple[BeamHits, Beams]]:
    """Each scan at `times_s` of a sensor on a moving body: beam i of a scan at t measured at t + offsets_s[i]."""
    n = len(angles_rad)
    beam_times = (np.asarray(times_s, dtype=float)[:, None] + offsets_s).ravel()
    rays = mount.moving_rays(angles_rad, beam_times)
    prepared = world.with_moving_solids(world.prepare(rays.origins, rays.directions, max_range_m), beam_times)
    casts = []
    for index, time_s in enumerate(times_s):
        rows = slice(index * n, (index + 1) * n)
        hits = world.cast_prepared(prepared.rows(rows.start, rows.stop), time_s, beam_times[rows])
        beams = Beams(scene, spec, world, time_s, angles_rad, rays.origins[rows], rays.directions[rows], rays.rotations[rows], beam_times[rows])
        casts.append((hits, beams))
    return casts
