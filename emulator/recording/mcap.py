"""A scene's Foxglove channels, and MCAP recordings of them (`record --format mcap`, `serve --mcap`).

Channels (Foxglove's well-known schemas, protobuf-encoded by foxglove-sdk):

| topic | schema | what |
|---|---|---|
| `/SENSOR/scan` | `foxglove.LaserScan` | each scan's measured beams (`sensors/published.py`) in metres, frame `SENSOR`; error codes as ±inf / NaN (`laserscan.py`); the intensities of a model that reports them |
| `/SENSOR/values` | `lrf.DeviceValues` (JSON) | the same beams' values exactly as on the wire, unit and codes included; intensities and every echo where the model reports them |
| `/tf` | `foxglove.FrameTransforms` | `world` → each sensor (and body) at the scan's instant |
| `/scene` | `foxglove.SceneUpdate` | entity `solids` (once), `smoke` (regions, opacity from density) and `plumes` (particles) |

Message timestamps and MCAP log times are simulated time (ns from t = 0), so
a recording replays scan for scan and is independent of the wall clock.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Iterable, Sequence

import foxglove
import numpy as np
from foxglove.channels import FrameTransformsChannel, LaserScanChannel, SceneUpdateChannel
from foxglove.messages import (
    Color,
    CubePrimitive,
    CylinderPrimitive,
    FrameTransform,
    FrameTransforms,
    LaserScan,
    Point3,
    Pose as FoxglovePose,
    Quaternion,
    SceneEntity,
    SceneUpdate,
    SpherePrimitive,
    Timestamp,
    TriangleListPrimitive,
    Vector3,
)

from emulator.errors import UserError
from emulator.recording.laserscan import values_to_ranges
from emulator.recording.scene_look import (
    SMOKE_RGB,
    material_rgb,
    quaternion_xyzw,
    smoke_alpha,
    thickness_m,
)
from emulator.recording.world_snapshot import SceneSnapshots, WorldSnapshot
from emulator.scene.geometry import world_mesh
from emulator.scene.model import Box, Cylinder, Pose, Scene, Shape, Sphere
from emulator.sensors.published import published
from emulator.sensors.scan import Scan

WORLD_FRAME = "world"
DEVICE_VALUES_SCHEMA = foxglove.Schema(
    name="lrf.DeviceValues",
    encoding="jsonschema",
    data=json.dumps(
        {
            "title": "lrf.DeviceValues",
            "description": "One scan's device values exactly as on the wire (URG: mm or an error code < 20; "
            "LMS200: distance in `unit` or a code 8183..8191)",
            "type": "object",
            "properties": {
                "timestamp": {"type": "object", "properties": {"sec": {"type": "integer"}, "nsec": {"type": "integer"}}},
                "sensor": {"type": "string"},
                "model": {"type": "string"},
                "unit": {"type": "string"},
                "angles_rad": {"type": "array", "items": {"type": "number"}},
                "values": {"type": "array", "items": {"type": "integer"}},
                "intensities": {"type": "array", "items": {"type": "integer"}},
                "echoes": {"type": "array", "description": "per beam, every echo nearest first, -1 past its last",
                           "items": {"type": "array", "items": {"type": "integer"}}},
                "echo_intensities": {"type": "array", "items": {"type": "array", "items": {"type": "integer"}}},
            },
        }
    ).encode(),
)
SMOKE_UPDATE_PERIOD_S = 0.1  # smoke and plumes are drawn at most this often (simulated time)


def timestamp(time_s: float) -> Timestamp:
    nanoseconds = nanoseconds_of(time_s)
    return Timestamp(sec=nanoseconds // 1_000_000_000, nsec=nanoseconds % 1_000_000_000)


def nanoseconds_of(time_s: float) -> int:
    return max(0, int(round(time_s * 1e9)))


def foxglove_pose(pose: Pose) -> FoxglovePose:
    x, y, z, w = quaternion_xyzw(pose.rotation_deg)
    return FoxglovePose(position=Vector3(x=pose.position[0], y=pose.position[1], z=pose.position[2]),
                        orientation=Quaternion(x=x, y=y, z=z, w=w))


def laser_scan(scan: Scan) -> LaserScan:
    """The scan as a `foxglove.LaserScan` in its sensor's frame (angles evenly spaced, as the devices'
    are)."""
    angles = np.asarray(scan.angles_rad, dtype=float)
    ranges = values_to_ranges(scan.values, scan.model, scan.unit)
    intensities = None if scan.intensities is None else np.asarray(scan.intensities, dtype=float).tolist()
    return LaserScan(
        timestamp=timestamp(scan.time_s), frame_id=scan.sensor,
        start_angle=float(angles[0]), end_angle=float(angles[-1]), ranges=ranges.tolist(), intensities=intensities,
    )


def device_values(scan: Scan) -> dict:
    """The scan's wire values as a `lrf.DeviceValues` JSON message."""
    nanoseconds = nanoseconds_of(scan.time_s)
    return {
        "timestamp": {"sec": nanoseconds // 1_000_000_000, "nsec": nanoseconds % 1_000_000_000},
        "sensor": scan.sensor, "model": scan.model, "unit": scan.unit,
        "angles_rad": np.round(np.asarray(scan.angles_rad, dtype=float), 9).tolist(),
        "values": np.asarray(scan.values, dtype=np.int64).tolist(),
        **{name: np.asarray(array, dtype=np.int64).tolist() for name, array in (
            ("intensities", scan.intensities), ("echoes", scan.echoes), ("echo_intensities", scan.echo_intensities),
        ) if array is not None},
    }


def _shape_primitives(shape: Shape, pose: Pose, rgba: tuple[float, float, float, float]) -> dict[str, list]:
    """The shape as Foxglove primitives (a mesh file as its triangles), by primitive kind."""
    color = Color(r=rgba[0], g=rgba[1], b=rgba[2], a=rgba[3])
    if isinstance(shape, Box):
        size = Vector3(x=shape.size[0], y=shape.size[1], z=shape.size[2])
        return {"cubes": [CubePrimitive(pose=foxglove_pose(pose), size=size, color=color)]}
    if isinstance(shape, Sphere):
        diameter = 2.0 * shape.radius
        return {"spheres": [SpherePrimitive(pose=foxglove_pose(pose), size=Vector3(x=diameter, y=diameter, z=diameter), color=color)]}
    if isinstance(shape, Cylinder):
        diameter = 2.0 * shape.radius
        size = Vector3(x=diameter, y=diameter, z=shape.height)
        return {"cylinders": [CylinderPrimitive(pose=foxglove_pose(pose), size=size, bottom_scale=1.0, top_scale=1.0, color=color)]}
    mesh = world_mesh(shape, pose)
    corners = mesh.vertices[mesh.faces].reshape(-1, 3)
    points = [Point3(x=float(x), y=float(y), z=float(z)) for x, y, z in corners]
    return {"triangles": [TriangleListPrimitive(points=points, color=color)]}


def _entity(time_s: float, entity_id: str, parts: Iterable[dict[str, list]], frame: str = WORLD_FRAME) -> SceneEntity:
    kinds: dict[str, list] = {}
    for part in parts:
        for kind, primitives in part.items():
            kinds.setdefault(kind, []).extend(primitives)
    return SceneEntity(timestamp=timestamp(time_s), frame_id=frame, id=entity_id, frame_locked=True, **kinds)


def solids_update(scene: Scene, time_s: float = 0.0) -> SceneUpdate:
    """Every solid object, coloured by its material: entity `solids` in the world frame, and
    `solids/BODY` in each body's frame for the solids riding on it (they move with its /tf)."""
    frames: dict[str, list] = {}
    for obj in scene.objects:
        primitives = _shape_primitives(obj.shape, obj.pose, (*material_rgb(scene, obj.material), 1.0))
        frames.setdefault(obj.body or WORLD_FRAME, []).append(primitives)
    return SceneUpdate(entities=[
        _entity(time_s, "solids" if frame == WORLD_FRAME else f"solids/{frame}", parts, frame)
        for frame, parts in frames.items()
    ])


def smoke_update(scene: Scene, snapshot: WorldSnapshot) -> SceneUpdate:
    """Smoke regions as translucent volumes (opacity from their density now) and plume particles as cubes."""
    regions = []
    for region in scene.regions:
        alpha = float(smoke_alpha(snapshot.densities.get(region.name, 0.0), scene.density_to_extinction, thickness_m(region.shape)))
        if alpha > 0.0:
            regions.append(_shape_primitives(region.shape, region.pose, (*SMOKE_RGB, alpha)))
    cubes = []
    for particles in snapshot.particles.values():
        alphas = smoke_alpha(particles.density, scene.density_to_extinction, 2.0 * particles.half_sizes)
        for center, half, alpha in zip(particles.centers, particles.half_sizes, alphas):
            edge = 2.0 * float(half)
            cubes.append(CubePrimitive(
                pose=FoxglovePose(position=Vector3(x=float(center[0]), y=float(center[1]), z=float(center[2])),
                                  orientation=Quaternion(w=1.0)),
                size=Vector3(x=edge, y=edge, z=edge), color=Color(r=0.45, g=0.45, b=0.45, a=float(min(alpha, 0.5))),
            ))
    return SceneUpdate(entities=[_entity(snapshot.time_s, "smoke", regions), _entity(snapshot.time_s, "plumes", [{"cubes": cubes}])])


def transforms(snapshot: WorldSnapshot) -> FrameTransforms:
    """`world` → each body and sensor frame at the snapshot's instant."""
    frames = [*snapshot.body_poses.items(), *snapshot.sensor_poses.items()]
    return FrameTransforms(transforms=[
        FrameTransform(
            timestamp=timestamp(snapshot.time_s), parent_frame_id=WORLD_FRAME, child_frame_id=name,
            translation=Vector3(x=pose.position[0], y=pose.position[1], z=pose.position[2]),
            rotation=Quaternion(**dict(zip("xyzw", quaternion_xyzw(pose.rotation_deg)))),
        )
        for name, pose in frames
    ])


class SceneChannels:
    """The scene's channels (module docstring) in one foxglove `Context`: every sink attached
    to that context (an MCAP file, a WebSocket server) receives what is logged here."""

    def __init__(self, scene: Scene, context: foxglove.Context, sensors: Sequence[str] | None = None) -> None:
        self.scene = scene
        names = [spec.name for spec in scene.sensors] if sensors is None else list(sensors)
        self._scans = {name: LaserScanChannel(f"/{name}/scan", context=context) for name in names}
        self._values = {
            name: foxglove.Channel(f"/{name}/values", schema=DEVICE_VALUES_SCHEMA, message_encoding="json", context=context)
            for name in names
        }
        self._tf = FrameTransformsChannel("/tf", context=context)
        self._scene = SceneUpdateChannel("/scene", context=context)
        self._smoke_drawn_at: float | None = None

    def log_scan(self, scan: Scan) -> None:
        """The scan's measured beams (`published`) on `/SENSOR/scan` and their wire values on `/SENSOR/values`."""
        channel = self._scans.get(scan.sensor)
        if channel is None:
            return
        scan = published(scan)
        log_time = nanoseconds_of(scan.time_s)
        channel.log(laser_scan(scan), log_time=log_time)
        self._values[scan.sensor].log(device_values(scan), log_time=log_time)

    def log_solids(self, time_s: float = 0.0) -> None:
        self._scene.log(solids_update(self.scene, time_s), log_time=nanoseconds_of(time_s))

    def log_world(self, snapshot: WorldSnapshot, force: bool = False) -> None:
        """Transforms at the snapshot's instant; smoke and plumes at most every SMOKE_UPDATE_PERIOD_S."""
        log_time = nanoseconds_of(snapshot.time_s)
        self._tf.log(transforms(snapshot), log_time=log_time)
        drawn = self._smoke_drawn_at
        if force or drawn is None or snapshot.time_s - drawn >= SMOKE_UPDATE_PERIOD_S - 1e-9 or snapshot.time_s < drawn:
            self._scene.log(smoke_update(self.scene, snapshot), log_time=log_time)
            self._smoke_drawn_at = snapshot.time_s


def open_mcap_file(path: Path, context: foxglove.Context) -> foxglove.MCAPWriter:
    """An MCAP writer for `path` on `context` (replacing the file, as a text recording does)."""
    try:
        return foxglove.open_mcap(str(path), allow_overwrite=True, context=context)
    except Exception as error:  # foxglove raises its own error types for I/O failures
        raise UserError(f"cannot write {path}: {error}") from None


def record_mcap(path: Path, scene: Scene, sensor: str, scans: Iterable[Scan]) -> int:
    """Write `sensor`'s `scans` with the scene's solids, smoke and transforms; return the count."""
    context = foxglove.Context()
    channels = SceneChannels(scene, context, [sensor])
    snapshots = SceneSnapshots(scene)
    writer = open_mcap_file(path, context)
    count = 0
    try:
        for scan in scans:
            if count == 0:
                channels.log_solids(scan.time_s)
            channels.log_world(snapshots(scan.time_s))
            channels.log_scan(scan)
            count += 1
    finally:
        writer.close()
    return count
