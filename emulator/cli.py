"""lrf-emulator: virtual Hokuyo URG-04LX and Sick LMS200 laser range finders in a smoky 3D scene.

Each subcommand lives in `emulator/commands/`; `lrf-emulator COMMAND --help` describes it.
"""

from __future__ import annotations

import os
import sys

from emulator.commands.stopping import Interrupted, hold_stop_signals, raise_on_stop_signals

if __name__ == "__main__" or os.path.basename(sys.argv[0]) == "lrf-emulator":
    hold_stop_signals()  # first: a ^C while the rest is imported must not print a traceback

import argparse  # noqa: E402
import importlib  # noqa: E402
import signal  # noqa: E402
import traceback  # noqa: E402

from emulator.errors import UserError  # noqa: E402

def package_version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("lrf-emulator")
    except PackageNotFoundError:
        return "unknown"

# subcommand → (module in emulator.commands, one-line help)
SUBCOMMANDS: dict[str, tuple[str, str]] = {
    "serve": ("serve", "serve the scene's sensors on their endpoints (the daemon)"),
    "scan": ("scan", "print one scan at a simulated time as JSON"),
    "plot": ("plot", "draw a waterfall of scans and the smoke level over time (PNG)"),
    "record": ("record", "write scans to a text log in the seed dataset's format"),
    "replay": ("replay", "serve a recorded log through the real protocol"),
    "bench": ("bench", "measure the simulation's and protocols' speed on this machine"),
    "scenes": ("scenes", "list the bundled scenes"),
    "ctl": ("ctl", "change a running daemon through its control API (smoke, plumes, poses, clock)"),
}


class _Parser(argparse.ArgumentParser):
    """Usage errors: one line on stderr, exit status 2."""

    def error(self, message: str) -> None:  # type: ignore[override]
        sys.stderr.write(f"{self.prog}: {message}\n")
        raise SystemExit(2)


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="lrf-emulator", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--version", action="version", version=f"%(prog)s {package_version()}")
    parser.add_argument("--debug", action="store_true", help="show tracebacks for errors")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    sub.required = True
    for name, (module_name, help_text) in SUBCOMMANDS.items():
        module = importlib.import_module(f"emulator.commands.{module_name}")
        command_parser = sub.add_parser(name, help=help_text, description=help_text)
        # after the subcommand too; SUPPRESS keeps a --debug given before it
        command_parser.add_argument("--debug", action="store_true", default=argparse.SUPPRESS,
                                    help="show tracebacks for errors")
        module.add_arguments(command_parser)
        command_parser.set_defaults(_run=module.run)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = None
    hold_stop_signals()
    try:
        # Modules load while stop signals are only held: trimesh catches BaseException
        # around its imports and would turn an interrupt there into a later TypeError.
        parser = build_parser()
        raise_on_stop_signals()
        args = parser.parse_args(argv)
        return int(args._run(args) or 0)
    except UserError as error:
        if args.debug:
            traceback.print_exc()
        sys.stderr.write(f"lrf-emulator {args.command}: {error}\n")
        return 2
    except Interrupted as interrupted:
        return 128 + interrupted.signum
    except KeyboardInterrupt:
        return 128 + signal.SIGINT
    except BrokenPipeError:
        return 0


if __name__ == "__main__":
    sys.exit(main())
