"""`lrf-emulator scan SCENE --sensor NAME [--time T] [--seed N] [--model PRESET]`: one scan as JSON (CLI.md).

The URG-04LX gives all 769 steps (0..768; steps outside 44..725 carry the
sensor's out-of-area value); the LMS200 the scan its scene options select
(angle_deg, resolution_deg, units), e.g. 100° → device angles 40°..140°.
`pose` is the sensor's world pose at the scan's time stamp and `times_s` the
instant each value was measured (the mirror sweeps the beams one by one; a
sensor on a moving body casts each beam from where it is at that instant).
"""

from __future__ import annotations

import argparse
import json
import sys

import numpy as np

from emulator.commands.options import add_scene_options, scene_from_args
from emulator.scene.bodies import matrix_euler_deg, matrix_quaternion
from emulator.sensors import Scan, Sensor, beam_times_s, create_sensor, ranges_m

ANGLE_DECIMALS = 9  # the devices' angles are exact in far fewer digits; drop float noise
TIME_DECIMALS = 9  # beam instants: nanoseconds, far below the µs grid the world is evaluated on
POSE_DECIMALS = 12


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_scene_options(parser)
    parser.add_argument("--sensor", required=True, metavar="NAME", help="the scene's sensor to scan with")
    parser.add_argument("--time", type=float, default=0.0, metavar="T", help="simulated time in seconds (default 0)")


def pose_json(sensor: Sensor, time_s: float) -> dict:
    """The sensor's world pose at `time_s`: position (m), roll/pitch/yaw (degrees), quaternion (x, y, z, w)."""
    position, rotation = sensor.mount.pose_at(time_s)
    return {
        "position": [round(float(v), POSE_DECIMALS) for v in position],
        "rotation_deg": [round(v, POSE_DECIMALS) for v in matrix_euler_deg(rotation)],
        "quaternion": [round(float(v), POSE_DECIMALS) for v in matrix_quaternion(rotation)],
    }


def scan_json(scan: Scan, sensor: Sensor | None = None) -> dict:
    """The scan as JSON; with the `sensor` that took it, also its `pose` and the beams' `times_s`."""
    ranges = ranges_m(scan)
    extra = {} if sensor is None else {
        "pose": pose_json(sensor, scan.time_s),
        "times_s": np.round(beam_times_s(scan), TIME_DECIMALS).tolist(),
    }
    return {
        "sensor": scan.sensor,
        "model": scan.model,
        "time_s": scan.time_s,
        "unit": scan.unit,
        "angles_deg": np.round(np.degrees(scan.angles_rad), ANGLE_DECIMALS).tolist(),
        "values": [int(v) for v in scan.values],
        "ranges_m": [None if np.isnan(r) else float(r) for r in ranges],
        **extra,
    }


def run(args: argparse.Namespace) -> int:
    scene = scene_from_args(args)
    sensor = create_sensor(scene, args.sensor)
    scan = sensor.configured_scan(args.time)
    json.dump(scan_json(scan, sensor), sys.stdout)
    sys.stdout.write("\n")
    return 0
