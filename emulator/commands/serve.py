"""`lrf-emulator serve`: the daemon.

Prints `ready SENSOR MODEL URI[ -> /dev/pts/N]` as each endpoint serves, then
`ready control http://HOST:PORT` when the control API (docs/control.md) listens,
`ready foxglove ws://HOST:PORT` and `ready view http://HOST:PORT` for Foxglove
live and the browser view (emulator/view); `--mcap FILE` records the session.
SIGINT / SIGTERM / SIGHUP / SIGQUIT stop it (symlinks removed, exit 0; during
start-up: exit 128 + the signal's number, no traceback); SIGUSR1 prints one
`stats` line on stderr (clients, fds, asyncio tasks) for operators and tests.
"""

from __future__ import annotations

import argparse
import asyncio
import gc
import importlib
import math
import os
import signal
import sys
from pathlib import Path
from typing import Any, Mapping, Sequence

from emulator.commands.options import (
    LOOPBACK_HOSTS,
    MAX_SIMULATED_TIME_S,
    add_events_in_option,
    add_scene_options,
    output_path,
    parse_listen,
    scene_from_args,
)
from emulator.commands import stopping
from emulator.commands.stopping import STOP_SIGNALS
from emulator.commands.values import bearer_token, named_path
from emulator.control.events import ControlError, EventWriter, read_events
from emulator.control.scan_feed import configured_request
from emulator.control.server import DEFAULT_ADDRESS, ControlAddress, ControlServer, check_exposure, parse_control_address
from emulator.control.session import LiveSession
from emulator.daemon.clock import MAX_SPEED, MIN_SPEED, WallClock
from emulator.daemon.memory import keep_freed_memory
from emulator.daemon.workers import WORKER_NICE
from emulator.daemon.service import Daemon, Ready
from emulator.errors import UserError
from emulator.recording.world_snapshot import SceneSnapshots
from emulator.scene import Scene
from emulator.transport.tcp import IDLE_TIMEOUT_S
from emulator.view.feed import LiveFeed

SWITCH_INTERVAL_S = 0.0005
DEFAULT_VIEW = "127.0.0.1:8080"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_scene_options(parser, optional_scene=True)
    parser.add_argument(
        "--endpoint",
        action="append",
        default=[],
        metavar="SENSOR=URI",
        help="serve SENSOR on URI (pty:PATH, tcp:HOST:PORT or rfc2217:HOST:PORT) instead of its scene endpoints; repeatable",
    )
    parser.add_argument("--speed", type=float, default=1.0, help="simulated seconds per wall second (default 1)")
    parser.add_argument(
        "--control", default=DEFAULT_ADDRESS, metavar="HOST:PORT|off",
        help=f"the control API's address (default {DEFAULT_ADDRESS}; port 0 picks a free one; off: none)",
    )
    parser.add_argument(
        "--control-token", type=bearer_token, default=None, metavar="TOKEN",
        help="require Authorization: Bearer TOKEN on the control API (needed beyond loopback)",
    )
    parser.add_argument("--events", type=named_path, default=None, metavar="FILE", help="write each live change to FILE (JSON lines; created or truncated; a FIFO waits for its reader)")
    add_events_in_option(parser)
    parser.add_argument(
        "--sensors",
        metavar="NAME[,NAME...]",
        help="serve only these sensors of the scene (a fleet: each daemon serves a group)",
    )
    parser.add_argument(
        "--epoch",
        type=unix_time,
        metavar="UNIX_TIME",
        help="simulated time = (now − UNIX_TIME) × speed, so daemons given one epoch agree (default: start at 0)",
    )
    parser.add_argument(
        "--idle-timeout", type=float, default=IDLE_TIMEOUT_S, metavar="S",
        help=f"a TCP client with no byte either way for S seconds gives way to a newcomer (default {IDLE_TIMEOUT_S:g})",
    )
    parser.add_argument(
        "--workers",
        type=int,
        metavar="N",
        help="worker processes computing scans (default: one per core, at most one per sensor; 0: in-process)",
    )
    parser.add_argument(
        "--worker-nice",
        type=int,
        default=WORKER_NICE,
        metavar="N",
        help=f"run the workers N nice levels below the daemon, 0..19 (default {WORKER_NICE}: the daemon's priority; 19 on "
        "a machine with idle cores lets them give way to the wire at once, but starves them against other busy processes)",
    )
    parser.add_argument(
        "--view", metavar="HOST:PORT|off", default=None,
        help=f"the browser view (default {DEFAULT_VIEW}; quietly off if that port is taken; loopback only)",
    )
    parser.add_argument("--foxglove", metavar="HOST:PORT", default="off",
                        help="stream the scene's Foxglove channels over Foxglove's WebSocket protocol (default off)")
    parser.add_argument("--mcap", type=mcap_path, metavar="FILE", default=None,
                        help="record the session's scans, transforms and scene to an MCAP file")


