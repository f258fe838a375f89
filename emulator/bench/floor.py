"""Bare timed senders, the floor under the serve and CoLa rows: nothing on their loop but the sends.

Each stream listens on a free loopback port; once a client connects (and, for a
protocol that needs one, has asked), it sends a message at PHASE + k · PERIOD
(monotonic time since start) on one asyncio loop woken by the project's timerfd
(`PreciseTimer`). Subclasses say what a client is answered first and what
message k is; per message they only patch stamps, so what the clients measure
is what the machine (timer, scheduler, sockets, the client itself) allows.
"""

from __future__ import annotations

import asyncio
import socket
import sys
import time
from collections.abc import Callable

from emulator.transport.timer import PreciseTimer


class FloorStream:
    """One stream: a listening socket; once a client is there, a message every period."""

    def __init__(self, name: str, period_ms: float, phase_ms: float, start: float, timer: PreciseTimer) -> None:
        self.name, self.period_s, self.phase_s, self.start = name, period_ms / 1000, phase_ms / 1000, start
        self.timer = timer
        self.listener = socket.create_server(("127.0.0.1", 0))
        self.listener.setblocking(False)
        self.client: socket.socket | None = None
        self.index = 0

    async def answer(self, loop: asyncio.AbstractEventLoop, client: socket.socket) -> bool:
        """What a new client gets before the stream starts; False: it left."""
        return True

    def message(self, index: int) -> bytes | bytearray:
        """Message `index`, due at phase + index × period."""
        raise NotImplementedError

    async def serve(self) -> None:
        loop = asyncio.get_running_loop()
        client, _ = await loop.sock_accept(self.listener)
        client.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        if not await self.answer(loop, client):
            return
        self.client = client
        self.index = int((time.monotonic() - self.start - self.phase_s) / self.period_s) + 1
        self._schedule()

    def _schedule(self) -> None:
        self.timer.call_at(self.start + self.phase_s + self.index * self.period_s, self._send)

    def _send(self) -> None:
        try:
            self.client.send(self.message(self.index))  # type: ignore[union-attr]
        except OSError:
            return  # the client left: this stream is done
        self.index += 1
        self._schedule()


StreamFactory = Callable[[list[str], float, PreciseTimer], FloorStream]


async def serve(specs: list[str], make: StreamFactory) -> None:
    """One stream per `specs` entry (its ':'-separated fields go to `make`), until terminated."""
    timer = PreciseTimer(asyncio.get_running_loop())
    start = time.monotonic()
    streams = [make(spec.split(":"), start, timer) for spec in specs]
    for stream in streams:
        print(f"ready {stream.name} {stream.listener.getsockname()[1]}", flush=True)
    await asyncio.gather(*(stream.serve() for stream in streams))
    await asyncio.Event().wait()  # until the bench terminates this process


def main(make: StreamFactory) -> None:
    try:
        asyncio.run(serve(sys.argv[1:], make))
    except KeyboardInterrupt:
        pass
