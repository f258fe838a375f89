"""`Scip22Device`: a UTM-30LX, UTM-30LX-EW, UST-10LX or UST-20LX speaking SCIP 2.2.

A sans-I/O state machine like `UrgDevice`: bytes and simulated time in, whole
messages out. What differs from the URG-04LX (docs/scip.md):

- commands are answered when they arrive (no 100 ms command cycle), one at a
  time: a command that arrives while a single scan's reply waits for its data
  runs once that reply has left (a pipelined MD's echo precedes its scans, a
  TM1 behind a GD reads the timer when the GD is done);
- the mirror turns in `period_ms` (25 ms); scan k's sweep starts at
  phase + k · period, and its time stamp is that instant (the SCIP 2.0
  specification: "a timer value at 0th step of every scan"). Its data leave
  when the mirror has swept the last requested step:
  start + period · end / ARES;
- GE/ME add each step's intensity (3 + 3 characters); HD/HE/ND/NE send up to
  three echoes per step, each further echo prefixed by '&'; a unit without
  multi-echo (UTM-30LX) answers them 0E, like every command it lacks;
- TM1 answers in any state (urg_stamped's urg_sim, written against real
  units); TM0 while streaming and BM/QT in time-adjust mode are refused 10.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from protocols.device import Output
from protocols.scip.encoding import cluster_choice, data_lines, encode_steps, encode_value
from protocols.scip.framing import Line, LineSplitter
from protocols.scip.profiles import PROFILES, ScipProfile
from protocols.scip.requests import SCAN_PARAMETER_CHARS, STREAM_PARAMETER_CHARS, ScanRequest, parse_scan_request
from protocols.scip.streaming import (
    EPSILON_S,
    MAX_TAG_CHARS,
    TAG_CHARS,
    StreamingDevice,
    checked_line,
    frame,
    milliseconds,
)

MAX_WAITING_COMMANDS = 32  # lines waiting behind a single scan's reply; further lines are lost (bounded under a flood)

SINGLE_SCAN = frozenset({b"GD", b"GS", b"GE", b"HD", b"HE"})
STREAMING = frozenset({b"MD", b"MS", b"ME", b"ND", b"NE"})
PARAMETER_CHARS = {
    **{code: 0 for code in (b"VV", b"PP", b"II", b"BM", b"QT", b"RS", b"RT", b"RB", b"%ST", b"%SL")},
    b"TM": 1, b"SS": 6,
    **{code: SCAN_PARAMETER_CHARS for code in SINGLE_SCAN},
    **{code: STREAM_PARAMETER_CHARS for code in STREAMING},
}
ADJUST_MODE_COMMANDS = frozenset({b"TM", b"RS", b"RT", b"RB", b"VV", b"PP", b"II", b"%ST"})
DEFAULT_BIT_RATE = 115200
REBOOT_CONFIRM_S = 1.0  # RB reboots when a second RB follows the first within a second
# After the second RB's 00 the unit "waits for 1 second, during this time the host system disconnects
# from the sensor", then stops all communication (the SCIP 2.2 specification, as hokuyolx quotes it):
# it drops the connection, its timer restarts from zero, and it boots with its power-on settings
# (urg_stamped's urg_sim, written against real units). Commands that arrive while it boots are
# answered once it is up.
REBOOT_DELAY_S = 1.0
BOOT_S = 1.0
# %ST: the state codes of the UST protocol (standby, time adjustment, single scan, multi scan, sleep)
STANDBY, TIME_ADJUSTMENT, SINGLE_SCAN_STATE, MULTI_SCAN_STATE, SLEEP = b"000", b"002", b"003", b"004", b"005"


class EchoScan(Protocol):
    """What the device needs of a scan: values per step 0..AMAX, optional intensities
    and echo lists (`emulator.sensors.scan.Scan`), and its time."""

    @property
    def values(self) -> np.ndarray: ...

    @property
    def intensities(self) -> np.ndarray | None: ...

    @property
    def echoes(self) -> np.ndarray | None: ...

    @property
    def echo_intensities(self) -> np.ndarray | None: ...

    @property
    def time_s(self) -> float: ...


ScanSource = Callable[[float], EchoScan]


@dataclass(frozen=True)
class _Format:
    """How a command's data are encoded: value width, with intensity, with every echo."""

    width: int
    intensity: bool
    echoes: bool


FORMATS = {
    b"GD": _Format(3, False, False), b"MD": _Format(3, False, False),
    b"GS": _Format(2, False, False), b"MS": _Format(2, False, False),
    b"GE": _Format(3, True, False), b"ME": _Format(3, True, False),
    b"HD": _Format(3, False, True), b"ND": _Format(3, False, True),
    b"HE": _Format(3, True, True), b"NE": _Format(3, True, True),
}  # fmt: skip


