"""`bench --section soak` for under a minute: the report's shape, and growth bounded even that early.

The hour itself (`make soak`) runs outside the suite; docs/performance.md
holds its figures.
"""

from __future__ import annotations

import json
import subprocess
import sys

from emulator.bench.soak import MEMORY_GROWTH_LIMIT, STREAM_STARTS, protocol_of, soak_scenes
from emulator.scene import bundled_scenes, load_scene

SAMPLE_KEYS = {"minute", "rss_mb", "fds", "threads", "scans", "scans_per_s", "scans_late", "longest_gap_s",
               "event_log_kb", "mcap_mb", "late_5ms", "dropped", "load_average", "daemons"}


def test_the_soak_covers_every_bundled_model_with_a_client_for_its_protocol():
    models = {spec.model for bundled in bundled_scenes() for spec in load_scene(bundled.name).sensors}
    chosen = soak_scenes()
    assert {spec.model for scene in chosen for spec in scene.sensors} == models
    missing = {spec.model: protocol_of(spec) for scene in chosen for spec in scene.sensors}.items()
    assert not [(model, protocol) for model, protocol in missing if protocol not in STREAM_STARTS], "no soak client"


def test_a_short_soak_reports_every_minute_and_stays_flat():
    result = subprocess.run(
        [sys.executable, "-m", "emulator.cli", "bench", "--section", "soak", "--minutes", "0.75", "--json"],
        capture_output=True, text=True, timeout=600,
    )
    assert result.returncode == 0, result.stderr[-3000:]
    soak = json.loads(result.stdout)["soak"]
    assert len(soak["samples"]) >= 9 and all(SAMPLE_KEYS <= set(sample) for sample in soak["samples"])
    sensors = {spec.name for scene in soak_scenes() for spec in scene.sensors}
    assert {f"{sensor} {kind}" for sensor in sensors for kind in ("pty", "tcp")} == set(soak["streams"])
    assert soak["changes"]["accepted"] >= 30 and soak["changes"]["refused"] == 0
    assert soak["churned"]["serial"] >= 3 and soak["churned"]["websocket"] >= 1 and soak["churned"]["failed"] == 0
    assert all(sample["scans"] > 0 for sample in soak["samples"]), "a sample saw no scan"
    first, last = soak["samples"][0], soak["samples"][-1]
    assert last["event_log_kb"] > first["event_log_kb"] > 0 and last["mcap_mb"] > first["mcap_mb"] > 0
    assert soak["fd_growth"] == 0 and soak["memory_growth"] <= MEMORY_GROWTH_LIMIT and soak["passed"]
    assert "RSS MB" in result.stderr and result.stderr.count("\n") >= len(soak["samples"])
