"""`lrf-emulator bench --json --quick`: the report's structure (timings themselves are machine facts, not tested)."""

from __future__ import annotations

import json
import math
import subprocess
import sys

from emulator.scene import bundled_scenes, load_scene


def test_bench_json_reports_every_bundled_sensor():
    result = subprocess.run(
        [sys.executable, "-m", "emulator.cli", "bench", "--json", "--quick"], capture_output=True, text=True, timeout=300
    )
    assert result.returncode == 0, result.stderr
    report = json.loads(result.stdout)

    specs = {(bundled.name, spec.name): spec for bundled in bundled_scenes() for spec in load_scene(bundled.name).sensors}
    expected = {(scene, name, spec.model) for (scene, name), spec in specs.items()}
    assert {(row["scene"], row["sensor"], row["model"]) for row in report["scans"]} == expected
    for row in report["scans"]:
        assert row["scan_ms"] > 0 and row["max_scan_ms"] >= row["scan_ms"]
        spec = specs[row["scene"], row["sensor"]]
        if spec.model == "urg-04lx":
            assert row["period_ms"] == 100.0
        else:  # the mirror's revolutions (13.33 ms each) one scan at that resolution needs
            revolutions = {1.0: 1, 0.5: 2, 0.25: 4}[float(spec.options["resolution_deg"])]
            assert math.isclose(row["period_ms"], revolutions * 1000.0 / 75.0)
        assert math.isclose(row["fraction"], row["scan_ms"] / row["period_ms"])

    assert {(row["scene"], row["sensor"]) for row in report["rays"]} == {(s, n) for s, n, _ in expected}
    for row in report["rays"]:
        assert row["rays"] > 0 and row["raw_rays_per_s"] > 0 and row["ours_rays_per_s"] > 0
    assert report["ratio"] > 0
    assert report["peak_rss_mb"] > 0


def test_bench_table_has_every_section():
    result = subprocess.run(
        [sys.executable, "-m", "emulator.cli", "bench", "--quick"], capture_output=True, text=True, timeout=300
    )
    assert result.returncode == 0, result.stderr
    for heading in ("rays:", "scans:", "memory:"):
        assert any(line.startswith(heading) for line in result.stdout.splitlines()), heading
