"""Arguments several subcommands share: the scene, its seed and its smoke preset; a sensor's time span."""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

from emulator.scene import Scene, load_scene
from emulator.sensors.response import apply_model_override


def add_scene_options(parser: argparse.ArgumentParser, *, optional_scene: bool = False, seed: bool = True) -> None:
    """SCENE (a bundled name or a .toml path), `--model PRESET` and, unless `seed=False`, `--seed N`."""
    if optional_scene:
        parser.add_argument("scene", nargs="?", default="railway", metavar="SCENE",
                            help="bundled scene name or path to a .toml file (default: railway)")
    else:
        parser.add_argument("scene", metavar="SCENE", help="bundled scene name or path to a .toml file")
    if seed:
        parser.add_argument("--seed", type=int, default=None, metavar="N", help="override the scene's seed")
    parser.add_argument(
        "--model", metavar="PRESET", default=None,
        help="smoke/sensor response preset replacing the scene's (formsma2011 or physical)",
    )


def scene_from_args(args: argparse.Namespace) -> Scene:
    """The scene named on the command line, with its `--model` and `--seed` overrides applied."""
    scene = apply_model_override(load_scene(args.scene), args.model)
    if getattr(args, "seed", None) is not None:
        scene = dataclasses.replace(scene, seed=args.seed)
    return scene


def add_span_options(parser: argparse.ArgumentParser, *, verb: str, out_metavar: str, out_help: str) -> None:
    """`--sensor NAME --start T0 --end T1 --out FILE`: one sensor's scans over a span of simulated time."""
    parser.add_argument("--sensor", required=True, metavar="NAME", help=f"the scene's sensor to {verb}")
    parser.add_argument("--start", type=float, default=0.0, metavar="T0", help="first simulated time (s)")
    parser.add_argument("--end", type=float, required=True, metavar="T1", help="last simulated time (s)")
    parser.add_argument("--out", required=True, type=Path, metavar=out_metavar, help=out_help)
