"""ROS bags of a recording (`record --format rosbag2|rosbag1`), written with rosbags: no ROS needed.

A ROS 2 bag is a directory as `ros2 bag record -s mcap` makes it
(`metadata.yaml` and one MCAP file of CDR messages); a ROS 1 bag one `.bag`
file. Both hold the same topics:

| topic | type | what |
|---|---|---|
| `/SENSOR/scan` | `sensor_msgs/msg/LaserScan` | each scan's measured beams, fields as the model's driver sets them (`sensors/published.py`), codes per REP 117; frame `SENSOR` |
| `/SENSOR/echoes` | `sensor_msgs/msg/MultiEchoLaserScan` | every echo of each beam in metres, nearest first (sensors that report echoes) |
| `/SENSOR/values` | `std_msgs/msg/Int32MultiArray` | the same beams' device values exactly as on the wire |
| `/tf_static` | `tf2_msgs/msg/TFMessage` | map → odom (identity: the odometry is the ground truth) and base → each laser |
| `/tf` | `tf2_msgs/msg/TFMessage` | odom → base at TF_RATE_HZ |
| `/odom` | `nav_msgs/msg/Odometry` | the ground truth: base's pose in odom and its velocity in base, at TF_RATE_HZ |

Frames per REP 105: map → odom → base → laser. `base` is the body the
sensors ride on (the world origin for sensors fixed in the scene); a sensor on
another body hangs from map on `/tf` instead.

Time: a message's stamp is `epoch` + simulated time (ROS time must be > 0;
`serve --epoch` gives the drivers' stamps the same origin). A LaserScan's
stamp is its first beam's instant, as the drivers stamp it; its log time the
instant the scan completed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterable, Iterator, Sequence

import numpy as np
from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime
from rosbags.rosbag1 import Writer as Ros1Writer
from rosbags.rosbag2 import StoragePlugin, Writer as Ros2Writer
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from emulator.errors import UserError
from emulator.recording.laserscan import values_to_ranges
from emulator.scene.bodies import Frames, matrix_quaternion
from emulator.sensors import Sensor, beam_times_s
from emulator.sensors.published import laser_scan_fields, publication, published
from emulator.sensors.scan import Scan

FORMATS = ("rosbag2", "rosbag1")
TF_RATE_HZ = 50.0
TF_CHUNK = 3000  # /tf and /odom instants computed at once (a minute at TF_RATE_HZ): a bag's memory does not grow with its span
DEFAULT_EPOCH_S = 1_000_000_000  # 2001-09-09: plainly simulated, and far from ROS time 0 ("no stamp")
ROS2_BAG_VERSION = 8
ROS1_TFMESSAGE = "geometry_msgs/TransformStamped[] transforms\n"  # tf2_msgs/TFMessage.msg
LATCHED = Qos(
    QosHistory.KEEP_LAST, 1, QosReliability.RELIABLE, QosDurability.TRANSIENT_LOCAL, QosTime(0, 0), QosTime(0, 0),
    QosLiveliness.AUTOMATIC, QosTime(0, 0), False,
)


@dataclass(frozen=True)
class FrameNames:
    """REP 105 frame names (configurable: `record --map-frame/--odom-frame/--base-frame`)."""

    map: str = "map"
    odom: str = "odom"
    base: str = "base_link"


def _nanoseconds(epoch_s: float, time_s: float) -> int:
    """ROS time in ns of simulated `time_s` (each rounded alone: their float sum would lose 100s of ns)."""
    return int(round(epoch_s * 1e9)) + int(round(time_s * 1e9))


class _Messages:
    """The bag's messages as the typestore's classes (ROS 1 headers carry a `seq`)."""

    def __init__(self, typestore: Any) -> None:
        self.types = typestore.types
        self._with_seq = "seq" in self.types["std_msgs/msg/Header"].__dataclass_fields__

    def new(self, name: str, **fields: Any) -> Any:
        return self.types[name](**fields)

    def time(self, nanoseconds: int) -> Any:
        return self.new("builtin_interfaces/msg/Time", sec=nanoseconds // 1_000_000_000, nanosec=nanoseconds % 1_000_000_000)

    def header(self, nanoseconds: int, frame: str) -> Any:
        extra = {"seq": 0} if self._with_seq else {}
        return self.new("std_msgs/msg/Header", **extra, stamp=self.time(nanoseconds), frame_id=frame)

    def transform(self, nanoseconds: int, parent: str, child: str, position: np.ndarray, rotation: np.ndarray) -> Any:
        qx, qy, qz, qw = (float(v) for v in matrix_quaternion(rotation))
        x, y, z = (float(v) for v in position)
        return self.new(
            "geometry_msgs/msg/TransformStamped", header=self.header(nanoseconds, parent), child_frame_id=child,
            transform=self.new("geometry_msgs/msg/Transform", translation=self.new("geometry_msgs/msg/Vector3", x=x, y=y, z=z),
                               rotation=self.new("geometry_msgs/msg/Quaternion", x=qx, y=qy, z=qz, w=qw)),
        )

    def tf(self, transforms: list[Any]) -> Any:
        return self.new("tf2_msgs/msg/TFMessage", transforms=transforms)


def laser_scan(messages: _Messages, scan: Scan, stamp_ns: int, period_s: float | None) -> Any:
    """`sensor_msgs/msg/LaserScan` of a published scan, stamped at its first beam."""
    fields = laser_scan_fields(scan, period_s)
    intensities = scan.intensities if scan.intensities is not None else ()
    return messages.new(
        "sensor_msgs/msg/LaserScan", header=messages.header(stamp_ns, scan.sensor), **fields,
        ranges=values_to_ranges(scan.values, scan.model, scan.unit).astype(np.float32),
        intensities=np.asarray(intensities, dtype=np.float32),
    )


def multi_echo_scan(messages: _Messages, scan: Scan, stamp_ns: int, period_s: float | None) -> Any:
    """`sensor_msgs/msg/MultiEchoLaserScan`: each beam's echoes in metres, nearest first (none: empty)."""
    assert scan.echoes is not None
    per_metre = publication(scan.model).units_per_m[scan.unit]
    echo_intensities = scan.echo_intensities
    ranges, intensities = [], []
    for index, row in enumerate(np.asarray(scan.echoes)):
        present = row >= 0
        ranges.append(messages.new("sensor_msgs/msg/LaserEcho", echoes=(row[present] / per_metre).astype(np.float32)))
        strength = echo_intensities[index][present] if echo_intensities is not None else np.zeros(0)
        intensities.append(messages.new("sensor_msgs/msg/LaserEcho", echoes=np.asarray(strength, dtype=np.float32)))
    return messages.new(
        "sensor_msgs/msg/MultiEchoLaserScan", header=messages.header(stamp_ns, scan.sensor),
        **laser_scan_fields(scan, period_s), ranges=ranges, intensities=intensities,
    )


