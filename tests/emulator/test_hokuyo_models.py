"""The SCIP 2.2 Hokuyos as simulated sensors: geometry, timing, echoes, and the commands around them."""

from __future__ import annotations

import dataclasses
import subprocess
from pathlib import Path

import numpy as np
import pytest
from support.interop import write_room

from emulator.bench.serve_process import serve_command
from emulator.recording.replay_sources import replay_sensor
from emulator.recording.textlog import read_log
from emulator.scene import load_scene
from emulator.sensors import beam_times_s, create_sensor, hokuyo_model, ranges_m
from emulator.sensors.hokuyo import revolution_phase_ms

MULTI_ECHO = ("utm-30lx-ew", "ust-10lx", "ust-20lx")


def room(tmp_path: Path, model: str, preset: str = "formsma2011"):
    path = write_room(tmp_path, "utm")
    scene = load_scene(path)
    spec = dataclasses.replace(scene.sensors[0], model=model)
    return dataclasses.replace(scene, model=preset, sensors=(spec,))


@pytest.mark.parametrize("model", ["utm-30lx", *MULTI_ECHO])
def test_geometry_and_sweep_timing(tmp_path, model):
    sensor = create_sensor(room(tmp_path, model), "utm")
    scan = sensor.scan(1.0)
    assert len(scan.values) == 1081 and sensor.configured_period_s == 0.025
    np.testing.assert_allclose(np.degrees(scan.angles_rad[[0, 540, 1080]]), [-135.0, 0.0, 135.0])
    times = beam_times_s(scan)
    assert times[0] == 1.0 and times[-1] == pytest.approx(1.0 + 0.025 * 1080 / 1440)  # stamped at step 0
    assert scan.timestamp_ms == 1000
    straight = ranges_m(scan)[540]
    assert straight == pytest.approx(3.4, abs=0.01)  # the front wall's face at x = 3.4 m


@pytest.mark.parametrize("model", MULTI_ECHO)
def test_physical_echoes_are_nearest_first_within_range_and_values_are_the_first(tmp_path, model):
    sensor = create_sensor(room(tmp_path, model, "physical"), "utm")
    scan = sensor.scan(0.5)
    hokuyo = hokuyo_model(model)
    echoes, strengths = scan.echoes, scan.echo_intensities
    assert echoes.shape == strengths.shape == (1081, 3)
    np.testing.assert_array_equal(scan.values, echoes[:, 0])
    np.testing.assert_array_equal(scan.intensities, strengths[:, 0])
    present = echoes >= 0
    assert np.all(present[:, 0]) and np.all(present[:, :-1] >= present[:, 1:]), "no gaps: -1 only after the last echo"
    distances = np.where(present[:, 1:], echoes[:, 1:], np.iinfo(np.int64).max)
    assert np.all(np.diff(np.concatenate([echoes[:, :1], distances], axis=1), axis=1) >= 0), "nearest first"
    further = echoes[:, 1:][present[:, 1:]]
    assert np.all((further >= hokuyo.min_value_mm) & (further <= hokuyo.max_value_mm))
    codes = scan.values < hokuyo.min_value_mm
    assert np.all(scan.intensities[codes] == 0) and np.all(scan.intensities[~codes] > 0)
    assert np.all(strengths[~present] == -1)


def test_a_beam_through_the_smoke_block_sees_the_smoke_then_the_wall(tmp_path):
    """The room's smoke block (density 0.008 over 1.5 m) lies before the left wall: under `physical`
    beams crossing it return two echoes, the nearer one inside the block (others have two at an
    object's edge: a mixed pixel)."""
    sensor = create_sensor(room(tmp_path, "utm-30lx-ew", "physical"), "utm")
    scan = sensor.scan(0.5)
    two = scan.echoes[:, 1] >= 0
    assert two.sum() >= 3
    angles = scan.angles_rad[two]
    first_m = scan.echoes[two, 0] / 1000.0
    x, y = first_m * np.cos(angles), first_m * np.sin(angles)
    inside = (np.abs(x - 2.6) <= 0.75) & (np.abs(y - 1.6) <= 0.75)
    assert inside.sum() >= 3, list(zip(x, y))
    assert np.all(scan.echoes[two, 1] > scan.echoes[two, 0])


def test_single_echo_units_and_formsma2011(tmp_path):
    utm = create_sensor(room(tmp_path, "utm-30lx", "physical"), "utm").scan(0.5)
    assert utm.echoes is None and utm.intensities is not None
    ew = create_sensor(room(tmp_path, "utm-30lx-ew"), "utm").scan(0.5)
    assert np.all(ew.echoes[:, 1:] == -1), "the paper's rule gives one echo"
    assert set(np.unique(ew.values[ew.values < 23])) <= {1, 2, 3}


def test_units_of_one_model_sweep_out_of_step(tmp_path):
    scene = room(tmp_path, "ust-10lx")
    specs = [dataclasses.replace(scene.sensors[0], name=f"u{i}", endpoints=()) for i in range(4)]
    scene = dataclasses.replace(scene, sensors=tuple(specs))
    assert [revolution_phase_ms(scene, f"u{i}", hokuyo_model("ust-10lx")) for i in range(4)] == [0, 6, 12, 18]


@pytest.mark.parametrize("model", ["utm-30lx", "ust-20lx"])
def test_record_then_replay_gives_the_recorded_values(tmp_path, model):
    path = write_room(tmp_path, "utm")
    path.write_text(path.read_text().replace('model = "utm-30lx-ew"', f'model = "{model}"'))
    log = tmp_path / "run.log"
    result = subprocess.run([*serve_command(), "record", str(path), "--sensor", "utm", "--end", "0.1", "--out", str(log)],
                            capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    sensor = create_sensor(load_scene(path), "utm")
    replay = replay_sensor(read_log(log), model, "utm")
    for time_s in (0.0, 0.025, 0.1):
        expected = sensor.scan(time_s).values
        np.testing.assert_array_equal(replay.scan(time_s).values, expected)
