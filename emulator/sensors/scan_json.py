"""A scan as the JSON of `lrf-emulator scan`, shared by the command and the control API.

The scan as its ROS driver publishes it (`published.py`): only the beams the
device measures, and the LaserScan fields (`angle_min` … `range_max`) beside
the wire values and metres. What a model reports besides ranges comes too:
`intensities` (per value), every echo (`echoes` on the wire, nearest first,
-1 past a beam's last; `echo_ranges_m`; `echo_intensities`), an LMS200's
`reflector` bits.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from emulator.scene.bodies import matrix_euler_deg, matrix_quaternion
from emulator.sensors import Scan, Sensor, beam_times_s, ranges_m
from emulator.sensors.published import laser_scan_fields, published

ANGLE_DECIMALS = 9  # the devices' angles are exact in far fewer digits; drop float noise
TIME_DECIMALS = 9  # beam instants: nanoseconds, far below the µs grid the world is evaluated on
POSE_DECIMALS = 12


def pose_json(sensor: Sensor, time_s: float) -> dict:
    """The sensor's world pose at `time_s`: position (m), roll/pitch/yaw (degrees), quaternion (x, y, z, w)."""
    position, rotation = sensor.mount.pose_at(time_s)
    return {
        "position": [round(float(v), POSE_DECIMALS) for v in position],
        "rotation_deg": [round(v, POSE_DECIMALS) for v in matrix_euler_deg(rotation)],
        "quaternion": [round(float(v), POSE_DECIMALS) for v in matrix_quaternion(rotation)],
    }


def scan_json(scan: Scan, sensor: Sensor | None = None, period_s: float | None = None) -> dict:
    """The scan's measured beams as JSON; with the `sensor` that took it, also its `pose` and the beams' `times_s`.
    `scan_time` is the sensor's configured period (`period_s` without a sensor; else the model's default)."""
    scan = published(scan)
    ranges = ranges_m(scan)
    extra = {} if sensor is None else {
        "pose": pose_json(sensor, scan.time_s),
        "times_s": np.round(beam_times_s(scan), TIME_DECIMALS).tolist(),
    }
    reported = {}
    if scan.intensities is not None:
        reported["intensities"] = scan.intensities.astype(int).tolist()
    if scan.echoes is not None:
        echo_ranges = np.where(scan.echoes >= 0, ranges_m(dataclasses.replace(scan, values=scan.echoes)), np.nan)
        reported["echoes"] = scan.echoes.astype(int).tolist()
        reported["echo_ranges_m"] = _metres(echo_ranges)
    if scan.echo_intensities is not None:
        reported["echo_intensities"] = scan.echo_intensities.astype(int).tolist()
    if scan.reflector is not None:
        reported["reflector"] = scan.reflector.astype(bool).tolist()
    return {
        "sensor": scan.sensor,
        "model": scan.model,
        "time_s": scan.time_s,
        "unit": scan.unit,
        "angles_deg": np.round(np.degrees(scan.angles_rad), ANGLE_DECIMALS).tolist(),
        "values": scan.values.astype(int).tolist(),
        "ranges_m": _metres(ranges),
        **reported,
        **laser_scan_fields(scan, sensor.configured_period_s if sensor is not None else period_s),
        **extra,
    }


def _metres(ranges: np.ndarray) -> list:
    """Metres as JSON numbers, NaN (an error code, no echo) as null: one numpy pass, not one per value."""
    return np.where(np.isnan(ranges), None, ranges).tolist()
