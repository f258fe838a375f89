"""Foxglove live (`serve --foxglove HOST:PORT`) and the session's MCAP (`serve --mcap FILE`).

One foxglove-sdk `Context` holds the scene's channels (`recording/mcap.py`);
the WebSocket server and the MCAP writer are sinks of it, so both get the
same messages. Everything is encoded and written on the publisher's own
thread: it takes scans from its `LiveFeed` queue, and at most WORLD_RATE_HZ
times a second logs the transforms, smoke and plumes at the clock's now.
The solid geometry is logged once, and again whenever a Foxglove client
subscribes to `/scene` (a live stream keeps no history for late-comers).
"""

from __future__ import annotations

import queue
import threading
import time
from pathlib import Path
from typing import Callable

import foxglove
from foxglove.websocket import ChannelView, Client

from emulator.errors import UserError
from emulator.recording.mcap import SceneChannels, open_mcap_file
from emulator.recording.world_snapshot import WorldSnapshot
from emulator.scene.model import Scene
from emulator.view.feed import LiveFeed

WORLD_RATE_HZ = 10.0


class _SceneSubscriptions:
    """foxglove's ServerListener: a client subscribing to `/scene` asks for the solids again."""

    def __init__(self, wanted: threading.Event) -> None:
        self._wanted = wanted

    def on_subscribe(self, client: Client, channel: ChannelView) -> None:
        if channel.topic == "/scene":
            self._wanted.set()


class FoxglovePublisher:
    """The scene's channels to an MCAP file and/or a Foxglove WebSocket server, on its own thread."""

    def __init__(
        self, scene: Scene, feed: LiveFeed, snapshot: Callable[[float], WorldSnapshot], now: Callable[[], float],
        *, sensors: list[str], mcap_path: Path | None = None, websocket: tuple[str, int] | None = None,
    ) -> None:
        self._feed, self._snapshot, self._now = feed, snapshot, now
        self._context = foxglove.Context()
        self._channels = SceneChannels(scene, self._context, sensors)
        self._solids_wanted = threading.Event()
        self._solids_wanted.set()
        self._writer = open_mcap_file(mcap_path, self._context) if mcap_path is not None else None
        self.server = None
        self._server_host = websocket[0] if websocket is not None else ""
        if websocket is not None:
            host, port = websocket
            try:
                self.server = foxglove.start_server(
                    name="lrf-emulator", host=host, port=port, context=self._context,
                    server_listener=_SceneSubscriptions(self._solids_wanted),
                )
            except Exception as error:  # foxglove raises its own error type for a port in use
                self._close_writer()
                raise UserError(f"--foxglove {host}:{port}: cannot listen: {error}") from None
        self._scans = feed.subscribe()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="foxglove", daemon=True)

    @property
    def url(self) -> str | None:
        """`ws://HOST:PORT` of the WebSocket server, if there is one."""
        return None if self.server is None else f"ws://{self._server_host}:{self.server.port}"

    def start(self) -> None:
        self._feed.watch()
        self._thread.start()

    def stop(self) -> None:
        """Write what is queued, close the MCAP file (finishing its summary), stop the server."""
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout=5.0)
        self._feed.unwatch()
        self._close_writer()
        if self.server is not None:
            self.server.stop()
            self.server = None

    def _close_writer(self) -> None:
        if self._writer is not None:
            self._writer.close()
            self._writer = None

    def _run(self) -> None:
        next_world = 0.0
        while not self._stop.is_set():
            try:
                scan = self._scans.get(timeout=1.0 / WORLD_RATE_HZ)
            except queue.Empty:
                scan = None
            wall = time.monotonic()
            if wall >= next_world:
                self._log_world()
                next_world = wall + 1.0 / WORLD_RATE_HZ
            if scan is not None:
                self._channels.log_scan(scan)
        while True:  # what was delivered before the stop still goes into the file
            try:
                self._channels.log_scan(self._scans.get_nowait())
            except queue.Empty:
                break

    def _log_world(self) -> None:
        now = self._now()
        if self._solids_wanted.is_set():
            self._solids_wanted.clear()
            self._channels.log_solids(now)
        self._channels.log_world(self._snapshot(now))
