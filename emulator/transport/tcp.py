"""TCP: the URG's Ethernet models on port 10940, or a serial-to-Ethernet converter.

One client at a time. A second connection while one is open is refused: it
is accepted and closed at once (the client sees end-of-stream), so a running
client is never hijacked. A client that has already closed but whose
end-of-stream is not yet read does not count (a restarting driver gets in),
nor does one idle for longer than `idle_timeout_s` (no byte either way: a
half-open peer, or a client that hung): the newcomer takes over. There is no termios: output is paced at each
Output's baud, and baud commands are followed by the device logically.
"""

from __future__ import annotations

import asyncio
import select
import socket

from emulator.errors import UserError
from emulator.scene.endpoints import TcpAddress
from emulator.transport import Session
from emulator.transport.link import READ_SIZE, ClientSlot, unsent_bytes
from emulator.transport.outbox import DEFAULT_LIMIT_BYTES

# The kernel's send buffer would otherwise autotune to megabytes of stale scans
# ahead of a slow client; keep it near a device's own buffering so the outbox
# drops old scans and the client sees fresh ones.
SEND_BUFFER_BYTES = 16 * 1024
# A connection with no byte either way for this long no longer locks others out:
# a streaming client is never idle, a driver between commands for 30 s is gone or hung.
IDLE_TIMEOUT_S = 30.0


class TcpEndpoint(ClientSlot):
    """Serves one session on a listening TCP socket."""

    def __init__(
        self,
        address: TcpAddress,
        session: Session,
        *,
        limit_bytes: int = DEFAULT_LIMIT_BYTES,
        idle_timeout_s: float = IDLE_TIMEOUT_S,
    ) -> None:
        super().__init__(session, limit_bytes=limit_bytes)
        self.address = address
        self.bound: TcpAddress | None = None
        self.refused = 0
        self.taken_over = 0  # idle clients replaced by a newcomer
        self.idle_timeout_s = idle_timeout_s
        self._listener: socket.socket | None = None
        self._client: socket.socket | None = None
        self._loop: asyncio.AbstractEventLoop | None = None

    def open(self, loop: asyncio.AbstractEventLoop) -> TcpAddress:
        """Bind and listen; returns the bound address (the real port when 0 was asked)."""
        self._loop = loop
        try:
            family, kind, proto, _, sockaddr = socket.getaddrinfo(
                self.address.host, self.address.port, type=socket.SOCK_STREAM
            )[0]
            listener = socket.socket(family, kind, proto)
        except OSError as error:
            raise UserError(f"{self.address}: {error.strerror or error}") from None
        try:
            listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            listener.bind(sockaddr)
            listener.listen(1)
        except OSError as error:
            listener.close()
            raise UserError(f"{self.address}: {error.strerror}") from None
        listener.setblocking(False)
        self._listener = listener
        self.bound = type(self.address)(self.address.host, listener.getsockname()[1])
        loop.add_reader(listener.fileno(), self._accept)
        return self.bound

    def close(self) -> None:
        self._drop_client()
        if self._listener is not None:
            self._loop.remove_reader(self._listener.fileno())
            self._listener.close()
            self._listener = None

    def _accept(self) -> None:
        try:
            client, _ = self._listener.accept()
        except (BlockingIOError, InterruptedError, ConnectionAbortedError):
            return
        if self.connected and self._client_still_there():
            if self.link is None or self.link.idle_for() < self.idle_timeout_s:
                self.refused += 1
                client.close()
                return
            self.taken_over += 1
            self._client_left()
        client.setblocking(False)
        client.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        client.setsockopt(socket.SOL_SOCKET, socket.SO_KEEPALIVE, 1)
        client.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, SEND_BUFFER_BYTES)
        self._client = client
        self._attach(client)

    def _attach(self, client: socket.socket) -> None:
        """Wire an accepted client to the session (RFC 2217 adds its telnet layer here)."""
        self._connect(
            self._loop,
            client.fileno(),
            read=lambda: client.recv(READ_SIZE),
            write=client.send,
            kernel_backlog=lambda: unsent_bytes(client.fileno()),
            on_lost=self._client_left,
            on_hang_up=self._client_left,
        )

    def _client_still_there(self) -> bool:
        """Whether the current client is alive; if its end-of-stream is waiting unread
        (a driver restarting reconnects at once), or it has closed its side with input still
        unread, it is retired here first."""
        try:
            alive = self._client.recv(1, socket.MSG_PEEK | socket.MSG_DONTWAIT) != b""
        except BlockingIOError:
            alive = True
        except OSError:
            alive = False
        if alive and _finished_sending(self._client):  # gone with input unread (still worked off at its share)
            alive = False
        if not alive:
            self._client_left()
        return alive

    def _client_left(self) -> None:
        self._drop_client()
        self._session.disconnected()

    def _drop_client(self) -> None:
        self._disconnect()
        if self._client is not None:
            self._client.close()
            self._client = None


def _finished_sending(client: socket.socket) -> bool:
    """Whether the peer has closed its side (or reset) the connection, whatever input waits unread."""
    poller = select.poll()
    poller.register(client.fileno(), select.POLLRDHUP)
    return any(events & (select.POLLRDHUP | select.POLLHUP | select.POLLERR) for _, events in poller.poll(0))
