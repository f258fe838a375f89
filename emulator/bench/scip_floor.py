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
import sys
import time

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


class FloorStream:
    """One stream: a listening socket; once a client has asked, a scan message every period."""

    def __init__(self, name: str, period_ms: float, phase_ms: float, steps: int, chars: int, start: float,
                 timer: PreciseTimer) -> None:
        self.name, self.period_s, self.phase_s, self.start = name, period_ms / 1000, phase_ms / 1000, start
        self.steps, self.chars = steps, chars
        self.timer = timer
        self.listener = socket.create_server(("127.0.0.1", 0))
        self.listener.setblocking(False)
        self.client: socket.socket | None = None
        self.message = bytearray()
        self.stamp_at = 0
        self.index = 0

    async def serve(self) -> None:
        loop = asyncio.get_running_loop()
        client, _ = await loop.sock_accept(self.listener)
        client.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        command = b""
        while not command.endswith(b"\n"):
            data = await loop.sock_recv(client, 256)
            if not data:
                return
            command += data
        echo = command.rstrip(b"\r\n")
        client.send(echo + b"\n00P\n\n")
        self.message = scan_message(echo, self.steps, self.chars)
        self.stamp_at = self.message.index(b"\n", len(echo) + 1) + 1
        self.client = client
        self.index = int((time.monotonic() - self.start - self.phase_s) / self.period_s) + 1
        self._schedule()

    def _schedule(self) -> None:
        self.timer.call_at(self.start + self.phase_s + self.index * self.period_s, self._send)

    def _send(self) -> None:
        stamp_ms = round((self.phase_s + self.index * self.period_s) * 1000)
        self.message[self.stamp_at:self.stamp_at + STAMP_LINE_BYTES] = checked_line(encode_value(stamp_ms % TIMER_MODULUS, 4))
        try:
            self.client.send(self.message)  # type: ignore[union-attr]
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
        name, period_ms, phase_ms, steps, chars = spec.split(":")
        streams.append(FloorStream(name, float(period_ms), float(phase_ms), int(steps), int(chars), start, timer))
    for stream in streams:
        print(f"ready {stream.name} {stream.listener.getsockname()[1]}", flush=True)
    await asyncio.gather(*(stream.serve() for stream in streams))
    await asyncio.Event().wait()  # until the bench terminates this process


if __name__ == "__main__":
    try:
        asyncio.run(serve(sys.argv[1:]))
    except KeyboardInterrupt:
        pass
