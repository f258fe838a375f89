"""The robustness suite: attacks on the real daemon (`lrf-emulator serve`).

Marked `robustness`; `ROBUSTNESS_SCALE` (default 1, `make robustness-soak` sets more)
multiplies attack durations and hypothesis example counts.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from emulator.bench.serve_process import ServeProcess

SCALE = max(1.0, float(os.environ.get("ROBUSTNESS_SCALE", "1")))


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    for item in items:
        if "tests/robustness/" in str(item.fspath):
            item.add_marker(pytest.mark.robustness)


@pytest.fixture
def daemon(tmp_path: Path):
    """railway with the URG on a pty and TCP, the LMS200 on a pty and TCP."""
    endpoints = [
        f"urg=pty:{tmp_path / 'ttyURG0'}", "urg=tcp:127.0.0.1:0",
        f"lms=pty:{tmp_path / 'ttyLMS0'}", "lms=tcp:127.0.0.1:0",
    ]
    with ServeProcess("railway", endpoints) as served:
        yield served
