"""`lrf-emulator serve`: the daemon (CLI.md).

Prints `ready SENSOR MODEL URI[ -> /dev/pts/N]` as each endpoint serves.
SIGINT / SIGTERM stop it (symlinks removed, exit 0); SIGUSR1 prints one
`stats` line on stderr (clients, fds, asyncio tasks) for operators and tests.
"""

from __future__ import annotations

import argparse
import asyncio
import signal
import sys

from emulator.commands.options import add_scene_options, scene_from_args
from emulator.daemon.clock import WallClock
from emulator.daemon.service import Daemon, Ready
from emulator.errors import UserError

SWITCH_INTERVAL_S = 0.0005


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_scene_options(parser, optional_scene=True)
    parser.add_argument(
        "--endpoint",
        action="append",
        default=[],
        metavar="SENSOR=URI",
        help="serve SENSOR on URI (pty:PATH or tcp:HOST:PORT) instead of its scene endpoints; repeatable",
    )
    parser.add_argument("--speed", type=float, default=1.0, help="simulated seconds per wall second (default 1)")


def endpoint_overrides(items: list[str]) -> dict[str, list[str]]:
    """`SENSOR=URI` arguments → URIs per sensor, in the order given."""
    overrides: dict[str, list[str]] = {}
    for item in items:
        sensor, sep, uri = item.partition("=")
        if not sep or not sensor or not uri:
            raise UserError(f"--endpoint {item!r}: expected SENSOR=URI")
        overrides.setdefault(sensor, []).append(uri)
    return overrides


def run(args: argparse.Namespace) -> int:
    if not args.speed > 0:
        raise UserError(f"--speed must be > 0, got {args.speed}")
    overrides = endpoint_overrides(args.endpoint)
    scene = scene_from_args(args)
    daemon = Daemon(scene, overrides, WallClock(args.speed))
    serve_until_signalled(daemon)
    return 0


def serve_until_signalled(daemon: Daemon) -> None:
    """Run the daemon until SIGINT/SIGTERM, announcing each ready endpoint on stdout."""
    # While the scan thread computes, the loop thread must get the GIL back within
    # a fraction of a millisecond to answer commands (the default is 5 ms).
    sys.setswitchinterval(SWITCH_INTERVAL_S)
    asyncio.run(_serve(daemon))


async def _serve(daemon: Daemon) -> None:
    loop = asyncio.get_running_loop()
    for signum in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(signum, daemon.stop)
    loop.add_signal_handler(signal.SIGUSR1, _print_stats, daemon)
    await daemon.run(_announce)


def _announce(ready: Ready) -> None:
    print(ready.line, flush=True)


def _print_stats(daemon: Daemon) -> None:
    counters = " ".join(f"{key}={value}" for key, value in daemon.stats().items())
    print(f"stats {counters}", file=sys.stderr, flush=True)
