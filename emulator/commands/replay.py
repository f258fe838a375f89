"""`lrf-emulator replay LOG --device MODEL [--endpoint URI]...`, and `replay FILE.mcap --topic T --device ...`: a LaserScan topic of an MCAP file
(a Foxglove recording, or a ROS 2 bag's MCAP file; emulator/recording/mcap_replay.py) or of a ROS bag
(a ROS 2 bag directory or a ROS 1 `.bag`; emulator/recording/bag_replay.py).

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
from emulator.errors import UserError
from emulator.recording.replay_sources import (
    LMS_MODEL,
    MODELS,
    URG_MODEL,
    ColaReplay,
    replay_sensor,
)
from emulator.scene.sick_models import MODELS as SICK_MODELS
from emulator.recording.textlog import Log, read_log
from emulator.scene.model import Pose, Scene, SensorSpec

MCAP_MAGIC = b"\x89MCAP"
ROS1_BAG_MAGIC = b"#ROSBAG V2.0"
DEFAULT_ENDPOINTS = {**{model: "tcp:127.0.0.1:10940" for model in MODELS if model != LMS_MODEL}, LMS_MODEL: "pty:ttyLMS0",
                     **{model: "tcp:127.0.0.1:2111" for model in SICK_MODELS}}
DEFAULT_NAMES = {URG_MODEL: "urg", "utm-30lx": "utm", "utm-30lx-ew": "utm", "ust-10lx": "ust", "ust-20lx": "ust", LMS_MODEL: "lms",
                 **{model: "sick" for model in SICK_MODELS}}
LMS_WINDOWS = {(180, 1.0), (180, 0.5), (100, 1.0), (100, 0.5), (100, 0.25)}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("log", type=log_path, metavar="LOG", help="a log written by `record` (or in its format), an MCAP file, or a ROS bag (ROS 2 directory, ROS 1 .bag)")
    parser.add_argument("--topic", metavar="T", default=None,
                        help="for an MCAP file or a bag: the LaserScan topic to serve (default: its only one)")
    # --device: every other command's --model is the smoke preset
    parser.add_argument("--device", dest="model", required=True, choices=MODELS, help="the device to serve the log as")
    parser.add_argument(
        "--endpoint", action="append", default=[], metavar="URI",
        help="pty:PATH, tcp:HOST:PORT or rfc2217:HOST:PORT (repeatable; default: a Hokuyo tcp:127.0.0.1:10940, lms200 pty:ttyLMS0,"
             " a CoLa SICK tcp:127.0.0.1:2111)",
    )


def log_path(text: str) -> Path:
    """An argparse type: LOG named (Path('') is '.', the working directory) and, if there, a file or a bag
    directory: a FIFO blocked replay while it looked for the MCAP magic, and a pipe's bytes are read once."""
    if not text.strip():
        raise argparse.ArgumentTypeError(f"expected a log file, got {text!r}")
    path = Path(text)
    if path.exists() and not path.is_dir() and not path.is_file():
        raise argparse.ArgumentTypeError(f"{text}: is not a regular file (a FIFO or device cannot be replayed: give a log file)")
    return path


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
    """The scene for a text log: its sensor, named from the header, in the log's LMS200 window."""
    name = log.header.sensor or DEFAULT_NAMES[model]
    options = lms_options(log) if model == LMS_MODEL else {}
    if model in SICK_MODELS:  # the unit powers on in the scan configuration the log was recorded in
        options = ColaReplay(log, name, SICK_MODELS[model]).scan_configuration()
    return sensor_only_scene(SensorSpec(name, model, Pose(), tuple(endpoints or [DEFAULT_ENDPOINTS[model]]), options))


def sensor_only_scene(spec: SensorSpec) -> Scene:
    """A scene holding just the replayed sensor, for the daemon."""
    return Scene(
        path=None, name=f"replay of {spec.name}", description="", seed=0, model="formsma2011",
        density_to_extinction=250.0, materials={}, objects=(), regions=(), plumes=(), sensors=(spec,),
    )


def is_mcap(path: Path) -> bool:
    """An MCAP file starts with its magic bytes, whatever its name."""
    try:
        with open(path, "rb") as file:
            return file.read(len(MCAP_MAGIC)) == MCAP_MAGIC
    except OSError:
        return False


def is_bag(path: Path) -> bool:
    """A ROS 2 bag directory (its metadata.yaml) or a ROS 1 bag file (its magic line)."""
    if path.is_dir():
        return (path / "metadata.yaml").is_file()
    try:
        with open(path, "rb") as file:
            return file.read(len(ROS1_BAG_MAGIC)) == ROS1_BAG_MAGIC
    except OSError:
        return False


def run(args: argparse.Namespace) -> int:
    if is_mcap(args.log) or is_bag(args.log):
        return _run_mcap(args)
    if args.topic is not None:
        raise UserError(f"--topic: {args.log} is not an MCAP file or a ROS bag")
    if args.log.is_dir():  # a ROS 2 bag's directory holds metadata.yaml (is_bag); this one does not
        raise UserError(f"{args.log}: is a directory, not a log file (nor a ROS 2 bag: it has no metadata.yaml)")
    log = read_log(args.log)
    sensor = replay_sensor(log, args.model, log.header.sensor or DEFAULT_NAMES[args.model])
    scene = replay_scene(log, args.model, args.endpoint)
    serve_until_signalled(Daemon(scene, _given(scene, args.endpoint), WallClock(), sensor_factory=lambda spec: sensor))
    return 0


def _run_mcap(args: argparse.Namespace) -> int:
    from emulator.recording.bag_replay import read_bag_laser_scans  # readers: only when asked for
    from emulator.recording.mcap_replay import LaserScanReplay, read_laser_scans

    scans = read_bag_laser_scans(args.log, args.topic) if is_bag(args.log) else read_laser_scans(args.log, args.topic)
    name = DEFAULT_NAMES[args.model]
    sensor = LaserScanReplay(scans, args.model, name)
    options = sensor.scan_configuration() if args.model in SICK_MODELS else {}  # powers on as it was recorded
    scene = sensor_only_scene(SensorSpec(name, args.model, Pose(), tuple(args.endpoint or [DEFAULT_ENDPOINTS[args.model]]), options))
    serve_until_signalled(Daemon(scene, _given(scene, args.endpoint), WallClock(), sensor_factory=lambda spec: sensor))
    return 0


def _given(scene: Scene, endpoints: list[str]) -> dict[str, list[str]] | None:
    """The --endpoint URIs as the daemon's overrides of the replayed sensor, so an endpoint that cannot
    serve is reported as `--endpoint NAME: ...`, not as the `scene: sensors[0].endpoints[0]` of no file."""
    return {scene.sensors[0].name: list(endpoints)} if endpoints else None
