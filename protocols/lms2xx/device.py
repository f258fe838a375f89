"""`Lms200Device`: a sans-I/O SICK LMS200 speaking the LMS2xx telegram protocol.

Feed it host bytes with `receive`, advance it with `poll`; it answers with
whole `Output`s (ACK/NAK, reply telegrams, streamed scans) tagged with the
line rate they go out at. It keeps its own model of the serial line (10 bits
per byte at the current baud) so that continuous modes send no more scans
than the line carries, as the real unit does. docs/lms200.md explains the
choices made where the telegram listing is silent.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from enum import IntEnum
from typing import Protocol

import numpy as np

from protocols.device import Output
from protocols.lms2xx.config import Configuration
from protocols.lms2xx.framing import (
    ACK,
    DEFAULT_GAP_TOLERANCE_S,
    FRAME_OVERHEAD,
    HOST_ADDRESS,
    MAX_REPLY_BYTES,
    NAK,
    REPLY_ADDRESS_FLAG,
    CorruptTelegram,
    FrameEvent,
    TelegramReader,
    build_telegram,
)
from protocols.lms2xx.scanning import (
    TIME_EPSILON_S,
    Variant,
    completion_time,
    latest_complete,
    partial_scan_grid,
    transmit_seconds,
)
from protocols.lms2xx.measuring import MeasuringMode
from protocols.lms2xx.status import BAUD_CODES, DeviceStatus, status_block
from protocols.lms2xx.values import (
    Indices,
    mean_body,
    mean_of_scans,
    mean_subrange_body,
    scan_body,
    subrange_body,
)

STATUS_OK = 0x10  # no error, LMS type 6 (bits 3–4 = 10b): MRPT insists on it
POWER_ON_BAUD = 9600
RESET_BOOT_S = 1.0  # simulated boot after command 10 (a real unit takes up to 60 s)
DEFAULT_PASSWORD = b"SICK_LMS"
NOT_ACKNOWLEDGED = b"\x92"  # valid frame, invalid command or wrong mode (TL §7.3.4)
BAUD_SUBMODES = {0x40: 38400, 0x41: 19200, 0x42: 9600, 0x48: 500_000}
MEAN_SCANS_RANGE = range(2, 251)
DIRECT_SUBRANGE_BIT = 0x8000  # bit 15 of a sub-range's first value: one telegram per partial scan
MAX_REPLY_BODY = MAX_REPLY_BYTES - FRAME_OVERHEAD - 1  # CMD + DATA, leaving room for STATUS
PARTIAL_SCANS = 4
_REPLY_ADDRESS = HOST_ADDRESS | REPLY_ADDRESS_FLAG


class Mode(IntEnum):
    """Operating modes (sub-commands of 20h) the emulator implements."""

    INSTALLATION = 0x00
    STREAM_ALL = 0x24
    ON_REQUEST = 0x25
    STREAM_MEANS = 0x26
    STREAM_SUBRANGE = 0x27
    STREAM_MEAN_SUBRANGE = 0x28
    STREAM_PARTIAL = 0x2A


STREAMING_MODES = frozenset(
    {Mode.STREAM_ALL, Mode.STREAM_MEANS, Mode.STREAM_SUBRANGE, Mode.STREAM_MEAN_SUBRANGE, Mode.STREAM_PARTIAL}
)
MEAN_MODES = frozenset({Mode.STREAM_MEANS, Mode.STREAM_MEAN_SUBRANGE})


class ScanValues(Protocol):
    """`values`: distances in the unit, or error codes at the top of a `field_bits` field.
    `reflector` (optional, bool per beam): the echo came from a retro-reflector."""

    values: np.ndarray


class ScanSource(Protocol):
    """Device values of `count` beams at device angles start_deg + i·step_deg, at `time_s`,
    in a distance field `field_bits` wide (13: 8 m, 14: 16 m, 15: 32 m in mm)."""

    def __call__(
        self, time_s: float, *, start_deg: float, step_deg: float, count: int, unit: str, field_bits: int
    ) -> ScanValues: ...


@dataclass(frozen=True)
class _Measured:
    """One scan as the device measured it: distance-field values and reflector flags."""

    values: np.ndarray
    reflector: np.ndarray | None


@dataclass(frozen=True)
class _Reply:
    """Reply bodies (CMD + DATA) to a command, and the baud rate to switch to after them."""

    bodies: tuple[bytes, ...]
    next_baud: int | None = None


@dataclass
class _Stream:
    """A continuous mode's schedule: telegrams every `revolutions`, from scan `next_index` on."""

    revolutions: int
    next_index: int


