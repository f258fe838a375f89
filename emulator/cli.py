"""The `lrf-emulator` command (CLI.md). Each subcommand lives in `emulator/commands/`."""

from __future__ import annotations

import argparse
import importlib
import sys
import traceback

from emulator.errors import UserError

# subcommand → (module in emulator.commands, one-line help)
SUBCOMMANDS: dict[str, tuple[str, str]] = {
    "serve": ("serve", "serve the scene's sensors on their endpoints (the daemon)"),
    "scan": ("scan", "print one scan at a simulated time as JSON"),
    "plot": ("plot", "draw a waterfall of scans and the smoke level over time (PNG)"),
    "record": ("record", "write scans to a text log in the seed dataset's format"),
    "replay": ("replay", "serve a recorded log through the real protocol"),
    "bench": ("bench", "measure the simulation's and protocols' speed on this machine"),
    "scenes": ("scenes", "list the bundled scenes"),
}


class _Parser(argparse.ArgumentParser):
    """Usage errors: one line on stderr, exit status 2."""

    def error(self, message: str) -> None:  # type: ignore[override]
        sys.stderr.write(f"{self.prog}: {message}\n")
        raise SystemExit(2)


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="lrf-emulator", description=__doc__)
    parser.add_argument("--debug", action="store_true", help="show tracebacks for errors")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    sub.required = True
    for name, (module_name, help_text) in SUBCOMMANDS.items():
        module = importlib.import_module(f"emulator.commands.{module_name}")
        command_parser = sub.add_parser(name, help=help_text, description=help_text)
        module.add_arguments(command_parser)
        command_parser.set_defaults(_run=module.run)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args._run(args) or 0)
    except UserError as error:
        if args.debug:
            traceback.print_exc()
        sys.stderr.write(f"lrf-emulator {args.command}: {error}\n")
        return 2
    except KeyboardInterrupt:
        return 130
    except BrokenPipeError:
        return 0


if __name__ == "__main__":
    sys.exit(main())
