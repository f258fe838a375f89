"""The floor under `bench --section cola`: bare CoLa-B senders with nothing else on their loop.

`python -m emulator.bench.cola_floor NAME:PERIOD_MS:PHASE_MS:BEAMS ...` listens on
a free loopback port per stream, prints `ready NAME PORT` for each, and, once a
client connects, sends it a LMDscandata telegram of BEAMS 16-bit values at
PHASE_MS + k · PERIOD_MS (monotonic time since start), stamped like the
daemon's (scan counter k, transmission time the instant it was due, µs), on
one asyncio loop woken by the project's timerfd (`PreciseTimer`). Per telegram
it only patches the header's counters and times and recomputes the checksum,
so what its clients measure is what the machine (timer, scheduler, sockets,
the client itself) allows: the daemon's figures are read against it.
"""

from __future__ import annotations

import struct

import numpy as np

from emulator.bench.floor import FloorStream, main
from emulator.transport.timer import PreciseTimer
from protocols.cola.framing import Dialect, frame
from protocols.cola.scandata import Channel, ScanHeader, scandata_arguments

PREFIX = b"sSN LMDscandata "
COUNTERS = struct.Struct(">HH")  # telegram counter, scan counter: after version, device, serial, status
COUNTERS_AT = len(PREFIX) + 10
TIMES = struct.Struct(">II")  # time since power-up, time of transmission (µs)
TIMES_AT = COUNTERS_AT + 4


def telegram_payload(beams: int, period_ms: float) -> bytearray:
    """A LMDscandata payload of `beams` distances (the sizes the daemon sends), counters and times 0."""
    header = ScanHeader(12345678, 0, 0, 0, 0, 0, int(round(100_000 / period_ms)), 0, None, None, None)
    channel = Channel("DIST1", 1.0, -450000, 3333, np.full(beams, 4000, np.uint16), True)
    return bytearray(PREFIX + scandata_arguments(header, [channel], Dialect.BINARY))


class ColaFloorStream(FloorStream):
    """A LMDscandata telegram every period, its counters and times patched."""

    def __init__(self, fields: list[str], start: float, timer: PreciseTimer) -> None:
        name, period_ms, phase_ms, beams = fields
        super().__init__(name, float(period_ms), float(phase_ms), start, timer)
        self.payload = telegram_payload(int(beams), float(period_ms))

    def message(self, index: int) -> bytes:
        due_us = int(round((self.phase_s + index * self.period_s) * 1e6))
        COUNTERS.pack_into(self.payload, COUNTERS_AT, index & 0xFFFF, index & 0xFFFF)
        TIMES.pack_into(self.payload, TIMES_AT, due_us & 0xFFFF_FFFF, due_us & 0xFFFF_FFFF)
        return frame(bytes(self.payload), Dialect.BINARY)


if __name__ == "__main__":
    main(ColaFloorStream)
