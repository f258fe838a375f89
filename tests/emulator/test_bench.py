"""`lrf-emulator bench --json --quick`: the report's structure (timings themselves are machine facts, not tested)."""

from __future__ import annotations

import dataclasses
import json
import math
import subprocess
import sys

from emulator.scene import bundled_scenes, load_scene
from emulator.scene.sick_models import MODELS as SICK_MODELS


def bench(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "emulator.cli", "bench", "--quick", *args], capture_output=True, text=True, timeout=600
    )


def test_bench_json_reports_every_bundled_sensor_and_every_section():
    result = bench("--json")
    assert result.returncode == 0, result.stderr
    report = json.loads(result.stdout)

    specs = {(bundled.name, spec.name): spec for bundled in bundled_scenes() for spec in load_scene(bundled.name).sensors}
    expected = {(scene, name, spec.model) for (scene, name), spec in specs.items()}
    # every scene and sensor under every preset, once; and railway with 10 000 live particles
    dense = {("railway-10k", name, model) for scene, name, model in expected if scene == "railway"}
    # and the SCIP 2.2 Hokuyos each of rescue and railway lacks, on its URG's mount
    mounted = {
        (f"{scene}-hokuyos", model, model)
        for scene in ("rescue", "railway") for model in ("utm-30lx", "utm-30lx-ew", "ust-10lx", "ust-20lx")
        if model not in {spec.model for spec in load_scene(scene).sensors}
    }
    assert ("rescue-hokuyos", "ust-10lx", "ust-10lx") in mounted and ("railway-hokuyos", "utm-30lx-ew", "utm-30lx-ew") in mounted
    scan_rows = [(row["scene"], row["sensor"], row["model"], row["preset"]) for row in report["scans"]]
    assert len(scan_rows) == len(set(scan_rows))
    assert set(scan_rows) == {(*key, preset) for key in expected | dense | mounted for preset in ("formsma2011", "physical")}
    for scene, name, _ in dense:
        specs[scene, name] = specs["railway", name]
    for scene, name, model in mounted:
        specs[scene, name] = dataclasses.replace(specs[scene.removesuffix("-hokuyos"), "urg"], name=name, model=model, options={})
    for row in report["scans"]:
        assert row["scan_ms"] > 0 and row["max_scan_ms"] >= row["scan_ms"]
        spec = specs[row["scene"], row["sensor"]]
        if spec.model == "urg-04lx":
            assert row["period_ms"] == 100.0
        elif spec.model in SICK_MODELS:  # a CoLa SICK: one turn per scan at its scan frequency
            assert math.isclose(row["period_ms"], 1000.0 / float(spec.options["scan_frequency_hz"]))
        elif spec.model in ("utm-30lx", "utm-30lx-ew", "ust-10lx", "ust-20lx"):
            assert row["period_ms"] == 25.0
        else:  # the mirror's revolutions (13.33 ms each) one scan at that resolution needs
            revolutions = {1.0: 1, 0.5: 2, 0.25: 4}[float(spec.options["resolution_deg"])]
            assert math.isclose(row["period_ms"], revolutions * 1000.0 / 75.0)
        # a steady stream as the daemon computes it, beside the one-scan-alone figure
        assert 0 < row["streamed_ms"] <= row["max_streamed_ms"] < math.inf
        assert math.isclose(row["fraction"], row["streamed_ms"] / row["period_ms"])
        assert math.isclose(row["max_fraction"], row["max_streamed_ms"] / row["period_ms"]) and 1.0 <= row["slowest_at_s"] <= 60.0

    assert {(row["scene"], row["sensor"]) for row in report["rays"]} == {(s, n) for s, n, _ in expected}
    for row in report["rays"]:
        assert row["rays"] > 0 and row["raw_rays_per_s"] > 0 and row["ours_rays_per_s"] > 0
    assert report["ratio"] > 0
    assert report["peak_rss_mb"] > 0
    # the sections measured through a served daemon
    for timing in ("fast", "real"):
        assert report["latency"][timing]["pty"]["p99_ms"] > 0 and report["latency"][timing]["tcp"]["p99_ms"] > 0
    # the real unit's command cycle: commands spread over it wait up to 100 ms, fast ones do not
    assert report["latency"]["real"]["tcp"]["max_ms"] > 30 > report["latency"]["fast"]["tcp"]["p50_ms"]
    assert report["jitter"]["mean_period_ms"] > 0
    assert all(row["measured_per_s"] > 0 for row in report["lms_scans_per_s"]["rows"])
    changes = report["change_to_scan"]
    assert changes["violations"] == 0  # no scan stamped after a change shows the world before it
    assert 0 <= changes["simulated"]["p50_ms"] <= changes["simulated"]["max_ms"]
    assert report["control_jitter"]["pose_stream_100hz"]["poses_sent"] > 0
    flood = report["control_jitter"]["change_flood"]  # beyond the change rate most are refused
    assert flood["changes_sent"] > flood["changes_applied"] > 0 and flood["p99_ms"] >= 0
    # what watching costs: view off, view unwatched, view in chromium (twice: nice 0 and 19), --mcap
    assert [row["case"] for row in report["view"]] == [
        "view off", "view, no browser", "view + chromium", "view + chromium nice 19", "--mcap"]
    assert all(row["rate"] > 0.5 and row["cpu_ms_per_scan"] > 0 for row in report["view"])
    assert all(row["loop_wakes"] > 0 and 0 <= row["loop_late_2ms"] <= 1 for row in report["view"])  # the daemon's counts
    assert report["view"][4]["mcap_bytes"] > 0
    # CoLa streams: the fine LMS511, then the six units of one daemon, each followed by its floor (bare senders)
    six = ("tim0", "tim1", "tim2", "tim3", "lms0", "lms1")
    assert [(row["case"], row["client"]) for row in report["cola"]] == [("lms511-fine", "lms511"), ("floor", "lms511")] + [
        ("six-units", name) for name in six] + [("floor", name) for name in six]
    assert all(row["telegrams"] > 0 and row["jitter_p99_ms"] >= 0 and row["load"] >= 0
               for row in report["cola"])
    # SLAM in smoke: the URG-04LX and a UTM-30LX-EW's first and last echo through icp-slam
    assert [row["sensor"] for row in report["slam"]] == ["URG-04LX", "UTM-30LX-EW first echo", "UTM-30LX-EW last echo"]
    assert all(row["scans"] > 100 and 0 < row["ate_rmse_m"] <= row["ate_max_m"] for row in report["slam"])


