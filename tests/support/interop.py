"""Helpers shared by the interop tests: the test scene, the `scan` command, client checks."""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from emulator.bench.serve_process import serve_command

# A closed room, a pillar, a box and a block of static smoke on the front left:
# no plumes and no noise, so every scan equals `lrf-emulator scan` at any time,
# and the URG's beams through the smoke return error codes (the paper's rule).
ROOM_SCENE = """\
[scene]
name = "interop room"
description = "static room with a smoke block, for interop tests"
seed = 11

[[objects]]
name = "front wall"
box = {{ size = [0.2, 10.0, 2.0] }}
position = [3.5, 0.0, 1.0]

[[objects]]
name = "left wall"
box = {{ size = [10.0, 0.2, 2.0] }}
position = [0.0, 2.5, 1.0]
material = "white_paper"

[[objects]]
name = "right wall"
box = {{ size = [10.0, 0.2, 2.0] }}
position = [0.0, -2.0, 1.0]

[[objects]]
name = "back wall"
box = {{ size = [0.2, 10.0, 2.0] }}
position = [-2.0, 0.0, 1.0]

[[objects]]
name = "pillar"
cylinder = {{ radius = 0.25, height = 2.0 }}
position = [1.5, -0.8, 1.0]

[[objects]]
name = "crate"
box = {{ size = [0.4, 0.4, 1.0] }}
position = [2.0, 0.9, 0.5]
rotation_deg = [0, 0, 30]

[[smoke.regions]]
name = "smoke block"
box = {{ size = [1.5, 1.5, 2.0] }}
position = [2.6, 1.6, 1.0]
density = 0.008
"""

# One sensor per scene, so that a URG test does not depend on the LMS200 and back.
SENSORS = {
    "urg": """
[[sensors]]
name = "urg"
model = "urg-04lx"
position = [0.0, 0.0, 0.3]
endpoints = ["pty:{folder}/scene-ttyURG"]
""",
    "lms": """
[[sensors]]
name = "lms"
model = "lms200"
position = [0.0, 0.0, 0.45]
endpoints = ["pty:{folder}/scene-ttyLMS"]
""",
    "ust": """
[[sensors]]
name = "ust"
model = "ust-10lx"
position = [0.0, 0.0, 0.3]
endpoints = ["pty:{folder}/scene-ttyUST"]
""",
    "utm": """
[[sensors]]
name = "utm"
model = "utm-30lx-ew"
position = [0.0, 0.0, 0.3]
endpoints = ["pty:{folder}/scene-ttyUTM"]
""",
    "tim": """
[[sensors]]
name = "tim"
model = "tim561"
position = [0.0, 0.0, 0.4]
endpoints = ["tcp:127.0.0.1:0"]
""",
    "utm-usb": """
[[sensors]]
name = "utm"
model = "utm-30lx"
position = [0.0, 0.0, 0.3]
endpoints = ["pty:{folder}/scene-ttyUTM"]
""",
}


def require_program(name: str, install_hint: str) -> str:
    """The program's path; FAIL (never skip) when the client is not installed."""
    path = shutil.which(name)
    if path is None:
        pytest.fail(f"{name} not found: {install_hint}")
    return path


def write_room(folder: Path, sensor: str) -> Path:
    path = folder / f"room-{sensor}.toml"
    path.write_text((ROOM_SCENE + SENSORS[sensor]).format(folder=folder))
    return path


def scan_values(scene: Path, sensor: str, time_s: float) -> tuple[np.ndarray, np.ndarray]:
    """(angles_deg, values) from `lrf-emulator scan SCENE --sensor NAME --time T`, sorted by angle."""
    result = subprocess.run(
        [*serve_command(), "scan", str(scene), "--sensor", sensor, "--time", repr(time_s)],
        capture_output=True, text=True, timeout=60,
    )
    assert result.returncode == 0, result.stderr
    scan = json.loads(result.stdout)
    angles = np.asarray(scan["angles_deg"], dtype=float)
    order = np.argsort(angles, kind="stable")
    return angles[order], np.asarray(scan["values"], dtype=np.int64)[order]


def urg_step_values(scene: Path, time_s: float, first: int = 44, last: int = 725) -> np.ndarray:
    """The `scan` command's URG values for steps first..last (step 384 ahead, 1024 per turn)."""
    angles, values = scan_values(scene, "urg", time_s)
    wanted = (np.arange(first, last + 1) - 384) * 360.0 / 1024.0
    index = np.searchsorted(angles, wanted - 1e-6)
    assert np.all(index < len(angles)), "scan lacks steps"
    np.testing.assert_allclose(angles[index], wanted, atol=1e-4)
    return values[index]
