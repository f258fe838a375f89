"""`lrf-emulator plot SCENE --sensor NAME --start T0 --end T1 --out FILE.png`,
and `lrf-emulator plot SCENE --map [--time T] [--sensor NAME] --out FILE.png`.

A waterfall of the sensor's scans (time down, beam angle across, darker =
shorter with a range colour bar, red = error code) like the paper's Fig. 3 and
10, with the smoke level over time beside it like Fig. 5 (mean density along
the beams for scenes with smoke regions, the assumed camera saturation for
scenes with a camera reference, the share of beams meeting a plume for scenes
with plumes). With `--map`, a top-down picture of the scene at time T instead
(emulator/plots/map.py): solids, smoke shaded by density, plume particles,
bodies' trajectories and, with `--sensor`, that sensor's scan and error codes,
with axes in metres and a legend. FILE's suffix chooses the format (png, svg,
pdf, jpg, ...: docs/plots.md). Needs matplotlib (`pip install '.[plot]'`).
"""

from __future__ import annotations

import argparse
import math

from emulator.commands.options import add_scene_options, add_span_options, scene_from_args
from emulator.commands.progress import progress
from emulator.errors import UserError
from emulator.plots.map import draw_map
from emulator.plots.output import output_format
from emulator.plots.waterfall import draw_waterfall, pyplot, sensor_series

MAX_PIXELS = 8000


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_scene_options(parser)
    add_span_options(parser, verb="plot (with --map: whose scan to draw)", out_metavar="FILE.png",
                     out_help="image to write, in the format its suffix names (png, svg, pdf, jpg, ...)", required=False)
    parser.add_argument("--map", action="store_true", help="a top-down map of the scene at --time instead of a waterfall")
    parser.add_argument("--time", type=float, default=0.0, metavar="T", help="with --map: the simulated time drawn (s)")
    parser.add_argument("--width", type=int, default=1200, metavar="PX", help="image width in pixels")
    parser.add_argument("--height", type=int, default=800, metavar="PX", help="image height in pixels")


def run(args: argparse.Namespace) -> int:
    for name, pixels in (("--width", args.width), ("--height", args.height)):
        if not 200 <= pixels <= MAX_PIXELS:
            raise UserError(f"{name} must be between 200 and {MAX_PIXELS} pixels, got {pixels}")
    pyplot()  # fail before the computation when matplotlib is missing
    output_format(args.out)  # or when it cannot write the format asked for
    if args.map:
        return _run_map(args)
    if args.sensor is None or args.end is None:
        raise UserError("--sensor and --end are required (or --map for a top-down map)")
    scene = scene_from_args(args)
    series = sensor_series(scene, args.sensor, args.start, args.end,
                           progress=lambda scans, count: progress(scans, count, f"plot {args.sensor}"))
    draw_waterfall(series, args.out, width_px=args.width, height_px=args.height)
    print(f"wrote {args.out} ({len(series.times_s)} scans of {series.sensor})")
    return 0


def _run_map(args: argparse.Namespace) -> int:
    if not math.isfinite(args.time) or args.time < 0:
        raise UserError(f"--time must be a finite time >= 0, got {args.time}")
    scene = scene_from_args(args)
    if args.sensor is not None and args.sensor not in {spec.name for spec in scene.sensors}:
        known = ", ".join(spec.name for spec in scene.sensors) or "none"
        raise UserError(f"--sensor: no sensor named {args.sensor!r} in scene {scene.name!r} (known: {known})")
    draw_map(scene, args.time, args.out, sensor=args.sensor, width_px=args.width, height_px=args.height)
    print(f"wrote {args.out} (map of {scene.name} at {args.time:g} s)")
    return 0

