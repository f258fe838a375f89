"""Foxglove live (`serve --foxglove HOST:PORT`) and the session's MCAP (`serve --mcap FILE`).

One foxglove-sdk `Context` holds the scene's channels (`recording/mcap.py`);
the WebSocket server and the MCAP writer are sinks of it, so both get the
same messages. Encoding (protobuf for every scan) and writing are Python and
file I/O that would hold the daemon's GIL, so they run in a process of their
own (spawned before the daemon's loop runs, at FOXGLOVE_NICE), like the
browser view's (`process.py`). The daemon's `foxglove` thread takes every
scan from its `LiveFeed` queue and sends them over a pipe, and at most
WORLD_RATE_HZ times a second the world's snapshot at the clock's now
(transforms, smoke, plumes). The solid geometry is logged once, and again
whenever a Foxglove client subscribes to `/scene` (a live stream keeps no
history for late-comers). At the end the daemon sends what is still queued
and waits for the MCAP file to be closed (its summary written).
"""

from __future__ import annotations

import multiprocessing
import multiprocessing.connection
import os
import queue
import signal
import threading
import time
from pathlib import Path
from typing import Any, Callable

from emulator.errors import UserError
from emulator.recording.world_snapshot import WorldSnapshot
from emulator.scene.model import Scene
from emulator.view.feed import LiveFeed
from emulator.view.process import START_TIMEOUT_S

WORLD_RATE_HZ = 10.0
FOXGLOVE_NICE = 10
STOP_TIMEOUT_S = 30.0  # the child writes what is queued and the MCAP summary


class _SceneSubscriptions:
    """foxglove's ServerListener: a client subscribing to `/scene` asks for the solids again."""

    def __init__(self, wanted: threading.Event) -> None:
        self._wanted = wanted

    def on_subscribe(self, client: Any, channel: Any) -> None:
        if channel.topic == "/scene":
            self._wanted.set()


def _child_main(
    scene: Scene, sensors: list[str], mcap_path: Path | None, websocket: tuple[str, int] | None,
    connection: multiprocessing.connection.Connection, nice: int,
) -> None:
    """The publisher's process: open the sinks, say ready (or why not), log what arrives, close."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # a terminal's Ctrl-C reaches the daemon, which stops us
    os.nice(nice)
    import foxglove

    from emulator.recording.mcap import SceneChannels, open_mcap_file

    context = foxglove.Context()
    channels = SceneChannels(scene, context, sensors)
    solids_wanted = threading.Event()
    solids_wanted.set()
    writer = server = None
    try:
        writer = open_mcap_file(mcap_path, context) if mcap_path is not None else None
        if websocket is not None:
            host, port = websocket
            try:
                server = foxglove.start_server(name="lrf-emulator", host=host, port=port, context=context,
                                               server_listener=_SceneSubscriptions(solids_wanted))
            except Exception as error:  # foxglove raises its own error type for a port in use
                raise UserError(f"--foxglove {host}:{port}: cannot listen: {error}") from None
    except UserError as error:
        if writer is not None:
            writer.close()
        connection.send(("failed", str(error)))
        return
    connection.send(("ready", None if server is None else f"ws://{websocket[0]}:{server.port}"))
    try:
        while True:
            message = connection.recv()
            if message[0] == "stop":
                break
            if message[0] == "scans":
                for scan in message[1]:
                    channels.log_scan(scan)
            elif message[0] == "world":
                snapshot: WorldSnapshot = message[1]
                if solids_wanted.is_set():
                    solids_wanted.clear()
                    channels.log_solids(snapshot.time_s)
                channels.log_world(snapshot)
    except (EOFError, OSError):
        pass  # the daemon went away: still close the file properly
    finally:
        if writer is not None:
            writer.close()
        if server is not None:
            server.stop()
        try:
            connection.send(("closed", None))
        except OSError:
            pass


class FoxglovePublisher:
    """The daemon's side: the publisher's process, and the thread that feeds it."""

    def __init__(
        self, scene: Scene, *, sensors: list[str], mcap_path: Path | None = None,
        websocket: tuple[str, int] | None = None, nice: int = FOXGLOVE_NICE,
    ) -> None:
        context = multiprocessing.get_context("spawn")
        self._connection, child = context.Pipe()
        self._process = context.Process(target=_child_main, args=(scene, sensors, mcap_path, websocket, child, nice),
                                        name="lrf-foxglove", daemon=True)
        self._process.start()
        child.close()
        self.url = self._wait_ready()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._feed: LiveFeed | None = None

    def _wait_ready(self) -> str | None:
        """`ws://HOST:PORT` of the WebSocket server (None without one), once the sinks are open."""
        if not self._connection.poll(START_TIMEOUT_S):
            self._process.kill()
            raise UserError(f"the Foxglove/MCAP process did not start within {START_TIMEOUT_S:g} s")
        try:
            kind, detail = self._connection.recv()
        except (EOFError, OSError):
            raise UserError(f"the Foxglove/MCAP process ended at start-up (exit status {self._process.exitcode})") from None
        if kind != "ready":
            self._process.join(timeout=5.0)
            raise UserError(detail)
        return detail

    def start(self, feed: LiveFeed, snapshot: Callable[[float], WorldSnapshot], now: Callable[[], float]) -> None:
        """Take every scan `feed` delivers from now on, and the world at `now`, to the process."""
        self._feed = feed
        scans = feed.subscribe()
        feed.watch()
        self._thread = threading.Thread(target=self._run, args=(scans, snapshot, now), name="foxglove", daemon=True)
        self._thread.start()

    def _run(self, scans: queue.Queue, snapshot: Callable[[float], WorldSnapshot], now: Callable[[], float]) -> None:
        next_world = 0.0
        try:
            while not self._stop.is_set():
                batch = []
                try:
                    batch.append(scans.get(timeout=1.0 / WORLD_RATE_HZ))
                except queue.Empty:
                    pass
                batch += _drain(scans)
                if batch:
                    self._connection.send(("scans", batch))
                wall = time.monotonic()
                if wall >= next_world:
                    self._connection.send(("world", snapshot(now())))
                    next_world = wall + 1.0 / WORLD_RATE_HZ
            rest = _drain(scans)  # what was delivered before the stop still goes into the file
            if rest:
                self._connection.send(("scans", rest))
        except OSError:
            pass  # the process ended: the daemon serves on without it

    def stop(self) -> None:
        """Send what is queued, then wait for the process to close the MCAP file and the server."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
        if self._feed is not None:
            self._feed.unwatch()
        try:
            self._connection.send(("stop",))
        except OSError:
            pass
        self._process.join(timeout=STOP_TIMEOUT_S)
        if self._process.is_alive():
            self._process.kill()
            self._process.join(timeout=2.0)
        self._connection.close()


def _drain(scans: queue.Queue) -> list:
    taken = []
    while True:
        try:
            taken.append(scans.get_nowait())
        except queue.Empty:
            return taken
