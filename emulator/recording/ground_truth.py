"""Ground truth beside a recording: the sensor's pose at each scan's time stamp as a TUM file.

TUM lines `t x y z qx qy qz qw` (seconds, metres, unit quaternion) are what SLAM
evaluation tools (evo, the TUM RGB-D scripts) read, and what a scene's
`trajectory = { file = ... }` accepts back.
"""

from __future__ import annotations

from typing import Iterable, Iterator, TextIO

import numpy as np

from emulator.scene.bodies import matrix_quaternion
from emulator.sensors import Sensor
from emulator.sensors.scan import Scan

TUM_HEADER = "# ground truth: sensor pose at each scan's time stamp; t x y z qx qy qz qw"


def tum_line(time_s: float, position: np.ndarray, rotation: np.ndarray) -> str:
    qx, qy, qz, qw = matrix_quaternion(rotation)
    x, y, z = (float(v) for v in position)
    return f"{time_s:.6f} {x:.9f} {y:.9f} {z:.9f} {qx:.9f} {qy:.9f} {qz:.9f} {qw:.9f}"


def with_ground_truth(scans: Iterable[Scan], sensor: Sensor, out: TextIO) -> Iterator[Scan]:
    """`scans` passed through, writing each one's sensor pose to `out` as it goes by."""
    out.write(TUM_HEADER + "\n")
    for scan in scans:
        position, rotation = sensor.mount.pose_at(scan.time_s)
        out.write(tum_line(scan.time_s, position, rotation) + "\n")
        yield scan
