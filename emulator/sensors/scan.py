"""`Scan`: one revolution's output, exactly what the device would put on the wire."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

TICKS_PER_S = 1_000_000


def simulated_instant(time_s: float) -> float:
    """The instant the world is evaluated at for a scan at `time_s`: whole microseconds.

    Times a device computes one way (scan index × period) and a scan cache
    another (last time + stride) differ in their last bits; on the µs grid they
    give the same, bit-identical scan. Decimal times with up to six places are
    unchanged.
    """
    return round(time_s * TICKS_PER_S) / TICKS_PER_S


@dataclass(frozen=True)
class Scan:
    """Raw device values of one scan.

    `values` are wire values (URG: mm or an error code < 20; LMS200: distance
    in `unit` or 8183–8191), one per entry of `angles_rad` (sensor frame:
    0 = straight ahead along +x, positive to the left). `time_s` is the
    simulated time of the scan's stamp: when it completed (URG-04LX, LMS200)
    or when its sweep began (the SCIP 2.2 Hokuyos stamp step 0); `timestamp_ms`
    its millisecond stamp (`emulator.sensors.beam_times_s` gives the instant
    each value was measured: the mirror sweeps the beams one after another).
    """

    sensor: str
    model: str
    time_s: float
    angles_rad: np.ndarray
    values: np.ndarray
    unit: str = "mm"
    reflector: np.ndarray | None = None  # LMS200: the echo came from a retro-reflector (bool per value)
    # Scanners that report them (docs/scene-format.md): the intensity of each entry of `values` (N,);
    # every echo's wire value (N, E), nearest first, -1 where a beam has fewer than E; their intensities.
    # A Hokuyo's first slot is always what ND sends for the step: its error code when nothing came back.
    intensities: np.ndarray | None = None
    echoes: np.ndarray | None = None
    echo_intensities: np.ndarray | None = None

    @property
    def timestamp_ms(self) -> int:
        return int(round(self.time_s * 1000.0))
