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

`--out` is checked before any work: its directory must exist (nothing is
created on the way to it, and the message names `--out`, not the ground
truth's `.tum` beside it); a suffix that names a format must be that format's
(`.mcap`: `--format mcap`, `.bag`: `--format rosbag1`; `.db3`, a ROS 2 bag's
SQLite storage, is never written); and a rosbag2 bag is a
directory named without a suffix: `--out run` makes `run/metadata.yaml` and
`run/run.mcap`, so `--out run.mcap` (which made `run.mcap/run.mcap.mcap`) or
`--out run.db3` is refused, naming the directory to give instead.

A span is counted before any work: more than `--max-scans` scans in all
(default MAX_SCANS, 100 000: 2.8 h of a URG-04LX at 10 Hz, 22 min of an LMS200
at 1°, 75 Hz) is refused in one line that names the count, unless
`--max-scans` is raised. The scans are then made, written and dropped one by
one (their times too, and a bag's /tf and /odom a minute at a time), so
memory stays flat whatever the span, but for the index rosbags' ROS 1 writer
keeps until it closes (about 200 bytes a message); only the files grow.
"""

from __future__ import annotations

import argparse
import heapq
import itertools
import math
import os
from pathlib import Path

from emulator.commands.options import MAX_SIMULATED_TIME_S, add_events_in_option, add_scene_options, add_span_options, scene_from_args, world_from_args
from emulator.commands.values import whole_number
from emulator.commands.progress import progress
from emulator.errors import UserError
from emulator.recording.ground_truth import with_ground_truth
from emulator.recording.rosbag import DEFAULT_EPOCH_S, FORMATS as BAG_FORMATS, FrameNames, write_bag
from emulator.scene.model import Scene
from emulator.recording.textlog import LogHeader, write_log
from emulator.sensors import Sensor, create_sensor
from emulator.sensors.published import published
from emulator.sensors.series import scan_count, scan_series, span_times

MAX_SCANS = 100_000  # record --max-scans's default: scans of all --sensor together
# Suffixes that name a format: an --out with one must be written in it (rosbag2 takes a directory: none of them).
SUFFIX_FORMATS = {".mcap": "mcap", ".bag": "rosbag1", ".db3": "rosbag2"}


BAG_OPTIONS = ("epoch", "map_frame", "odom_frame", "base_frame")  # None unless given: refused for a format that has no use for them


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_scene_options(parser)
    add_span_options(
        parser, verb="record (rosbag2|rosbag1: NAME[,NAME...])", out_metavar="FILE|DIR",
        out_help="where to write, in an existing directory: text: a log FILE (ground truth beside it in FILE.tum); "
        "mcap: FILE.mcap (and FILE.mcap.tum); rosbag1: FILE.bag; rosbag2: a new bag directory DIR named without a "
        "suffix (DIR/metadata.yaml, DIR/DIR.mcap), so an --out ending in .mcap or .bag is refused for rosbag2, as "
        "is one of those for any other format than its own, and .db3 always (record writes no SQLite bags)",
        end_help="last simulated time (s); a span of more than --max-scans scans is refused",
    )
    parser.add_argument(
        "--max-scans", type=whole_number(1), default=MAX_SCANS, metavar="N",
        help=f"refuse a span of more than N scans of all --sensor together, before writing anything "
        f"(default {MAX_SCANS}: 2.8 h of a URG-04LX at 10 Hz, 22 min of an LMS200 at 75 Hz; a text log of a "
        "URG-04LX takes 9 kB a scan); scans are made, written and dropped one by one: memory stays flat whatever N "
        "(but for the index a ROS 1 bag's writer keeps until it closes, about 200 bytes a message)",
    )
    add_events_in_option(parser, "--events")
    parser.add_argument(
        "--format", choices=("text", "mcap", *BAG_FORMATS), default="text",
        help="text: the seed dataset's log (default); mcap: Foxglove LaserScan, device values, transforms and scene; "
        "rosbag2 (--out DIR, no suffix) / rosbag1 (--out FILE.bag): a ROS bag of every --sensor NAME[,NAME...] "
        "with tf and odometry",
    )
    bag = parser.add_argument_group("ROS bags (--format rosbag2|rosbag1)")
    bag.add_argument("--epoch", type=bag_epoch, default=None, metavar="UNIX_TIME",
                     help=f"ROS time of simulated time 0 (default {DEFAULT_EPOCH_S}; serve --epoch takes the same)")
    bag.add_argument("--map-frame", metavar="NAME", help="REP 105 map frame (default map)")
    bag.add_argument("--odom-frame", metavar="NAME", help="REP 105 odom frame (default odom)")
    bag.add_argument("--base-frame", metavar="NAME", help="the robot's frame (default base_link)")


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


def check_out(out: Path, fmt: str) -> None:
    """Refuse, before any work, an --out in a directory that is not there, with a suffix of another
    format, or (rosbag2: a bag directory) with a file's suffix."""
    parent = out.parent
    if not parent.is_dir():
        what = "is not a directory" if parent.exists() else "does not exist"
        raise UserError(f"--out {out}: its directory {parent} {what} (record creates no directories)")
    suffix = out.suffix.lower()
    if fmt == "rosbag2" and suffix in SUFFIX_FORMATS:
        bare = out.with_suffix("")
        raise UserError(f"--out {out}: --format rosbag2 writes a bag directory, named without a suffix "
                        f"(--out {bare} makes {bare}/metadata.yaml and {bare}/{bare.name}.mcap)")
    if suffix == ".db3":
        raise UserError(f"--out {out}: .db3 is a ROS 2 bag's SQLite storage, which record does not write "
                        f"(--format rosbag2 --out {out.with_suffix('')} writes a bag directory)")
    if suffix in SUFFIX_FORMATS and SUFFIX_FORMATS[suffix] != fmt:
        raise UserError(f"--out {out}: a {suffix} name is for --format {SUFFIX_FORMATS[suffix]}, not --format {fmt} "
                        f"(pass --format {SUFFIX_FORMATS[suffix]}, or name the file otherwise)")


def check_span(args: argparse.Namespace, sensors: list[Sensor]) -> int:
    """The number of scans the span holds (at least one), or a UserError when it holds none or
    more than --max-scans."""
    names = ", ".join(sensor.name for sensor in sensors)
    total = sum(scan_count(s.configured_period_s, args.start, args.end, s.configured_phase_s) for s in sensors)
    if total == 0:
        raise UserError(f"no scan of {names} completes between {args.start} and {args.end} s")
    if total > args.max_scans:
        per_second = sum(1.0 / sensor.configured_period_s for sensor in sensors)
        raise UserError(
            f"--start {args.start:.10g} to --end {args.end:.10g} holds {total} scans of {names}, more than --max-scans "
            f"{args.max_scans} allows (that many span {args.max_scans / per_second:.6g} s here): "
            "record a shorter span, or raise --max-scans"
        )
    return total


def run(args: argparse.Namespace) -> int:
    check_out(args.out, args.format)
    if args.format not in BAG_FORMATS:
        given = [f"--{name.replace('_', '-')}" for name in BAG_OPTIONS if getattr(args, name) is not None]
        if given:
            raise UserError(f"{', '.join(given)}: for --format rosbag2 or rosbag1 only (a {args.format} recording has no ROS time or frames)")
    scene = scene_from_args(args)
    if args.format in BAG_FORMATS:
        return _run_bag(args, scene)
    if "," in args.sensor:
        raise UserError(f"--sensor {args.sensor}: --format {args.format} records one sensor (a ROS bag takes several)")
    sensor = create_sensor(scene, args.sensor, world_from_args(scene, args))
    total = check_span(args, [sensor])
    times = span_times(sensor.configured_period_s, args.start, args.end, sensor.configured_phase_s)
    scans = map(published, progress(scan_series(sensor, times), total, f"record {sensor.name}"))
    first = next(scans)
    truth_path = ground_truth_path(args.out)
    for path in (args.out, truth_path):
        if path.is_symlink():
            raise UserError(f"{path} is a symbolic link: record writes only files, never through links")
        if os.path.lexists(path) and not path.is_file():  # checked before either is opened: neither is left behind
            raise UserError(f"{path}: exists and is not a regular file (a FIFO, device, socket or directory is never written: name a new file)")
    try:
        if args.format == "mcap":
            from emulator.recording.mcap import record_mcap  # foxglove-sdk: loaded only when asked for

            with truth_path.open("w", encoding="ascii") as truth:
                count = record_mcap(args.out, scene, sensor.name, with_ground_truth(itertools.chain([first], scans), sensor, truth))
        else:  # the user's file first: a failure names it, not the ground truth beside it
            with args.out.open("w", encoding="ascii") as out, truth_path.open("w", encoding="ascii") as truth:
                every_scan = with_ground_truth(itertools.chain([first], scans), sensor, truth)
                count = write_log(out, every_scan, LogHeader(sensor.name, sensor.model, first.unit))
    except OSError as error:
        raise UserError(f"cannot write {error.filename or args.out}: {error.strerror}") from None
    print(f"recorded {_scans(count)} of {sensor.name} ({sensor.model}) to {args.out}, ground truth to {truth_path}")
    return 0


def _run_bag(args: argparse.Namespace, scene: Scene) -> int:
    """Every named sensor's scans, in time order, into one bag with its frames and ground truth."""
    frames = frame_names(args)
    world = world_from_args(scene, args)
    names = [name.strip() for name in args.sensor.split(",")]
    if not all(names):
        raise UserError(f"--sensor {args.sensor!r}: a sensor name is empty (expected NAME[,NAME...])")
    if len(set(names)) != len(names):
        raise UserError(f"--sensor {args.sensor}: name each sensor once")
    clashing = {"--map-frame": frames.map, "--odom-frame": frames.odom, "--base-frame": frames.base}
    for option, frame in clashing.items():
        if frame in names:  # a sensor's frame is its name, the base its parent
            raise UserError(f"{option} {frame}: the sensor {frame}'s own frame (tf would make a frame its own parent)")
    sensors = [create_sensor(scene, name, world) for name in names]
    total = check_span(args, sensors)
    series = [scan_series(sensor, span_times(sensor.configured_period_s, args.start, args.end, sensor.configured_phase_s))
              for sensor in sensors]
    scans = progress(heapq.merge(*series, key=lambda scan: scan.time_s), total, f"record {args.sensor}")
    count = write_bag(args.out, args.format, sensors, scans, args.end, frames, DEFAULT_EPOCH_S if args.epoch is None else args.epoch)
    print(f"recorded {_scans(count)} of {', '.join(names)} to the {args.format} bag {args.out}")
    return 0


def frame_names(args: argparse.Namespace) -> FrameNames:
    """The bag's REP 105 frames: each named (tf refuses an empty frame id) and all three apart (a frame
    that is its own parent breaks every tf lookup)."""
    defaults = FrameNames()
    given = {f"--{kind}-frame": getattr(defaults, kind) if getattr(args, f"{kind}_frame") is None else getattr(args, f"{kind}_frame")
             for kind in ("map", "odom", "base")}
    for option, name in given.items():
        if not name or any(character.isspace() for character in name) or name.startswith("/"):
            raise UserError(f"{option} {name!r}: expected a frame name (not empty, no spaces, not starting with /: tf2 refuses it)")
    if len(set(given.values())) < len(given):
        shown = ", ".join(f"{option} {name}" for option, name in given.items())
        raise UserError(f"{shown}: the three frames must differ (tf would make a frame its own parent)")
    return FrameNames(*given.values())


def _scans(count: int) -> str:
    return f"{count} scan" if count == 1 else f"{count} scans"


def ground_truth_path(log: Path) -> Path:
    """Where the ground truth of `log` goes: its whole name and `.tum`, so no two logs share one."""
    return log.with_name(log.name + ".tum")
