"""`lrf-emulator plot SCENE --sensor NAME --start T0 --end T1 --out FILE.png`,
`lrf-emulator plot SCENE --map [--time T] [--sensor NAME] --out FILE.png`,
and `lrf-emulator plot SCENE --map --sensor NAME [--start T0] --end T1 --out FILE.png`.

A waterfall of the sensor's scans (time down, beam angle across, darker =
shorter with a range colour bar, red = error code) like the paper's Fig. 3 and
10, with the smoke level over time beside it like Fig. 5 (mean density along
the beams for scenes with smoke regions, the assumed camera saturation for
scenes with a camera reference, the share of beams meeting a plume for scenes
with plumes). With `--map`, a top-down picture of the scene at time T instead
(emulator/plots/map.py): solids, smoke shaded by density, plume particles,
bodies' trajectories and, with `--sensor`, that sensor's scan and error codes,
with axes in metres and a legend. With `--map --start T0 --end T1` the map
shows the span: the scene at T1 and every scan of `--sensor` from T0 to T1
(`--time` is one instant: not with a span, and not without `--map`).
FILE's suffix chooses the format (png, svg, pdf, jpg, ...: docs/plots.md).
Needs matplotlib (`pip install '.[plot]'`).

A span is counted before its scans are made: a waterfall draws at most
MAX_PLOT_BEAMS beams (6 000 000: 880 s of a URG-04LX), a map MAX_MAP_BEAMS
(1 000 000: 130 s); a longer span is refused in one line naming --end and the
latest --end that fits, so a huge --end never takes memory without bound.
"""

from __future__ import annotations

import argparse

from emulator.commands.options import add_scene_options, add_span_options, scene_from_args, simulated_time
from emulator.commands.progress import progress
from emulator.errors import UserError
from emulator.plots.map import MAX_MAP_BEAMS, draw_map
from emulator.plots.output import output_format
from emulator.plots.waterfall import MAX_PLOT_BEAMS, draw_waterfall, pyplot, sensor_series

MAX_PIXELS = 8000


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_scene_options(parser)
    add_span_options(
        parser, verb="plot (with --map: whose scans to draw)", out_metavar="FILE.png",
        out_help="image to write, in the format its suffix names (png, svg, pdf, jpg, ...)", required=False,
        start_help="first simulated time (s, default 0); with --map: draw every scan of --sensor from T0 to --end",
        end_help=f"last simulated time (s); a span of more than {MAX_PLOT_BEAMS} beams for a waterfall, {MAX_MAP_BEAMS} "
        "for a map, is refused (a URG-04LX: 880 s, 130 s); with --map: the instant the scene is drawn at",
    )
    parser.set_defaults(start=None)  # given or not: with --map, a span is asked for only when --start or --end is
    parser.add_argument("--map", action="store_true",
                        help="a top-down map of the scene instead of a waterfall: at --time, or at --end with every "
                        "scan of --sensor from --start")
    parser.add_argument("--time", type=simulated_time, default=None, metavar="T",
                        help="with --map: the one simulated time drawn (s, default 0); not with --start/--end")
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
    if args.time is not None:
        raise UserError("--time is the instant of a --map; a waterfall spans --start to --end")
    if args.sensor is None or args.end is None:
        raise UserError("--sensor and --end are required (or --map for a top-down map)")
    scene = scene_from_args(args)
    start = 0.0 if args.start is None else args.start
    series = sensor_series(scene, args.sensor, start, args.end, max_beams=MAX_PLOT_BEAMS,
                           progress=lambda scans, count: progress(scans, count, f"plot {args.sensor}"))
    draw_waterfall(series, args.out, width_px=args.width, height_px=args.height)
    print(f"wrote {args.out} ({len(series.times_s)} scans of {series.sensor})")
    return 0


def _run_map(args: argparse.Namespace) -> int:
    span = args.start is not None or args.end is not None
    if span:
        if args.time is not None:
            raise UserError("--time and --start/--end: a map shows one instant (--time T) or a span's scans "
                            "(--start T0 --end T1, drawn at T1), not both")
        if args.end is None:
            raise UserError("--map --start needs --end: the span's last instant, where the map is drawn")
        if args.sensor is None:
            raise UserError("--map --start/--end draws the scans of a --sensor over the span: name the --sensor "
                            "(or give --time T for one instant)")
        start = 0.0 if args.start is None else args.start
        if start > args.end:
            raise UserError(f"need 0 <= --start <= --end, got {start} and {args.end}")
        time_s = args.end
    else:
        time_s = 0.0 if args.time is None else args.time
    scene = scene_from_args(args)
    if args.sensor is not None and args.sensor not in {spec.name for spec in scene.sensors}:
        known = ", ".join(spec.name for spec in scene.sensors) or "none"
        raise UserError(f"--sensor: no sensor named {args.sensor!r} in scene {scene.name!r} (known: {known})")
    draw_map(scene, time_s, args.out, sensor=args.sensor, since_s=start if span else None,
             width_px=args.width, height_px=args.height)
    what = f"at {time_s:g} s" if not span else f"at {time_s:g} s with the scans of {args.sensor} from {start:g} s"
    print(f"wrote {args.out} (map of {scene.name} {what})")
    return 0

