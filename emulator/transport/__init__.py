"""Transports: move a device's bytes over a pty or TCP, paced at its line rate.

A transport knows the device only through `Session` (bytes in, "the client
went away", the device's current baud) and gets whole `Output`s back through
its endpoint's `send`. It never looks inside the bytes.
"""

from __future__ import annotations

from typing import Protocol


class Session(Protocol):
    """The device side of one endpoint, as a transport sees it."""

    def received(self, data: bytes) -> None:
        """Bytes the client sent."""

    def disconnected(self) -> None:
        """The client went away (pty closed, TCP connection ended)."""

    @property
    def baud(self) -> int | None:
        """The device's current line rate, None for an unpaced link."""
