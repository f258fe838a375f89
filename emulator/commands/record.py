"""`lrf-emulator record` (CLI.md). PLACEHOLDER: replaced by the module's owner."""

from __future__ import annotations

import argparse

from emulator.errors import UserError


def add_arguments(parser: argparse.ArgumentParser) -> None:
    pass


def run(args: argparse.Namespace) -> int:
    raise UserError("not implemented yet")
