"""`lrf-emulator scenes`: the bundled scenes, one line each with its description."""

from __future__ import annotations

import argparse

from emulator.scene import bundled_scenes


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """No options: the command only lists."""


def run(args: argparse.Namespace) -> int:
    scenes = bundled_scenes()
    width = max((len(scene.name) for scene in scenes), default=0) + 2
    for scene in scenes:
        print(f"{scene.name:<{width}}{scene.description}".rstrip())
    return 0
