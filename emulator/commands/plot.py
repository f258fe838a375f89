"""`lrf-emulator plot SCENE --sensor NAME --start T0 --end T1 --out FILE.png` (CLI.md).

A waterfall of the sensor's scans (time down, beam angle across, darker =
shorter, red = error code) like the paper's Fig. 3 and 10, with the smoke level
over time beside it like Fig. 5 (mean density along the beams and the assumed
camera saturation for scenes with smoke regions; the share of beams meeting a
plume for scenes with plumes). Needs matplotlib (`pip install '.[plot]'`).
"""

from __future__ import annotations

import argparse

from emulator.commands.options import add_scene_options, add_span_options, scene_from_args
from emulator.errors import UserError
from emulator.plots.waterfall import draw_waterfall, pyplot, sensor_series

MAX_PIXELS = 8000


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_scene_options(parser, seed=False)
    add_span_options(parser, verb="plot", out_metavar="FILE.png", out_help="PNG file to write")
    parser.add_argument("--width", type=int, default=1200, metavar="PX", help="image width in pixels")
    parser.add_argument("--height", type=int, default=800, metavar="PX", help="image height in pixels")


def run(args: argparse.Namespace) -> int:
    for name, pixels in (("--width", args.width), ("--height", args.height)):
        if not 200 <= pixels <= MAX_PIXELS:
            raise UserError(f"{name} must be between 200 and {MAX_PIXELS} pixels, got {pixels}")
    pyplot()  # fail before the computation when matplotlib is missing
    scene = scene_from_args(args)
    series = sensor_series(scene, args.sensor, args.start, args.end)
    try:
        draw_waterfall(series, args.out, width_px=args.width, height_px=args.height)
    except OSError as error:
        raise UserError(f"cannot write {args.out}: {error.strerror or error}") from None
    print(f"wrote {args.out} ({len(series.times_s)} scans of {series.sensor})")
    return 0
