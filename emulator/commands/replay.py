"""`lrf-emulator replay LOG --model urg-04lx|lms200 [--endpoint URI]...` (CLI.md).

Serves a recorded log (from `record`, or a real sensor's log in the same
format) through the real protocol on the daemon, at the log's recorded rate,
looping at its end (emulator/recording/replay_sources.py). The served sensor is named after the
log's header (default `urg` / `lms`). Endpoints as for `serve`: `pty:PATH` or
`tcp:HOST:PORT`; defaults: URG-04LX tcp:127.0.0.1:10940, LMS200 pty:ttyLMS0.
An LMS200 starts in the angle, resolution and unit of the log.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from emulator.commands.serve import serve_until_signalled
from emulator.daemon.clock import WallClock
from emulator.daemon.service import Daemon
from emulator.recording.replay_sources import (
    LMS_MODEL,
    MODELS,
    URG_MODEL,
    replay_sensor,
)
from emulator.recording.textlog import Log, read_log
from emulator.scene.model import Pose, Scene, SensorSpec

DEFAULT_ENDPOINTS = {URG_MODEL: "tcp:127.0.0.1:10940", LMS_MODEL: "pty:ttyLMS0"}
DEFAULT_NAMES = {URG_MODEL: "urg", LMS_MODEL: "lms"}
LMS_WINDOWS = {(180, 1.0), (180, 0.5), (100, 1.0), (100, 0.5), (100, 0.25)}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("log", type=Path, metavar="LOG", help="a log written by `record` (or in its format)")
    parser.add_argument("--model", required=True, choices=MODELS, help="the device to serve the log as")
    parser.add_argument(
        "--endpoint", action="append", default=[], metavar="URI",
        help="pty:PATH or tcp:HOST:PORT (repeatable; default: urg-04lx tcp:127.0.0.1:10940, lms200 pty:ttyLMS0)",
    )


def lms_options(log: Log) -> dict[str, object]:
    """The LMS200's power-on window and unit matching the log, when it is one the device has."""
    degrees = np.degrees(log.angles_rad[0])
    span = int(round(degrees[-1] - degrees[0]))
    resolution = round(float(np.median(np.diff(degrees))) * 4) / 4 if len(degrees) > 1 else 1.0
    options: dict[str, object] = {"units": log.header.unit}
    if (span, resolution) in LMS_WINDOWS:
        options.update(angle_deg=span, resolution_deg=resolution)
    return options


def replay_scene(log: Log, model: str, endpoints: list[str]) -> Scene:
    """A scene holding just the replayed sensor, for the daemon."""
    name = log.header.sensor or DEFAULT_NAMES[model]
    options = lms_options(log) if model == LMS_MODEL else {}
    spec = SensorSpec(name, model, Pose(), tuple(endpoints or [DEFAULT_ENDPOINTS[model]]), options)
    return Scene(
        path=None, name=f"replay of {name}", description="", seed=0, model="formsma2011",
        density_to_extinction=250.0, materials={}, objects=(), regions=(), plumes=(), sensors=(spec,),
    )


def run(args: argparse.Namespace) -> int:
    log = read_log(args.log)
    sensor = replay_sensor(log, args.model, log.header.sensor or DEFAULT_NAMES[args.model])
    scene = replay_scene(log, args.model, args.endpoint)
    serve_until_signalled(Daemon(scene, None, WallClock(), sensor_factory=lambda spec: sensor))
    return 0