def test_bench_table_shows_only_the_chosen_sections():
    result = bench("--section", "rays", "--section", "memory")
    assert result.returncode == 0, result.stderr
    headings = [line.split(":")[0] for line in result.stdout.splitlines() if line and not line.startswith(" ")]
    assert headings == ["rays", "memory"]


def test_bench_scans_table_has_a_row_per_sensor_and_preset_with_both_figures():
    result = bench("--section", "scans")
    assert result.returncode == 0, result.stderr
    lines = result.stdout.splitlines()
    assert "best of 3 wall-clock timings" in lines[0]  # how each figure was taken
    assert "stream ms" in lines[1] and "alone ms" in lines[1] and "at s" in lines[1] and "max frac" in lines[1]
    rows = [line.split() for line in lines[2:] if line.strip()]
    sensors = sum(len(load_scene(bundled.name).sensors) for bundled in bundled_scenes())
    dense = len(load_scene("railway").sensors)  # railway-10k: railway with 10 000 live particles
    mounted = 3 + 4  # rescue-hokuyos (rescue has its UTM-30LX-EW), railway-hokuyos
    assert len(rows) == 2 * (sensors + dense + mounted)  # formsma2011 and physical
    assert [row[0] for row in rows[-2 * (dense + mounted) : -2 * mounted]] == ["railway-10k"] * 2 * dense
    assert [row[0] for row in rows[-2 * mounted :]] == ["railway-hokuyos"] * 8 + ["rescue-hokuyos"] * 6
    for row in rows:
        streamed, slowest, slowest_at, alone, period = float(row[4]), float(row[5]), float(row[6]), float(row[7]), float(row[9])
        assert 0 < streamed <= slowest and alone > 0 and 1.0 <= slowest_at <= 60.0
        assert abs(float(row[-2].rstrip("%")) - 100 * streamed / period) < 0.1  # the fraction is the streamed cost
        assert abs(float(row[-1].rstrip("%")) - 100 * slowest / period) < 0.1  # and at the slowest instant


def test_unknown_section_is_a_usage_error():
    result = bench("--section", "warp")
    assert result.returncode == 2 and "warp" in result.stderr and "Traceback" not in result.stderr


def test_the_dense_plume_scene_keeps_10000_particles_alive_once_its_plume_is_full():
    from emulator.bench.sections import dense_plume_scene
    from emulator.optics import World

    world = World(dense_plume_scene())
    assert [len(world.particles_at(t)) for t in (20.0, 30.0, 40.0)] == [10_000] * 3
