"""`lrf-emulator ctl`: a terminal client of the control API (docs/control.md).

Each subcommand is one request; the answer is printed as JSON (`state`) or
as one line saying what was applied. `watch SENSOR` prints a line per scan
from the WebSocket until interrupted; while the simulated clock is paused
there are no scans, so it says so on stderr, once when it learns of the
pause and once when the clock resumes (from the state messages the
WebSocket sends on every change: nothing is polled). Any refusal or
unreachable daemon is one line on stderr and exit status 2 (a `UserError`).
"""

from __future__ import annotations

import asyncio
import http.client
import json
import math
import os
import sys
import urllib.error
import urllib.parse
import urllib.request
from typing import Any

from emulator.errors import UserError

DEFAULT_URL = "http://127.0.0.1:8765"
TIMEOUT_S = 10.0


class ControlClient:
    """Requests to one daemon's control API; `token` is sent as a Bearer token."""

    def __init__(self, url: str = DEFAULT_URL, token: str | None = None) -> None:
        self.url = checked_url(url).rstrip("/")
        self.token = token

    def _headers(self) -> dict[str, str]:
        headers = {"Content-Type": "application/json"}
        if self.token:
            headers["Authorization"] = f"Bearer {self.token}"
        return headers

    def call(self, method: str, path: str, body: Any = None) -> Any:
        """The answer's JSON; UserError with the API's own words for a refusal."""
        data = json.dumps(body).encode() if body is not None else None
        request = urllib.request.Request(self.url + path, data=data, method=method, headers=self._headers())
        try:
            with urllib.request.urlopen(request, timeout=TIMEOUT_S) as answer:
                return json.loads(answer.read())
        except urllib.error.HTTPError as error:
            raise UserError(f"{error.code}: {_error_text(error.read(), error.reason)}") from None
        except (urllib.error.URLError, OSError) as error:
            reason = getattr(error, "reason", error)
            raise UserError(f"cannot reach the control API at {self.url}: {reason}") from None
        except http.client.HTTPException:  # not HTTP at all: a device's port, say
            raise UserError(f"{self.url} does not answer HTTP: is it the control API's address (serve prints 'ready control URL')?") from None
        except ValueError:
            raise UserError(f"{self.url}{path}: the answer is not JSON") from None

    def state(self) -> dict[str, Any]:
        return self.call("GET", "/api/state")

    def set_region(self, name: str, density: float) -> dict[str, Any]:
        return self.call("PATCH", f"/api/smoke/regions/{_quote(name)}", {"density": density})

    def plume(self, name: str, **changes: Any) -> dict[str, Any]:
        return self.call("PATCH", f"/api/smoke/plumes/{_quote(name)}", changes)

    def pose(self, name: str, position: list[float], rotation_deg: list[float]) -> dict[str, Any]:
        return self.call("PUT", f"/api/bodies/{_quote(name)}/pose", {"position": position, "rotation_deg": rotation_deg})

    def twist(self, name: str, vx: float, vy: float, wz: float) -> dict[str, Any]:
        """Drive live body `name` at (vx, vy) m/s in its frame, turning at wz rad/s, until its watchdog."""
        return self.call("PUT", f"/api/bodies/{_quote(name)}/twist", {"vx": vx, "vy": vy, "wz": wz})

    def clock(self, **changes: Any) -> dict[str, Any]:
        return self.call("PATCH", "/api/clock", changes)

    def watch(self, sensor: str, count: int | None = None, out=print, note=None) -> None:
        """A line per scan of `sensor` from the WebSocket (`count` scans, or until interrupted) to `out`;
        a line to `note` (default: stderr) when the clock is paused, and when it runs again."""
        asyncio.run(self._watch(sensor, count, out, note or _to_stderr))

    async def _watch(self, sensor: str, count: int | None, out, note) -> None:
        import aiohttp

        headers = {"Authorization": f"Bearer {self.token}"} if self.token else {}
        ws_url = self.url.replace("http://", "ws://", 1) + "/api/ws"
        try:
            async with aiohttp.ClientSession(headers=headers) as session:
                async with session.ws_connect(ws_url, max_msg_size=0) as socket:
                    await socket.send_json({"subscribe": [sensor]})
                    seen = 0
                    paused = False  # as the last state message said (the first comes on connecting)
                    async for message in socket:
                        if message.type != aiohttp.WSMsgType.TEXT:
                            break
                        data = json.loads(message.data)
                        if data.get("type") == "error":
                            raise UserError(f"{data.get('status')}: {data.get('error')}")
                        if data.get("type") == "state" and bool(data.get("paused")) != paused:
                            paused = not paused
                            note(clock_line(data, sensor))
                        if data.get("type") == "scan":
                            try:
                                out(scan_line(data))
                            except BrokenPipeError:  # the reader went away (`ctl watch | head`): stop quietly
                                _quiet_stdout()
                                return
                            seen += 1
                            if count is not None and seen >= count:
                                return
                    raise UserError(f"the daemon at {self.url} closed the connection (it stopped)")  # not a quiet end
        except aiohttp.WSServerHandshakeError as error:
            raise UserError(f"{error.status}: {error.message}") from None
        except (aiohttp.ClientError, OSError) as error:
            raise UserError(f"cannot reach the control API at {self.url}: {error}") from None