def endpoint_overrides(items: list[str]) -> dict[str, list[str]]:
    """`SENSOR=URI` arguments → URIs per sensor, in the order given."""
    overrides: dict[str, list[str]] = {}
    for item in items:
        sensor, sep, uri = item.partition("=")
        if not sep or not sensor or not uri:
            raise UserError(f"--endpoint {item!r}: expected SENSOR=URI")
        overrides.setdefault(sensor, []).append(uri)
    return overrides


def mcap_path(text: str) -> Path:
    """An argparse type: the MCAP file to write, a new or regular file, never written through a symbolic
    link (its target was overwritten) and never a FIFO or device (a FIFO blocked serve before it served)."""
    path = output_path(text)
    if path.is_symlink():
        raise argparse.ArgumentTypeError(f"{text} is a symbolic link: serve writes only files, never through links")
    return path


MAX_UNIX_TIME_S = 1e11  # the year 5138: beyond it an epoch is a typo


def unix_time(text: str) -> float:
    """An argparse type: a finite UNIX time in seconds (NaN would stop every clock read)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected UNIX seconds, got {text!r}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"expected a finite UNIX time, got {text!r}")
    if abs(value) > MAX_UNIX_TIME_S:  # its error would print the epoch's distance to now in 300 digits
        raise argparse.ArgumentTypeError(f"expected a UNIX time within ±{MAX_UNIX_TIME_S:g} s, got {text!r}")
    return value


def run(args: argparse.Namespace) -> int:
    if not (math.isfinite(args.speed) and MIN_SPEED <= args.speed <= MAX_SPEED):
        raise UserError(f"--speed must be >= {MIN_SPEED:g} and <= {MAX_SPEED:g}, got {args.speed:g}")
    if args.events is not None and args.mcap is not None and os.path.abspath(args.events) == os.path.abspath(args.mcap):
        raise UserError(f"--events {args.events} and --mcap {args.mcap}: one file each (both wrote it)")
    overrides = endpoint_overrides(args.endpoint)
    watching = Watching.from_args(args)
    scene = scene_from_args(args)
    sensors = served_sensors(scene, args.sensors)
    refuse_nothing_to_serve(scene, overrides, sensors)
    if not (math.isfinite(args.idle_timeout) and args.idle_timeout > 0):
        raise UserError(f"--idle-timeout must be a finite number of seconds > 0, got {args.idle_timeout}")
    if args.workers is not None and args.workers < 0:
        raise UserError(f"--workers must be >= 0, got {args.workers}")
    workers = args.workers if args.workers is not None else os.cpu_count() or 1
    if not 0 <= args.worker_nice <= 19:
        raise UserError(f"--worker-nice must be 0..19, got {args.worker_nice}")
    try:
        clock = WallClock.from_epoch(args.epoch, args.speed) if args.epoch is not None else WallClock(args.speed)
    except ValueError as error:
        raise UserError(f"--epoch: {error}") from None
    if clock.now() > MAX_SIMULATED_TIME_S:
        raise UserError(
            f"--epoch: simulated time would start at {clock.now():.6g} s (the epoch's age × speed); "
            f"at most {MAX_SIMULATED_TIME_S:g} s (115 days): give a more recent epoch"
        )
    for name in overrides:
        if sensors is not None and name in {spec.name for spec in scene.sensors} and name not in sensors:
            raise UserError(f"--endpoint {name}=...: sensor {name!r} is not among --sensors {args.sensors}")
    control = parse_control_address(args.control)
    check_exposure(control, args.control_token)
    replayed = read_events(args.events_in, scene) if args.events_in is not None else []
    watching.feed = LiveFeed(clock.now)
    daemon = Daemon(scene, overrides, clock, sensors=sensors, workers=workers, worker_nice=args.worker_nice, on_scan=watching.feed.scan_delivered,
                    idle_timeout_s=args.idle_timeout)
    session = LiveSession(daemon, EventWriter(args.events) if args.events is not None else None)
    watching.prepare(daemon, sensors, args.control_token)
    try:
        for event in replayed:
            if event.op != "clock":  # the clock's changes are kept in the log; scans do not depend on them
                try:
                    session.apply(event)
                except ControlError as error:
                    raise UserError(f"--events-in {args.events_in}: {error}") from None
        serve_until_signalled(daemon, session, control, args.control_token, watching)
    finally:
        watching.stop()
        session.close()
    return 0


def refuse_nothing_to_serve(
    scene: Scene, overrides: Mapping[str, Sequence[str]], sensors: Sequence[str] | None
) -> None:
    """A daemon with no endpoint would run forever in silence: say so instead."""
    where = scene.path.name if scene.path is not None else "the scene"
    if not scene.sensors:
        raise UserError(f"{where}: sensors: the scene has no [[sensors]] to serve")
    served = [spec for spec in scene.sensors if sensors is None or spec.name in sensors]
    if not any(overrides.get(spec.name, spec.endpoints) for spec in served):
        raise UserError(f"{where}: sensors: no sensor has an endpoint (give one with --endpoint SENSOR=URI)")


class Watching:
    """The viewers `serve` was asked for (browser view, Foxglove live, MCAP): their options, and
    once every endpoint serves, the running ones, each on threads of its own."""

    def __init__(self, view: tuple[str, int] | None, explicit_view: bool,
                 foxglove: tuple[str, int] | None, mcap: Path | None) -> None:
        self.view, self.explicit_view, self.foxglove, self.mcap = view, explicit_view, foxglove, mcap
        self.feed: LiveFeed | None = None
        self.browser: Any = None  # the view's process (process.BrowserViewProcess), once prepared
        self.publisher: Any = None  # the Foxglove/MCAP process (foxglove_live.FoxglovePublisher), once prepared
        self.running: list = []
        self.refused: list[str] = []  # an address asked for and taken, reported with the endpoints' (serve fails)

    @staticmethod
    def from_args(args: argparse.Namespace) -> Watching:
        view = parse_listen("--view", args.view if args.view is not None else DEFAULT_VIEW)
        if view is not None and view[0] not in LOOPBACK_HOSTS:
            raise UserError(f"--view {args.view}: the view changes the world, so it listens on loopback only")
        foxglove = parse_listen("--foxglove", args.foxglove)
        # viser and foxglove-sdk take a while to import: before the loop runs, never on it
        if view is not None:
            importlib.import_module("emulator.view.process")
        if foxglove is not None or args.mcap is not None:
            importlib.import_module("emulator.view.foxglove_live")
        return Watching(view, args.view is not None, foxglove, args.mcap)

    def prepare(self, daemon: Daemon, sensors: Sequence[str] | None, token: str | None) -> None:
        """Before the daemon's loop runs: start the Foxglove/MCAP and the view's processes
        (spawning them and importing foxglove and viser take a while); a default view whose
        port is taken stays off, with a note."""
        self.daemon, self.token = daemon, token
        self.served = [spec for spec in daemon.scene.sensors if sensors is None or spec.name in sensors]
        self.browser = self.publisher = None
        if self.foxglove is not None or self.mcap is not None:
            from emulator.view.foxglove_live import FoxglovePublisher

            self.publisher = FoxglovePublisher(daemon.scene, sensors=[spec.name for spec in self.served],
                                               mcap_path=self.mcap, websocket=self.foxglove)
        if self.view is not None:
            try:
                self.browser = self._start_view(daemon.scene)
            except BaseException:
                self.stop()  # the Foxglove/MCAP process closes its file
                raise

    def _start_view(self, scene: Scene) -> Any:
        from emulator.view.process import BrowserViewProcess, PortTaken, ViewFailed

        assert self.view is not None
        try:
            return BrowserViewProcess(scene, self.view)
        except PortTaken as taken:
            if self.explicit_view:
                self.refused.append(f"--view {self.view[0]}:{self.view[1]}: {taken}")
                return None
            print(f"view off: {taken} (choose one with --view HOST:PORT)", file=sys.stderr, flush=True)
            return None
        except ViewFailed as failed:
            raise UserError(f"--view {self.view[0]}:{self.view[1]}: {failed}") from None

    def start(self, control_url: str | None) -> None:
        """On the loop thread, once every endpoint (and the control API) serves: start what was
        asked for, printing ready lines; a default view whose port is taken stays off, with a note."""
        daemon, feed = self.daemon, self.feed
        assert feed is not None
        snapshots = SceneSnapshots(daemon.scene, daemon.live)
        if self.publisher is not None:
            self.publisher.start(feed, snapshots, daemon.clock.now)
            self.running.append(self.publisher)
            if self.publisher.url is not None:
                print(f"ready foxglove {self.publisher.url}", flush=True)
        if self.browser is not None:
            self.browser.start(feed, snapshots, daemon.clock, control_url, self.token)
            self.running.append(self.browser)
            print(f"ready view {self.browser.url}", flush=True)
        feed.start(daemon.scan_caches, {spec.name: configured_request(spec) for spec in self.served},
                   asyncio.get_running_loop())

    def stop(self) -> None:
        for started in (self.publisher, self.browser):
            if started is not None and started not in self.running:
                self.running.append(started)  # started, but the daemon stopped before it served
        for watcher in reversed(self.running):
            watcher.stop()
        self.running.clear()
        if self.feed is not None:
            self.feed.stop()


def served_sensors(scene: Scene, listed: str | None) -> tuple[str, ...] | None:
    """`--sensors a,b` → ("a", "b"), each a sensor of the scene and named once; None serves them all."""
    if listed is None:
        return None
    names = tuple(name.strip() for name in listed.split(","))
    known = [spec.name for spec in scene.sensors]
    for index, name in enumerate(names):
        if name not in known:
            raise UserError(f"--sensors: no sensor named {name!r} (known: {', '.join(known) or 'none'})")
        if name in names[:index]:
            raise UserError(f"--sensors {listed}: sensor {name!r} named more than once")
    return names


def serve_until_signalled(
    daemon: Daemon,
    session: LiveSession | None = None,
    control: ControlAddress | None = None,
    token: str | None = None,
    watching: Watching | None = None,
) -> None:
    """Run the daemon until a stop signal (SIGINT, SIGTERM, SIGHUP, SIGQUIT), announcing each ready
    endpoint (and the control API, and what `watching` starts) on stdout."""
    # While the scan thread computes, the loop thread must get the GIL back within
    # a fraction of a millisecond to answer commands (the default is 5 ms).
    sys.setswitchinterval(SWITCH_INTERVAL_S)
    keep_freed_memory()  # scans computed in this process (--workers 0) reuse their temporaries
    asyncio.run(_serve(daemon, session, control, token, watching))


async def _serve(
    daemon: Daemon, session: LiveSession | None, control: ControlAddress | None, token: str | None,
    watching: Watching | None = None,
) -> None:
    loop = asyncio.get_running_loop()
    for signum in STOP_SIGNALS:
        loop.add_signal_handler(signum, daemon.stop)
    if stopping.caught():  # raised earlier, but swallowed by some library
        daemon.stop()
    loop.add_signal_handler(signal.SIGUSR1, _print_stats, daemon)
    server = ControlServer(session, control, token) if session is not None and control is not None else None
    refused = list(watching.refused) if watching is not None else []  # a port taken: told with the endpoints'
    if server is not None:
        try:
            await server.start()  # before any endpoint serves: a port in use stops serve at once
        except UserError as error:
            refused.insert(0, str(error))
            server = None
    try:
        await daemon.run(_announce, lambda: _started(server, watching), refused)
    finally:
        if server is not None:
            await server.close()


def _announce(ready: Ready) -> None:
    print(ready.line, flush=True)


def _started(server: ControlServer | None, watching: Watching | None) -> None:
    # Everything built so far (scene, world, sessions) lives as long as the daemon: out of the
    # collector's sight, a full collection no longer stops the loop for 50-80 ms walking it.
    gc.freeze()
    if server is not None:
        print(f"ready control {server.address.url}", flush=True)
    if watching is not None:
        watching.start(server.address.url if server is not None else None)


def _print_stats(daemon: Daemon) -> None:
    counters = " ".join(f"{key}={value}" for key, value in daemon.stats().items())
    print(f"stats {counters}", file=sys.stderr, flush=True)
