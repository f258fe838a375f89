"""The bundled railway scene does its job: the fire's plume drifts across both sensors' view."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from emulator.scene import load_scene
from emulator.sensors import create_sensor

FRONT_DEG = 30.0  # the plume drifts across the sensors' front sector


@pytest.mark.parametrize("sensor_name", ["urg", "lms"])
@pytest.mark.parametrize("time_s", [3.0, 30.0])
def test_the_plume_changes_the_front_beams_of_both_sensors(sensor_name: str, time_s: float) -> None:
    scene = load_scene("railway")
    clear_air = dataclasses.replace(scene, plumes=(), regions=())
    smoky = create_sensor(scene, sensor_name).scan(time_s)
    clear = create_sensor(clear_air, sensor_name).scan(time_s)
    front = np.abs(np.degrees(smoky.angles_rad)) <= FRONT_DEG
    changed = np.asarray(smoky.values) != np.asarray(clear.values)
    assert np.count_nonzero(changed & front) >= 10
    assert np.count_nonzero(changed & ~front) < np.count_nonzero(changed & front)


def test_without_smoke_every_front_beam_of_the_urg_sees_the_wreck_within_range() -> None:
    """So that in smoke an error code replaces a real range, as in the paper's Fig. 8."""
    clear_air = dataclasses.replace(load_scene("railway"), plumes=(), regions=())
    scan = create_sensor(clear_air, "urg").scan(0.0)
    front = np.abs(np.degrees(scan.angles_rad)) <= FRONT_DEG
    values = np.asarray(scan.values)[front]
    assert values.size > 100
    assert np.all((values >= 20) & (values <= 5600))
