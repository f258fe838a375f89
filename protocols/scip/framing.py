"""Host → device framing: commands end with LF, CR or CRLF (spec p.9).

Whatever the client sends, the buffer never holds more than `max_line`
bytes: a longer line is kept truncated and flagged, so the device can refuse
it with a status instead of growing without bound.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

MAX_LINE_BYTES = 64  # the longest valid command with a 16-char tag is 32 bytes

_TERMINATOR = re.compile(rb"[\r\n]")


@dataclass(frozen=True)
class Line:
    """One command line without its terminator; `overlong` if cut at the bound."""

    text: bytes
    overlong: bool = False


class LineSplitter:
    """Cuts a byte stream into non-empty lines; empty lines are ignored (a bare
    LF is how urg_library drains the device)."""

    def __init__(self, max_line: int = MAX_LINE_BYTES) -> None:
        self._max_line = max_line
        self._pending = b""
        self._overlong = False

    def feed(self, data: bytes) -> list[Line]:
        """The lines completed by `data`, in order."""
        pieces = _TERMINATOR.split(data)
        lines = []
        for piece in pieces[:-1]:
            self._keep(piece)
            if self._pending or self._overlong:
                lines.append(Line(self._pending, self._overlong))
            self._pending, self._overlong = b"", False
        self._keep(pieces[-1])
        return lines

    def reset(self) -> None:
        """Forget a partial line (the client went away)."""
        self._pending, self._overlong = b"", False

    def _keep(self, piece: bytes) -> None:
        room = self._max_line - len(self._pending)
        if len(piece) > room:
            self._overlong = True
        self._pending += piece[: max(room, 0)]