def device_values(messages: _Messages, scan: Scan) -> Any:
    """`std_msgs/msg/Int32MultiArray` of the scan's wire values (dimension `beams`)."""
    values = np.asarray(scan.values, dtype=np.int32)
    layout = messages.new(
        "std_msgs/msg/MultiArrayLayout",
        dim=[messages.new("std_msgs/msg/MultiArrayDimension", label="beams", size=len(values), stride=len(values))],
        data_offset=0,
    )
    return messages.new("std_msgs/msg/Int32MultiArray", layout=layout, data=values)


class BagContent:
    """The messages of a recording of `sensors` (sharing one world) between their scans' instants."""

    def __init__(self, sensors: Sequence[Sensor], frames: FrameNames, epoch_s: float, typestore: Any) -> None:
        self.sensors = {sensor.name: sensor for sensor in sensors}
        self.frames, self.epoch_s = frames, epoch_s
        self.messages = _Messages(typestore)
        self.base_body = sensors[0].spec.body
        self._poses = sensors[0].world.bodies

    def topics(self) -> list[tuple[str, str, bool]]:
        """(topic, type, latched) of every connection known before the scans (a sensor's echoes: with its first)."""
        topics = [("/tf_static", "tf2_msgs/msg/TFMessage", True), ("/tf", "tf2_msgs/msg/TFMessage", False),
                  ("/odom", "nav_msgs/msg/Odometry", False)]
        for name in self.sensors:
            topics += [(f"/{name}/scan", "sensor_msgs/msg/LaserScan", False), (f"/{name}/values", "std_msgs/msg/Int32MultiArray", False)]
        return topics

    def base_frames(self, times_s: np.ndarray) -> Frames:
        """The base's pose in map (= odom) at `times_s`: its body's, or the origin."""
        if self.base_body is None:
            return Frames(np.zeros((len(times_s), 3)), np.broadcast_to(np.eye(3), (len(times_s), 3, 3)))
        return self._poses.frames(self.base_body, times_s)

    def static_transforms(self, time_s: float) -> Any:
        """map → odom (identity) and base → each laser on the base's body (or fixed, with no base body)."""
        stamp, names = _nanoseconds(self.epoch_s, time_s), self.frames
        transforms = [self.messages.transform(stamp, names.map, names.odom, np.zeros(3), np.eye(3))]
        for name, sensor in self.sensors.items():
            if sensor.spec.body == self.base_body:
                pose = sensor.spec.pose
                transforms.append(self.messages.transform(stamp, names.base, name, np.asarray(pose.position, float), pose.rotation_matrix()))
        return self.messages.tf(transforms)

    def motion(self, times_s: np.ndarray, first: int = 0, stop: int | None = None) -> Iterator[tuple[int, str, Any]]:
        """(log time, topic, message) of /tf (odom → base, and map → lasers on other bodies) and /odom
        at `times_s[first:stop]` (the instants around them give the velocities' central differences)."""
        frames = self.base_frames(times_s)
        linear, angular = _body_velocities(frames, times_s)
        others = {name: sensor.mount.frames(times_s) for name, sensor in self.sensors.items() if sensor.spec.body != self.base_body}
        names = self.frames
        for index in range(first, len(times_s) if stop is None else stop):
            time_s = times_s[index]
            stamp = _nanoseconds(self.epoch_s, float(time_s))
            position, rotation = frames.positions[index], frames.rotations[index]
            transforms = [self.messages.transform(stamp, names.odom, names.base, position, rotation)]
            transforms += [self.messages.transform(stamp, names.map, name, other.positions[index], other.rotations[index])
                           for name, other in others.items()]
            yield stamp, "/tf", self.messages.tf(transforms)
            yield stamp, "/odom", self._odometry(stamp, position, rotation, linear[index], angular[index])

    def motion_between(self, scans_start_s: float, end_s: float) -> Iterator[tuple[int, str, Any]]:
        """`motion(tf_times(scans_start_s, end_s))`, TF_CHUNK instants at a time: memory stays flat however long the span."""
        count = tf_count(scans_start_s, end_s)
        for low in range(0, count, TF_CHUNK):
            high = min(low + TF_CHUNK, count)
            around_low, around_high = max(low - 1, 0), min(high + 1, count)  # the neighbours of the chunk's ends
            times_s = tf_times(scans_start_s, end_s, around_low, around_high)
            yield from self.motion(times_s, low - around_low, high - around_low)

    def _odometry(self, stamp: int, position: np.ndarray, rotation: np.ndarray, linear: np.ndarray, angular: np.ndarray) -> Any:
        new = self.messages.new
        qx, qy, qz, qw = (float(v) for v in matrix_quaternion(rotation))
        pose = new("geometry_msgs/msg/Pose", position=new("geometry_msgs/msg/Point", x=float(position[0]), y=float(position[1]), z=float(position[2])),
                   orientation=new("geometry_msgs/msg/Quaternion", x=qx, y=qy, z=qz, w=qw))
        twist = new("geometry_msgs/msg/Twist", linear=new("geometry_msgs/msg/Vector3", x=float(linear[0]), y=float(linear[1]), z=float(linear[2])),
                    angular=new("geometry_msgs/msg/Vector3", x=float(angular[0]), y=float(angular[1]), z=float(angular[2])))
        zeros = np.zeros(36, dtype=np.float64)
        return new(
            "nav_msgs/msg/Odometry", header=self.messages.header(stamp, self.frames.odom), child_frame_id=self.frames.base,
            pose=new("geometry_msgs/msg/PoseWithCovariance", pose=pose, covariance=zeros),
            twist=new("geometry_msgs/msg/TwistWithCovariance", twist=twist, covariance=zeros),
        )

    def scan_messages(self, scan: Scan) -> Iterator[tuple[int, str, Any]]:
        """(log time, topic, message) of one scan: its LaserScan, echoes and device values."""
        sensor = self.sensors[scan.sensor]
        scan = published(scan)
        log_time = _nanoseconds(self.epoch_s, scan.time_s)
        stamp = _nanoseconds(self.epoch_s, float(beam_times_s(scan)[0]))
        period = sensor.configured_period_s
        yield log_time, f"/{scan.sensor}/scan", laser_scan(self.messages, scan, stamp, period)
        if scan.echoes is not None:
            yield log_time, f"/{scan.sensor}/echoes", multi_echo_scan(self.messages, scan, stamp, period)
        yield log_time, f"/{scan.sensor}/values", device_values(self.messages, scan)


