"""Transports: move a device's bytes over a pty or TCP, paced at its line rate.

A transport knows the device only through `Session` (bytes in, "the client
went away", the device's current baud) and gets whole `Output`s back through
its endpoint's `send`. It never looks inside the bytes.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, Union

from emulator.errors import UserError


class Session(Protocol):
    """The device side of one endpoint, as a transport sees it."""

    def received(self, data: bytes) -> None:
        """Bytes the client sent."""

    def disconnected(self) -> None:
        """The client went away (pty closed, TCP connection ended)."""

    @property
    def baud(self) -> int | None:
        """The device's current line rate, None for an unpaced link."""


@dataclass(frozen=True)
class PtyAddress:
    """`pty:PATH`: a pty published under the symlink PATH (relative to the cwd)."""

    path: str

    def __str__(self) -> str:
        return f"pty:{self.path}"


@dataclass(frozen=True)
class TcpAddress:
    """`tcp:HOST:PORT`; port 0 lets the system choose (the ready line names it)."""

    host: str
    port: int

    def __str__(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"tcp:{host}:{self.port}"


Address = Union[PtyAddress, TcpAddress]


def parse_endpoint(uri: str) -> Address:
    """`pty:PATH` or `tcp:HOST:PORT` (IPv6 hosts in brackets); UserError otherwise."""
    scheme, sep, rest = uri.partition(":")
    if sep and scheme == "pty":
        if not rest:
            raise UserError(f"endpoint {uri!r}: pty needs a path (pty:PATH)")
        return PtyAddress(rest)
    if sep and scheme == "tcp":
        host, sep, port_text = rest.rpartition(":")
        host = host[1:-1] if host.startswith("[") and host.endswith("]") else host
        if not sep or not host or not port_text.isdigit() or not 0 <= int(port_text) <= 65535:
            raise UserError(f"endpoint {uri!r}: expected tcp:HOST:PORT with PORT 0..65535")
        return TcpAddress(host, int(port_text))
    raise UserError(f"endpoint {uri!r}: expected pty:PATH or tcp:HOST:PORT")
