"""Scans as the ROS drivers publish them: each model's measured range and LaserScan fields, in one table.

Every export (`scan` JSON, the control API's scans and `ctl watch`, `record`
in every format, Foxglove live and MCAP, the browser view) passes a scan
through `published(scan)`: it keeps only the beams the device measures (a
URG-04LX sends steps 0..768 but measures only 44..725; urg_node publishes just
those) and says, in `laser_scan_fields(scan)`, what a LaserScan of it carries
by that model's driver. The protocols keep every value the device sends.

A new model adds one `Publication` to `PUBLICATIONS`; nothing else branches on
the model. docs/ros.md cites the drivers' source for each figure.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Mapping

import numpy as np

from emulator.scene import sick_models
from emulator.scene.sick_models import FREQUENCY_TICKS_PER_HZ, SickModel
from emulator.sensors import lms200
from emulator.sensors.hokuyo_models import HOKUYO_MODELS, HokuyoModel
from emulator.sensors.scan import Scan

ANGLE_SLACK_RAD = 1e-6  # a beam on the range's edge is in it (angles computed two ways)


@dataclass(frozen=True)
class Publication:
    """How one model's scans are published.

    `measured_rad`: the sensor-frame angles the device measures (first, last beam);
    beams outside are dropped. `revolution_s`: one mirror turn; a scan at a resolution
    in `revolutions` interlaces that many turns (`scan_time`). `range_min_m`,
    `range_max_m` per unit: the driver's limits. Device values, read by REP 117:
    values in `distances` (inclusive) are distances in the scan's unit, `no_return`
    codes become +inf, `too_close` codes −inf, every other code NaN; the way back
    (replaying metres through the device) uses `replay_codes` (no return, too close,
    erroneous) and `above_maximum` for a distance past the largest value.
    """

    model: str
    driver: str
    measured_rad: tuple[float, float]
    revolution_s: float
    revolutions: Mapping[float, int]
    range_min_m: float
    range_max_m: Mapping[str, float]
    units_per_m: Mapping[str, float]
    distances: tuple[int, int]
    no_return: tuple[int, ...]
    too_close: tuple[int, ...]
    replay_codes: tuple[int, int, int]
    above_maximum: int


def _cola_publication(sick: SickModel) -> Publication:
    """A CoLa SICK measures its whole field; `values` are first-echo distance counts, 0 for none."""
    counts_per_m = 1000.0 / sick.distance_scale
    return Publication(
        model=sick.name,
        driver="sick_scan_xd",
        measured_rad=(math.radians(sick.start_deg - 90.0), math.radians(sick.stop_deg - 90.0)),
        revolution_s=FREQUENCY_TICKS_PER_HZ / sick.default[0],
        revolutions={},
        range_min_m=sick.min_range_m,
        range_max_m={"mm": sick.max_range_m},
        units_per_m={"mm": counts_per_m},
        distances=(1, int(math.ceil(sick.max_range_m * counts_per_m))),
        no_return=(0,),
        too_close=(),
        replay_codes=(0, 0, 0),
        above_maximum=0,
    )


def _hokuyo_publication(hokuyo: HokuyoModel) -> Publication:
    """A Hokuyo publishes its measured steps AMIN..AMAX, DMIN..DMAX in mm (urg_node reads both from PP)."""
    angles = hokuyo.step_angles_rad()
    return Publication(
        model=hokuyo.name,
        driver="urg_node (ROS 1 and ROS 2), urg_node2",
        measured_rad=(float(angles[hokuyo.first_valid_step]), float(angles[hokuyo.last_valid_step])),
        revolution_s=hokuyo.period_s,
        revolutions={},
        range_min_m=hokuyo.min_value_mm / 1000.0,
        range_max_m={"mm": hokuyo.max_range_m},
        units_per_m={"mm": 1000.0},
        distances=(hokuyo.min_value_mm, hokuyo.max_value_mm),
        no_return=(hokuyo.no_echo,),
        too_close=(hokuyo.non_measurable,),
        replay_codes=(hokuyo.no_echo, hokuyo.non_measurable, hokuyo.low_intensity),
        above_maximum=hokuyo.no_echo,
    )


PUBLICATIONS: dict[str, Publication] = {
    publication.model: publication
    for publication in (
        *(_hokuyo_publication(hokuyo) for hokuyo in HOKUYO_MODELS.values()),
        Publication(
            model=lms200.MODEL,
            driver="sicktoolbox_wrapper's sicklms (ROS 1)",
            measured_rad=(-math.pi / 2, math.pi / 2),  # any window of device angles 0°..180°
            revolution_s=lms200.PERIOD_S,
            revolutions=lms200.REVOLUTIONS_PER_SCAN,
            range_min_m=0.0,
            range_max_m={"mm": 8.1, "cm": 81.0},
            units_per_m=lms200.UNITS_PER_M,
            distances=(0, lms200.ABOVE_MAXIMUM - 1),
            no_return=(lms200.NO_ECHO, lms200.ABOVE_MAXIMUM),
            too_close=(),
            replay_codes=(lms200.NO_ECHO, 0, 8187),  # 8187: signal-to-noise too small, what smoke gives
            above_maximum=lms200.ABOVE_MAXIMUM,
        ),
        *(_cola_publication(sick) for sick in sick_models.MODELS.values()),
    )
}


def publication(model: str) -> Publication:
    try:
        return PUBLICATIONS[model]
    except KeyError:
        raise ValueError(f"unknown sensor model {model!r}") from None


def measured_mask(scan: Scan) -> np.ndarray:
    """Per beam of `scan`: whether the device measures it."""
    first, last = publication(scan.model).measured_rad
    angles = np.asarray(scan.angles_rad, dtype=float)
    return (angles >= first - ANGLE_SLACK_RAD) & (angles <= last + ANGLE_SLACK_RAD)


def published(scan: Scan) -> Scan:
    """`scan` with only the beams the device measures (every per-beam field cropped alike)."""
    keep = measured_mask(scan)
    if keep.all():
        return scan
    count = len(keep)
    cropped = {
        field.name: value[keep]
        for field in dataclasses.fields(scan)
        if isinstance(value := getattr(scan, field.name), np.ndarray) and value.ndim >= 1 and value.shape[0] == count
    }
    return dataclasses.replace(scan, **cropped)


def scan_time_s(scan: Scan, period_s: float | None = None) -> float:
    """The time one scan takes: `period_s` when the caller knows it (the sensor's configured period),
    else a mirror turn at the model's power-on rate, or the turns an interlaced resolution needs."""
    if period_s is not None:
        return float(period_s)
    entry = publication(scan.model)
    if not entry.revolutions or len(scan.angles_rad) < 2:
        return entry.revolution_s
    step_deg = round(float(np.degrees(np.min(np.diff(scan.angles_rad)))), 6)
    return entry.revolutions.get(step_deg, 1) * entry.revolution_s


def laser_scan_fields(scan: Scan, period_s: float | None = None) -> dict[str, float]:
    """The LaserScan fields besides the ranges, as the model's driver sets them for this (published) scan:
    angle_min/max the first and last beam, angle_increment their spacing, scan_time, time_increment
    (scan_time · angle_increment / 2π: the time the mirror takes to turn one increment in a revolution
    measuring the whole scan), range_min/range_max of the unit. `period_s`: as for `scan_time_s`."""
    entry = publication(scan.model)
    angles = np.asarray(scan.angles_rad, dtype=float)
    increment = float((angles[-1] - angles[0]) / (len(angles) - 1)) if len(angles) > 1 else 0.0
    scan_time = scan_time_s(scan, period_s)
    return {
        "angle_min": float(angles[0]),
        "angle_max": float(angles[-1]),
        "angle_increment": increment,
        "time_increment": scan_time * increment / (2.0 * math.pi),
        "scan_time": scan_time,
        "range_min": entry.range_min_m,
        "range_max": entry.range_max_m[scan.unit],
    }
