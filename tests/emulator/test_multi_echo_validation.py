"""The multi-echo validation (docs/validation.md): a smoke slab in front of a wall, and puffs crossing
the beams. The crossovers computed from the parameters and those measured on the model agree within 5 %."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from emulator.sensors.physical.params import PULSED_RECEIVERS
from emulator.validation.multi_echo_targets import (
    GEOMETRIES,
    log_slope,
    measured_crossovers,
    plume_crossing,
    predicted_crossovers,
    sweep,
)

CASES = [("utm-30lx-ew", False), ("lms511", False), ("lms511", True)]


@pytest.mark.parametrize(("model", "fog_filter"), CASES)
def test_the_crossovers_measured_on_the_model_are_those_computed_from_the_parameters(model, fog_filter):
    receiver, geometry = PULSED_RECEIVERS[model], GEOMETRIES[model]
    predicted = predicted_crossovers(receiver, geometry, fog_filter)
    measured = measured_crossovers(receiver, geometry, fog_filter)
    assert measured.first_on_slab == pytest.approx(predicted.first_on_slab, rel=0.05)
    assert measured.last_loses_wall == pytest.approx(predicted.last_loses_wall, rel=0.05)
    assert measured.first_on_slab < measured.last_loses_wall  # a band where both the slab and the wall are reported


def test_the_crossovers_fail_the_five_percent_when_a_parameter_is_off():
    """The comparison can fail: a receiver whose separation is 20 % longer than the one predicted for."""
    receiver, geometry = PULSED_RECEIVERS["utm-30lx-ew"], GEOMETRIES["utm-30lx-ew"]
    predicted = predicted_crossovers(receiver, geometry)
    longer = measured_crossovers(dataclasses.replace(receiver, separation_m=receiver.separation_m * 1.2), geometry)
    assert abs(longer.first_on_slab / predicted.first_on_slab - 1.0) > 0.05


def test_the_fog_filter_moves_the_first_crossover_by_its_gain_and_leaves_the_far_wall_alone():
    receiver, geometry = PULSED_RECEIVERS["lms511"], GEOMETRIES["lms511"]
    off, on = measured_crossovers(receiver, geometry, False), measured_crossovers(receiver, geometry, True)
    assert on.first_on_slab > 2.0 * off.first_on_slab
    assert on.last_loses_wall == off.last_loses_wall  # the wall lies beyond the filter's 16 m


@pytest.mark.parametrize("model", ["utm-30lx-ew", "lms511"])
def test_the_last_echo_intensity_falls_as_the_two_way_loss_while_the_wall_is_seen(model):
    receiver, geometry = PULSED_RECEIVERS[model], GEOMETRIES[model]
    wall_lost = predicted_crossovers(receiver, geometry).last_loses_wall
    result = sweep(receiver, geometry, np.linspace(0.0, 0.95 * wall_lost, 25))
    np.testing.assert_allclose(result.last_m, geometry.wall_m, atol=1e-6)
    assert log_slope(result, wall_lost) == pytest.approx(-2.0 * geometry.path_m, rel=0.05)


def test_first_echo_on_the_slab_and_last_on_the_wall_between_the_crossovers():
    receiver, geometry = PULSED_RECEIVERS["utm-30lx-ew"], GEOMETRIES["utm-30lx-ew"]
    predicted = predicted_crossovers(receiver, geometry)
    result = sweep(receiver, geometry, np.array([0.5 * predicted.first_on_slab, 0.5 * (predicted.first_on_slab + predicted.last_loses_wall),
                                                  1.5 * predicted.last_loses_wall]))
    assert result.first_m[0] == pytest.approx(geometry.wall_m)  # thin smoke: the wall only
    assert geometry.near_m <= result.first_m[1] < geometry.far_m and result.last_m[1] == pytest.approx(geometry.wall_m)
    assert geometry.near_m <= result.first_m[2] < geometry.far_m and result.last_m[2] == result.first_m[2]  # the wall is gone


def test_puffs_crossing_the_beams_give_the_first_echo_on_a_puff_and_the_last_on_the_wall():
    crossing = plume_crossing(times_s=np.arange(4.0, 10.0, 0.5))
    assert crossing.beams_in_smoke > 200
    assert crossing.puff_then_wall > 0.9


def test_the_lms511_fog_filter_hides_part_of_the_puffs_and_keeps_the_wall_behind_them():
    lms, times = PULSED_RECEIVERS["lms511"], np.arange(4.0, 10.0, 0.5)
    off, on = plume_crossing(lms, times, fog_filter=False), plume_crossing(lms, times, fog_filter=True)
    assert 0 < on.beams_in_smoke < off.beams_in_smoke
    assert on.puff_then_wall > 0.9 and off.puff_then_wall > 0.9
