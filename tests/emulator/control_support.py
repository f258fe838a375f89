"""Helpers for the control API tests: raw HTTP calls and scenes made for live changes."""

from __future__ import annotations

import http.client
import json
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

# A closed room with a URG-04LX and an LMS200 looking along +x at a wall 3 m
# away, a smoke region filling the room (clear at first) and a plume that
# does not emit until switched on, right in front of both sensors.
LIVE_ROOM = """\
[scene]
name = "live room"
description = "a room whose smoke and fire are switched by the control API"
seed = 5
model = "formsma2011"

[[objects]]
name = "front wall"
box = { size = [0.2, 10.0, 3.0] }
position = [3.0, 0.0, 1.5]

[[objects]]
name = "back wall"
box = { size = [0.2, 10.0, 3.0] }
position = [-3.0, 0.0, 1.5]

[[smoke.regions]]
name = "room"
box = { size = [5.8, 9.8, 2.9] }
position = [0.0, 0.0, 1.5]
density = 0.0

[[smoke.plumes]]
name = "fire"
source = [1.5, 0.0, 0.3]
rate = 40.0
lifetime = 4.0
size = 0.3
growth = 0.05
velocity = [0.0, 0.0, 0.05]
density = 1.0
start = 100000.0

[[sensors]]
name = "urg"
model = "urg-04lx"
position = [0.0, 0.0, 0.3]

[[sensors]]
name = "lms"
model = "lms200"
position = [0.0, 0.0, 0.3]
"""


ENDPOINTS = ("urg=tcp:127.0.0.1:0", "lms=tcp:127.0.0.1:0")


def write_live_room(folder: Path) -> Path:
    path = folder / "live-room.toml"
    path.write_text(LIVE_ROOM)
    return path


def call(url: str, method: str, path: str, body: Any = None, raw: bytes | None = None,
         headers: dict[str, str] | None = None, as_json: bool = True) -> tuple[int, Any]:
    """(status, JSON answer) of one request; `raw` sends bytes as they are."""
    parts = urlsplit(url)
    connection = http.client.HTTPConnection(parts.hostname, parts.port, timeout=20)
    try:
        data = raw if raw is not None else (json.dumps(body).encode() if body is not None else None)
        connection.request(method, path, body=data, headers=headers or {})
        answer = connection.getresponse()
        payload = answer.read()
        if not as_json:
            return answer.status, payload
        return answer.status, json.loads(payload) if payload else None
    finally:
        connection.close()


# A URG-04LX looking along +x at a wall 3 m away, and a crate on a live body
# (a robot driven from outside) that starts out of the beam plane's way.
LIVE_BODY_ROOM = """\
[scene]
name = "live body room"
description = "a crate on a body driven by the control API"
seed = 7
model = "formsma2011"

[[objects]]
name = "front wall"
box = { size = [0.2, 10.0, 3.0] }
position = [3.0, 0.0, 1.5]

[[bodies]]
name = "robot"
position = [1.0, 3.0, 0.0]
trajectory = "live"

[[objects]]
name = "crate"
body = "robot"
box = { size = [0.4, 0.4, 1.0] }
position = [0.0, 0.0, 0.5]

[[sensors]]
name = "urg"
model = "urg-04lx"
position = [0.0, 0.0, 0.3]
"""


def write_live_body_room(folder: Path) -> Path:
    path = folder / "live-body-room.toml"
    path.write_text(LIVE_BODY_ROOM)
    return path
