"""Rough edges of the control API, the browser view's port and `ctl watch`, against the real daemon.

A JSON null in a change is refused in JSON's words ("got null", not Python's
"got None"); the browser view's port answers a method other than GET with
405 and `Allow: GET` (it closed the connection without a word); `ctl watch`
says on stderr when the clock is paused (no scans come) and when it resumes.
Nothing here sleeps: each wait is for an answer or a line, with a generous
bound only so that a failure cannot hang the run.
"""

from __future__ import annotations

import asyncio
import http.client
import json
import queue
import subprocess
import threading
from pathlib import Path
from typing import IO
from urllib.parse import urlsplit

import aiohttp
import pytest
from control_support import ENDPOINTS, call, write_live_room

from emulator.bench.serve_process import ServeProcess, serve_command

WAIT_S = 60.0  # the most any line or answer is waited for (a busy machine); a working daemon takes well under 1 s


@pytest.fixture
def room(tmp_path: Path) -> Path:
    return write_live_room(tmp_path)


@pytest.fixture
def daemon(room: Path):
    with ServeProcess(room, ENDPOINTS) as process:
        yield process
        assert process.process.poll() is None, process.stderr


def test_a_speed_that_all_but_stops_the_clock_is_refused(daemon: ServeProcess) -> None:
    """`{"speed": 1e-320}` was applied: the clock all but stopped, with no scan due again and no pause shown."""
    before = call(daemon.control_url, "GET", "/api/state")[1]["speed"]
    assert call(daemon.control_url, "PATCH", "/api/clock", {"speed": 1e-320}) == (
        400, {"error": "clock.speed: must be >= 0.001, got 1e-320", "key": "clock.speed"}
    )
    assert call(daemon.control_url, "GET", "/api/state")[1]["speed"] == before


def test_a_json_null_is_refused_in_jsons_words(daemon: ServeProcess) -> None:
    """The scene loader shows a refused value as TOML writes it, and TOML has no null: a null in a
    change read "got None". Over HTTP and WebSocket alike it reads "got null", still a 400 with the
    API's error body, and nothing is applied."""
    url = daemon.control_url
    assert call(url, "PATCH", "/api/smoke/regions/room", {"density": None}) == (
        400, {"error": "smoke.regions[room].density: expected a number, got null", "key": "smoke.regions[room].density"}
    )
    assert call(url, "PATCH", "/api/clock", {"speed": None}) == (
        400, {"error": "clock.speed: expected a number, got null", "key": "clock.speed"}
    )
    assert call(url, "PATCH", "/api/smoke/plumes/fire", {"wind": [1, None, 2]}) == (
        400, {"error": "smoke.plumes[fire].wind: expected 3 numbers, got [1, null, 2]", "key": "smoke.plumes[fire].wind"}
    )
    assert call(url, "PATCH", "/api/smoke/plumes/fire", raw=b"null") == (
        400, {"error": "smoke.plumes[fire]: expected a table, got null", "key": "smoke.plumes[fire]"}
    )
    status, answer = call(url, "PATCH", "/api/smoke/plumes/fire", {"colour": None})  # an unknown key is named first
    assert status == 400 and answer["error"].startswith("smoke.plumes[fire].colour: unknown key"), answer

    async def over_the_websocket() -> dict:
        async with aiohttp.ClientSession() as session:
            async with session.ws_connect(url + "/api/ws") as socket:
                await socket.send_json({"op": "region", "name": "room", "density": None})
                async with asyncio.timeout(WAIT_S):
                    while True:
                        message = json.loads((await socket.receive()).data)
                        if message["type"] == "error":
                            return message

    assert asyncio.run(over_the_websocket()) == {
        "type": "error", "status": 400, "error": "smoke.regions[room].density: expected a number, got null",
        "key": "smoke.regions[room].density",
    }
    assert call(url, "GET", "/api/events") == (200, [])


def _request(url: str, method: str, path: str = "/", body: bytes | None = None) -> tuple[int, dict[str, str], bytes]:
    parts = urlsplit(url)
    connection = http.client.HTTPConnection(parts.hostname, parts.port, timeout=WAIT_S)
    try:
        connection.request(method, path, body=body)
        answer = connection.getresponse()
        return answer.status, dict(answer.getheaders()), answer.read()
    finally:
        connection.close()


