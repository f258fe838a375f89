"""`lrf-emulator record SCENE --sensor NAME --start T0 --end T1 --out FILE [--format text|mcap|rosbag2|rosbag1]`.

Writes one log line per scan (emulator/recording/textlog.py), or with
`--format mcap` an MCAP file with the scene's Foxglove channels
(emulator/recording/mcap.py), at the sensor's scan
period, as the scene configures it (`configured_scan`, `configured_period_s`):
the URG-04LX every 0.1 s; the LMS200 every full scan of its resolution, i.e.
the mirror revolutions that scan needs (1°: 1/75 s, 0.5°: 2/75 s,
0.25°: 4/75 s), with the scene's angle, resolution and units. Each scan holds
the beams the device measures, as its ROS driver publishes them
(emulator/sensors/published.py: the URG-04LX's steps 44..725).
Scan k is taken at t = k · period, for every k with T0 ≤ t ≤ T1.
Beside the log goes the ground truth: FILE.tum (`run.log` → `run.log.tum`, so
`run.log` and `run.mcap` keep theirs apart), one TUM line `t x y z qx qy qz qw`
per scan, the sensor's world pose at its time stamp.

`--format rosbag2 --out DIR` (a ROS 2 bag directory) and `--format rosbag1
--out FILE.bag` write every sensor of `--sensor NAME[,NAME...]` with the
frames and the ground truth inside the bag (emulator/recording/rosbag.py:
`/odom`, `/tf`, `/tf_static`); `--epoch` sets the ROS time of simulated time 0
and `--map-frame`, `--odom-frame`, `--base-frame` the frame names.
"""

from __future__ import annotations

import argparse
import heapq
import itertools
import math
from pathlib import Path

from emulator.commands.options import MAX_SIMULATED_TIME_S, add_events_in_option, add_scene_options, add_span_options, scene_from_args, world_from_args
from emulator.commands.progress import progress
from emulator.errors import UserError
from emulator.recording.ground_truth import with_ground_truth
from emulator.recording.rosbag import DEFAULT_EPOCH_S, FORMATS as BAG_FORMATS, FrameNames, write_bag
from emulator.scene.model import Scene
from emulator.recording.textlog import LogHeader, write_log
from emulator.sensors import create_sensor
from emulator.sensors.published import published
from emulator.sensors.series import scan_series, scan_times


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_scene_options(parser)
    add_span_options(parser, verb="record", out_metavar="FILE", out_help="log file to write")
    add_events_in_option(parser, "--events")
    parser.add_argument(
        "--format", choices=("text", "mcap", *BAG_FORMATS), default="text",
        help="text: the seed dataset's log (default); mcap: Foxglove LaserScan, device values, transforms and scene; "
        "rosbag2 (--out DIR) / rosbag1 (--out FILE.bag): a ROS bag of every --sensor NAME[,NAME...] with tf and odometry",
    )
    bag = parser.add_argument_group("ROS bags (--format rosbag2|rosbag1)")
    bag.add_argument("--epoch", type=bag_epoch, default=DEFAULT_EPOCH_S, metavar="UNIX_TIME",
                     help=f"ROS time of simulated time 0 (default {DEFAULT_EPOCH_S}; serve --epoch takes the same)")
    bag.add_argument("--map-frame", default=FrameNames.map, metavar="NAME", help="REP 105 map frame (default map)")
    bag.add_argument("--odom-frame", default=FrameNames.odom, metavar="NAME", help="REP 105 odom frame (default odom)")
    bag.add_argument("--base-frame", default=FrameNames.base, metavar="NAME", help="the robot's frame (default base_link)")


def bag_epoch(text: str) -> float:
    """An argparse type: the ROS time of simulated time 0, at least 1 s (a scan's first beam precedes its
    time by up to a scan period, and ROS time is never negative) and below 2^31 s (ROS 1's time)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected UNIX seconds, got {text!r}") from None
    if not (math.isfinite(value) and 1 <= value < 2**31 - MAX_SIMULATED_TIME_S):
        raise argparse.ArgumentTypeError(f"must be in 1..{2**31 - MAX_SIMULATED_TIME_S:g} s, got {text!r}")
    return value


def run(args: argparse.Namespace) -> int:
    scene = scene_from_args(args)
    if args.format in BAG_FORMATS:
        return _run_bag(args, scene)
    if "," in args.sensor:
        raise UserError(f"--sensor {args.sensor}: --format {args.format} records one sensor (a ROS bag takes several)")
    sensor = create_sensor(scene, args.sensor, world_from_args(scene, args))
    times = scan_times(sensor.configured_period_s, args.start, args.end, sensor.configured_phase_s)
    scans = map(published, progress(scan_series(sensor, times), len(times), f"record {sensor.name}"))
    first = next(scans, None)
    if first is None:
        raise UserError(f"no scan of {sensor.name} completes between {args.start} and {args.end} s")
    truth_path = ground_truth_path(args.out)
    for path in (args.out, truth_path):
        if path.is_symlink():
            raise UserError(f"{path} is a symbolic link: record writes only files, never through links")
    try:
        with truth_path.open("w", encoding="ascii") as truth:
            every_scan = with_ground_truth(itertools.chain([first], scans), sensor, truth)
            if args.format == "mcap":
                from emulator.recording.mcap import record_mcap  # foxglove-sdk: loaded only when asked for

                count = record_mcap(args.out, scene, sensor.name, every_scan)
            else:
                with args.out.open("w", encoding="ascii") as out:
                    count = write_log(out, every_scan, LogHeader(sensor.name, sensor.model, first.unit))
    except OSError as error:
        raise UserError(f"cannot write {error.filename or args.out}: {error.strerror}") from None
    print(f"recorded {count} scans of {sensor.name} ({sensor.model}) to {args.out}, ground truth to {truth_path}")
    return 0


def _run_bag(args: argparse.Namespace, scene: Scene) -> int:
    """Every named sensor's scans, in time order, into one bag with its frames and ground truth."""
    world = world_from_args(scene, args)
    names = [name.strip() for name in args.sensor.split(",")]
    if len(set(names)) != len(names) or not all(names):
        raise UserError(f"--sensor {args.sensor}: name each sensor once")
    sensors = [create_sensor(scene, name, world) for name in names]
    series, total = [], 0
    for sensor in sensors:
        times = scan_times(sensor.configured_period_s, args.start, args.end, sensor.configured_phase_s)
        series.append(scan_series(sensor, times))
        total += len(times)
    if total == 0:
        raise UserError(f"no scan of {args.sensor} completes between {args.start} and {args.end} s")
    scans = progress(heapq.merge(*series, key=lambda scan: scan.time_s), total, f"record {args.sensor}")
    frames = FrameNames(args.map_frame, args.odom_frame, args.base_frame)
    count = write_bag(args.out, args.format, sensors, scans, args.end, frames, args.epoch)
    print(f"recorded {count} scans of {', '.join(names)} to the {args.format} bag {args.out}")
    return 0


def ground_truth_path(log: Path) -> Path:
    """Where the ground truth of `log` goes: its whole name and `.tum`, so no two logs share one."""
    return log.with_name(log.name + ".tum")