def _body_velocities(frames: Frames, times_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Linear and angular velocity (T, 3) in the body's own frame, by central differences (one-sided at the ends)."""
    count = len(times_s)
    if count < 2:
        return np.zeros((count, 3)), np.zeros((count, 3))
    after = np.minimum(np.arange(count) + 1, count - 1)
    before = np.maximum(np.arange(count) - 1, 0)
    span = (times_s[after] - times_s[before])[:, None]
    rotations = np.asarray(frames.rotations)
    world_linear = (frames.positions[after] - frames.positions[before]) / span
    linear = np.einsum("tji,tj->ti", rotations, world_linear)  # Rᵀ v
    change = np.einsum("tij,tkj->tik", rotations[after], rotations[before])  # R(t+) R(t-)ᵀ, a world-frame turn
    cos_angle = np.clip((np.trace(change, axis1=1, axis2=2) - 1.0) / 2.0, -1.0, 1.0)
    angle = np.arccos(cos_angle)
    axis = np.stack([change[:, 2, 1] - change[:, 1, 2], change[:, 0, 2] - change[:, 2, 0], change[:, 1, 0] - change[:, 0, 1]], axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        scale = np.where(angle > 1e-12, angle / (2.0 * np.sin(angle)), 0.5)
    world_angular = axis * scale[:, None] / span
    angular = np.einsum("tji,tj->ti", rotations, world_angular)
    return linear, angular


def _tf_grid(scans_start_s: float, end_s: float) -> tuple[float, float, int]:
    """(first instant, step, count) of the /tf and /odom instants."""
    step = 1.0 / TF_RATE_HZ
    first = math.floor(scans_start_s / step) * step
    return first, step, max(0, math.ceil((end_s + step / 2 - first) / step))


def tf_count(scans_start_s: float, end_s: float) -> int:
    """How many /tf and /odom instants `tf_times` holds."""
    return _tf_grid(scans_start_s, end_s)[2]


def tf_times(scans_start_s: float, end_s: float, low: int = 0, high: int | None = None) -> np.ndarray:
    """The /tf and /odom instants: every 1/TF_RATE_HZ from just before the first beam to the end
    (`[low:high]` of them: made alone, each exactly as in the whole `np.arange(first, end + step / 2, step)`,
    whose n-th element, n ≥ 2, numpy makes as first + n · ((first + step) − first))."""
    first, step, count = _tf_grid(scans_start_s, end_s)
    high = count if high is None else min(high, count)
    low = min(max(low, 0), high)
    times = np.arange(low, high, dtype=np.float64) * ((first + step) - first) + first
    if low <= 1 < high:
        times[1 - low] = first + step
    if low == 0 and high > 0:
        times[0] = first
    return np.round(times, 9)


def bag_typestore(fmt: str) -> Any:
    """ROS 2 Humble's message types, or ROS 1 Noetic's (whose store here lacks tf2_msgs: added)."""
    if fmt == "rosbag2":
        return get_typestore(Stores.ROS2_HUMBLE)
    typestore = get_typestore(Stores.ROS1_NOETIC)
    typestore.register(get_types_from_msg(ROS1_TFMESSAGE, "tf2_msgs/msg/TFMessage"))
    return typestore


def write_bag(
    path: Path, fmt: str, sensors: Sequence[Sensor], scans: Iterable[Scan], end_s: float,
    frames: FrameNames = FrameNames(), epoch_s: float = DEFAULT_EPOCH_S,
) -> int:
    """Write `scans` (time-ordered, of `sensors`) with the scene's frames and ground truth as a ROS 2
    (`rosbag2`: a new directory) or ROS 1 (`rosbag1`: a new file) bag; return the number of scans."""
    if path.exists() or path.is_symlink():
        raise UserError(f"{path} exists: a bag is written to a new path")
    typestore = bag_typestore(fmt)
    content = BagContent(sensors, frames, epoch_s, typestore)
    serialize = typestore.serialize_cdr if fmt == "rosbag2" else typestore.serialize_ros1
    writer = (Ros2Writer(path, version=ROS2_BAG_VERSION, storage_plugin=StoragePlugin.MCAP)
              if fmt == "rosbag2" else Ros1Writer(path))
    count = 0
    try:
        writer.open()
    except OSError as error:
        raise UserError(f"cannot write {path}: {error.strerror or error}") from None
    try:
        connections = {}

        def connect(topic: str, msgtype: str, latched: bool) -> None:
            if fmt == "rosbag2":
                qos = [LATCHED] if latched else []
                connections[topic] = writer.add_connection(topic, msgtype, typestore=typestore, offered_qos_profiles=qos)
            else:
                connections[topic] = writer.add_connection(topic, msgtype, typestore=typestore, latching=1 if latched else None)

        for topic, msgtype, latched in content.topics():
            connect(topic, msgtype, latched)

        def write(log_time: int, topic: str, message: Any) -> None:
            if topic not in connections:  # a sensor's echoes, with its first scan
                connect(topic, message.__msgtype__, False)
            writer.write(connections[topic], log_time, serialize(message, message.__msgtype__))

        pending: Iterator[tuple[int, str, Any]] | None = None
        next_motion: tuple[int, str, Any] | None = None
        for scan in scans:
            if pending is None:
                start = float(beam_times_s(published(scan))[0])
                write(_nanoseconds(epoch_s, start), "/tf_static", content.static_transforms(start))
                pending = content.motion_between(start, end_s)
                next_motion = next(pending, None)
            scan_time = _nanoseconds(epoch_s, scan.time_s)
            while next_motion is not None and next_motion[0] <= scan_time:
                write(*next_motion)
                next_motion = next(pending, None)
            for message in content.scan_messages(scan):
                write(*message)
            count += 1
        while pending is not None and next_motion is not None:
            write(*next_motion)
            next_motion = next(pending, None)
    finally:
        writer.close()
    return count
