"""Scans as the ROS drivers publish them: each model's exports cover exactly what its device measures.

The URG-04LX's count and first angle come from the device's own `PP` answer
(AMIN, AMAX, AFRT, ARES); the LMS200's from the window the device sends for
each variant (`scan_request`). A scan's values stay on the wire unchanged.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from emulator.control.ctl import scan_line
from emulator.recording.laserscan import values_to_ranges
from emulator.scene import load_scene
from emulator.scene.loader import SENSOR_MODELS
from emulator.sensors import create_sensor, lms200, urg04lx
from emulator.sensors.hokuyo_models import HOKUYO_MODELS
from emulator.sensors.published import PUBLICATIONS, laser_scan_fields, published
from emulator.sensors.scan import Scan
from emulator.sensors.scan_json import scan_json
from protocols.lms2xx import Lms200Device
from protocols.scip import UrgDevice
from protocols.scip.scip22 import Scip22Device


def pp_parameters(model: str = urg04lx.MODEL) -> dict[str, int]:
    """AMIN, AMAX, AFRT, ARES as the emulated Hokuyo `model` answers `PP`."""
    device = UrgDevice(lambda t: None, timing="fast") if model == urg04lx.MODEL else Scip22Device(lambda t: None, model)
    [reply] = device.receive(b"PP\n", 1.0)
    fields = {}
    for line in reply.data.split(b"\n")[2:]:
        if b":" in line:
            key, value = line.split(b":", 1)
            fields[key.decode()] = value[:-2].decode()  # drop ";" and the checksum
    return {key: int(fields[key]) for key in ("AMIN", "AMAX", "AFRT", "ARES")}


def test_every_exported_urg_scan_is_the_steps_pp_names() -> None:
    pp = pp_parameters()
    assert (pp["AMIN"], pp["AMAX"]) == (44, 725)
    sensor = create_sensor(load_scene("bocas"), "urg")
    scan = sensor.scan(1.0)
    assert len(scan.values) == 769  # the protocol sends steps 0..768
    shown = published(scan)
    assert len(shown.values) == pp["AMAX"] - pp["AMIN"] + 1 == 682
    fields = laser_scan_fields(shown)
    step = 2 * math.pi / pp["ARES"]
    assert fields["angle_min"] == pytest.approx((pp["AMIN"] - pp["AFRT"]) * step, abs=1e-12)
    assert fields["angle_max"] == pytest.approx((pp["AMAX"] - pp["AFRT"]) * step, abs=1e-12)
    assert fields["angle_increment"] == pytest.approx(step, abs=1e-12)
    np.testing.assert_array_equal(shown.values, scan.values[pp["AMIN"]: pp["AMAX"] + 1])
    out = scan_json(scan, sensor)
    assert len(out["values"]) == len(out["times_s"]) == 682 and out["angle_min"] == fields["angle_min"]


@pytest.mark.parametrize("model", sorted(set(HOKUYO_MODELS) - {urg04lx.MODEL}))
def test_every_exported_scip22_scan_is_the_steps_pp_names(model: str) -> None:
    pp = pp_parameters(model)
    hokuyo = HOKUYO_MODELS[model]
    angles = hokuyo.step_angles_rad()
    scan = Scan("front", model, 1.0, angles, np.full(len(angles), 1000), "mm")
    shown = published(scan)
    assert len(shown.values) == pp["AMAX"] - pp["AMIN"] + 1
    step = 2 * math.pi / pp["ARES"]
    fields = laser_scan_fields(shown)
    assert fields["angle_min"] == pytest.approx((pp["AMIN"] - pp["AFRT"]) * step, abs=1e-12)
    assert fields["angle_max"] == pytest.approx((pp["AMAX"] - pp["AFRT"]) * step, abs=1e-12)


@pytest.mark.parametrize("angle, resolution", [(180, 1.0), (180, 0.5), (100, 1.0), (100, 0.5), (100, 0.25)])
def test_every_exported_lms_scan_is_the_window_the_device_sends(angle: int, resolution: float) -> None:
    window = Lms200Device(lambda *a, **k: None, angle_deg=angle, resolution_deg=resolution).scan_request()
    scene = load_scene("marulan")
    spec = dataclasses.replace(scene.sensor("lms"), options={"angle_deg": angle, "resolution_deg": resolution, "units": "cm"})
    scene = dataclasses.replace(scene, sensors=(spec,))
    scan = create_sensor(scene, "lms").configured_scan(0.4)
    shown = published(scan)
    assert len(shown.values) == window["count"]
    fields = laser_scan_fields(shown)
    assert fields["angle_min"] == pytest.approx(math.radians(window["start_deg"] - 90), abs=1e-9)
    assert fields["angle_max"] == pytest.approx(math.radians(angle / 2), abs=1e-9)
    assert fields["angle_increment"] == pytest.approx(math.radians(resolution), abs=1e-9)
    # sicklms: one mirror turn is 1/75 s; 0.5° and 0.25° interlace 2 and 4 turns; 81 m in cm
    assert fields["scan_time"] == pytest.approx(lms200.REVOLUTIONS_PER_SCAN[resolution] / 75)
    assert fields["time_increment"] == pytest.approx(fields["scan_time"] / (2 * math.pi) * math.radians(resolution))
    assert (fields["range_min"], fields["range_max"]) == (0.0, 81.0)


def test_urg_fields_are_urg_nodes() -> None:
    """urg_node: scan_time from the 600 rpm, time_increment one step's share of it, DMIN/DMAX as range limits."""
    fields = laser_scan_fields(published(create_sensor(load_scene("bocas"), "urg").scan(0.5)))
    assert fields["scan_time"] == 0.1
    assert fields["time_increment"] == pytest.approx(0.1 / 1024, rel=1e-12)
    assert (fields["range_min"], fields["range_max"]) == (0.02, 5.6)


