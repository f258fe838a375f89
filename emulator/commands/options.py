"""Arguments several subcommands share: the scene, its seed and its smoke preset."""

from __future__ import annotations

import argparse
import dataclasses

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
