"""`lrf-emulator bench [--json] [--quick] [--section NAME]...`: the emulator's speed on this machine.

The sections themselves live in `emulator.bench.sections`.
"""

from __future__ import annotations

import argparse
import json
import sys

from emulator.bench.sections import SECTIONS


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--json", action="store_true", help="print one JSON object instead of a table")
    parser.add_argument("--quick", action="store_true", help="few repetitions (a smoke test of the bench itself)")
    parser.add_argument(
        "--section", action="append", choices=list(SECTIONS), metavar="NAME",
        help=f"run only this section (repeatable; default all: {', '.join(SECTIONS)})",
    )


def run(args: argparse.Namespace) -> int:
    chosen = [name for name in SECTIONS if not args.section or name in args.section]
    report: dict = {}
    for name in chosen:
        data, lines = SECTIONS[name](args.quick)
        report.update(data)
        if not args.json:
            sys.stdout.write("\n".join(lines) + "\n\n")
            sys.stdout.flush()
    if args.json:
        json.dump(report, sys.stdout)
        sys.stdout.write("\n")
    return 0
