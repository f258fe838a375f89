"""The floor under the SCIP serve rows: bare SCIP senders with nothing else on their loop.

`python -m emulator.bench.scip_floor NAME:PERIOD_MS:PHASE_MS:STEPS:CHARS ...` listens on
a free loopback port per stream and prints `ready NAME PORT` for each. Once a
client connects and sends its streaming command (MD/ME…, one line), the
stream echoes it (status 00) and then sends a scan message of STEPS × CHARS
data characters (MD: 3 a step, ME: 6) at PHASE_MS + k · PERIOD_MS (monotonic
time since start), stamped like the daemon's (the scan's time, whole ms), on
one asyncio loop woken by the project's timerfd (`PreciseTimer`), as
`cola_floor` does for CoLa. Per message it only rewrites the time stamp line,
so what its clients measure is what the machine (timer, scheduler, sockets,
the client itself) allows: the daemon's SCIP figures are read against it.
"""

from __future__ import annotations

import asyncio
import socket

from emulator.bench.floor import FloorStream, main
from emulator.transport.timer import PreciseTimer
from protocols.scip.encoding import checksum, data_lines, encode_value
from protocols.scip.streaming import TIMER_MODULUS, checked_line

STAMP_LINE_BYTES = 6  # 4 characters, their sum, LF


def scan_message(echo: bytes, steps: int, chars: int, stamp_ms: int = 0) -> bytearray:
    """A SCIP 2.x scan message as the daemon frames it: echo, status 99, stamp line, data lines of
    `steps` × `chars` characters (values 0x30…, any: the client reads only the stamp), empty line."""
    status = b"99"
    head = echo + b"\n" + status + checksum(status) + b"\n"
    data = bytes(0x30 + (index % 64) for index in range(steps * chars))
    return bytearray(head + checked_line(encode_value(stamp_ms % TIMER_MODULUS, 4)) + data_lines(data) + b"\n")


class ScipFloorStream(FloorStream):
    """Once a client has sent its streaming command: the echo, then a scan message every period."""

    def __init__(self, fields: list[str], start: float, timer: PreciseTimer) -> None:
        name, period_ms, phase_ms, steps, chars = fields
        super().__init__(name, float(period_ms), float(phase_ms), start, timer)
        self.steps, self.chars = int(steps), int(chars)
        self.scan = bytearray()
        self.stamp_at = 0

    async def answer(self, loop: asyncio.AbstractEventLoop, client: socket.socket) -> bool:
        command = b""
        while not command.endswith(b"\n"):
            data = await loop.sock_recv(client, 256)
            if not data:
                return False
            command += data
        echo = command.rstrip(b"\r\n")
        client.send(echo + b"\n00P\n\n")
        self.scan = scan_message(echo, self.steps, self.chars)
        self.stamp_at = self.scan.index(b"\n", len(echo) + 1) + 1
        return True

    def message(self, index: int) -> bytearray:
        stamp_ms = round((self.phase_s + index * self.period_s) * 1000)
        self.scan[self.stamp_at:self.stamp_at + STAMP_LINE_BYTES] = checked_line(encode_value(stamp_ms % TIMER_MODULUS, 4))
        return self.scan


if __name__ == "__main__":
    main(ScipFloorStream)
