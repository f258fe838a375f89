"""`lrf-emulator record SCENE --sensor NAME --start T0 --end T1 --out FILE` (CLI.md).

Writes one log line per scan (emulator/logfile.py) at the sensor's scan
period, as the scene configures it (`configured_scan`, `configured_period_s`):
the URG-04LX every 0.1 s; the LMS200 every full scan of its resolution, i.e.
the mirror revolutions that scan needs (1°: 1/75 s, 0.5°: 2/75 s,
0.25°: 4/75 s), with the scene's angle, resolution and units.
Scan k is taken at t = k · period, for every k with T0 ≤ t ≤ T1.
"""

from __future__ import annotations

import argparse
import itertools
import math
from pathlib import Path
from typing import Iterator

import numpy as np

from emulator.errors import UserError
from emulator.logfile import LogHeader, write_log
from emulator.scene import load_scene
from emulator.sensors import Sensor, create_sensor
from emulator.sensors.physical import apply_model_override
from emulator.sensors.scan import Scan


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("scene", metavar="SCENE", help="bundled scene name or path to a .toml file")
    parser.add_argument("--sensor", required=True, metavar="NAME", help="the scene's sensor to record")
    parser.add_argument("--start", type=float, default=0.0, metavar="T0", help="first simulated time (s)")
    parser.add_argument("--end", type=float, required=True, metavar="T1", help="last simulated time (s)")
    parser.add_argument(
        "--model", metavar="PRESET", help="smoke/sensor response preset replacing the scene's (formsma2011 or physical)"
    )
    parser.add_argument("--out", required=True, type=Path, metavar="FILE", help="log file to write")


def scan_times(period_s: float, start_s: float, end_s: float) -> np.ndarray:
    """The scan completion times k · period_s within [start_s, end_s]."""
    if not (math.isfinite(start_s) and math.isfinite(end_s)) or start_s < 0 or end_s < start_s:
        raise UserError(f"need 0 <= --start <= --end, got {start_s} and {end_s}")
    first = math.ceil(start_s / period_s - 1e-9)
    last = math.floor(end_s / period_s + 1e-9)
    return np.arange(first, last + 1) * period_s


def scan_series(sensor: Sensor, times_s: np.ndarray) -> Iterator[Scan]:
    """The sensor's configured scans at `times_s`, as the device would put them on the wire."""
    for time_s in times_s:
        yield sensor.configured_scan(float(time_s))


def run(args: argparse.Namespace) -> int:
    scene = apply_model_override(load_scene(args.scene), args.model)
    sensor = create_sensor(scene, args.sensor)
    scans = scan_series(sensor, scan_times(sensor.configured_period_s, args.start, args.end))
    first = next(scans, None)
    if first is None:
        raise UserError(f"no scan of {sensor.name} completes between {args.start} and {args.end} s")
    try:
        with args.out.open("w", encoding="ascii") as out:
            header = LogHeader(sensor.name, sensor.model, first.unit)
            count = write_log(out, itertools.chain([first], scans), header)
    except OSError as error:
        raise UserError(f"cannot write {args.out}: {error.strerror}") from None
    print(f"recorded {count} scans of {sensor.name} ({sensor.model}) to {args.out}")
    return 0
