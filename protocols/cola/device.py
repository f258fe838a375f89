"""`ColaDevice`: one client's CoLa session with a SICK unit; `ColaUnit`: the unit's settings.

A unit powers on measuring at simulated time `power_on_s` with its model's
default scan configuration. Settings written by any client (scan
configuration, output range, data content, echo filter) stay until the unit
is rebooted (`sMN mSCreboot`), which restores what `sMN mEEwriteall` last
saved. A session holds what a real unit keeps per connection: the access
level and whether LMDscandata is streamed to it (and in which dialect).
Answers go out in the dialect of their request. docs/cola.md lists every
command, its answer and its error codes.
"""

from __future__ import annotations

import dataclasses
import datetime
import functools
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from protocols.cola.framing import ColaReader, Dialect, Telegram, frame
from protocols.cola.scandata import Channel, ScanHeader, scandata_arguments
from protocols.device import Output
from protocols.cola.values import (
    BadArguments,
    Value,
    decode,
    encode,
    flex,
    i16,
    i32,
    prepare_tables,
    u8,
    u16,
    u32,
)

TIME_EPSILON_S = 1e-9
CATCH_UP_S = 0.5  # a stream woken late sends the scans it missed over this long (the newest of them)
CLOCK_BASE = datetime.datetime(2000, 1, 1)  # the unit's clock at power-on (it has no battery-backed clock)

# Sopas error codes (the `sFA` answer): SICK's numbering, as sick_scan_xd and pysicktim list them.
METHOD_ACCESS_DENIED = 0x1
LOCAL_CONDITION_FAILED = 0x4
BUFFER_UNDERFLOW = 0x8
VARIABLE_WRITE_ACCESS_DENIED = 0xA
UNKNOWN_NAME = 0xB  # Sopas_Error_UNKNOWN_CMD_FOR_NAMESERVER
UNKNOWN_COLA_COMMAND = 0xC
COLA_A_VALUE_OVERFLOW = 0x10
COLA_A_INVALID_CHARACTER = 0x11

# SetAccessMode: user level → password hash (SICK's defaults)
PASSWORDS = {2: 0xB21ACE26, 3: 0xF4724744, 4: 0x81BE23AA}
AUTHORIZED_CLIENT = 3
STATE_MEASURING = 7  # STlms: ready for measurement
STATE_IDLE = 3
ECHO_FIRST, ECHO_ALL, ECHO_LAST = 0, 1, 2
# Filters and encoder settings drivers write at start-up (sick_scan_xd, comma's LMS driver): taken and
# answered like the unit, without effect on the scans.
ACCEPTED_SETTINGS: dict[bytes, tuple[str, ...]] = {
    b"LFPparticle": ("u8", "u16"), b"LFPmeanfilter": ("u8", "u16", "u8"), b"LFPnto1filter": ("u8",),
    b"LICsrc": ("u8",), b"LICencset": ("u8",), b"DO3And4Fnc": ("u8",), b"CLNFDigFilterEn": ("u8",),
    b"CLHWGating": ("u8",),
}


class ScanValues(Protocol):
    """The scan of the whole field at one resolution: `echoes` (N, E) distance counts nearest
    first (-1: no such echo), `echo_intensities` (N, E) the unit's RSSI (-1 likewise; an 8-bit
    channel saturates at 255)."""

    echoes: np.ndarray
    echo_intensities: np.ndarray


ScanSource = Callable[..., ScanValues]  # (time_s, *, frequency_ticks, resolution_ticks, fog_filter)


