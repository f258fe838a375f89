"""The view's way to change the world: the daemon's own control API over HTTP (docs/control.md).

The browser view's sliders, toggles and gizmo call these from viser's
callback threads, never from the daemon's loop; the loop answers them as it
answers any client, so a change from the view is applied, logged and
replayable exactly like one from `ctl` or a script.
"""

from __future__ import annotations

import json
import urllib.error
import urllib.request
from typing import Any

TIMEOUT_S = 2.0


class ControlError(RuntimeError):
    """The control API refused a change or could not be reached; the message says why."""


class ControlClient:
    """JSON requests to `base_url` (`http://HOST:PORT`), with a bearer token if the API wants one."""

    def __init__(self, base_url: str, token: str | None = None) -> None:
        self.base_url = base_url.rstrip("/")
        self._token = token

    def request(self, method: str, path: str, body: dict[str, Any] | None = None) -> Any:
        data = None if body is None else json.dumps(body).encode()
        request = urllib.request.Request(self.base_url + path, data=data, method=method)
        request.add_header("Content-Type", "application/json")
        if self._token:
            request.add_header("Authorization", f"Bearer {self._token}")
        try:
            with urllib.request.urlopen(request, timeout=TIMEOUT_S) as response:
                return json.loads(response.read() or b"null")
        except urllib.error.HTTPError as error:
            raise ControlError(f"{method} {path}: {error.code} {error.read()[:200].decode(errors='replace')}") from None
        except (urllib.error.URLError, OSError) as error:
            raise ControlError(f"{method} {path}: {error}") from None

    def set_density(self, region: str, density: float) -> None:
        self.request("PATCH", f"/api/smoke/regions/{region}", {"density": density})

    def set_emitting(self, plume: str, emitting: bool) -> None:
        self.request("PATCH", f"/api/smoke/plumes/{plume}", {"emitting": emitting})

    def set_clock(self, **change: Any) -> None:
        """`speed=x` and/or `paused=bool`."""
        self.request("PATCH", "/api/clock", change)

    def set_pose(self, body: str, position: list[float], rotation_deg: list[float]) -> None:
        self.request("PUT", f"/api/bodies/{body}/pose", {"position": position, "rotation_deg": rotation_deg})

    def state(self) -> dict[str, Any]:
        return self.request("GET", "/api/state")
