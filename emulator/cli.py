"""lrf-emulator: virtual laser range finders in a smoky 3D scene, served as the real ones are.

Hokuyo URG-04LX, UTM-30LX(-EW) and UST-10LX/20LX over SCIP; SICK LMS200 over
its serial telegrams, TiM561/571/781, LMS111 and LMS511 over CoLa; on a
virtual serial device, TCP or RFC 2217. `lrf-emulator COMMAND --help`
describes each command.
"""

from __future__ import annotations

import os
import sys

from emulator.commands.stopping import Interrupted, hold_stop_signals, raise_on_stop_signals

if __name__ == "__main__" or os.path.basename(sys.argv[0]) == "lrf-emulator":
    hold_stop_signals()  # first: a ^C while the rest is imported must not print a traceback

import argparse  # noqa: E402
import errno  # noqa: E402
import importlib  # noqa: E402
import signal  # noqa: E402
import traceback  # noqa: E402
from collections.abc import Sequence  # noqa: E402

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
    "plot": ("plot", "draw a waterfall of scans and the smoke level over time, or a map (PNG, SVG, PDF...)"),
    "record": ("record", "write scans to a file: a text log (with a TUM trajectory), MCAP, or a ROS 1 / ROS 2 bag"),
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

    def _get_values(self, action: argparse.Action, arg_strings: list[str]) -> object:
        """`--option=--` is a value argparse (3.11) turns into [] for any type: refused as one."""
        if action.option_strings and action.nargs is None and arg_strings == ["--"]:
            self.error(f"argument {'/'.join(action.option_strings)}: expected a value, got '--'")
        return super()._get_values(action, arg_strings)


class _CommandParser(_Parser):
    """A subcommand's parser (and a sub-action's, as `ctl state`): arguments left after it are refused
    here, under its own prog (`lrf-emulator ctl state: unrecognized arguments: extra`); argparse would
    hand them up to the top-level parser, which names only `lrf-emulator`."""

    def parse_known_args(  # type: ignore[override]
        self, args: Sequence[str] | None = None, namespace: argparse.Namespace | None = None
    ) -> tuple[argparse.Namespace, list[str]]:
        namespace, extras = super().parse_known_args(args, namespace)
        if extras:
            self.error(f"unrecognized arguments: {' '.join(extras)}")
        return namespace, extras


def build_parser(argv: list[str] | None = None) -> argparse.ArgumentParser:
    """The parser for `argv`: only the subcommand it names has its module imported and its options
    added (`ctl` and `--version` start without loading the simulation or the server); every
    subcommand's without `argv`."""
    chosen = None if argv is None else _subcommand_in(argv)
    parser = _Parser(prog="lrf-emulator", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--version", action=_VersionAction, help="show the version and exit")
    parser.add_argument("--debug", action="store_true", help="show tracebacks for errors")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_CommandParser)
    sub.required = True
    for name, (module_name, help_text) in SUBCOMMANDS.items():
        command_parser = sub.add_parser(name, help=help_text, description=help_text)
        if argv is not None and name != chosen:
            continue
        module = importlib.import_module(f"emulator.commands.{module_name}")
        # after the subcommand too; SUPPRESS keeps a --debug given before it
        command_parser.add_argument("--debug", action="store_true", default=argparse.SUPPRESS,
                                    help="show tracebacks for errors")
        module.add_arguments(command_parser)
        command_parser.set_defaults(_run=module.run)
    return parser


def _subcommand_in(argv: list[str]) -> str | None:
    """The subcommand: the first argument that is not an option (no top-level option takes a value)."""
    first = next((arg for arg in argv if not arg.startswith("-")), None)
    return first if first in SUBCOMMANDS else None


class _VersionAction(argparse.Action):
    """`--version`: the installed version, looked up only when asked for."""

    def __init__(self, option_strings: list[str], dest: str = argparse.SUPPRESS, **kwargs: object) -> None:
        super().__init__(option_strings, dest, nargs=0, default=argparse.SUPPRESS, **kwargs)

    def __call__(self, parser: argparse.ArgumentParser, *args: object) -> None:
        print(f"{parser.prog} {package_version()}")
        parser.exit()


WRITE_FAILURES = (errno.ENOSPC, errno.EDQUOT, errno.EFBIG, errno.EIO)  # the machine's, not a bug: said as such


def main(argv: list[str] | None = None) -> int:
    args = None
    hold_stop_signals()
    try:
        # Modules load while stop signals are only held: trimesh catches BaseException
        # around its imports and would turn an interrupt there into a later TypeError.
        parser = build_parser(sys.argv[1:] if argv is None else argv)
        raise_on_stop_signals()
        args = parser.parse_args(argv)
        return int(args._run(args) or 0)
    except UserError as error:
        _report(args, str(error))
        return 2
    except Interrupted as interrupted:
        return 128 + interrupted.signum
    except KeyboardInterrupt:
        return 128 + signal.SIGINT
    except BrokenPipeError:
        return 0
    except Exception as error:  # a bug: still one line, the traceback with --debug
        if isinstance(error, OSError) and error.errno in WRITE_FAILURES:  # stdout on /dev/full: no bug
            _report(args, f"cannot write{' ' + str(error.filename) if error.filename else ''}: {error.strerror}")
        else:
            _report(args, f"internal error ({type(error).__name__}: {error}); run with --debug for the traceback")
        return 1


def _report(args: argparse.Namespace | None, message: str) -> None:
    """The error on stderr, each line prefixed with the command (with --debug: its traceback first)."""
    if args is not None and args.debug:
        traceback.print_exc()
    prefix = f"lrf-emulator {args.command}: " if args is not None else "lrf-emulator: "
    sys.stderr.write("".join(prefix + line + "\n" for line in message.splitlines() or [""]))


if __name__ == "__main__":
    sys.exit(main())