@dataclass(frozen=True)
class UnitModel:
    """What a CoLa device is told about its unit (the daemon fills it from the model table)."""

    family: str  # TiM5xx, TiM7xx, LMS1xx, LMS5xx
    device_ident: str
    firmware_version: str
    serial_number: str  # decimal digits, as on the unit's label
    start_ticks: int  # field of view, 1/10 000 °
    stop_ticks: int
    scan_configs: dict[int, tuple[int, ...]]  # frequency (1/100 Hz) → resolutions (1/10 000 °)
    default: tuple[int, int]
    echoes: int
    distance_scale: float
    location_name: str = "not defined"
    fog_filter: bool = False  # LMS5xx: the fog filter's power-on state

    def beam_count(self, resolution_ticks: int) -> int:
        return int(round((self.stop_ticks - self.start_ticks) / resolution_ticks)) + 1

    @property
    def has_echo_filter(self) -> bool:
        return self.family in ("LMS5xx", "TiM7xx")

    @property
    def has_fog_filter(self) -> bool:
        return self.family == "LMS5xx"


@dataclass
class Settings:
    """What a client can change, and `mEEwriteall` saves."""

    frequency_ticks: int
    resolution_ticks: int
    output_start_ticks: int
    output_stop_ticks: int
    channels: int = 1  # LMDscandatacfg: bit k-1 = echo k (DISTk)
    rssi: bool = False
    rssi_16_bits: bool = False
    encoder: bool = False
    device_name: bool = False
    comment: bool = False
    time: bool = False
    interval: int = 1
    echo_filter: int = ECHO_FIRST
    fog_filter: bool = False
    measuring: bool = True


class ColaUnit:
    """One scanner's settings and counters, shared by all its sessions (both its ports)."""

    def __init__(self, model: UnitModel, power_on_s: float = 0.0) -> None:
        self.model = model
        self._saved = self._factory()
        self.settings = dataclasses.replace(self._saved)
        self.power_on_s = power_on_s
        self.telegram_counter = 0
        self._epoch_s = power_on_s  # scans complete at epoch + k · period since the last change
        self._scans_before_epoch = 0
        self.epoch = 0  # counts the changes: a stream's scan indices are those of one epoch
        self.boots = 0  # counts the reboots: each drops the connections of both ports

    def _factory(self) -> Settings:
        model = self.model
        frequency, resolution = model.default
        return Settings(frequency, resolution, model.start_ticks, model.stop_ticks,
                        echo_filter=ECHO_FIRST if model.has_echo_filter else ECHO_ALL, fog_filter=model.fog_filter)

    @property
    def period_s(self) -> float:
        return 100.0 / self.settings.frequency_ticks

    def scan_index(self, now: float) -> int:
        """The newest scan complete at `now` (0 before the first)."""
        return max(0, math.floor((now - self._epoch_s) / self.period_s + TIME_EPSILON_S))

    def index_at(self, scan_time_s: float) -> int:
        """The scan that completes at `scan_time_s`."""
        return int(round((scan_time_s - self._epoch_s) / self.period_s))

    def scan_time(self, index: int) -> float:
        return self._epoch_s + index * self.period_s

    def scan_counter(self, index: int) -> int:
        return self._scans_before_epoch + index

    def reconfigure(self, now: float, **changes: Any) -> None:
        """New scan settings from `now` on: the mirror's scans restart counting there."""
        self._scans_before_epoch += self.scan_index(now)
        self._epoch_s = now
        self.epoch += 1
        self.settings = dataclasses.replace(self.settings, **changes)

    def save(self) -> None:
        self._saved = dataclasses.replace(self.settings)

    def reboot(self, now: float) -> None:
        self.settings = dataclasses.replace(self._saved)
        self.power_on_s = self._epoch_s = now
        self._scans_before_epoch = 0
        self.epoch += 1
        self.boots += 1
        self.telegram_counter = 0

    def load_defaults(self, now: float) -> None:
        self.reconfigure(now, **dataclasses.asdict(self._factory()))

    def scan_request(self) -> dict[str, Any]:
        settings = self.settings
        return {"frequency_ticks": settings.frequency_ticks, "resolution_ticks": settings.resolution_ticks,
                "fog_filter": settings.fog_filter}


