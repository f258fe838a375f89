"""A LaserScan topic of a ROS bag served as a device (`replay BAG --topic T`): ROS 2 or ROS 1, read with rosbags.

A ROS 2 bag is a directory holding `metadata.yaml` (any storage rosbags
reads: MCAP, SQLite 3); a ROS 1 bag a file starting `#ROSBAG V2.0`. The
topic's `sensor_msgs/msg/LaserScan` messages become `mcap_replay.LaserScans`
under the same checks and the same resampling onto the device's beams.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Iterator

from rosbags.highlevel import AnyReader, AnyReaderError
from rosbags.typesys import Stores, get_typestore

from emulator.errors import UserError
from emulator.recording.mcap_replay import LaserScans, laser_scans

LASERSCAN = "sensor_msgs/msg/LaserScan"


def read_bag_laser_scans(path: Path, topic: str | None) -> LaserScans:
    """The scans of `topic` (default: the bag's only LaserScan topic)."""
    try:
        with AnyReader([path], default_typestore=get_typestore(Stores.ROS2_HUMBLE)) as reader:
            scan_topics = sorted({c.topic for c in reader.connections if c.msgtype == LASERSCAN})
            if topic is None:
                if len(scan_topics) != 1:
                    raise UserError(f"{path.name}: --topic: choose one of the LaserScan topics: {', '.join(scan_topics) or 'none'}")
                topic = scan_topics[0]
            elif topic not in scan_topics:
                raise UserError(f"{path.name}: --topic {topic}: not a LaserScan topic (LaserScan topics: {', '.join(scan_topics) or 'none'})")
            connections = [c for c in reader.connections if c.topic == topic]

            def messages() -> Iterator[tuple[Any, int]]:
                for connection, log_time_ns, raw in reader.messages(connections=connections):
                    yield reader.deserialize(raw, connection.msgtype), log_time_ns

            return laser_scans(path, topic, messages())
    except (AnyReaderError, OSError, ValueError, KeyError, TypeError, RuntimeError, AssertionError) as error:
        first_line = (str(error).strip().splitlines() or [type(error).__name__])[0]  # YAML errors run to many lines
        raise UserError(f"{path.name}: cannot read the bag: {first_line}") from None
