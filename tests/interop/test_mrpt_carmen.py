"""The SLAM-with-echoes pipeline (emulator/bench/slam_echoes.py) through MRPT's own tools: the scans
written as a CARMEN log reach icp-slam through carmen2rawlog unchanged, and in clear air its path
lies on the ground truth."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from emulator.bench import slam_echoes
from emulator.bench.mrpt import carmen_to_rawlog, export_2d_scans
from emulator.optics import World
from emulator.scene import load_scene
from emulator.scene.smoke_scale import scale_smoke
from emulator.sensors import Scan, create_sensor
from emulator.sensors.response import apply_model_override


def test_scans_written_as_carmen_reach_the_rawlog_unchanged(tmp_path: Path) -> None:
    scene = load_scene("railway")
    sensor = create_sensor(scene, "urg", World(scene))
    scans = sensor.scans([20.0, 20.1, 20.2])
    ranges = [slam_echoes.echo_ranges(scan, None) for scan in scans]
    carmen = tmp_path / "scans.log"
    slam_echoes.write_carmen(carmen, scans, [np.where(np.isfinite(r), r, 0.0) for r in ranges], 5.6)
    exported = export_2d_scans(carmen_to_rawlog(carmen, tmp_path / "scans.rawlog"), "ROBOTLASER1")
    assert exported.ranges_m.shape == (3, len(scans[0].angles_rad))  # the laser scans alone: no odometry entries
    expected = np.array([np.where(np.isfinite(r), r, 0.0) for r in ranges])
    np.testing.assert_allclose(exported.ranges_m, expected, atol=0.0005)
    np.testing.assert_array_equal(exported.valid, expected > 0)


def test_first_and_last_echo_ranges_of_a_scan():
    echoes = np.array([[1200, 3400, -1], [2500, -1, -1], [-1, -1, -1], [5, 900, 4000]])  # 5: an error code
    scan = Scan("u", "urg-04lx", 1.0, np.zeros(4), echoes[:, 0], echoes=echoes)
    first, last = slam_echoes.echo_ranges(scan, "first"), slam_echoes.echo_ranges(scan, "last")
    np.testing.assert_array_equal(first, [1.2, 2.5, np.nan, np.nan])
    np.testing.assert_array_equal(last, [3.4, 2.5, np.nan, 4.0])


def test_scan_instants_take_every_kth_scan_from_the_start():
    np.testing.assert_allclose(slam_echoes.scan_instants(0.025, 0.0, 10.0, 10.5), [10.0, 10.1, 10.2, 10.3, 10.4, 10.5])
    np.testing.assert_allclose(slam_echoes.scan_instants(0.1, 0.05, 10.0, 10.3), [10.05, 10.15, 10.25])


def test_in_clear_air_icp_slam_follows_the_urg_around_the_loop(tmp_path: Path) -> None:
    scene = scale_smoke(apply_model_override(load_scene("rescue"), "physical"), 0.0)
    run = slam_echoes.run(scene, "urg", None, "URG-04LX", tmp_path, start_s=10.0, end_s=40.0)
    assert len(run.times_s) == 301
    assert run.error.rmse_m < 0.15, run.error
    assert np.degrees(run.error.heading_rmse_rad) < 3.0
