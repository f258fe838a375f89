"""The bundled scenes of the paper: `bocas` (§3.1, Fig. 5), `marulan` (§2, Fig. 3/10) and `railway` (§1, Fig. 1)."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest
from support.ports import free_tcp_port

from emulator.bench.serve_process import ServeProcess
from emulator.optics import World
from emulator.plots.waterfall import saturation
from emulator.scene import bundled_scenes, load_scene
from emulator.scene.plumes import particles_at
from emulator.sensors import create_sensor
from emulator.validation import report as validation
from emulator.validation.report import keyframe_crossings, machine_on_intervals

PENETRATION_POWER = 0.007  # d·m, paper eq. 1
TARGET_RANGE_M = 2.5
URG_FRONT_STEP = 384
URG_LOW_INTENSITY = 1


def predicted_crossings(keyframes: list[tuple[float, float]], threshold: float) -> list[tuple[float, str]]:
    """Times where the piecewise-linear density crosses `threshold`, solved per segment."""
    crossings = []
    for (t0, d0), (t1, d1) in zip(keyframes, keyframes[1:]):
        if (d0 <= threshold < d1) or (d1 <= threshold < d0):
            crossings.append((t0 + (threshold - d0) * (t1 - t0) / (d1 - d0), "up" if d1 > d0 else "down"))
    return crossings


def test_paper_scenes_are_bundled_with_a_description() -> None:
    described = {scene.name: scene.description for scene in bundled_scenes()}
    assert "Fig. 5" in described["bocas"] and "§3.1" in described["bocas"]
    assert "Fig. 10" in described["marulan"] and "Fig. 3" in described["marulan"]


def test_bocas_layout_matches_section_3_1() -> None:
    scene = load_scene("bocas")
    (urg,) = scene.sensors
    assert (urg.name, urg.model, urg.endpoints) == ("urg", "urg-04lx", ("pty:ttyURG0", "tcp:127.0.0.1:10940"))
    sensor_z = urg.pose.position[2]
    bollards = [obj for obj in scene.objects if obj.name.startswith("bollard")]
    xs = sorted(obj.pose.position[0] for obj in bollards)
    assert len(bollards) == 3 and np.allclose(np.diff(xs), 0.6)
    assert all(obj.pose.position[2] + obj.shape.height / 2 < sensor_z for obj in bollards)
    materials = {obj.material for obj in scene.objects if obj.name.startswith("target")}
    assert materials == {"blue_paper", "yellow_paper", "gold_paper"}
    assert any(obj.material == "rusty_steel" for obj in scene.objects)


def test_bocas_beams_reach_the_target_at_2_5_m_and_never_a_bollard() -> None:
    scene = load_scene("bocas")
    sensor = create_sensor(scene, "urg")
    values = sensor.scan(0.0).values
    assert values[URG_FRONT_STEP] == 2500
    world = World(scene)
    angles = (np.arange(44, 726) - URG_FRONT_STEP) * 2 * math.pi / 1024
    directions = np.stack([np.cos(angles), np.sin(angles), np.zeros_like(angles)], axis=1)
    origins = np.tile(scene.sensors[0].pose.position, (len(angles), 1))
    hits = world.cast(origins, directions, 5.6, 0.0)
    hit_names = {scene.objects[i].name for i in hits.object_index if i >= 0}
    assert not any(name.startswith("bollard") for name in hit_names)
    assert {"target_blue", "target_yellow", "target_gold", "steel_plates"} <= hit_names


def test_bocas_error_onset_happens_when_and_where_the_model_predicts() -> None:
    scene = load_scene("bocas")
    (fog,) = scene.regions
    threshold = PENETRATION_POWER / TARGET_RANGE_M
    crossings = predicted_crossings(list(fog.density.keyframes), threshold)
    assert [direction for _, direction in crossings] == ["up", "down"]  # one error episode (Fig. 5)
    onset_s, clearing_s = crossings[0][0], crossings[1][0]
    sensor = create_sensor(scene, "urg")
    times = np.arange(0, 3301) / 10
    centre = np.array([sensor.scan(float(t)).values[URG_FRONT_STEP] for t in times])
    in_error = centre == URG_LOW_INTENSITY
    assert set(centre[~in_error].tolist()) == {2500}
    first_error = times[np.argmax(in_error)]
    last_error = times[len(in_error) - 1 - np.argmax(in_error[::-1])]
    assert onset_s < first_error <= onset_s + 0.1  # within one scan period
    assert clearing_s - 0.1 <= last_error < clearing_s
    assert np.all(in_error[(times > onset_s) & (times < clearing_s)])
    assert 40 < onset_s < 120 and clearing_s - onset_s > 60  # a run of a few minutes
    assert saturation(fog.density.at(first_error)) == pytest.approx(0.14, abs=0.01)
    assert saturation(fog.density.at(first_error - 0.1)) > 0.14


def test_bocas_fog_machine_runs_10_s_then_40_s_as_in_fig_5() -> None:
    keyframes = load_scene("bocas").regions[0].density.keyframes
    on = machine_on_intervals(keyframes)
    assert [stop - start for start, stop in on] == [10.0, 40.0]
    threshold = PENETRATION_POWER / TARGET_RANGE_M
    assert keyframe_crossings(keyframes, threshold) == [t for t, _ in predicted_crossings(list(keyframes), threshold)]


def test_marulan_layout_has_the_static_obstacles_of_fig_3_in_view() -> None:
    scene = load_scene("marulan")
    lms, lms5 = scene.sensors  # the LMS200 of the experiment, and an LMS511 beside it over CoLa
    assert (lms.name, lms.model, lms.endpoints) == ("lms", "lms200", ("pty:ttyLMS0",))
    assert (lms5.name, lms5.model, [str(e) for e in lms5.endpoints]) == ("lms5", "lms511", ["tcp:127.0.0.1:2111"])
    world = World(scene)
    angles = np.radians(np.arange(361) * 0.5 - 90.0)
    directions = np.stack([np.cos(angles), np.sin(angles), np.zeros_like(angles)], axis=1)
    origins = np.tile(lms.pose.position, (len(angles), 1))
    hits = world.cast(origins, directions, 80.0, 0.0)
    seen = {scene.objects[i].name for i in hits.object_index if i >= 0}
    assert {"house", "table", "cart"} <= seen
    assert sum(name.startswith("tree") for name in seen) >= 4
    for index in set(hits.object_index[hits.object_index >= 0].tolist()):  # each within the mm mode's maximum
        assert hits.solid_range_m[hits.object_index == index].min() < 8.183


def bearing_deg(points: np.ndarray, origin: np.ndarray) -> np.ndarray:
    """Sensor-frame bearing of points (+ = the sensor's left)."""
    offset = points - origin
    return np.degrees(np.arctan2(offset[:, 1], offset[:, 0]))


def test_marulan_puffs_drift_across_the_view_from_left_to_right() -> None:
    scene = load_scene("marulan")
    origin = np.array(scene.sensors[0].pose.position)
    for index, plume in enumerate(scene.plumes):
        if plume.name == "puff_right":
            continue
        early = particles_at(plume, scene.seed, index, plume.stop + 2.0)
        late = particles_at(plume, scene.seed, index, plume.stop + 18.0)
        assert len(early) and len(late)
        assert np.median(bearing_deg(early.centers, origin)) > 20.0
        assert np.median(bearing_deg(late.centers, origin)) < -20.0
        in_scan_plane = np.abs(late.centers[:, 2] - origin[2]) < late.half_sizes
        assert in_scan_plane.mean() > 0.75  # dispersed, but mostly still at beam height


def test_marulan_puffs_meet_on_the_sensors_right_late_in_the_run() -> None:
    scene = load_scene("marulan")
    origin = np.array(scene.sensors[0].pose.position)
    meeting_times = []
    for time_s in np.arange(60.0, 100.0, 1.0):
        sources_on_right = 0
        for index, plume in enumerate(scene.plumes):
            particles = particles_at(plume, scene.seed, index, float(time_s))
            if len(particles) and np.any(bearing_deg(particles.centers, origin) < -30.0):
                sources_on_right += 1
        if sources_on_right >= 2:
            meeting_times.append(time_s)
    assert len(meeting_times) >= 10


@pytest.mark.parametrize(("scene_name", "sensor", "model"), [("bocas", "urg", "urg-04lx"), ("marulan", "lms", "lms200")])
def test_paper_scene_is_served_by_the_real_daemon(tmp_path: Path, scene_name: str, sensor: str, model: str) -> None:
    port = free_tcp_port()
    endpoints = [f"{sensor}=pty:{tmp_path / 'tty'}", f"{sensor}=tcp:127.0.0.1:{port}"]
    with ServeProcess(scene_name, endpoints, cwd=tmp_path) as served:
        lines = {(ready.sensor, ready.model, ready.uri) for ready in served.ready if ready.sensor == sensor}
        assert lines == {(sensor, model, f"pty:{tmp_path / 'tty'}"), (sensor, model, f"tcp:127.0.0.1:{port}")}
        assert (tmp_path / "tty").is_symlink()
        assert served.endpoint(sensor, "pty").device.startswith("/dev/pts/")
    assert served.process.returncode == 0
    assert not (tmp_path / "tty").exists()


def test_validation_report_is_deterministic_and_states_the_onset(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(validation, "BOCAS_RUN_S", (65.0, 80.0))  # short runs; the onset stays inside
    monkeypatch.setattr(validation, "MARULAN_RUN_S", (68.0, 72.0))
    reports = []
    for name in ("first", "second"):
        out = tmp_path / name / "validation.md"
        out.parent.mkdir()
        validation.write_report(out)
        figures = sorted((out.parent / "figures").glob("*.png"))
        reports.append((out.read_bytes(), [figure.read_bytes() for figure in figures], [f.name for f in figures]))
    assert reports[0] == reports[1]
    text = reports[0][0].decode()
    assert "| first scan with an error code (scans every 0.1 s) | – | t = 71.6 s |" in text
    assert "0.1396 (within 0.14 ± 0.01)" in text
    assert {"bocas_fig5_saturation_and_ranges.png", "marulan_fig10_waterfall.png"} <= set(reports[0][2])
    for figure in reports[0][2]:
        assert f"](figures/{figure})" in text


def test_railway_smouldering_car_end_blanks_the_urg_but_not_the_lms() -> None:
    """The paper's two smoke types in the 2009 scene: a smoke area the URG cannot see through (§4.1, §4.3)."""
    scene = load_scene("railway")
    (car_end,) = [region for region in scene.regions if region.name == "car_end_smoke"]
    clear_air = dataclasses.replace(scene, plumes=(), regions=())
    only_car_end = dataclasses.replace(scene, plumes=(), regions=(car_end,))
    for name, blanked in (("urg", True), ("lms", False)):
        before = create_sensor(only_car_end, name).scan(4.0).values
        after = create_sensor(only_car_end, name).scan(30.0).values
        clear = create_sensor(clear_air, name).scan(30.0).values
        assert np.array_equal(before, clear)
        assert bool(np.count_nonzero(after != clear) >= 10) == blanked
    urg_after = create_sensor(only_car_end, "urg").scan(30.0).values
    assert set(urg_after[urg_after != create_sensor(clear_air, "urg").scan(30.0).values].tolist()) == {URG_LOW_INTENSITY}


def test_railway_fallen_mast_lies_between_the_two_scan_planes() -> None:
    scene = load_scene("railway")
    (mast,) = [obj for obj in scene.objects if obj.name == "fallen_mast"]
    top = mast.pose.position[2] + mast.shape.radius
    assert scene.sensor("urg").pose.position[2] < top < scene.sensor("lms").pose.position[2]
