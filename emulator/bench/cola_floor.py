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

import asyncio
import socket
import struct
import sys
import time

import numpy as np

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


class FloorStream:
    """One stream: a listening socket; once a client is there, a telegram every period."""

    def __init__(self, name: str, period_ms: float, phase_ms: float, beams: int, start: float, timer: PreciseTimer) -> None:
        self.name, self.period_s, self.phase_s, self.start = name, period_ms / 1000, phase_ms / 1000, start
        self.payload = telegram_payload(beams, period_ms)
        self.timer = timer
        self.listener = socket.create_server(("127.0.0.1", 0))
        self.listener.setblocking(False)
        self.client: socket.socket | None = None
        self.index = 0

    async def serve(self) -> None:
        loop = asyncio.get_running_loop()
        client, _ = await loop.sock_accept(self.listener)
        client.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self.client = client
        self.index = int((time.monotonic() - self.start - self.phase_s) / self.period_s) + 1
        self._schedule()

    def _schedule(self) -> None:
        self.timer.call_at(self.start + self.phase_s + self.index * self.period_s, self._send)

    def _send(self) -> None:
        due_us = int(round((self.phase_s + self.index * self.period_s) * 1e6))
        COUNTERS.pack_into(self.payload, COUNTERS_AT, self.index & 0xFFFF, self.index & 0xFFFF)
        TIMES.pack_into(self.payload, TIMES_AT, due_us & 0xFFFF_FFFF, due_us & 0xFFFF_FFFF)
        try:
            self.client.send(frame(bytes(self.payload), Dialect.BINARY))  # type: ignore[union-attr]
        except OSError:
            return  # the client left: this stream is done
        self.index += 1
        self._schedule()


async def serve(specs: list[str]) -> None:
    loop = asyncio.get_running_loop()
    timer = PreciseTimer(loop)
    start = time.monotonic()
    streams = []
    for spec in specs:
        name, period_ms, phase_ms, beams = spec.split(":")
        streams.append(FloorStream(name, float(period_ms), float(phase_ms), int(beams), start, timer))
    for stream in streams:
        print(f"ready {stream.name} {stream.listener.getsockname()[1]}", flush=True)
    await asyncio.gather(*(stream.serve() for stream in streams))
    await asyncio.Event().wait()  # until the bench terminates this process


if __name__ == "__main__":
    try:
        asyncio.run(serve(sys.argv[1:]))
    except KeyboardInterrupt:
        pass
