"""What every sans-I/O device offers a transport, and what it hands back.

A device is fed the bytes a client sent and the current simulated time, and
returns `Output`s: whole messages (a reply, a scan telegram) that a transport
writes atomically, paced at `baud` when that is set. A transport never looks
inside the bytes.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol


@dataclass(frozen=True)
class Output:
    """One whole message for the wire.

    `baud`: the line rate to pace it at (10 bits per byte), or None for an
    unpaced link (the URG-04LX's USB). `interrupt`: drop whatever earlier
    output has not gone out yet (a host command interrupts the LMS200's
    streaming). `droppable`: a streamed scan, which a transport whose client
    is not reading may drop whole; replies to commands are never dropped.
    `hang_up`: the unit drops the connection once the output before this one
    has gone (a reboot); a transport that cannot (a pty) keeps it.
    """

    data: bytes
    baud: int | None = None
    interrupt: bool = False
    droppable: bool = False
    hang_up: bool = False


class Device(Protocol):
    """A virtual sensor's protocol session: one per connected endpoint."""

    def receive(self, data: bytes, now: float) -> list[Output]:
        """Bytes from the client at simulated time `now` (seconds)."""

    def poll(self, now: float) -> list[Output]:
        """Advance to `now`: streamed output that has come due."""

    def next_deadline(self) -> float | None:
        """Simulated time at which `poll` has something to do, or None."""

    def connection_lost(self) -> None:
        """The client went away: stop streaming, reset the session."""

    @property
    def baud(self) -> int | None:
        """The device's current line rate; None where the link has none."""
