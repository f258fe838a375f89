"""The browser view's own process, and the daemon's side of it.

viser (its server thread, its asyncio loop, msgpack of every point cloud and
scene update) is Python holding the GIL; inside the daemon it made the loop
wait for the GIL up to a switch interval (5 ms) before sending a scan, and a
busy view competed with the loop for a core. So the view runs in a process of
its own, started with `spawn` before the daemon's loop runs, at VIEW_NICE (the
daemon's loop and clients come first; the view may lag a frame). The daemon
sends it, over a pipe, at most UPDATE_RATE_HZ times a second and only while a
browser is connected: the world's snapshot at the clock's now and the scans
delivered since the last frame (a few kB; pickled on the sender thread). The
panel acts through the control API over HTTP, as any client does; the child
tells the daemon how many browsers watch, so idle sensors get scanned for them
(`feed.py`).
"""

from __future__ import annotations

import multiprocessing
import multiprocessing.connection
import os
import signal
import threading
from typing import Any, Mapping

import emulator.daemon.workers  # noqa: F401  (registers the pickling of scenes' read-only mappings)
from emulator.recording.world_snapshot import SceneSnapshots
from emulator.scene.model import Scene
from emulator.sensors.scan import Scan
from emulator.view.feed import LiveFeed

UPDATE_RATE_HZ = 10.0
VIEW_NICE = 10
START_TIMEOUT_S = 120.0  # spawn + importing viser, on a busy machine


class PortTaken(Exception):
    """The view's port is in use."""


class ViewFailed(RuntimeError):
    """The view's process could not start; the message says why."""


def _child_main(scene: Scene, listen: tuple[str, int], connection: multiprocessing.connection.Connection, nice: int) -> None:
    """The view process: serve the view, report browsers coming and going, draw each frame it
    is sent (only the newest when several wait), until told to stop or the daemon goes away."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # a terminal's Ctrl-C reaches the daemon, which stops us
    os.nice(nice)
    from emulator.view.browser import BrowserView
    from emulator.view.control_client import ControlClient

    sending = threading.Lock()  # viser calls back from its own threads

    def send(message: tuple) -> None:
        with sending:
            try:
                connection.send(message)
            except (BrokenPipeError, OSError):
                pass  # the daemon is stopping

    try:
        view = BrowserView(scene, listen, on_watchers=lambda count: send(("watchers", count)))
    except PortTaken as taken:
        send(("taken", str(taken)))
        return
    except Exception as error:  # said to the daemon, which reports it in one line
        send(("failed", f"{type(error).__name__}: {error}"))
        return
    send(("ready", view.url))
    try:
        while True:
            message = connection.recv()
            snapshot, scans = None, {}
            while True:  # take every waiting message; frames merge into the newest
                kind = message[0]
                if kind == "stop":
                    return
                if kind == "control":
                    view.build_panel(ControlClient(message[1], message[2]) if message[1] is not None else None)
                elif kind == "frame":
                    snapshot = message[1]
                    scans.update(message[2])
                if not connection.poll():
                    break
                message = connection.recv()
            if snapshot is not None and view.watchers():
                view.update(snapshot, scans)
    except (EOFError, OSError):
        return  # the daemon went away
    finally:
        view.stop()


class BrowserViewProcess:
    """The daemon's handle on the view's process: start it, learn its URL, feed it, stop it."""

    def __init__(self, scene: Scene, listen: tuple[str, int], nice: int = VIEW_NICE) -> None:
        context = multiprocessing.get_context("spawn")
        self._connection, child = context.Pipe()
        self._process = context.Process(target=_child_main, args=(scene, listen, child, nice), name="lrf-view", daemon=True)
        self._process.start()
        child.close()
        self.url = self._wait_ready()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._watchers = 0

    def _wait_ready(self) -> str:
        if not self._connection.poll(START_TIMEOUT_S):
            self._process.kill()
            raise ViewFailed(f"the view's process did not start within {START_TIMEOUT_S:g} s")
        try:
            kind, detail = self._connection.recv()
        except (EOFError, OSError):
            raise ViewFailed(f"the view's process ended at start-up (exit status {self._process.exitcode})") from None
        if kind == "ready":
            return detail
        self._process.join(timeout=5.0)
        raise PortTaken(detail) if kind == "taken" else ViewFailed(detail)

    def start(self, feed: LiveFeed, snapshots: SceneSnapshots, clock: Any,
              control_url: str | None, token: str | None) -> None:
        """Build the panel (acting through `control_url`, if any) and feed the view from a thread."""
        self._connection.send(("control", control_url, token))
        self._thread = threading.Thread(target=self._feed, args=(feed, snapshots, clock), name="view-feed", daemon=True)
        self._thread.start()

    def _feed(self, feed: LiveFeed, snapshots: SceneSnapshots, clock: Any) -> None:
        sent: dict[str, Scan] = {}
        try:
            while not self._stop.wait(1.0 / UPDATE_RATE_HZ):
                while self._connection.poll():
                    kind, count = self._connection.recv()
                    if kind == "watchers":
                        self._follow_watchers(feed, count)
                if self._watchers == 0:
                    continue  # nobody looking: nothing computed or sent
                latest: Mapping[str, Scan] = dict(feed.latest)
                fresh = {name: scan for name, scan in latest.items() if sent.get(name) is not scan}
                sent.update(fresh)
                self._connection.send(("frame", snapshots(clock.now()), fresh))
        except (EOFError, OSError):
            pass  # the view's process ended: the daemon serves on without it
        finally:
            self._follow_watchers(feed, 0)

    def _follow_watchers(self, feed: LiveFeed, count: int) -> None:
        while self._watchers < count:
            feed.watch()
            self._watchers += 1
        while self._watchers > count:
            feed.unwatch()
            self._watchers -= 1

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
        try:
            self._connection.send(("stop",))
        except (BrokenPipeError, OSError):
            pass
        self._process.join(timeout=5.0)
        if self._process.is_alive():
            self._process.kill()
            self._process.join(timeout=2.0)
        self._connection.close()