def clock_line(state: dict[str, Any], sensor: str) -> str:
    """What `watch` says when a state message finds the clock paused (no scans come until it runs
    again), or running again."""
    at = f"{state.get('time_s', math.nan):.3f} s"
    if state.get("paused"):
        return f"clock paused at {at}: no scans of {sensor} until it resumes (ctl clock --resume)"
    return f"clock resumed at {at}"


def _to_stderr(line: str) -> None:
    try:
        print(line, file=sys.stderr, flush=True)
    except BrokenPipeError:  # nobody reads stderr any more: the scans go on
        pass


def _quiet_stdout() -> None:
    """Point stdout at /dev/null, so flushing it at exit raises no second BrokenPipeError."""
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, sys.stdout.fileno())
    os.close(devnull)


def checked_url(url: str) -> str:
    """`url` if it is an http(s)://HOST[:PORT] address, else a UserError saying what is expected."""
    try:
        parts = urllib.parse.urlsplit(url)
        valid = parts.scheme in ("http", "https") and bool(parts.hostname) and (parts.port is None or parts.port > 0)
    except ValueError:  # a port out of range or not a number
        valid = False
    if not valid:
        raise UserError(f"--url {url!r}: expected http://HOST:PORT (default {DEFAULT_URL})")
    if "@" in parts.netloc:  # urllib sent it to DNS as the host name ("Name or service not known")
        raise UserError(f"--url {url!r}: a user and password in the URL are not sent; give --token instead")
    return url


def scan_line(scan: dict[str, Any]) -> str:
    """One scan in a line: time, sensor, how many beams measured, their nearest and the error count; and
    how many of the sensor's scans its devices sent late or skipped so far (the daemon was behind)."""
    ranges = [r for r in scan.get("ranges_m", []) if r is not None]
    errors = len(scan.get("ranges_m", [])) - len(ranges)
    nearest = f"{min(ranges):.3f} m" if ranges else "-"
    ahead = _range_ahead(scan)
    behind = f", late {scan['late']}, skipped {scan['skipped']}" if "late" in scan and "skipped" in scan else ""
    return (
        f"{scan.get('time_s', math.nan):10.3f} s  {scan.get('sensor')}  {len(ranges)} ranges, "
        f"{errors} errors, nearest {nearest}, ahead {ahead}{behind}"
    )


def _range_ahead(scan: dict[str, Any]) -> str:
    angles = scan.get("angles_deg") or []
    if not angles:
        return "-"
    index = min(range(len(angles)), key=lambda i: abs(angles[i]))
    value, distance = scan["values"][index], scan["ranges_m"][index]
    return f"{distance:.3f} m" if distance is not None else f"error {value}"


def _quote(name: str) -> str:
    return urllib.request.quote(name, safe="")


def _error_text(raw: bytes, reason: object = "") -> str:
    """The API's own words, else the answer's text, else its status line's reason: a server that is not
    the control API (the browser view's port, say) may answer with an empty body."""
    try:
        data = json.loads(raw)
        return str(data.get("error", data)) if isinstance(data, dict) else str(data)
    except ValueError:
        text = raw.decode("utf-8", "replace").strip()[:200]
        return text or f"{reason} (is this the control API's address? serve prints 'ready control URL')"
