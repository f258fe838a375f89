"""`lrf-emulator scan SCENE --sensor NAME [--time T] [--seed N] [--model PRESET]`: one scan as JSON.

The scan as its ROS driver publishes it (emulator/sensors/published.py): the
URG-04LX its measured steps 44..725 (682 values; the protocol also sends
steps 0..43 and 726..768, which it never measures); the LMS200 the scan its
scene options select (angle_deg, resolution_deg, units), e.g. 100° → device
angles 40°..140°. Beside them the LaserScan fields angle_min … range_max.
`pose` is the sensor's world pose at the scan's time stamp and `times_s` the
instant each value was measured (the mirror sweeps the beams one by one; a
sensor on a moving body casts each beam from where it is at that instant).
"""

from __future__ import annotations

import argparse
import json
import sys

from emulator.commands.options import (
    add_events_in_option,
    add_scene_options,
    scene_from_args,
    simulated_time,
    world_from_args,
)
from emulator.sensors import create_sensor
from emulator.sensors.scan_json import scan_json


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_scene_options(parser)
    parser.add_argument("--sensor", required=True, metavar="NAME", help="the scene's sensor to scan with")
    parser.add_argument(
        "--time", type=simulated_time, default=0.0, metavar="T", help="simulated time in seconds (default 0)"
    )
    add_events_in_option(parser, "--events")


def run(args: argparse.Namespace) -> int:
    scene = scene_from_args(args)
    sensor = create_sensor(scene, args.sensor, world_from_args(scene, args))
    scan = sensor.configured_scan(args.time)
    json.dump(scan_json(scan, sensor), sys.stdout)
    sys.stdout.write("\n")
    return 0
