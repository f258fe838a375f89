"""`lrf-emulator scan SCENE --sensor NAME [--time T] [--seed N] [--model PRESET]`: one scan as JSON (CLI.md).

The URG-04LX gives all 769 steps (0..768; steps outside 44..725 carry the
sensor's out-of-area value); the LMS200 the scan its scene options select
(angle_deg, resolution_deg, units), e.g. 100° → device angles 40°..140°.
"""

from __future__ import annotations

import argparse
import json
import sys

import numpy as np

from emulator.commands.options import add_scene_options, scene_from_args
from emulator.sensors import Scan, create_sensor, ranges_m

ANGLE_DECIMALS = 9  # the devices' angles are exact in far fewer digits; drop float noise


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_scene_options(parser)
    parser.add_argument("--sensor", required=True, metavar="NAME", help="the scene's sensor to scan with")
    parser.add_argument("--time", type=float, default=0.0, metavar="T", help="simulated time in seconds (default 0)")


def scan_json(scan: Scan) -> dict:
    ranges = ranges_m(scan)
    return {
        "sensor": scan.sensor,
        "model": scan.model,
        "time_s": scan.time_s,
        "unit": scan.unit,
        "angles_deg": np.round(np.degrees(scan.angles_rad), ANGLE_DECIMALS).tolist(),
        "values": [int(v) for v in scan.values],
        "ranges_m": [None if np.isnan(r) else float(r) for r in ranges],
    }


def run(args: argparse.Namespace) -> int:
    scene = scene_from_args(args)
    scan = create_sensor(scene, args.sensor).configured_scan(args.time)
    json.dump(scan_json(scan), sys.stdout)
    sys.stdout.write("\n")
    return 0