@dataclass(frozen=True)
class _Pending:
    """A reply held until `due` (a single scan's data leave when the mirror has swept them)."""

    due: float
    scan_time: float
    build: Callable[[], bytes]


class Scip22Device(StreamingDevice):
    """One endpoint's virtual SCIP 2.2 Hokuyo, across the clients that connect to it.

    `scan_source(t)` returns the scan whose sweep starts at t = phase + k · period
    (its stamp). `now` is simulated seconds; the timer reads (now − epoch) in ms
    mod 2^24, the epoch being `start_time` until RS/RT.
    """

    def __init__(
        self,
        scan_source: ScanSource,
        model: str,
        *,
        serial: str | None = None,
        start_time: float = 0.0,
        phase_ms: int = 0,
    ) -> None:
        if model not in PROFILES:
            raise ValueError(f"no SCIP 2.2 profile for {model!r} (known: {', '.join(PROFILES)})")
        self.profile: ScipProfile = PROFILES[model]
        if not 0 <= phase_ms < self.profile.period_ms:
            raise ValueError(f"phase_ms must be 0..{self.profile.period_ms - 1}, got {phase_ms}")
        self._scan_source = scan_source
        self._period_ms = self.profile.period_ms
        self._phase_ms = phase_ms
        self._serial = serial or self.profile.default_serial
        self._epoch_ms = milliseconds(start_time)
        self._lines = LineSplitter()
        self._pending: _Pending | None = None  # the single scan's reply under way: later commands wait
        self._waiting: deque[Line] = deque()
        self._last_single_scan = -1  # a GD reports a scan no earlier GD reported
        self.lost_commands = 0
        self._laser_on = False
        self._adjust_mode = False
        self._asleep = False
        self._stream = None
        self._reboot_asked: float | None = None  # when the first RB came
        self._reboot_at: float | None = None  # a confirmed RB: when the unit goes down
        self._booting_until = -math.inf  # the unit is down and booting until then
        self._bit_rate = DEFAULT_BIT_RATE  # a USB unit's SS setting: reported, never pacing the link

    # --- protocols.device.Device -------------------------------------------

    @property
    def baud(self) -> int | None:
        """None: USB and Ethernet are unpaced."""
        return None

    def receive(self, data: bytes, now: float) -> list[Output]:
        outputs = self.poll(now)
        booting = self.booting(now)
        for line in self._lines.feed(data):
            if self._pending is None and not booting:
                reply = self._reply(line, now)
                if isinstance(reply, _Pending):
                    self._pending = reply
                else:
                    outputs.append(Output(reply))
            elif len(self._waiting) < MAX_WAITING_COMMANDS:
                self._waiting.append(line)
            else:
                self.lost_commands += 1
        return outputs

    def poll(self, now: float) -> list[Output]:
        """Replies and streamed scans whose data have left by `now`, in time order; the commands
        that waited behind a reply run when it leaves, at its time (those that came while the unit
        booted, once it is up). A confirmed reboot hangs up once what was due before it has gone."""
        if self._reboot_at is not None and now >= self._reboot_at - EPSILON_S:
            before = self._poll_until(self._reboot_at)
            self._go_down(self._reboot_at)
            return before + [Output(b"", hang_up=True)] + self._poll_until(now)
        return self._poll_until(now)

    def _poll_until(self, now: float) -> list[Output]:
        outputs: list[tuple[float, int, Output]] = []
        if self._waiting and self._pending is None and not self.booting(now):
            self._run_waiting(self._booting_until, outputs)  # held while the unit booted
        while self._pending is not None and self._pending.due <= now + EPSILON_S:
            item, self._pending = self._pending, None
            outputs.append((item.due, len(outputs), Output(item.build())))
            self._run_waiting(item.due, outputs)
        outputs += [(due, len(outputs) + i, output) for i, (due, output) in enumerate(self._stream_until(now))]
        return [output for _, _, output in sorted(outputs, key=lambda entry: entry[:2])]

    def _run_waiting(self, at: float, outputs: list[tuple[float, int, Output]]) -> None:
        """Answer the commands that waited, at `at`, until one of them waits for its scan."""
        while self._waiting and self._pending is None:
            reply = self._reply(self._waiting.popleft(), at)
            if isinstance(reply, _Pending):
                self._pending = reply
            else:
                outputs.append((at, len(outputs), Output(reply)))

    def next_deadline(self) -> float | None:
        deadlines = [self._pending.due] if self._pending is not None else []
        if self._reboot_at is not None:
            deadlines.append(self._reboot_at)
        if self._waiting and self._pending is None:
            deadlines.append(self._booting_until)  # commands held while the unit boots
        if self._stream is not None:
            deadlines.append(self._departure(self._stream.next_index, self._stream.request))
        return min(deadlines, default=None)

    def next_scan_time(self) -> float | None:
        """The scan wanted at `next_deadline`: its sweep started earlier than its data leave."""
        candidates = [(self._pending.due, self._pending.scan_time)] if self._pending is not None else []
        if self._stream is not None:
            index = self._stream.next_index
            candidates.append((self._departure(index, self._stream.request), self._scan_time(index)))
        return min(candidates)[1] if candidates else None

    def scan_request(self) -> dict:
        """Nothing beyond the time: every step is measured; requests choose among them."""
        return {}

    def scan_stride_s(self) -> float | None:
        """The period of the stream running (None: none runs), so a daemon can batch it from its first scans."""
        stream = self._stream
        return None if stream is None else (stream.request.interval + 1) * self.profile.period_ms / 1000

    def booting(self, now: float) -> bool:
        """Whether the unit is booting after a reboot (commands wait until it is up)."""
        return now < self._booting_until - EPSILON_S

    def _go_down(self, at: float) -> None:
        """The confirmed reboot: communication stops, the timer restarts, and the unit boots with its
        power-on settings."""
        self._reboot_at = None
        self._booting_until = at + BOOT_S
        self.connection_lost()
        self._laser_on, self._asleep, self._last_single_scan = False, False, -1
        self._bit_rate = DEFAULT_BIT_RATE
        self._epoch_ms = milliseconds(at)

    def connection_lost(self) -> None:
        """Streaming stops and unanswered commands are forgotten; the unit keeps its timer."""
        self._lines.reset()
        self._pending = None
        self._waiting.clear()
        self._stream = None
        self._adjust_mode = False

    @property
    def laser_on(self) -> bool:
        return self._laser_on

    # --- timing ----------------------------------------------------------------

    def _departure(self, index: int, request: ScanRequest) -> float:
        """When the mirror has swept the request's last step of scan `index`."""
        sweep = self.profile.period_ms * request.end / self.profile.steps_per_turn / 1000
        return self._scan_time(index) + sweep

    def _first_scan_from(self, now: float) -> int:
        """The first scan whose sweep starts at or after `now`."""
        return math.ceil(((now * 1000) - self._phase_ms) / self.profile.period_ms - EPSILON_S)

    # --- dispatch ----------------------------------------------------------------

    def _reply(self, line: Line, now: float) -> bytes | _Pending:
        if line.overlong:
            return frame(line.text, b"0B")
        command, _, tag = line.text.partition(b";")
        length = 3 if command.startswith(b"%") else 2
        code, params = command[:length], command[length:]
        has_tag = b";" in line.text
        if code not in PARAMETER_CHARS or code not in self.profile.commands:
            return frame(line.text, b"0E")
        if has_tag and len(tag) > MAX_TAG_CHARS:
            return frame(line.text, b"0G")
        if has_tag and not TAG_CHARS.issuperset(tag):
            return frame(line.text, b"0H")
        expected = PARAMETER_CHARS[code]
        if len(params) < expected:
            return frame(line.text, b"0C")
        if len(params) > expected:
            return frame(line.text, b"0D")
        if self._adjust_mode and code not in ADJUST_MODE_COMMANDS:
            return frame(line.text, b"10")
        return self._execute(code, params, line.text, b";" + tag if has_tag else b"", now)

    def _execute(self, code: bytes, params: bytes, echo: bytes, tag_suffix: bytes, now: float) -> bytes | _Pending:
        if code == b"VV":
            return frame(echo, b"00", self.profile.version_body(self._serial))
        if code == b"PP":
            return frame(echo, b"00", self.profile.parameter_body())
        if code == b"II":
            body = self.profile.status_body(
                laser_on=self._laser_on, streaming=self._stream is not None, timer_ms=self._timer_ms(now)
            )
            return frame(echo, b"00", body)
        if code == b"BM":
            if self._laser_on:
                return frame(echo, b"02")
            self._laser_on, self._asleep = True, False
            return frame(echo, b"00")
        if code == b"%ST":
            return frame(echo, b"00", checked_line(self._state_code()))
        if code == b"%SL":
            self._stream, self._laser_on, self._asleep = None, False, True
            return frame(echo, b"00")
        if code == b"RB":
            if self._reboot_asked is None or now - self._reboot_asked > REBOOT_CONFIRM_S:
                self._reboot_asked = now
                return frame(echo, b"01")
            self._reboot_asked = None
            self._reboot_at = now + REBOOT_DELAY_S
            return frame(echo, b"00")
        if code == b"QT":
            self._stream, self._laser_on = None, False
            return frame(echo, b"00")
        if code in (b"RS", b"RT"):
            self._stream, self._laser_on, self._adjust_mode, self._asleep = None, False, False, False
            self._epoch_ms = milliseconds(now)
            return frame(echo, b"00")
        if code == b"TM":
            return self._time_adjust(params, echo, now)
        if code == b"SS":
            return frame(echo, self._set_bit_rate(params))
        if code in SINGLE_SCAN:
            return self._single_scan(code, params, echo, now)
        return self._start_stream(code, params, echo, tag_suffix, now)

    def _set_bit_rate(self, params: bytes) -> bytes:
        """SS: an Ethernet unit has no bit rate (0F, which urg_library takes as an Ethernet sensor's
        answer); a USB unit accepts the serial rates as the URG-04LX does, without pacing its link."""
        if self.profile.interface == "ethernet":
            return b"0F"
        return super()._set_bit_rate(params)

    def _state_code(self) -> bytes:
        if self._adjust_mode:
            return TIME_ADJUSTMENT
        if self._stream is not None:
            return MULTI_SCAN_STATE
        if self._laser_on:
            return SINGLE_SCAN_STATE
        return SLEEP if self._asleep else STANDBY

    def _time_adjust(self, params: bytes, echo: bytes, now: float) -> bytes:
        if params == b"0":
            if self._adjust_mode:
                return frame(echo, b"02")
            if self._stream is not None:
                return frame(echo, b"10")
            self._adjust_mode, self._laser_on, self._asleep = True, False, False
            return frame(echo, b"00")
        if params == b"1":
            return frame(echo, b"00", checked_line(encode_value(self._timer_ms(now), 4)))
        if params == b"2":
            if not self._adjust_mode:
                return frame(echo, b"03")
            self._adjust_mode = False
            return frame(echo, b"00")
        return frame(echo, b"01")

    def _request(self, params: bytes, *, streaming: bool) -> ScanRequest | bytes:
        request = parse_scan_request(params, streaming=streaming, max_step=self.profile.max_step)
        if isinstance(request, bytes):
            return request
        if request.start < self.profile.first_step:
            return b"01"
        return request

    def _single_scan(self, code: bytes, params: bytes, echo: bytes, now: float) -> bytes | _Pending:
        request = self._request(params, streaming=False)
        if isinstance(request, bytes):
            return frame(echo, request)
        if not self._laser_on:
            return frame(echo, b"10")
        index = max(self._first_scan_from(now), self._last_single_scan + 1)
        self._last_single_scan = index
        scan_time = self._scan_time(index)
        return _Pending(
            self._departure(index, request),
            scan_time,
            lambda: frame(echo, b"00", self._scan_body(self._scan_source(scan_time), request, code)),
        )

    def _start_stream(self, code: bytes, params: bytes, echo: bytes, tag_suffix: bytes, now: float) -> bytes:
        request = self._request(params, streaming=True)
        if isinstance(request, bytes):
            return frame(echo, request)
        self._asleep = False
        self._new_stream(code, params, tag_suffix, request, self._first_scan_from(now))
        return frame(echo, b"00")

    # --- streaming ------------------------------------------------------------------

    def _stream_until(self, now: float) -> list[tuple[float, Output]]:
        """(departure, message) of the streamed scans whose data have left by `now`."""
        stream = self._stream
        if stream is None or self._departure(stream.next_index, stream.request) > now + EPSILON_S:
            return []
        request = stream.request
        sweep = self._departure(0, request) - self._scan_time(0)
        return [
            (self._departure(index, request), Output(message, droppable=True))
            for index, message in self._stream_through(self._latest_index(now - sweep))
        ]

    def _stamp_ms(self, scan: EchoScan) -> int:
        return round(scan.time_s * 1000)

    def _encode_data(self, scan: EchoScan, request: ScanRequest, command: bytes) -> bytes:
        """Data lines of the requested steps; a cluster reports its nearest step."""
        fmt = FORMATS[command]
        steps = slice(request.start, request.end + 1)
        chosen: slice | np.ndarray = steps  # unclustered: the steps themselves, read without copying an index
        if request.cluster > 1:
            chosen = cluster_choice(np.asarray(scan.values)[steps], request.cluster) + request.start
        if fmt.echoes and scan.echoes is not None:
            ranges = np.asarray(scan.echoes)[chosen, : self.profile.max_echoes]
            source, shape = scan.echo_intensities, np.shape(scan.echoes)
        else:
            ranges = np.asarray(scan.values)[chosen]
            source, shape = scan.intensities, np.shape(scan.values)
        strengths = None
        if fmt.intensity:
            strengths = _intensity_of(source, shape)[chosen]
            strengths = strengths[:, : ranges.shape[1]] if ranges.ndim > 1 else strengths
        return data_lines(encode_steps(ranges, strengths, fmt.width))


def _intensity_of(intensities: np.ndarray | None, shape: tuple[int, ...]) -> np.ndarray:
    """A scan's intensities, or zeros where the scan carries none."""
    if intensities is None:
        return np.zeros(shape, dtype=np.int64)
    return np.asarray(intensities)
