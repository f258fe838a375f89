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

from emulator.sensors.published import publication


def values_to_ranges(values: np.ndarray, model: str, unit: str = "mm") -> np.ndarray:
    """Metres per device value; error codes as +inf, -inf or NaN (module docstring)."""
    entry = publication(model)
    values = np.asarray(values, dtype=np.int64)
    ranges = values / entry.units_per_m[unit]
    low, high = entry.distances
    ranges[(values < low) | (values > high)] = np.nan
    ranges[np.isin(values, entry.no_return)] = np.inf
    ranges[np.isin(values, entry.too_close)] = -np.inf
    return ranges


def ranges_to_values(
    ranges_m: np.ndarray, model: str, unit: str = "mm", range_min_m: float = 0.0, range_max_m: float = np.inf
) -> np.ndarray:
    """Device values for ranges in metres (module docstring); `range_min_m`/`range_max_m`
    are the recording scanner's limits (ROS LaserScan): readings outside them are invalid."""
    entry = publication(model)
    no_return, too_close_code, erroneous = entry.replay_codes
    low, high = entry.distances
    ranges = np.asarray(ranges_m, dtype=float)
    with np.errstate(invalid="ignore"):
        too_far = (ranges == np.inf) | (np.isfinite(ranges) & (ranges > range_max_m))
        too_close = (ranges == -np.inf) | (np.isfinite(ranges) & (ranges < range_min_m))
    invalid = np.isnan(ranges)
    finite = np.where(np.isfinite(ranges), ranges, 0.0)
    values = np.round(finite * entry.units_per_m[unit]).astype(np.int64)
    too_close |= values < low
    values[values > high] = entry.above_maximum
    values[too_far] = no_return
    values[too_close & ~too_far] = too_close_code
    values[invalid] = erroneous
    return values
