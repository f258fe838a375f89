"""Device values ↔ metres in a LaserScan, by the conventions of ROS REP 117 and Foxglove.

A LaserScan carries only metres, so an error code becomes a non-finite range:

| device value | range |
|---|---|
| a distance | metres |
| "nothing within reach" (URG 0, LMS200 8191 no echo, 8183 above the mode's maximum) | +inf |
| "too close" (URG 19, closer than 20 mm) | -inf |
| any other error code (URG 1 low intensity, as in smoke; 2..18; LMS200 8184..8190) | NaN |

The way back (replaying a LaserScan through a device) maps +inf, and a
distance past the device's reach, to its "no echo"; -inf to "too close" (URG
19; an LMS200 has no such code and reports 0); NaN to the code smoke gives
(URG 1 low intensity; LMS200 8187 signal-to-noise too small). The exact codes
travel on the `/SENSOR/values` channel beside the scan.
"""

from __future__ import annotations

import numpy as np

from emulator.sensors import lms200, urg04lx

URG_CODES_AS_INF = (urg04lx.NO_ECHO,)
URG_CODES_AS_NEG_INF = (urg04lx.NON_MEASURABLE,)
LMS_CODES_AS_INF = (lms200.NO_ECHO, lms200.ABOVE_MAXIMUM)
LMS_FOR_NAN = 8187  # signal-to-noise too small
LMS_FOR_TOO_CLOSE = 0
LMS_MAX_DISTANCE = lms200.ABOVE_MAXIMUM - 1  # 8182 units


def values_to_ranges(values: np.ndarray, model: str, unit: str = "mm") -> np.ndarray:
    """Metres per device value; error codes as +inf, -inf or NaN (module docstring)."""
    values = np.asarray(values, dtype=np.int64)
    if model == urg04lx.MODEL:
        ranges = values / 1000.0
        is_code = values < urg04lx.MIN_VALUE_MM
        ranges[is_code] = np.nan
        ranges[np.isin(values, URG_CODES_AS_INF)] = np.inf
        ranges[np.isin(values, URG_CODES_AS_NEG_INF)] = -np.inf
        return ranges
    if model == lms200.MODEL:
        ranges = values / lms200.UNITS_PER_M[unit]
        ranges[values >= lms200.ABOVE_MAXIMUM] = np.nan
        ranges[np.isin(values, LMS_CODES_AS_INF)] = np.inf
        return ranges
    raise ValueError(f"unknown sensor model {model!r}")


def ranges_to_values(
    ranges_m: np.ndarray, model: str, unit: str = "mm", range_min_m: float = 0.0, range_max_m: float = np.inf
) -> np.ndarray:
    """Device values for ranges in metres (module docstring); `range_min_m`/`range_max_m`
    are the recording scanner's limits (ROS LaserScan): readings outside them are invalid."""
    ranges = np.asarray(ranges_m, dtype=float)
    with np.errstate(invalid="ignore"):
        too_far = (ranges == np.inf) | (np.isfinite(ranges) & (ranges > range_max_m))
        too_close = (ranges == -np.inf) | (np.isfinite(ranges) & (ranges < range_min_m))
    invalid = np.isnan(ranges)
    finite = np.where(np.isfinite(ranges), ranges, 0.0)
    if model == urg04lx.MODEL:
        values = np.round(finite * 1000.0).astype(np.int64)
        too_close |= values < urg04lx.MIN_VALUE_MM
        too_far |= values > round(urg04lx.MAX_RANGE_M * 1000)
        values[too_far] = urg04lx.NO_ECHO
        values[too_close & ~too_far] = urg04lx.NON_MEASURABLE
        values[invalid] = urg04lx.LOW_INTENSITY
        return values
    if model == lms200.MODEL:
        values = np.round(finite * lms200.UNITS_PER_M[unit]).astype(np.int64)
        values[values > LMS_MAX_DISTANCE] = lms200.ABOVE_MAXIMUM
        values[too_far] = lms200.NO_ECHO
        values[too_close & ~too_far] = LMS_FOR_TOO_CLOSE
        values[invalid] = LMS_FOR_NAN
        return values
    raise ValueError(f"unknown sensor model {model!r}")
