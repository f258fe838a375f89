"""`lrf-emulator bench [--json] [--quick] [--section NAME]...`: the emulator's speed on this machine.

The sections themselves live in `emulator.bench.sections`.
"""

from __future__ import annotations

import argparse
import json
import sys

from emulator.bench.sections import LONG_SECTIONS, SECTIONS
from emulator.errors import UserError


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--json", action="store_true", help="print one JSON object instead of a table")
    parser.add_argument("--quick", action="store_true", help="few repetitions (a smoke test of the bench itself)")
    parser.add_argument(
        "--section", action="append", choices=[*SECTIONS, *LONG_SECTIONS], metavar="NAME",
        help=f"run only this section (repeatable; default all: {', '.join(SECTIONS)}; "
        f"only when named: {', '.join(LONG_SECTIONS)})",
    )
    parser.add_argument(
        "--minutes", type=float, default=None, metavar="N",
        help="how long a long section runs (soak: default 60)",
    )


def run(args: argparse.Namespace) -> int:
    if args.minutes is not None and not 0 < args.minutes <= 24 * 60:
        raise UserError(f"--minutes must be > 0 and <= {24 * 60}, got {args.minutes:g}")
    chosen = [name for name in [*SECTIONS, *LONG_SECTIONS] if name in (args.section or SECTIONS)]
    report: dict = {}
    for name in chosen:
        if name in LONG_SECTIONS:
            data, lines = LONG_SECTIONS[name](args.quick, args.minutes)
        else:
            data, lines = SECTIONS[name](args.quick)
        report.update(data)
        if not args.json:
            sys.stdout.write("\n".join(lines) + "\n\n")
            sys.stdout.flush()
    if args.json:
        json.dump(report, sys.stdout)
        sys.stdout.write("\n")
    return 1 if report.get("soak", {}).get("passed") is False else 0
