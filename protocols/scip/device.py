"""`UrgDevice`: a Hokuyo URG-04LX speaking SCIP 2.0 (optionally booting in 1.1).

A sans-I/O state machine: bytes and simulated time in, whole messages out.
Facts: Hokuyo's SCIP 2.0 specification and a real unit's capture
(tests/protocols/data/urg04lx-real-session.txt); choices where they are silent: docs/scip.md.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from protocols.device import Output
from protocols.scip import scip1
from protocols.scip.encoding import cluster_minimum, data_lines, encode_value, encode_values
from protocols.scip.framing import Line, LineSplitter
from protocols.scip.identity import (
    DEFAULT_BIT_RATE,
    DEFAULT_SERIAL,
    LiveState,
    parameter_body,
    status_body,
    version_body,
)
from protocols.scip.requests import (
    SCAN_PARAMETER_CHARS,
    STREAM_PARAMETER_CHARS,
    ScanRequest,
    parse_scan_request,
)
from protocols.scip.streaming import (
    EPSILON_S,
    MAX_TAG_CHARS,
    TAG_CHARS,
    StreamingDevice,
    checked_line,
    frame,
    milliseconds,
)

SCANS_PER_SECOND = 10  # 600 rpm: scan k completes at k / 10 s
PERIOD_MS = 1000 // SCANS_PER_SECOND
MAX_SPEED_LEVEL = 10
DEFAULT_SPEED_CODE = 99  # CR99: back to the initial speed, like CR00
BOOT_PROTOCOLS = ("scip2", "scip1")
TIMINGS = ("real", "fast")
# The capture: a revolution's measurement starts ~6 ms after the cycle point at which
# the unit answers commands, so a GD that arrives just after a reply still gets the
# next revolution (back-to-back GDs: stamps 100 ms apart).
MEASUREMENT_START_S = 0.006
# Commands waiting for their cycle: a client that sends more without reading the
# replies overruns the unit's input buffer; further lines are lost (bounded memory and
# work under a flood).
MAX_QUEUED_COMMANDS = 32

# command → parameter characters before the optional ;tag
PARAMETER_CHARS = {
    b"BM": 0, b"QT": 0, b"RS": 0, b"VV": 0, b"PP": 0, b"II": 0,
    b"TM": 1, b"HS": 1, b"CR": 2, b"SS": 6,
    b"GD": SCAN_PARAMETER_CHARS, b"GS": SCAN_PARAMETER_CHARS,
    b"MD": STREAM_PARAMETER_CHARS, b"MS": STREAM_PARAMETER_CHARS,
}  # fmt: skip
VALUE_CHARS = {b"GD": 3, b"MD": 3, b"GS": 2, b"MS": 2}
ADJUST_MODE_COMMANDS = frozenset({b"TM", b"RS", b"VV", b"PP", b"II"})


class DeviceScan(Protocol):
    """What the device needs of a scan: 769 values (steps 0..768) and its time."""

    @property
    def values(self) -> np.ndarray: ...

    @property
    def timestamp_ms(self) -> int: ...


ScanSource = Callable[[float], DeviceScan]


@dataclass(frozen=True)
class _Command:
    """A line waiting for the command cycle that handles it."""

    due: float  # the cycle point (simulated s) at which it is handled
    line: Line
    received: float


@dataclass(frozen=True)
class _ScanReply:
    """A GD/GS reply waiting for the revolution it reports to complete."""

    due: float  # the scan's completion: k / 10 s
    build: Callable[[], bytes]


class UrgDevice(StreamingDevice):
    """One endpoint's virtual URG-04LX, across the clients that connect to it.

    `scan_source(t)` returns the scan completed at grid time t = phase + k / 10 s.
    `now` is simulated seconds; the device timer reads
    (now - epoch) in ms mod 2^24, the epoch being `start_time` until RS.
    `phase_ms` (0..99) shifts the mirror's revolutions: units that were not
    powered on together do not turn in step, and a daemon serving many of them
    then sends their scans spread over the period instead of all at once.

    `timing="real"` (default) answers as the real unit does: commands are handled
    at the cycle point of each 100 ms revolution (k / 10 s), so a reply is due
    0-100 ms after its command, and GD/GS report the first revolution measured
    after the command. `timing="fast"` handles each command when it arrives and
    answers GD/GS with the newest completed scan not already sent by a GD/GS
    (waiting for the next one only when it was). Replies not yet due are held
    by the device: `next_deadline()` says when to `poll`.
    """

    def __init__(
        self,
        scan_source: ScanSource,
        *,
        serial: str = DEFAULT_SERIAL,
        boot_protocol: str = "scip2",
        start_time: float = 0.0,
        timing: str = "real",
        phase_ms: int = 0,
    ) -> None:
        if boot_protocol not in BOOT_PROTOCOLS:
            raise ValueError(f"boot_protocol must be one of {BOOT_PROTOCOLS}, got {boot_protocol!r}")
        if timing not in TIMINGS:
            raise ValueError(f"timing must be one of {TIMINGS}, got {timing!r}")
        if not 0 <= phase_ms < PERIOD_MS:
            raise ValueError(f"phase_ms must be 0..{PERIOD_MS - 1}, got {phase_ms}")
        self._scan_source = scan_source
        self._period_ms = PERIOD_MS
        self._phase_ms = phase_ms
        self._phase_s = phase_ms / 1000
        self._serial = serial
        self._boot_protocol = boot_protocol
        self._fast = timing == "fast"
        self._epoch_ms = milliseconds(start_time)
        self._lines = LineSplitter()
        self._queue: deque[_Command | _ScanReply] = deque()
        self._handled_until = -math.inf  # replies leave in command order
        self._last_polled_scan = -1  # the newest scan a GD/GS has reported
        self.lost_commands = 0  # lines dropped because MAX_QUEUED_COMMANDS were waiting
        self._power_on_settings()

    # --- protocols.device.Device -------------------------------------------

    @property
    def baud(self) -> int | None:
        """None: the URG-04LX's USB link is unpaced (SS is only reported)."""
        return None

    def receive(self, data: bytes, now: float) -> list[Output]:
        """Queue each complete line for its command cycle; whatever is due by `now`."""
        due = now if self._fast else _next_cycle_point(now - self._phase_s) + self._phase_s
        for line in self._lines.feed(data):
            if len(self._queue) < MAX_QUEUED_COMMANDS:
                self._queue.append(_Command(due, line, now))
            else:
                self.lost_commands += 1
        return self.poll(now)

    def poll(self, now: float) -> list[Output]:
        """Streamed scans and replies that have come due by `now`, in time order.
        With real timing a command handled at a cycle point goes before the scan
        completed there, so a QT there ends the stream without one more scan after
        its reply; a fast command goes after the scans already due when it arrives."""
        outputs = []
        while self._queue and self._queue[0].due <= now + EPSILON_S:
            item = self._queue.popleft()
            at = max(item.due, self._handled_until)
            self._handled_until = at
            outputs += self._stream_until(at, before=not self._fast)
            if isinstance(item, _ScanReply):
                outputs.append(Output(item.build()))
                continue
            reply = self._reply(item.line, at, item.received)
            if isinstance(reply, _ScanReply):
                self._queue.appendleft(reply)  # later commands wait behind it
            else:
                outputs.append(Output(reply))
        return outputs + self._stream_until(now)

    def next_deadline(self) -> float | None:
        deadlines = [self._queue[0].due] if self._queue else []
        if self._stream is not None:
            deadlines.append(self._scan_time(self._stream.next_index))
        return min(deadlines, default=None)


    def scan_request(self) -> dict:
        """What the scan source is asked for besides a scan's time: nothing (a URG measures every step;
        requests choose among them), so a daemon can compute a client's very first scan ahead."""
        return {}

    def scan_stride_s(self) -> float | None:
        """The period of the MD/MS stream running (None: none runs), so a daemon can batch it from its first scans."""
        stream = self._stream
        return None if stream is None else (stream.request.interval + 1) / SCANS_PER_SECOND

    def latest_scan_time(self, now: float) -> float | None:
        """With fast timing, the scan a GD/GS received at `now` reads at once: a daemon
        computes it before handing the bytes over, so that answering never waits on a
        computation (with real timing a GD waits for a later scan, a deadline of its own)."""
        return self._scan_time(self._latest_index(now)) if self._fast else None

    def connection_lost(self) -> None:
        """Streaming stops and unanswered commands are forgotten; the unit keeps
        its settings (SCIP mode, laser, speed, bit rate, timer) as a real one does
        while powered: closing a port does not reboot it."""
        self._lines.reset()
        self._queue.clear()
        self._stream = None
        self._adjust_mode = False

    # --- state read by the daemon ---------------------------------------------

    @property
    def laser_on(self) -> bool:
        return self._laser_on

    @property
    def high_sensitivity(self) -> bool:
        """HS1 in force (the sensor model may use it)."""
        return self._high_sensitivity

    # --- state ----------------------------------------------------------------

    def _power_on_settings(self) -> None:
        self._protocol = self._boot_protocol
        self._laser_on = False
        self._adjust_mode = False
        self._stream = None
        self._speed_level = 0
        self._bit_rate = DEFAULT_BIT_RATE
        self._high_sensitivity = False

    def _stream_until(self, now: float, *, before: bool = False) -> list[Output]:
        """Streamed MD/MS scans that have come due by `now` (`before`: strictly before)."""
        stream = self._stream
        if stream is None:
            return []
        latest = self._latest_index(now) - (before and _on_grid(now - self._phase_s))
        return [Output(message, droppable=True) for _, message in self._stream_through(latest)]

    # --- dispatch ---------------------------------------------------------------

    def _reply(self, line: Line, now: float, received: float) -> bytes | _ScanReply:
        if self._protocol == "scip1":
            return self._scip1_reply(line, now)
        if line.overlong:
            return frame(line.text, b"0B")
        command, _, tag = line.text.partition(b";")
        code, params = command[:2], command[2:]
        has_tag = b";" in line.text
        if code not in PARAMETER_CHARS:
            return frame(line.text, b"0E")
        if has_tag and len(tag) > MAX_TAG_CHARS:
            return frame(line.text, b"0G")
        if has_tag and not TAG_CHARS.issuperset(tag):
            return frame(line.text, b"0H")
        if self._adjust_mode and code not in ADJUST_MODE_COMMANDS:
            return frame(line.text, b"0E")
        expected = PARAMETER_CHARS[code]
        if len(params) < expected:
            return frame(line.text, b"0C")
        if len(params) > expected:
            return frame(line.text, b"0D")
        return self._execute(code, params, line.text, b";" + tag if has_tag else b"", now, received)

    def _execute(
        self, code: bytes, params: bytes, echo: bytes, tag_suffix: bytes, now: float, received: float
    ) -> bytes | _ScanReply:
        if code == b"VV":
            return frame(echo, b"00", version_body(self._serial))
        if code == b"PP":
            return frame(echo, b"00", parameter_body())
        if code == b"II":
            state = LiveState(self._laser_on, self._speed_level, self._bit_rate, self._timer_ms(now))
            return frame(echo, b"00", status_body(state))
        if code == b"BM":
            if self._laser_on:
                return frame(echo, b"02")
            self._laser_on = True
            return frame(echo, b"00")
        if code == b"QT":
            self._stream, self._laser_on = None, False
            return frame(echo, b"00")
        if code == b"RS":
            self._power_on_settings()
            self._protocol = "scip2"  # drivers send RS right after SCIP2.0 and expect to stay in 2.0
            self._epoch_ms = milliseconds(now)
            return frame(echo, b"00")
        if code == b"TM":
            return self._time_adjust(params, echo, now)
        if code == b"SS":
            return frame(echo, self._set_bit_rate(params))
        if code == b"CR":
            return frame(echo, self._set_speed(params))
        if code == b"HS":
            return frame(echo, self._set_sensitivity(params))
        if code in (b"GD", b"GS"):
            return self._fresh_scan(code, params, echo, now, received)
        return self._start_stream(code, params, echo, tag_suffix, now)

    # --- commands ---------------------------------------------------------------

    def _time_adjust(self, params: bytes, echo: bytes, now: float) -> bytes:
        if params == b"0":
            if self._adjust_mode:
                return frame(echo, b"02")
            self._adjust_mode, self._laser_on, self._stream = True, False, None
            return frame(echo, b"00")
        if params == b"1":
            if not self._adjust_mode:
                return frame(echo, b"04")
            return frame(echo, b"00", checked_line(encode_value(self._timer_ms(now), 4)))
        if params == b"2":
            if not self._adjust_mode:
                return frame(echo, b"03")
            self._adjust_mode = False
            return frame(echo, b"00")
        return frame(echo, b"01")

    def _set_speed(self, params: bytes) -> bytes:
        if not params.isdigit():
            return b"01"
        code = int(params)
        if code > MAX_SPEED_LEVEL and code != DEFAULT_SPEED_CODE:
            return b"02"
        level = 0 if code == DEFAULT_SPEED_CODE else code
        if level == self._speed_level:
            return b"03"
        self._speed_level = level
        return b"00"

    def _set_sensitivity(self, params: bytes) -> bytes:
        if params not in (b"0", b"1"):
            return b"01"
        high = params == b"1"
        if high == self._high_sensitivity:
            return b"02"
        self._high_sensitivity = high
        return b"00"

    def _fresh_scan(
        self, code: bytes, params: bytes, echo: bytes, now: float, received: float
    ) -> bytes | _ScanReply:
        """GD/GS: a scan no GD/GS has reported and measured after the last RS; with
        real timing, the first revolution whose measurement starts after the command."""
        request = parse_scan_request(params, streaming=False)
        if isinstance(request, bytes):
            return frame(echo, request)
        if not self._laser_on:
            return frame(echo, b"10")
        if self._fast:
            index = self._latest_index(now)
        else:
            measured_from = received - self._phase_s - MEASUREMENT_START_S
            index = math.ceil(measured_from * SCANS_PER_SECOND - EPSILON_S) + 1
        first_after_reset = (self._epoch_ms - self._phase_ms) // PERIOD_MS + 1
        index = max(index, self._last_polled_scan + 1, first_after_reset)
        self._last_polled_scan = index

        def build() -> bytes:
            return frame(echo, b"00", self._scan_body(self._scan_at(index), request, code))

        due = self._scan_time(index)
        return build() if due <= now + EPSILON_S else _ScanReply(due, build)

    def _start_stream(self, code: bytes, params: bytes, echo: bytes, tag_suffix: bytes, now: float) -> bytes:
        request = parse_scan_request(params, streaming=True)
        if isinstance(request, bytes):
            return frame(echo, request)
        self._new_stream(code, params, tag_suffix, request, _first_scan_after(now - self._phase_s))
        return frame(echo, b"00")

    # --- scans ---------------------------------------------------------------------

    def _stamp_ms(self, scan: DeviceScan) -> int:
        return int(scan.timestamp_ms)

    def _encode_data(self, scan: DeviceScan, request: ScanRequest, command: bytes) -> bytes:
        values = cluster_minimum(np.asarray(scan.values)[request.start : request.end + 1], request.cluster)
        return data_lines(encode_values(values, VALUE_CHARS[command]))

    # --- SCIP 1.1 -----------------------------------------------------------------

    def _scip1_reply(self, line: Line, now: float) -> bytes:
        if line.overlong:
            return scip1.refusal(line.text)
        if line.text == scip1.SWITCH_COMMAND:
            self._protocol = "scip2"
            return scip1.SWITCH_REPLY
        return scip1.reply(
            line.text, lambda: np.asarray(self._scan_at(self._latest_index(now)).values), self._serial
        )


def _on_grid(now: float) -> bool:
    """Whether `now` is a scan completion k / 10 s."""
    return abs(now * SCANS_PER_SECOND - round(now * SCANS_PER_SECOND)) < 1e-6


def _next_cycle_point(now: float) -> float:
    """The first command cycle point at or after `now`: the unit handles commands
    once per revolution, at the scan grid k / 10 s."""
    return math.ceil(now * SCANS_PER_SECOND - EPSILON_S) / SCANS_PER_SECOND


def _first_scan_after(now: float) -> int:
    """Index of the first scan measured wholly after `now` (spec p.10: MD sends
    data "taken after the command was received"): it starts at or after now."""
    return math.ceil(now * SCANS_PER_SECOND - 1e-9) + 1
