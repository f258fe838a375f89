"""`lrf-emulator record SCENE --sensor NAME --start T0 --end T1 --out FILE` (CLI.md).

Writes one log line per scan (emulator/logfile.py) at the sensor's scan
period: the URG-04LX every 0.1 s; the LMS200 every full scan of its configured
resolution, i.e. the mirror revolutions that scan needs (1°: 1/75 s,
0.5°: 2/75 s, 0.25°: 4/75 s), with the scene's angle, resolution and units.
Scan k is taken at t = k · period, for every k with T0 ≤ t ≤ T1.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import Iterator

import numpy as np

from emulator.errors import UserError
from emulator.logfile import LogHeader, write_log
from emulator.optics import World
from emulator.sensors.physical import apply_model_override
from emulator.scene import Scene, load_scene
from emulator.scene.model import SensorSpec
from emulator.sensors import create_sensor
from emulator.sensors.scan import Scan

LMS_REVOLUTION_S = 1.0 / 75.0
LMS_REVOLUTIONS_PER_SCAN = {1.0: 1, 0.5: 2, 0.25: 4}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("scene", metavar="SCENE", help="bundled scene name or path to a .toml file")
    parser.add_argument("--sensor", required=True, metavar="NAME", help="the scene's sensor to record")
    parser.add_argument("--start", type=float, default=0.0, metavar="T0", help="first simulated time (s)")
    parser.add_argument("--end", type=float, required=True, metavar="T1", help="last simulated time (s)")
    parser.add_argument(
        "--model", metavar="PRESET", help="smoke/sensor response preset replacing the scene's (formsma2011 or physical)"
    )
    parser.add_argument("--out", required=True, type=Path, metavar="FILE", help="log file to write")


def scan_period_s(spec: SensorSpec) -> float:
    """Seconds between two complete scans of the sensor as configured in the scene."""
    if spec.model == "lms200":
        return LMS_REVOLUTIONS_PER_SCAN[float(spec.options.get("resolution_deg", 0.5))] * LMS_REVOLUTION_S
    return 0.1


def scan_times(spec: SensorSpec, start_s: float, end_s: float) -> np.ndarray:
    """The scan completion times k · period within [start_s, end_s]."""
    if not (math.isfinite(start_s) and math.isfinite(end_s)) or start_s < 0 or end_s < start_s:
        raise UserError(f"need 0 <= --start <= --end, got {start_s} and {end_s}")
    period = scan_period_s(spec)
    first = math.ceil(start_s / period - 1e-9)
    last = math.floor(end_s / period + 1e-9)
    return np.arange(first, last + 1) * period


def scan_series(scene: Scene, sensor_name: str, times_s: np.ndarray, world: World | None = None) -> Iterator[Scan]:
    """The sensor's scans at `times_s`, as the device would put them on the wire."""
    spec = _sensor_spec(scene, sensor_name)
    sensor = create_sensor(scene, sensor_name, world=world)
    if spec.model == "lms200":
        angle = float(spec.options.get("angle_deg", 180))
        step = float(spec.options.get("resolution_deg", 0.5))
        window = dict(
            start_deg=(180.0 - angle) / 2.0, step_deg=step,
            count=int(round(angle / step)) + 1, unit=str(spec.options.get("units", "mm")),
        )
        for time_s in times_s:
            yield sensor.scan(float(time_s), **window)
    else:
        for time_s in times_s:
            yield sensor.scan(float(time_s))


def _sensor_spec(scene: Scene, sensor_name: str) -> SensorSpec:
    try:
        return scene.sensor(sensor_name)
    except KeyError as error:
        raise UserError(error.args[0]) from None


def run(args: argparse.Namespace) -> int:
    scene = apply_model_override(load_scene(args.scene), args.model)
    spec = _sensor_spec(scene, args.sensor)
    times = scan_times(spec, args.start, args.end)
    scans = scan_series(scene, args.sensor, times)
    unit = str(spec.options.get("units", "mm")) if spec.model == "lms200" else "mm"
    try:
        with args.out.open("w", encoding="ascii") as out:
            count = write_log(out, scans, LogHeader(spec.name, spec.model, unit))
    except OSError as error:
        raise UserError(f"cannot write {args.out}: {error.strerror}") from None
    print(f"recorded {count} scans of {spec.name} ({spec.model}) to {args.out}")
    return 0