@dataclass
class _Stream:
    dialect: Dialect
    next_index: int
    epoch: int  # the unit's epoch its indices count in
    last_sent: int = -1  # the newest scan index a telegram carried

    def follow(self, unit: ColaUnit) -> None:
        """After the unit's scans restarted counting (new settings, measuring again, a reboot from any
        port), stream on from the epoch's first new scan (its scan 0 is the last one before the change):
        the old indices waited for the new count to catch up, seconds to minutes without a scan."""
        if self.epoch != unit.epoch:
            self.epoch, self.next_index, self.last_sent = unit.epoch, 1, 0


@dataclass
class _Session:
    level: int = 0
    stream: _Stream | None = None
    pending: list[Telegram] = field(default_factory=list)


Handler = Callable[[bytes, Dialect, float], list[Value] | bytes | int]  # bytes: arguments already encoded


class ColaDevice:
    """One client's session: implements `protocols.device.Device`."""

    def __init__(self, scan_source: ScanSource, unit: ColaUnit) -> None:
        self._scans = scan_source
        self.unit = unit
        prepare_tables()  # not at the first scan's deadline
        self._reader = ColaReader()
        self._session = _Session()
        self._boots_seen: int | None = None  # the unit's reboots when this port's client first spoke
        self._handlers: dict[tuple[bytes, bytes], tuple[bytes, Handler]] = {
            (b"sMN", b"SetAccessMode"): (b"sAN", self._set_access_mode),
            (b"sMN", b"Run"): (b"sAN", self._run),
            (b"sMN", b"LMCstartmeas"): (b"sAN", self._start_measuring),
            (b"sMN", b"LMCstopmeas"): (b"sAN", self._stop_measuring),
            (b"sMN", b"LMCstandby"): (b"sAN", self._stop_measuring),
            (b"sMN", b"mLMPsetscancfg"): (b"sAN", self._set_scan_config),
            (b"sMN", b"mEEwriteall"): (b"sAN", self._write_eeprom),
            (b"sMN", b"mSCreboot"): (b"sAN", self._reboot),
            (b"sMN", b"mSCloadappdef"): (b"sAN", self._load_defaults),
            (b"sMN", b"mSCloadfacdef"): (b"sAN", self._load_defaults),
            (b"sRN", b"DeviceIdent"): (b"sRA", self._device_ident),
            (b"sRI", b"0"): (b"sRA", self._device_ident),
            (b"sRN", b"SerialNumber"): (b"sRA", lambda a, d, n: [flex(self.unit.model.serial_number)]),
            (b"sRN", b"FirmwareVersion"): (b"sRA", lambda a, d, n: [flex(self.unit.model.firmware_version)]),
            (b"sRN", b"LocationName"): (b"sRA", lambda a, d, n: [flex(self.unit.model.location_name)]),
            (b"sRN", b"SCdevicestate"): (b"sRA", lambda a, d, n: [u8(1)]),
            (b"sRN", b"ODoprh"): (b"sRA", self._operating_hours),
            (b"sRN", b"ODpwrc"): (b"sRA", lambda a, d, n: [u32(1)]),
            (b"sRN", b"STlms"): (b"sRA", self._status),
            (b"sRN", b"LMPscancfg"): (b"sRA", lambda a, d, n: self._scan_config()),
            (b"sRN", b"LMPoutputRange"): (b"sRA", self._output_range),
            (b"sWN", b"LMPoutputRange"): (b"sWA", self._set_output_range),
            (b"sRN", b"LMDscandatacfg"): (b"sRA", self._data_config),
            (b"sWN", b"LMDscandatacfg"): (b"sWA", self._set_data_config),
            (b"sRN", b"LMDscandata"): (b"sRA", self._one_scan),
            (b"sEN", b"LMDscandata"): (b"sEA", self._stream_scans),
            (b"sWN", b"EIHstCola"): (b"sWA", self._accept(("u8",))),
        }
        for name, kinds in ACCEPTED_SETTINGS.items():
            self._handlers[(b"sWN", name)] = (b"sWA", self._accept(kinds))
        if unit.model.has_echo_filter:
            self._handlers[(b"sRN", b"FREchoFilter")] = (b"sRA", lambda a, d, n: [u8(self.unit.settings.echo_filter)])
            self._handlers[(b"sWN", b"FREchoFilter")] = (b"sWA", self._set_echo_filter)
        if unit.model.has_fog_filter:
            self._handlers[(b"sRN", b"MSsuppmode")] = (b"sRA", lambda a, d, n: [u8(int(self.unit.settings.fog_filter))])
            self._handlers[(b"sWN", b"MSsuppmode")] = (b"sWA", self._set_fog_filter)

    # -- protocols.device.Device ------------------------------------------

    @property
    def baud(self) -> None:
        return None

    @property
    def dropped_telegrams(self) -> int:
        return self._reader.dropped

    def receive(self, data: bytes, now: float) -> list[Output]:
        """Streamed scans due, then the answer to every whole telegram in `data`, in order, as one
        output (a flood of thousands of requests is one write, not thousands)."""
        outputs = self.poll(now)
        if outputs and outputs[-1].hang_up:
            return outputs
        if self._boots_seen is None:
            self._boots_seen = self.unit.boots
        answers = []
        for telegram in self._reader.feed(data):
            answers.append(self._answer(telegram, now).data)
            if self._rebooted():
                break  # nothing after the reboot's answer is read
        if answers:
            outputs.append(_output(b"".join(answers)))
        return outputs + self._hang_up_if_rebooted()

    def _rebooted(self) -> bool:
        """Whether the unit rebooted (from either port) since this port's client first spoke."""
        return self._boots_seen is not None and self._boots_seen != self.unit.boots

    def _hang_up_if_rebooted(self) -> list[Output]:
        """A reboot drops the connection (after the answer to `mSCreboot`), as the unit's network restarts."""
        if not self._rebooted():
            return []
        self.connection_lost()
        return [Output(b"", hang_up=True)]

    def poll(self, now: float) -> list[Output]:
        """The scans measured since the last one sent, each in its own telegram (a late wake-up sends the
        ones it missed over the last CATCH_UP_S; of a longer gap, those)."""
        if self._rebooted():
            return self._hang_up_if_rebooted()
        stream = self._session.stream
        unit = self.unit
        if stream is None or not unit.settings.measuring:
            return []
        stream.follow(unit)
        latest = unit.scan_index(now)
        if stream.next_index > latest:
            return []
        interval = max(1, unit.settings.interval)
        first = max(stream.next_index, latest - int(CATCH_UP_S / unit.period_s) + 1)
        first = -(-first // interval) * interval
        outputs = []
        for index in range(first, latest + 1, interval):
            sent, arguments = self._scandata(index, unit.scan_time(index), stream.dialect)
            if sent <= stream.last_sent:
                continue  # a daemon that is behind hands out the freshest scan it has: sent already
            stream.last_sent = sent
            payload = b"sSN LMDscandata " + arguments
            outputs.append(_output(frame(payload, stream.dialect), droppable=True))
        stream.next_index = (latest // interval + 1) * interval
        return outputs

    def next_deadline(self) -> float | None:
        stream = self._session.stream
        if stream is None or not self.unit.settings.measuring:
            return None
        stream.follow(self.unit)
        return self.unit.scan_time(stream.next_index)

    def next_scan_time(self) -> float | None:
        return self.next_deadline()

    def latest_scan_time(self, now: float) -> float:
        """The scan an `sRN LMDscandata` received at `now` reads."""
        return self.unit.scan_time(self.unit.scan_index(now))

    def scan_request(self) -> dict[str, Any]:
        return self.unit.scan_request()

    def scan_stride_s(self) -> float | None:
        """The period of the LMDscandata stream (None: not streaming), so a daemon batches it from its first scans."""
        if self._session.stream is None or not self.unit.settings.measuring:
            return None
        return self.unit.period_s * max(1, self.unit.settings.interval)

    def connection_lost(self) -> None:
        """The client went away: streaming to it stops and its login ends; the unit's settings stay."""
        self._reader.clear()
        self._session = _Session()
        self._boots_seen = None

    # -- answering ----------------------------------------------------------

    def _answer(self, telegram: Telegram, now: float) -> Output:
        payload, dialect = telegram.payload, telegram.dialect
        kind, _, rest = payload.partition(b" ")
        name, _, arguments = rest.partition(b" ")
        if len(kind) != 3 or kind[:1] != b"s" or kind[1:2] not in b"RWME" or kind[2:3] not in b"NI":
            return self._error(UNKNOWN_COLA_COMMAND, dialect)
        entry = self._handlers.get((kind, name))
        if entry is None:
            return self._error(UNKNOWN_NAME, dialect)
        answer_kind, handler = entry
        if kind == b"sWN" and self._session.level < AUTHORIZED_CLIENT:
            return self._error(VARIABLE_WRITE_ACCESS_DENIED, dialect)
        try:
            result = handler(arguments, dialect, now)
        except BadArguments as error:
            return self._error(_argument_error(str(error), dialect), dialect)
        if isinstance(result, int):
            return self._error(result, dialect)
        head = answer_kind + b" " + name
        body = result if isinstance(result, bytes) else encode(result, dialect) if result else b""
        if result and (dialect is Dialect.ASCII or body):
            head += b" "
        return _output(frame(head + body, dialect))

    def _error(self, code: int, dialect: Dialect) -> Output:
        return _error_output(code, dialect)

    def _method(self, now: float) -> int | None:
        """A method that needs the authorised client's level: None, or the error code."""
        return None if self._session.level >= AUTHORIZED_CLIENT else METHOD_ACCESS_DENIED

    # -- handlers: each returns the answer's arguments or an sFA code ---------

    def _set_access_mode(self, arguments: bytes, dialect: Dialect, now: float) -> list[Value]:
        level, password = decode(arguments, ("u8", "u32"), dialect)
        if PASSWORDS.get(int(level)) == password:
            self._session.level = int(level)
            return [u8(1)]
        return [u8(0)]

    def _run(self, arguments: bytes, dialect: Dialect, now: float) -> list[Value]:
        self._session.level = 0
        return [u8(1)]

    def _start_measuring(self, arguments: bytes, dialect: Dialect, now: float) -> list[Value] | int:
        denied = self._method(now)
        if denied is not None:
            return denied
        if not self.unit.settings.measuring:
            self.unit.reconfigure(now, measuring=True)
        return [u8(0)]

    def _stop_measuring(self, arguments: bytes, dialect: Dialect, now: float) -> list[Value] | int:
        denied = self._method(now)
        if denied is not None:
            return denied
        if self.unit.settings.measuring:
            self.unit.reconfigure(now, measuring=False)
        return [u8(0)]

    def _set_scan_config(self, arguments: bytes, dialect: Dialect, now: float) -> list[Value] | int:
        denied = self._method(now)
        if denied is not None:
            return denied
        frequency, _sectors, resolution, _start, _stop = decode(arguments, ("u32", "i16", "u32", "i32", "i32"), dialect)
        configs = self.unit.model.scan_configs
        if frequency not in configs:
            status = 1  # frequency error
        elif resolution not in configs[frequency]:
            status = 2  # resolution error
        else:
            status = 0
            unit = self.unit
            if (frequency, resolution) != (unit.settings.frequency_ticks, unit.settings.resolution_ticks):
                model = unit.model
                unit.reconfigure(now, frequency_ticks=frequency, resolution_ticks=resolution,
                                 output_start_ticks=model.start_ticks, output_stop_ticks=model.stop_ticks)
        return [u8(status), *self._scan_config()]

    def _scan_config(self) -> list[Value]:
        settings, model = self.unit.settings, self.unit.model
        return [u32(settings.frequency_ticks), i16(1), u32(settings.resolution_ticks),
                i32(model.start_ticks), i32(model.stop_ticks)]

    def _write_eeprom(self, arguments: bytes, dialect: Dialect, now: float) -> list[Value] | int:
        denied = self._method(now)
        if denied is not None:
            return denied
        self.unit.save()
        return [u8(1)]

    def _reboot(self, arguments: bytes, dialect: Dialect, now: float) -> list[Value] | int:
        denied = self._method(now)
        if denied is not None:
            return denied
        self.unit.reboot(now)
        return []  # answered, then the connection drops (`receive`)

    def _load_defaults(self, arguments: bytes, dialect: Dialect, now: float) -> list[Value] | int:
        denied = self._method(now)
        if denied is not None:
            return denied
        self.unit.load_defaults(now)
        return []

    def _device_ident(self, arguments: bytes, dialect: Dialect, now: float) -> list[Value]:
        model = self.unit.model
        return [flex(model.device_ident), flex(model.firmware_version)]

    def _operating_hours(self, arguments: bytes, dialect: Dialect, now: float) -> list[Value]:
        return [u32(int((now - self.unit.power_on_s) / 360.0))]  # tenths of an hour since power-on

    def _status(self, arguments: bytes, dialect: Dialect, now: float) -> list[Value]:
        clock = CLOCK_BASE + datetime.timedelta(seconds=max(0.0, now - self.unit.power_on_s))
        state = STATE_MEASURING if self.unit.settings.measuring else STATE_IDLE
        return [u16(state), u8(0), flex(clock.strftime("%H:%M:%S")), flex(clock.strftime("%d.%m.%Y")),
                u16(0), u16(0), u16(0)]

    def _output_range(self, arguments: bytes, dialect: Dialect, now: float) -> list[Value]:
        settings = self.unit.settings
        return [u16(1), u32(settings.resolution_ticks), i32(settings.output_start_ticks), i32(settings.output_stop_ticks)]

    def _set_output_range(self, arguments: bytes, dialect: Dialect, now: float) -> list[Value] | int:
        _count, _resolution, start, stop = decode(arguments, ("u16", "u32", "i32", "i32"), dialect)
        model = self.unit.model
        if not model.start_ticks <= start < stop <= model.stop_ticks:
            return LOCAL_CONDITION_FAILED
        self.unit.settings = dataclasses.replace(self.unit.settings, output_start_ticks=start, output_stop_ticks=stop)
        return []

    def _data_config(self, arguments: bytes, dialect: Dialect, now: float) -> list[Value]:
        s = self.unit.settings
        return [u8(s.channels), u8(0), u8(int(s.rssi)), u8(int(s.rssi_16_bits)), u8(0), u8(int(s.encoder)), u8(0),
                u8(0), u8(int(s.device_name)), u8(int(s.comment)), u8(int(s.time)), u16(s.interval)]

    def _set_data_config(self, arguments: bytes, dialect: Dialect, now: float) -> list[Value] | int:
        kinds = ("u8", "u8", "u8", "u8", "u8", "u8", "u8", "u8", "u8", "u8", "u8", "i16")
        (channels, _, rssi, wide, _unit, encoder, _, _position, name, comment, time, interval) = decode(arguments, kinds, dialect)
        echo_bits = (1 << self.unit.model.echoes) - 1
        if not channels & echo_bits or channels & ~echo_bits & 0xFF or interval < 1 or rssi > 1 or wide > 1:
            return LOCAL_CONDITION_FAILED
        self.unit.settings = dataclasses.replace(
            self.unit.settings, channels=channels, rssi=bool(rssi), rssi_16_bits=bool(wide), encoder=bool(encoder),
            device_name=bool(name), comment=bool(comment), time=bool(time), interval=interval,
        )
        return []

    def _set_echo_filter(self, arguments: bytes, dialect: Dialect, now: float) -> list[Value] | int:
        (choice,) = decode(arguments, ("u8",), dialect)
        if choice not in (ECHO_FIRST, ECHO_ALL, ECHO_LAST):
            return LOCAL_CONDITION_FAILED
        self.unit.settings = dataclasses.replace(self.unit.settings, echo_filter=choice)
        return []

    def _set_fog_filter(self, arguments: bytes, dialect: Dialect, now: float) -> list[Value] | int:
        (choice,) = decode(arguments, ("u8",), dialect)
        if choice > 1:
            return LOCAL_CONDITION_FAILED
        self.unit.reconfigure(now, fog_filter=bool(choice))
        return []

    def _accept(self, kinds: tuple[str, ...]) -> Handler:
        """A setting the emulator takes and answers like the unit, without further effect."""
        def handler(arguments: bytes, dialect: Dialect, now: float) -> list[Value]:
            decode(arguments, kinds, dialect)
            return []
        return handler

    def _one_scan(self, arguments: bytes, dialect: Dialect, now: float) -> bytes | int:
        unit = self.unit
        if not unit.settings.measuring:
            return LOCAL_CONDITION_FAILED
        return self._scandata(unit.scan_index(now), now, dialect)[1]

    def _stream_scans(self, arguments: bytes, dialect: Dialect, now: float) -> list[Value] | int:
        (enable,) = decode(arguments, ("u8",), dialect)
        if enable > 1:
            return LOCAL_CONDITION_FAILED
        if enable:
            self._session.stream = _Stream(dialect, self.unit.scan_index(now) + 1, self.unit.epoch)
        else:
            self._session.stream = None
        return [u8(enable)]

    # -- scan data ------------------------------------------------------------

    def _scandata(self, index: int, now: float, dialect: Dialect) -> tuple[int, bytes]:
        """The arguments of scan `index`'s telegram sent at `now`, and the index it carries: a scan source may hand
        out another scan than the one asked (a daemon that is behind: its freshest), stamped with its own
        time, and the telegram then carries that scan's counter and times."""
        unit = self.unit
        settings, model = unit.settings, unit.model
        scan = self._scans(unit.scan_time(index), **unit.scan_request())
        actual_s = getattr(scan, "time_s", None)
        if actual_s is not None:
            index = unit.index_at(actual_s)
        scan_time = unit.scan_time(index)
        unit.telegram_counter += 1
        count = model.beam_count(settings.resolution_ticks)
        first, last = _output_beams(settings.output_start_ticks, settings.output_stop_ticks, model.start_ticks, model.stop_ticks, count)
        start_ticks = model.start_ticks + int(round(first * (model.stop_ticks - model.start_ticks) / (count - 1)))
        distances, intensities = _selected_echoes(scan, settings, model)
        channels = []
        for number, column in enumerate(range(distances.shape[1]), start=1):
            if settings.echo_filter == ECHO_ALL and not settings.channels >> (number - 1) & 1:
                continue
            channels.append(Channel(f"DIST{number}", model.distance_scale, start_ticks, settings.resolution_ticks,
                                    distances[first:last + 1, column], True))
        if settings.rssi:
            wide = settings.rssi_16_bits
            for channel_index, channel in enumerate(list(channels)):
                column = int(channel.content[4:]) - 1
                rssi = intensities[first:last + 1, column]  # type: ignore[index]
                channels.append(Channel(f"RSSI{column + 1}", 1.0, start_ticks, settings.resolution_ticks,
                                        rssi if wide else np.minimum(rssi, 0xFF), wide))
        period = unit.period_s
        first_beam_s = scan_time - period * (model.stop_ticks - model.start_ticks) / 3_600_000
        header = ScanHeader(
            serial_number=int(model.serial_number) & 0xFFFF_FFFF,
            device_status=0,
            telegram_counter=unit.telegram_counter,
            scan_counter=unit.scan_counter(index),
            power_up_us=_micros(first_beam_s - unit.power_on_s),
            transmission_us=_micros(now - unit.power_on_s),
            scan_frequency_ticks=settings.frequency_ticks,
            measurement_frequency=int(round(3_600_000 / settings.resolution_ticks * settings.frequency_ticks / 10_000)),
            encoder=(0, 0) if settings.encoder else None,
            device_name=model.device_ident if settings.device_name else None,
            time=_clock(now - unit.power_on_s) if settings.time else None,
        )
        return index, scandata_arguments(header, channels, dialect)


def _selected_echoes(scan: ScanValues, settings: Settings, model: UnitModel) -> tuple[np.ndarray, np.ndarray | None]:
    """Distances and RSSI (N, channels) as the echo filter picks them: the first or the last echo
    as DIST1, or every echo (DIST1..DISTE); 0 where a beam has no such echo (RSSI None unless asked)."""
    echoes = np.asarray(scan.echoes)[:, : model.echoes]
    powers = np.asarray(scan.echo_intensities)[:, : model.echoes]
    if settings.echo_filter == ECHO_ALL:
        chosen, chosen_power = echoes, powers
    elif settings.echo_filter == ECHO_FIRST:
        chosen, chosen_power = echoes[:, :1], powers[:, :1]
    else:
        pick = np.maximum((echoes >= 0).sum(axis=1) - 1, 0)[:, None]
        chosen, chosen_power = np.take_along_axis(echoes, pick, 1), np.take_along_axis(powers, pick, 1)
    seen = chosen >= 0
    distances = np.minimum(np.where(seen, chosen, 0), 0xFFFF).astype(np.uint16)
    if not settings.rssi:
        return distances, None
    return distances, np.where(seen, np.clip(chosen_power, 0, 0xFFFF), 0).astype(np.uint16)


def _micros(seconds: float) -> int:
    return max(0, int(round(seconds * 1_000_000)))


def _clock(seconds: float) -> tuple[int, int, int, int, int, int, int]:
    moment = CLOCK_BASE + datetime.timedelta(seconds=max(0.0, seconds))
    return moment.year, moment.month, moment.day, moment.hour, moment.minute, moment.second, moment.microsecond


def _argument_error(message: str, dialect: Dialect) -> int:
    if message.startswith("not a number"):
        return COLA_A_INVALID_CHARACTER
    if "does not fit" in message:
        return COLA_A_VALUE_OVERFLOW if dialect is Dialect.ASCII else LOCAL_CONDITION_FAILED
    return BUFFER_UNDERFLOW


@functools.lru_cache(maxsize=64)
def _error_output(code: int, dialect: Dialect) -> Output:
    """The `sFA` answer with Sopas error `code` (hex in CoLa-A, a u16 in CoLa-B)."""
    return _output(frame(b"sFA " + encode([u16(code) if dialect is Dialect.BINARY else u8(code)], dialect), dialect))


def _output(data: bytes, droppable: bool = False) -> Output:
    return Output(data, None, droppable=droppable)


def _output_beams(output_start: int, output_stop: int, field_start: int, field_stop: int, count: int) -> tuple[int, int]:
    """The first and last beam within LMPoutputRange, a beam counted in when its angle, in whole ticks
    as the telegram states it, lies in the range. The beams are (stop − start) / (count − 1) apart, not the
    rounded resolution (0.3333° is 1/3°: dividing by 3333 ticks put 0° past beam 135, and left it out)."""
    beams_per_tick = (count - 1) / (field_stop - field_start)
    first = math.ceil((output_start - field_start - 0.5) * beams_per_tick)
    last = math.floor((output_stop - field_start + 0.5) * beams_per_tick)
    return max(0, first), min(count - 1, last)
