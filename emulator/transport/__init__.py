"""Transports: move a device's bytes over a pty or TCP, paced at its line rate.

A transport knows the device only through `Session` (bytes in, "the client
went away", the device's current baud) and gets whole `Output`s back through
its endpoint's `send`. It never looks inside the bytes.
"""

from __future__ import annotations

from typing import Callable, Protocol

# A device's answer to input it cannot take yet: called with what to run once it has taken it.
InputHold = Callable[[Callable[[], None]], None]


class Session(Protocol):
    """The device side of one endpoint, as a transport sees it."""

    def received(self, data: bytes) -> InputHold | None:
        """Bytes the client sent. None once they are dealt with; a hold when the device keeps them
        until it can answer (a request that reads a scan still being computed): the transport then
        gives it nothing more from that client until the hold calls back."""

    def disconnected(self) -> None:
        """The client went away (pty closed, TCP connection ended)."""

    @property
    def baud(self) -> int | None:
        """The device's current line rate, None for an unpaced link."""