@pytest.mark.parametrize("model, first_deg, last_deg", [("tim571", -135.0, 135.0), ("lms511", -95.0, 95.0)])
def test_a_cola_sick_publishes_its_whole_field(model: str, first_deg: float, last_deg: float) -> None:
    angles = np.radians(np.linspace(first_deg, last_deg, 11))
    values = np.array([0, 1000, 2000, 0, 5, 6, 7, 8, 9, 10, 11])
    scan = Scan("front", model, 1.0, angles, values, "mm")
    assert published(scan) is scan
    fields = laser_scan_fields(scan, period_s=0.04)
    assert (fields["angle_min"], fields["angle_max"]) == pytest.approx((math.radians(first_deg), math.radians(last_deg)))
    assert fields["scan_time"] == 0.04
    assert values_to_ranges(values, model)[0] == np.inf  # no echo: nothing within reach


def test_cropping_keeps_every_per_beam_field_aligned() -> None:
    angles = urg04lx.step_angles_rad()
    reflector = np.arange(769) % 2 == 0
    scan = Scan("urg", urg04lx.MODEL, 1.0, angles, np.arange(769), "mm", reflector)
    shown = published(scan)
    np.testing.assert_array_equal(shown.values, np.arange(44, 726))
    np.testing.assert_array_equal(shown.reflector, reflector[44:726])
    np.testing.assert_array_equal(shown.angles_rad, angles[44:726])


def test_rep_117_codes() -> None:
    """+inf nothing within reach, -inf too close, NaN any other error; distances in metres."""
    urg = values_to_ranges(np.array([0, 19, 1, 7, 20, 5600]), urg04lx.MODEL)
    assert urg[0] == np.inf and urg[1] == -np.inf and np.isnan(urg[2:4]).all() and urg[4:].tolist() == [0.02, 5.6]
    lms = values_to_ranges(np.array([8191, 8183, 8187, 8190, 0, 8182]), lms200.MODEL, "mm")
    assert lms[:2].tolist() == [np.inf, np.inf] and np.isnan(lms[2:4]).all() and lms[4:].tolist() == [0.0, 8.182]


def test_ctl_watch_counts_no_beam_it_never_measured() -> None:
    """A room the URG sees whole: the watch line counts no error (the 87 steps outside 44..725 are not beams)."""
    angles = urg04lx.step_angles_rad()
    values = np.where((np.arange(769) >= 44) & (np.arange(769) <= 725), 2000, 0)
    line = scan_line(scan_json(Scan("urg", urg04lx.MODEL, 1.0, angles, values, "mm")))
    assert "682 ranges, 0 errors" in line


def test_every_model_a_scene_may_hold_has_a_publication() -> None:
    assert set(SENSOR_MODELS) <= set(PUBLICATIONS)


def test_the_view_draws_no_beam_the_urg_never_measured() -> None:
    """The browser view's points and error marks come from the measured steps only (steps 0..43 and
    726..768 carry 0, which would otherwise be drawn as 'nothing within reach' all round the back)."""
    from emulator.scene.model import Pose
    from emulator.view.browser import scan_points

    angles = urg04lx.step_angles_rad()
    values = np.where((np.arange(769) >= 44) & (np.arange(769) <= 725), 1, 2000)  # measured: error 1; never measured: 2 m
    hits, _, marks = scan_points(Scan("urg", urg04lx.MODEL, 1.0, angles, values, "mm"), Pose())
    assert len(hits) == 0 and len(marks) == 682
