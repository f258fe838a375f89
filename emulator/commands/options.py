"""Arguments several subcommands share: the scene, its seed, its smoke preset and a smoke scale; a sensor's time span."""

from __future__ import annotations

import argparse
import dataclasses
import math
import os
from pathlib import Path

from emulator.control.events import read_events, world_events
from emulator.commands.values import named_path, whole_number
from emulator.errors import UserError
from emulator.optics import World
from emulator.scene import Scene, load_scene
from emulator.scene.smoke_scale import scale_smoke
from emulator.sensors.response import apply_model_override

MAX_SMOKE_SCALE = 1000.0
MIN_SEED = 0  # a scene file's `seed` (scene/loader.py): a whole number, at least 0, with no upper bound


def add_scene_options(parser: argparse.ArgumentParser, *, optional_scene: bool = False, seed: bool = True) -> None:
    """SCENE (a bundled name or a .toml path), `--model PRESET` and, unless `seed=False`, `--seed N`."""
    if optional_scene:
        parser.add_argument("scene", nargs="?", default="railway", metavar="SCENE",
                            help="bundled scene name or path to a .toml file (default: railway)")
    else:
        parser.add_argument("scene", metavar="SCENE", help="bundled scene name or path to a .toml file")
    if seed:
        parser.add_argument("--seed", type=whole_number(MIN_SEED), default=None, metavar="N",
                            help=f"override the scene's seed (a whole number >= {MIN_SEED})")
    parser.add_argument(
        "--model", metavar="PRESET", default=None,
        help="smoke/sensor response preset replacing the scene's (formsma2011 or physical)",
    )
    parser.add_argument(
        "--smoke-scale", type=float, default=None, metavar="F",
        help="multiply every smoke density (regions and plumes) by F; 0 = clear air (no smoke at all)",
    )


def scene_from_args(args: argparse.Namespace) -> Scene:
    """The scene named on the command line, with its `--model` and `--seed` overrides applied."""
    scene = apply_model_override(load_scene(args.scene), args.model)
    if getattr(args, "seed", None) is not None:
        scene = dataclasses.replace(scene, seed=args.seed)
    if args.smoke_scale is not None:
        if not 0.0 <= args.smoke_scale <= MAX_SMOKE_SCALE:
            raise UserError(f"--smoke-scale must be between 0 and {MAX_SMOKE_SCALE:g}, got {args.smoke_scale}")
        scene = scale_smoke(scene, args.smoke_scale)
    return scene


MAX_SIMULATED_TIME_S = 1e7  # 115 days: far beyond any run, far inside the µs grid's exact range


def simulated_time(text: str) -> float:
    """An argparse type: a simulated time in seconds, finite and within 0..MAX_SIMULATED_TIME_S."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected seconds, got {text!r}") from None
    if not math.isfinite(value) or not 0 <= value <= MAX_SIMULATED_TIME_S:
        raise argparse.ArgumentTypeError(f"must be a time in 0..{MAX_SIMULATED_TIME_S:g} s, got {text!r}")
    return value


def add_span_options(
    parser: argparse.ArgumentParser, *, verb: str, out_metavar: str, out_help: str, required: bool = True,
    start_help: str = "first simulated time (s)", end_help: str = "last simulated time (s)",
) -> None:
    """`--sensor NAME --start T0 --end T1 --out FILE`: one sensor's scans over a span of simulated time
    (`required=False`: the caller checks --sensor and --end itself, for modes that need neither)."""
    parser.add_argument("--sensor", required=required, metavar="NAME", help=f"the scene's sensor to {verb}")
    parser.add_argument("--start", type=simulated_time, default=0.0, metavar="T0", help=start_help)
    parser.add_argument("--end", type=simulated_time, required=required, metavar="T1", help=end_help)
    parser.add_argument("--out", required=True, type=output_path, metavar=out_metavar, help=out_help)


def output_path(text: str) -> Path:
    """An argparse type: where to write, named (not empty), not an existing directory, and not an existing
    FIFO, device or socket (opening a FIFO blocks until someone reads it; plot renames its image over the
    path, which would replace /dev/null itself; record writes FILE.tum beside it, as /dev/null.tum)."""
    if not text.strip():
        raise argparse.ArgumentTypeError(f"expected a file name, got {text!r}")
    path = Path(text)
    if path.is_dir() and not path.is_symlink():
        raise argparse.ArgumentTypeError(f"{text}: a directory of that name exists (never written into or over: name a new file or bag)")
    if os.path.lexists(path) and not path.is_symlink() and not path.is_file():
        raise argparse.ArgumentTypeError(f"{text}: exists and is not a regular file (a FIFO, device or socket is never written: name a new file)")
    return path


def add_events_in_option(parser: argparse.ArgumentParser, *names: str) -> None:
    """`--events-in FILE`: an event log of live changes (`serve --events`) to apply at its times."""
    parser.add_argument(
        "--events-in", *names, dest="events_in", type=named_path, default=None, metavar="FILE",
        help="apply this event log of live changes (written by serve --events) at its recorded times; "
        "a pipe or FIFO (<(zcat log.gz)) is read whole first, so the command waits for its writer to finish",
    )


def world_from_args(scene: Scene, args: argparse.Namespace) -> World:
    """The scene's world with the `--events-in` log applied (a live session, reproduced)."""
    world = World(scene)
    if getattr(args, "events_in", None) is not None:
        for event in world_events(read_events(args.events_in, scene)):
            try:
                world.apply(event)
            except ValueError as error:  # a live pose stamped before the body's last one
                raise UserError(f"{args.events_in}: {error}") from None
    return world


LOOPBACK_HOSTS = ("127.0.0.1", "localhost", "::1")


def parse_listen(option: str, text: str) -> tuple[str, int] | None:
    """`HOST:PORT` (port 0: any free one) → (host, port); `off` → None; anything else a UserError."""
    if text == "off":
        return None
    host, sep, port = text.rpartition(":")
    host = host.strip("[]")
    if not sep or not host or not port.isdigit() or int(port) > 65535:
        raise UserError(f"{option} {text!r}: expected HOST:PORT or off")
    return host, int(port)
