"""What every SCIP device shares: the message frame, the 24-bit timer, the mirror's
revolution grid and the MD/MS-style stream (counting scans sent or skipped).

`UrgDevice` (SCIP 2.0) and `Scip22Device` (SCIP 2.2) differ in when a scan is
measured and when its data leave, and in how a scan's body is encoded; both
subclass `StreamingDevice`, which holds the rest.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from protocols.scip.encoding import checksum, encode_value
from protocols.scip.requests import ScanRequest

TIMER_MODULUS = 1 << 24  # the 24-bit millisecond timer
MAX_TAG_CHARS = 16
TAG_CHARS = frozenset(b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789 ._+@")
BIT_RATES = frozenset({19200, 38400, 57600, 115200, 250000, 500000, 750000})
# A poll that comes late (its host was behind) streams only the newest scan: skipped
# revolutions, never a burst.
MAX_BACKLOG_SCANS = 1
EPSILON_S = 1e-9


@dataclass
class Stream:
    """A streaming command (MD/MS, and SCIP 2.2's ME/ND/NE) in progress."""

    command: bytes
    request: ScanRequest
    echo_prefix: bytes  # the command and parameters as received, up to the count
    tag_suffix: bytes  # b"" or b";" + tag, echoed on every scan
    next_index: int  # scan index of the next message
    remaining: int | None  # None while unlimited


class StreamingDevice:
    """The revolution grid (scan k at phase + k · period, whole milliseconds), the timer
    and the stream. Subclasses set `_scan_source`, `_period_ms`, `_phase_ms`,
    `_epoch_ms`, `_stream`, `_laser_on`, `_bit_rate` and implement `_stamp_ms` and `_encode_data`."""

    _scan_source: Callable[[float], Any]
    _period_ms: int
    _phase_ms: int
    _epoch_ms: int
    _stream: Stream | None
    _laser_on: bool
    _bit_rate: int
    # The next streamed scan's data lines, encoded ahead (`prepare_next`): the scan's arrays, the request
    # and command they were encoded for, and the lines.
    _prepared: tuple[tuple, ScanRequest, bytes, bytes] | None = None

    def _stamp_ms(self, scan: Any) -> int:
        """The scan's time stamp in ms, as the model stamps it."""
        raise NotImplementedError

    def _encode_data(self, scan: Any, request: ScanRequest, command: bytes) -> bytes:
        """The data lines of `scan` as `command` sends `request`'s steps."""
        raise NotImplementedError

    def _scan_body(self, scan: Any, request: ScanRequest, command: bytes) -> bytes:
        """Stamp line and data lines of `scan` as `command` sends them (the lines encoded ahead if they
        were, for this very scan)."""
        data = self._prepared[3] if self._holds_prepared(scan, request, command) else self._encode_data(scan, request, command)
        return self._stamp_line(self._stamp_ms(scan)) + data

    def prepare_next(self, ready_scan: Callable[[float], Any | None]) -> None:
        """Encode the stream's next scan ahead, if `ready_scan(time)` has it computed already (None: not
        yet): its deadline then only stamps, frames and sends it. Nothing sent changes: the lines are
        reused only for the very scan (the same arrays) the deadline reads, with the same request."""
        stream = self._stream
        if stream is None:
            return
        scan = ready_scan(self._scan_time(stream.next_index))
        if scan is not None and not self._holds_prepared(scan, stream.request, stream.command):  # not twice (a reply between)
            self._prepared = (_arrays(scan), stream.request, stream.command, self._encode_data(scan, stream.request, stream.command))

    def _holds_prepared(self, scan: Any, request: ScanRequest, command: bytes) -> bool:
        """Whether the lines encoded ahead are this very scan's, for this request and command."""
        prepared = self._prepared
        return prepared is not None and prepared[1] == request and prepared[2] == command and _same_arrays(prepared[0], scan)

    def _set_bit_rate(self, params: bytes) -> bytes:
        """SS on a serial link: 01 not a number, 02 not a rate the unit has, 03 the rate it has already."""
        if not params.isdigit():
            return b"01"
        rate = int(params)
        if rate not in BIT_RATES:
            return b"02"
        if rate == self._bit_rate:
            return b"03"
        self._bit_rate = rate
        return b"00"

    # --- the revolution grid -------------------------------------------------------

    def _scan_time(self, index: int) -> float:
        """Scan `index`'s time on the grid (simulated s): a whole millisecond, so its stamp is exact."""
        return (index * self._period_ms + self._phase_ms) / 1000

    def _latest_index(self, now: float) -> int:
        """Index of the last grid point at or before `now`."""
        return math.floor((now * 1000 - self._phase_ms) / self._period_ms + EPSILON_S)

    def _scan_at(self, index: int) -> Any:
        return self._scan_source(self._scan_time(index))

    # --- the timer ----------------------------------------------------------------

    def _timer_ms(self, now: float) -> int:
        return (milliseconds(now) - self._epoch_ms) % TIMER_MODULUS

    def _stamp_line(self, stamp_ms: int) -> bytes:
        """A time stamp (ms since power-on) as the device's timer reads it: 4 characters and a sum."""
        return checked_line(encode_value((stamp_ms - self._epoch_ms) % TIMER_MODULUS, 4))

    # --- the stream -----------------------------------------------------------------

    def _new_stream(self, code: bytes, params: bytes, tag_suffix: bytes, request: ScanRequest, first: int) -> None:
        """Start streaming `request` from scan `first`; the laser goes on."""
        self._laser_on = True
        self._stream = Stream(
            command=code,
            request=request,
            echo_prefix=code + params[:-2],
            tag_suffix=tag_suffix,
            next_index=first,
            remaining=request.count or None,
        )

    def _stream_through(self, latest: int) -> list[tuple[int, bytes]]:
        """(index, message) of the stream's scans up to index `latest`; when more than
        MAX_BACKLOG_SCANS are due, the older ones are skipped."""
        stream = self._stream
        if stream is None or stream.next_index > latest:
            return []
        period = stream.request.interval + 1
        due = (latest - stream.next_index) // period + 1
        if stream.remaining is not None:
            due = min(due, stream.remaining)  # the last of N scans is the newest there will be
        self._skip(stream, max(due - MAX_BACKLOG_SCANS, 0))
        messages = []
        while self._stream is stream and stream.next_index <= latest:
            index = stream.next_index
            messages.append((index, self._stream_message(stream)))
        return messages

    def _stream_message(self, stream: Stream) -> bytes:
        """The next scan message; advances (and maybe ends) the stream."""
        scan = self._scan_at(stream.next_index)
        remaining = 0 if stream.remaining is None else stream.remaining - 1
        echo = stream.echo_prefix + b"%02d" % remaining + stream.tag_suffix
        message = frame(echo, b"99", self._scan_body(scan, stream.request, stream.command))
        self._skip(stream, 1)
        return message

    def _skip(self, stream: Stream, scans: int) -> None:
        """Count `scans` as sent; after the last of N, the laser goes off."""
        if scans == 0:
            return
        stream.next_index += scans * (stream.request.interval + 1)
        if stream.remaining is not None:
            stream.remaining -= scans
            if stream.remaining <= 0:
                self._stream, self._laser_on = None, False


SCAN_ARRAYS = ("values", "intensities", "echoes", "echo_intensities")


def _arrays(scan: Any) -> tuple:
    """What a scan's data lines are made of, held by identity."""
    return tuple(getattr(scan, name, None) for name in SCAN_ARRAYS)


def _same_arrays(arrays: tuple, scan: Any) -> bool:
    return all(held is getattr(scan, name, None) for held, name in zip(arrays, SCAN_ARRAYS))


def frame(echo: bytes, status: bytes, body: bytes = b"") -> bytes:
    """Echo, status with its sum, body lines, and the closing empty line."""
    return echo + b"\n" + status + checksum(status) + b"\n" + body + b"\n"


def checked_line(text: bytes) -> bytes:
    """One line: text, its sum, LF."""
    return text + checksum(text) + b"\n"


def milliseconds(seconds: float) -> int:
    """Whole milliseconds elapsed; the epsilon absorbs float noise (0.3 * 1000 = 299.99…)."""
    return math.floor(seconds * 1000 + 1e-6)