@dataclass(frozen=True)
class _PendingReply:
    """A reply that waits for scans still to be measured (36, 3F)."""

    due: float
    body: Callable[[], bytes]


class Lms200Device:
    """One LMS200 session: implements `protocols.device.Device`."""

    def __init__(
        self,
        scan_source: ScanSource,
        *,
        baud: int = POWER_ON_BAUD,
        type_string: str = "LMS200;301063;V02.10 ",
        angle_deg: int = 180,
        resolution_deg: float = 0.5,
        units: str = "mm",
        firmware_profile: str = "v2.30",
        start_time: float = 0.0,
        gap_tolerance_s: float = DEFAULT_GAP_TOLERANCE_S,
    ) -> None:
        if baud not in BAUD_CODES:
            raise ValueError(f"baud must be one of {sorted(BAUD_CODES)}, got {baud}")
        variant = Variant.of(angle_deg, round(resolution_deg * 100))
        if variant is None:
            raise ValueError(f"the LMS200 offers no {angle_deg}°/{resolution_deg}° variant")
        self._scan_source = scan_source
        self._type = type_string.encode("ascii")
        self._variant = variant
        self._config = Configuration.delivery(firmware_profile, units)
        self._baud = baud
        self._permanent_baud = baud != POWER_ON_BAUD  # a unit that powers on faster must have 66 01 set
        self._mode = Mode.ON_REQUEST
        self._means = 2
        self._subrange = (1, variant.count)
        self._direct_subrange = False
        self._reader = TelegramReader(gap_tolerance_s)
        self._power_on_at: float | None = start_time
        self._line_free_at = start_time
        self._last_output_streamed = False
        self._stream: _Stream | None = None
        self._pending: _PendingReply | None = None
        self._window_todo: list[int] | None = None  # [next, last] scan index a mean still needs
        self._telegram_counter = 0
        self._scan_cache: dict[tuple[Variant, str, int, int], _Measured] = {}
        self._handlers: dict[int, Callable[[bytes, float], _Reply]] = {
            0x10: self._reset,
            0x20: self._switch_mode,
            0x30: self._request_values,
            0x31: self._request_status,
            0x32: self._request_errors,
            0x36: self._request_means,
            0x37: self._request_subrange,
            0x3A: self._request_type,
            0x3B: self._switch_variant,
            0x3F: self._request_mean_subrange,
            0x66: self._define_permanent_baud,
            0x74: self._request_config,
            0x77: self._configure,
        }

    # -- protocols.device.Device ------------------------------------------

    @property
    def baud(self) -> int:
        return self._baud

    @property
    def mode(self) -> Mode:
        return self._mode

    def receive(self, data: bytes, now: float) -> list[Output]:
        outputs = self._emit_power_on(now)
        if self._power_on_at is not None:
            return outputs  # not yet powered on, or booting after a reset: deaf
        for event in self._reader.feed(data, now):
            outputs += self._on_frame(event, now)
            if self._power_on_at is not None:
                break  # a reset: the rest of the input is lost
        return outputs

    def poll(self, now: float) -> list[Output]:
        outputs = self._emit_power_on(now)
        if self._power_on_at is not None:
            return outputs
        for event in self._reader.expire(now):
            outputs += self._on_frame(event, now)
        self._fetch_window_scans(now)
        if self._pending is not None and self._pending.due <= now + TIME_EPSILON_S:
            body, self._pending = self._pending.body, None
            outputs.append(self._send_reply(body(), now))
        outputs += self._emit_stream(now)
        return outputs

    def next_deadline(self) -> float | None:
        if self._power_on_at is not None:
            return self._power_on_at
        candidates = [self._reader.deadline(), self._pending.due if self._pending else None, self._stream_due(),
                      self._window_scan_due()]
        due = [time for time in candidates if time is not None]
        return min(due) if due else None

    def latest_scan_time(self, now: float) -> float:
        """The full scan a request received at `now` reads (30 01, 37): a daemon computes it
        before handing the bytes over, so that answering never waits on a computation."""
        revolutions = self._variant.revolutions
        return completion_time(latest_complete(now, revolutions), revolutions)

    def scan_request(self) -> dict:
        """What the scan source is asked for with a full scan of the current variant (besides its time):
        a daemon can then compute a client's very first scan ahead, like every later one."""
        variant = self._variant
        return {
            "start_deg": variant.start_deg, "step_deg": variant.step_deg, "count": variant.count,
            "unit": self._config.units, "field_bits": self._measuring.field_bits,
        }

    def scan_stride_s(self) -> float | None:
        """The period of the continuous mode running, in whole scans of the current variant (None: none
        runs, partial scans, each asked for differently, or a line too slow for every scan), so a daemon
        can batch it from its first scans."""
        stream = self._stream
        if stream is None or self._mode is Mode.STREAM_PARTIAL:
            return None
        stride = completion_time(1, stream.revolutions)
        telegram_bytes = 2 * self._variant.count + 10  # values, header, status and CRC
        if transmit_seconds(telegram_bytes, self._baud) > stride:
            return None  # a slow line: each telegram the newest scan when it frees, at no steady period
        return stride

    def next_scan_time(self) -> float | None:
        """Simulated time of the scan the next streamed telegram will carry (None when not
        streaming): the newest scan complete when the line frees, so a daemon can compute
        it ahead. At a slow baud that is not the line-free time `next_deadline` gives."""
        window_due = self._window_scan_due()
        due = self._stream_due()
        if self._stream is None or due is None:
            return window_due
        index = max(self._stream.next_index, latest_complete(due, self._stream.revolutions))
        streamed = completion_time(index, self._stream.revolutions)
        return window_due if window_due is not None and window_due < streamed else streamed

    # -- a mean's scans, fetched one by one as they complete ---------------

    def _window_scan_due(self) -> float | None:
        """When the next scan a waiting mean needs completes: each is fetched then, so that
        answering a mean of 250 scans never asks for 250 scans at once (a daemon computes
        each ahead, off its loop; fetching them all at the reply blocked it for 0.1-0.4 s)."""
        if self._window_todo is None:
            return None
        return completion_time(self._window_todo[0], self._variant.revolutions)

    def _fetch_window_scans(self, now: float) -> None:
        while self._window_todo is not None and self._window_scan_due() <= now + TIME_EPSILON_S:
            self._scan(self._window_todo[0])
            self._window_todo[0] += 1
            if self._window_todo[0] > self._window_todo[1]:
                self._window_todo = None

    def connection_lost(self) -> None:
        """The host went away: stop streaming, back to mode 25. The line rate stays
        (a real unit does not notice a host disconnect). Output still queued for the
        line left with the host (the transport discards it), so the line is free: a
        client that sent 16 000 bad frames must not delay the next one's replies by 16 s."""
        self._reader.clear()
        self._line_free_at = float("-inf")
        self._stream = None
        self._pending = None
        self._window_todo = None
        self._last_output_streamed = False
        if self._power_on_at is None:
            self._mode = Mode.ON_REQUEST

    # -- framing and the line ---------------------------------------------

    def _on_frame(self, event: FrameEvent, now: float) -> list[Output]:
        """ACK + reply for a valid telegram, NAK for a bad CRC, silence for another address."""
        if event.address != HOST_ADDRESS:
            return []
        if isinstance(event, CorruptTelegram):
            return [self._send(NAK, now)]
        interrupt = self._last_output_streamed
        if interrupt:
            self._line_free_at = min(self._line_free_at, now)  # the rest of that scan is dropped
        self._pending = None
        self._window_todo = None
        outputs = [self._send(ACK, now, interrupt=interrupt)]
        handler = self._handlers.get(event.body[0])
        reply = handler(event.body[1:], now) if handler else _Reply((NOT_ACKNOWLEDGED,))
        outputs += [self._send_reply(body, now) for body in reply.bodies]
        if reply.next_baud is not None:
            self._baud = reply.next_baud
        return outputs

    def _send(self, data: bytes, now: float, *, interrupt: bool = False, droppable: bool = False) -> Output:
        start = max(now, self._line_free_at)
        self._line_free_at = start + transmit_seconds(len(data), self._baud)
        self._last_output_streamed = droppable
        return Output(data, baud=self._baud, interrupt=interrupt, droppable=droppable)

    def _send_reply(self, body: bytes, now: float, *, droppable: bool = False) -> Output:
        return self._send(build_telegram(_REPLY_ADDRESS, body + bytes((STATUS_OK,))), now, droppable=droppable)

    def _emit_power_on(self, now: float) -> list[Output]:
        if self._power_on_at is None or now < self._power_on_at - TIME_EPSILON_S:
            return []
        self._power_on_at = None
        return [self._send_reply(b"\x90" + self._type, now)]

    # -- continuous output ------------------------------------------------

    def _stream_due(self) -> float | None:
        stream = self._stream
        if stream is None:
            return None
        return max(self._line_free_at, completion_time(stream.next_index, stream.revolutions))

    def _emit_stream(self, now: float) -> list[Output]:
        """The newest complete scan, once the line is free: scans completed while
        the line was busy and superseded before it freed are skipped."""
        due = self._stream_due()
        if self._stream is None or due is None or due > now + TIME_EPSILON_S:
            return []
        index = max(self._stream.next_index, latest_complete(now, self._stream.revolutions))
        self._stream.next_index = index + 1
        return [self._send_reply(body, now, droppable=True) for body in self._streamed_bodies(index)]

    def _streamed_bodies(self, index: int) -> list[bytes]:
        if self._mode is Mode.STREAM_PARTIAL:
            return [self._partial_scan_body(index)]
        if self._mode is Mode.STREAM_ALL:
            return [self._full_scan_body(index)]
        if self._mode is Mode.STREAM_MEANS:
            return [self._mean_body(index, self._means)]
        if self._mode is Mode.STREAM_SUBRANGE:
            return self._subrange_bodies(index, *self._subrange, direct=self._direct_subrange)
        return [self._mean_subrange_body(index, self._means, *self._subrange)]

    def _start_stream(self, mode: Mode, now: float) -> None:
        """Enter a mode; continuous ones start with the first scan completed after `now`."""
        self._mode = mode
        if mode not in STREAMING_MODES:
            self._stream = None
            return
        revolutions = 1 if mode is Mode.STREAM_PARTIAL else self._variant.revolutions
        first = latest_complete(now, revolutions) + 1
        if mode in MEAN_MODES:
            self._window_todo = [first, first + self._means - 1]  # fetched as they complete, like 36's
            first += self._means - 1  # the first window of n scans
        self._stream = _Stream(revolutions, first)

    # -- scans and measured-value bodies ------------------------------------

    @property
    def _measuring(self) -> MeasuringMode:
        return self._config.measuring_mode

    def _scan(self, index: int) -> _Measured:
        """Full scan `index` of the current variant, measured when it completes."""
        field_bits = self._measuring.field_bits
        key = (self._variant, self._config.units, field_bits, index)
        if key not in self._scan_cache:
            variant = self._variant
            scan = self._scan_source(completion_time(index, variant.revolutions), **self.scan_request())
            self._scan_cache[key] = self._checked(scan, variant.count)
            self._prune_cache(index)
        return self._scan_cache[key]

    def _words(self, measured: _Measured, selection: slice | np.ndarray = slice(None)) -> np.ndarray:
        """Wire words of (some of) a scan's values in the current measuring mode."""
        reflector = None if measured.reflector is None else measured.reflector[selection]
        return self._measuring.encode(measured.values[selection], reflector)

    def _prune_cache(self, index: int) -> None:
        """Keep only what the longest mean window (250 scans) can still need."""
        if len(self._scan_cache) > 2 * MEAN_SCANS_RANGE.stop:
            oldest = index - MEAN_SCANS_RANGE.stop
            self._scan_cache = {key: values for key, values in self._scan_cache.items() if key[3] >= oldest}

    @staticmethod
    def _checked(scan: ScanValues, count: int) -> _Measured:
        values = np.asarray(scan.values)
        if values.shape != (count,):
            raise ValueError(f"scan source returned {values.shape} values, expected ({count},)")
        reflector = getattr(scan, "reflector", None)
        if reflector is not None:
            reflector = np.asarray(reflector, dtype=bool)
            if reflector.shape != (count,):
                raise ValueError(f"scan source returned {reflector.shape} reflector flags, expected ({count},)")
        return _Measured(values, reflector)

    def _next_indices(self, index: int, revolutions: int | None = None) -> Indices | None:
        """Count one more measured-value telegram; its real-time indices (revolution
        of scan `index`, telegram counter) when the configuration asks for them."""
        telegram = self._telegram_counter
        self._telegram_counter = (telegram + 1) % 256
        if not self._config.realtime_indices:
            return None
        return index * (revolutions or self._variant.revolutions) % 256, telegram

    def _window(self, last_index: int, scans: int) -> np.ndarray:
        """Distance-field values (no flags) of `scans` scans ending with `last_index`."""
        return np.stack([self._scan(index).values for index in range(last_index - scans + 1, last_index + 1)])

    def _full_scan_body(self, index: int, every: int = 1) -> bytes:
        words = self._words(self._scan(index), slice(None, None, every))
        return scan_body(words, self._config.units, indices=self._next_indices(index))

    def _partial_scan_body(self, revolution: int) -> bytes:
        partial_index, start_deg, count = partial_scan_grid(revolution)
        scan = self._scan_source(
            completion_time(revolution, 1), start_deg=start_deg, step_deg=1.0, count=count,
            unit=self._config.units, field_bits=self._measuring.field_bits,
        )
        words = self._words(self._checked(scan, count))
        return scan_body(words, self._config.units, partial_index=partial_index, indices=self._next_indices(revolution, 1))

    def _mean_body(self, last_index: int, scans: int) -> bytes:
        means = mean_of_scans(self._window(last_index, scans), self._measuring.field_bits)
        return mean_body(scans, means, self._config.units, indices=self._next_indices(last_index))

    def _subrange_bodies(self, index: int, first: int, last: int, *, direct: bool = False) -> list[bytes]:
        """B7 of values first..last (1-based): one telegram, or, for a direct request
        or a range too long for one telegram, one per partial scan (TL §7.12.1: "response
        telegrams depending on the selected angular resolution (between 1 and 4)")."""
        last = min(last, self._variant.count)
        measured = self._scan(index)
        if not direct and self._subrange_fits(first, last):
            words = self._words(measured, slice(first - 1, last))
            return [subrange_body(first, last, words, self._config.units, indices=self._next_indices(index))]
        numbers = np.arange(first, last + 1)
        revolutions = self._variant.revolutions
        bodies = []
        for offset in range(revolutions):
            selected = numbers[(numbers - 1) % revolutions == offset] - 1
            if selected.size:
                partial_index = offset * (PARTIAL_SCANS // revolutions)  # x.00, x.25, x.50, x.75
                words = self._words(measured, selected)
                bodies.append(subrange_body(
                    first, last, words, self._config.units,
                    partial_index=partial_index, indices=self._next_indices(index),
                ))
        return bodies

    def _mean_subrange_body(self, last_index: int, scans: int, first: int, last: int) -> bytes:
        last = min(last, self._variant.count)
        window = self._window(last_index, scans)[:, first - 1 : last]
        means = mean_of_scans(window, self._measuring.field_bits)
        return mean_subrange_body(scans, first, last, means, self._config.units, indices=self._next_indices(last_index))

    def _valid_subrange(self, first: int, last: int) -> bool:
        return 1 <= first <= last <= self._variant.count

    def _index_bytes(self) -> int:
        return 2 if self._config.realtime_indices else 0

    def _subrange_fits(self, first: int, last: int) -> bool:
        """Whether a combined B7 of first..last fits one telegram."""
        return 1 + 6 + 2 * (last - first + 1) + self._index_bytes() <= MAX_REPLY_BODY

    def _mean_subrange_fits(self, first: int, last: int) -> bool:
        """BF cannot be split into partial scans: a longer one is refused."""
        return 1 + 1 + 6 + 2 * (last - first + 1) + self._index_bytes() <= MAX_REPLY_BODY

    def _means_fit(self) -> bool:
        return 1 + 1 + 2 + 2 * self._variant.count + self._index_bytes() <= MAX_REPLY_BODY

    def _schedule_mean(self, scans: int, now: float, body: Callable[[int], bytes]) -> None:
        """Answer once the next `scans` scans are measured."""
        latest = latest_complete(now, self._variant.revolutions)
        last_index = latest + scans
        due = completion_time(last_index, self._variant.revolutions)
        self._pending = _PendingReply(due, lambda: body(last_index))
        self._window_todo = [latest + 1, last_index]

    # -- commands -----------------------------------------------------------

    def _reset(self, data: bytes, now: float) -> _Reply:
        """10: 91 at once, 90 at the power-on rate after a simulated boot, mode 25."""
        if data:
            return _Reply((NOT_ACKNOWLEDGED,))
        self._start_stream(Mode.ON_REQUEST, now)
        self._reader.clear()
        self._power_on_at = now + RESET_BOOT_S
        return _Reply((b"\x91",), next_baud=self._baud if self._permanent_baud else POWER_ON_BAUD)

    def _switch_mode(self, data: bytes, now: float) -> _Reply:
        """20: operating mode and line rate; A0 00 done, A0 01 refused (wrong password)."""
        if not data:
            return _Reply((NOT_ACKNOWLEDGED,))
        submode, parameters = data[0], data[1:]
        done, refused = _Reply((b"\xa0\x00",)), _Reply((b"\xa0\x01",))
        if submode in BAUD_SUBMODES and not parameters:
            return _Reply(done.bodies, next_baud=BAUD_SUBMODES[submode])
        if submode in (0x00, 0x30) and len(parameters) == len(DEFAULT_PASSWORD):
            if parameters != DEFAULT_PASSWORD:
                return refused
            if submode == 0x00:
                self._start_stream(Mode.INSTALLATION, now)
            return done
        if submode in (Mode.ON_REQUEST, Mode.STREAM_ALL, Mode.STREAM_PARTIAL) and not parameters:
            self._start_stream(Mode(submode), now)
            return done
        if submode == Mode.STREAM_MEANS and len(parameters) == 1 and parameters[0] in MEAN_SCANS_RANGE:
            if not self._means_fit():
                return _Reply((NOT_ACKNOWLEDGED,))
            self._means = parameters[0]
            self._start_stream(Mode.STREAM_MEANS, now)
            return done
        if submode == Mode.STREAM_SUBRANGE and len(parameters) == 4:
            first, last = _words(parameters)
            self._direct_subrange = bool(first & DIRECT_SUBRANGE_BIT)
            first &= ~DIRECT_SUBRANGE_BIT
            if self._valid_subrange(first, last):
                self._subrange = (first, last)
                self._start_stream(Mode.STREAM_SUBRANGE, now)
                return done
        if submode == Mode.STREAM_MEAN_SUBRANGE and len(parameters) == 6:
            scans, first, last = _words(parameters)
            if scans in MEAN_SCANS_RANGE and self._valid_subrange(first, last) and self._mean_subrange_fits(first, last):
                self._means, self._subrange = scans, (first, last)
                self._start_stream(Mode.STREAM_MEAN_SUBRANGE, now)
                return done
        return _Reply((NOT_ACKNOWLEDGED,))

    def _request_values(self, data: bytes, now: float) -> _Reply:
        """30: 01 the last full scan, 06 every other value, 07 every 20th, 08 the current partial scan."""
        if len(data) != 1 or data[0] not in (0x01, 0x06, 0x07, 0x08):
            return _Reply((NOT_ACKNOWLEDGED,))
        if data[0] == 0x08:
            return _Reply((self._partial_scan_body(latest_complete(now, 1)),))
        index = latest_complete(now, self._variant.revolutions)
        return _Reply((self._full_scan_body(index, {0x01: 1, 0x06: 2, 0x07: 20}[data[0]]),))

    def _request_status(self, data: bytes, now: float) -> _Reply:
        """31 → B1: 152 bytes of live status."""
        if data:
            return _Reply((NOT_ACKNOWLEDGED,))
        status = DeviceStatus(
            software_version=self._type.decode("ascii").rsplit(";", 1)[-1],
            operating_mode=int(self._mode),
            angle_deg=self._variant.angle_deg,
            resolution_cdeg=self._variant.resolution_cdeg,
            baud=self._baud,
            permanent_baud=self._permanent_baud,
            configuration=self._config,
        )
        return _Reply((b"\xb1" + status_block(status),))

    def _request_errors(self, data: bytes, now: float) -> _Reply:
        """32 → B2 without error pairs: a healthy unit."""
        return _Reply((b"\xb2",) if not data else (NOT_ACKNOWLEDGED,))

    def _request_means(self, data: bytes, now: float) -> _Reply:
        """36 n → B6, the mean of the next n scans, sent when the n-th is complete."""
        if len(data) != 1 or data[0] not in MEAN_SCANS_RANGE or not self._means_fit():
            return _Reply((NOT_ACKNOWLEDGED,))
        scans = data[0]
        self._schedule_mean(scans, now, lambda last: self._mean_body(last, scans))
        return _Reply(())

    def _request_subrange(self, data: bytes, now: float) -> _Reply:
        """37 first,last (1-based, inclusive; bit 15 of first: direct) → B7 from the last full scan,
        in one telegram or one per partial scan."""
        if len(data) != 4:
            return _Reply((NOT_ACKNOWLEDGED,))
        first, last = _words(data)
        direct = bool(first & DIRECT_SUBRANGE_BIT)
        first &= ~DIRECT_SUBRANGE_BIT
        if not self._valid_subrange(first, last):
            return _Reply((NOT_ACKNOWLEDGED,))
        index = latest_complete(now, self._variant.revolutions)
        return _Reply(tuple(self._subrange_bodies(index, first, last, direct=direct)))

    def _request_type(self, data: bytes, now: float) -> _Reply:
        """3A → BA: the type string."""
        return _Reply((b"\xba" + self._type,) if not data else (NOT_ACKNOWLEDGED,))

    def _switch_variant(self, data: bytes, now: float) -> _Reply:
        """3B angle,resolution → BB 01 switched / 00 refused, then the active variant."""
        if len(data) != 4:
            return _Reply((NOT_ACKNOWLEDGED,))
        variant = Variant.of(*_words(data))
        if variant is not None:
            self._variant = variant
            self._start_stream(self._mode, now)
        active = self._variant.angle_deg.to_bytes(2, "little") + self._variant.resolution_cdeg.to_bytes(2, "little")
        return _Reply((b"\xbb" + (b"\x01" if variant else b"\x00") + active,))

    def _request_mean_subrange(self, data: bytes, now: float) -> _Reply:
        """3F n,first,last → BF, the mean sub-range of the next n scans."""
        if len(data) != 5:
            return _Reply((NOT_ACKNOWLEDGED,))
        scans, (first, last) = data[0], _words(data[1:])
        if scans not in MEAN_SCANS_RANGE or not self._valid_subrange(first, last):
            return _Reply((NOT_ACKNOWLEDGED,))
        if not self._mean_subrange_fits(first, last):
            return _Reply((NOT_ACKNOWLEDGED,))  # a BF that long cannot be framed, nor split
        self._schedule_mean(scans, now, lambda end: self._mean_subrange_body(end, scans, first, last))
        return _Reply(())

    def _define_permanent_baud(self, data: bytes, now: float) -> _Reply:
        """66 (installation mode): 00 power on at 9600, 01 keep the rate, 02 keep the type → E6 accepted, setting."""
        if self._mode is not Mode.INSTALLATION or len(data) != 1:
            return _Reply((NOT_ACKNOWLEDGED,))
        setting = data[0]
        if setting not in (0x00, 0x01, 0x02):
            return _Reply((b"\xe6\x00" + data,))
        if setting != 0x02:
            self._permanent_baud = setting == 0x01
        return _Reply((b"\xe6\x01" + data,))

    def _request_config(self, data: bytes, now: float) -> _Reply:
        """74 → F4: the configuration block."""
        return _Reply((b"\xf4" + self._config.block,) if not data else (NOT_ACKNOWLEDGED,))

    def _configure(self, data: bytes, now: float) -> _Reply:
        """77 (installation mode): 1–34 bytes → F7 01 accepted / 00 rejected, then the active block."""
        if self._mode is not Mode.INSTALLATION or not 1 <= len(data) <= 34:
            return _Reply((NOT_ACKNOWLEDGED,))
        updated = self._config.updated(data)
        if updated is not None:
            self._config = updated
        return _Reply((b"\xf7" + (b"\x01" if updated else b"\x00") + self._config.block,))


def _words(data: bytes) -> tuple[int, ...]:
    """Little-endian WORDs."""
    return tuple(int.from_bytes(data[i : i + 2], "little") for i in range(0, len(data), 2))