def test_the_browser_views_port_answers_other_methods_405(room: Path) -> None:
    """viser's HTTP parser (websockets) takes GET alone: a POST had the connection closed with no answer
    at all, and a traceback on the daemon's stderr. Now 405 with `Allow: GET` (HEAD gets no body);
    the page is still served."""
    daemon = ServeProcess(room, ENDPOINTS, extra_args=["--view", "127.0.0.1:0", "--workers", "0"])
    try:
        view = daemon.service("view")
        for method, body in (("POST", b'{"density": 1}'), ("PUT", None), ("DELETE", None), ("OPTIONS", None)):
            status, headers, text = _request(view, method, "/", body)
            assert (status, headers.get("Allow")) == (405, "GET"), (method, status, headers, text)
            assert text == f"{method} is not allowed: the browser view serves its page to GET only\n".encode()
        status, headers, text = _request(view, "HEAD", "/index.html")
        assert (status, headers.get("Allow"), text) == (405, "GET", b"")
        status, headers, page = _request(view, "GET", "/")
        assert status == 200 and headers["Content-Type"].startswith("text/html") and page
    finally:
        assert daemon.stop() == 0, daemon.stderr
    assert "Traceback" not in daemon.stderr, daemon.stderr


class Lines:
    """The lines of a child's stream as they come, read on a thread; `next` waits for one."""

    def __init__(self, stream: IO[str]) -> None:
        self._lines: queue.Queue[str | None] = queue.Queue()
        threading.Thread(target=self._pump, args=(stream,), daemon=True).start()

    def _pump(self, stream: IO[str]) -> None:
        for line in stream:
            self._lines.put(line.rstrip("\n"))
        self._lines.put(None)

    def next(self) -> str:
        try:
            line = self._lines.get(timeout=WAIT_S)
        except queue.Empty:
            pytest.fail(f"no line within {WAIT_S:g} s")
        assert line is not None, "the stream ended"
        return line


def _watch(daemon: ServeProcess, sensor: str) -> tuple[subprocess.Popen, Lines, Lines]:
    watcher = subprocess.Popen(
        [*serve_command(), "ctl", "--url", daemon.control_url, "watch", sensor],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, bufsize=1,
    )
    return watcher, Lines(watcher.stdout), Lines(watcher.stderr)


def test_ctl_watch_says_when_the_clock_is_paused_and_when_it_resumes(daemon: ServeProcess) -> None:
    """A paused clock makes no scans, and `ctl watch` printed nothing: the user thought it hung. It says
    so on stderr, from the state messages the WebSocket already sends (one on connecting, one on every
    change), once when the clock pauses (a watcher started while it is paused, at once) and once when
    it resumes; its stdout holds scan lines only."""
    url = daemon.control_url
    running, running_out, running_notes = _watch(daemon, "lms")
    late = None
    try:
        assert " lms " in running_out.next()  # it watches
        status, answer = call(url, "PATCH", "/api/clock", {"paused": True})
        assert status == 200
        paused_at = answer["state"]["time_s"]
        said = f"clock paused at {paused_at:.3f} s: no scans of lms until it resumes (ctl clock --resume)"
        assert running_notes.next() == said
        late, late_out, late_notes = _watch(daemon, "lms")
        assert late_notes.next() == said  # started while paused: told at once
        status, answer = call(url, "PATCH", "/api/clock", {"paused": False})
        assert status == 200
        for notes in (running_notes, late_notes):  # the state message goes out a moment after the answer: time ran on
            note = notes.next()
            assert note.startswith("clock resumed at ") and note.endswith(" s"), note
            assert float(note.split()[3]) >= round(answer["state"]["time_s"], 3), (note, answer["state"])
        while float((line := running_out.next()).split()[0]) <= paused_at:
            assert " lms " in line  # scans from before the pause, still in the pipe
        assert " lms " in line and " lms " in late_out.next()  # scans again, stamped after the pause
    finally:
        for watcher in (running, late):
            if watcher is not None:
                watcher.terminate()
                watcher.wait(timeout=WAIT_S)


def test_ctl_watch_says_so_when_the_daemon_stops(room: Path) -> None:
    """It ended with exit status 0 and not a word, as if it had seen all it was asked for."""
    daemon = ServeProcess(room, ENDPOINTS, extra_args=["--control", "127.0.0.1:0", "--view", "off"])
    try:
        watcher, out, notes = _watch(daemon, "urg")
        assert " urg " in out.next()
    finally:
        assert daemon.stop() == 0, daemon.stderr
    assert watcher.wait(timeout=WAIT_S) == 2
    assert notes.next() == f"lrf-emulator ctl: the daemon at {daemon.control_url} closed the connection (it stopped)"
