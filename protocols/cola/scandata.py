"""The LMDscandata telegram's arguments: every field a unit sends, in its order, as CoLa-A text or CoLa-B bytes.

version, device number, serial number, device status (2 bytes), telegram
counter, scan counter, time since power-up and time of transmission (µs),
digital inputs and outputs (2 bytes each), a reserved u16, scan frequency
(1/100 Hz), measurement frequency (100 Hz), encoders, the 16-bit channels
(DIST1..DIST5, RSSI when 16 bits wide), the 8-bit channels (RSSI1..RSSI5),
then the position, name, comment, time and event blocks (docs/cola.md).

A streaming unit sends one of these per scan on the daemon's loop, so they are
written in one piece: the fixed fields with one `struct` (CoLa-B) or one `%X`
format (CoLa-A), each channel's values with numpy (`>u2` bytes, or hex tokens
read off a table), never a Python call per value. Encoding a TiM571's telegram
costs tens of µs (docs/cola.md "Speed").
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

import numpy as np

from protocols.cola.framing import Dialect
from protocols.cola.values import hex_token_runs

VERSION = 1
DEVICE_NUMBER = 1

# version … measurement frequency: the fields every telegram starts with (CoLa-B)
_HEAD = struct.Struct(">HHIBBHHIIBBBBHII")
_ENCODER = struct.Struct(">HIH")  # one encoder: count 1, position, speed
_CHANNEL = struct.Struct(">5sffiHH")  # content, scale, offset, start angle, step, count
_TIME = struct.Struct(">HHBBBBBI")  # count 1, year, month, day, hour, minute, second, µs
_U16 = struct.Struct(">H")
_F32 = struct.Struct(">f")
_U32 = struct.Struct(">I")
_ASCII_HEAD = b" ".join([b"%X"] * 16)


@dataclass(frozen=True)
class Channel:
    """One output channel: `content` "DIST1".."DIST5" or "RSSI1".."RSSI5", wire values (N,)."""

    content: str
    scale: float
    start_ticks: int  # 1/10 000 °
    step_ticks: int
    values: np.ndarray
    sixteen_bits: bool


@dataclass(frozen=True)
class ScanHeader:
    """The per-telegram fields before the channels."""

    serial_number: int
    device_status: int  # 0 ok, 1 error, 2 pollution warning (the first of the two status bytes)
    telegram_counter: int
    scan_counter: int
    power_up_us: int  # the scan's first beam, µs since power-up
    transmission_us: int
    scan_frequency_ticks: int  # 1/100 Hz
    measurement_frequency: int  # 100 Hz units
    encoder: tuple[int, int] | None  # (position, speed) when an encoder is configured
    device_name: str | None
    time: tuple[int, int, int, int, int, int, int] | None  # year, month, day, hour, minute, second, µs


def scandata_arguments(header: ScanHeader, channels: list[Channel], dialect: Dialect) -> bytes:
    """The telegram's arguments, as they follow `sSN LMDscandata ` (or `sRA LMDscandata `)."""
    head = (
        VERSION, DEVICE_NUMBER, header.serial_number & 0xFFFF_FFFF, header.device_status, 0,
        header.telegram_counter & 0xFFFF, header.scan_counter & 0xFFFF,
        header.power_up_us & 0xFFFF_FFFF, header.transmission_us & 0xFFFF_FFFF,
        0, 0, 0, 0, 0, header.scan_frequency_ticks, header.measurement_frequency,
    )
    wide = [channel for channel in channels if channel.sixteen_bits]
    narrow = [channel for channel in channels if not channel.sixteen_bits]
    if dialect is Dialect.ASCII:
        return _ascii(head, header, wide, narrow)
    return _binary(head, header, wide, narrow)


def _binary(head: tuple, header: ScanHeader, wide: list[Channel], narrow: list[Channel]) -> bytes:
    parts = [_HEAD.pack(*head)]
    parts.append(_U16.pack(0) if header.encoder is None else _ENCODER.pack(1, *header.encoder))
    for chosen, dtype in ((wide, ">u2"), (narrow, "u1")):
        parts.append(_U16.pack(len(chosen)))
        for channel in chosen:
            values = np.asarray(channel.values)
            parts.append(_CHANNEL.pack(channel.content.encode("ascii"), channel.scale, 0.0, channel.start_ticks,
                                       channel.step_ticks, len(values)))
            parts.append(values.astype(dtype).tobytes())
    parts.append(_U16.pack(0))  # no position block
    if header.device_name is None:
        parts.append(_U16.pack(0))
    else:
        name = header.device_name.encode("ascii")
        parts.append(_U16.pack(1) + _U16.pack(len(name)) + name)
    parts.append(_U16.pack(0))  # no comment
    parts.append(_U16.pack(0) if header.time is None else _TIME.pack(1, *header.time))
    parts.append(_U16.pack(0))  # no event block
    return b"".join(parts)


def _ascii(head: tuple, header: ScanHeader, wide: list[Channel], narrow: list[Channel]) -> bytes:
    """CoLa-A: integers in hex without leading zeros (an i32 as its two's complement), floats as the
    eight hex digits of their bits, a string with its length as `LEN TEXT`, tokens one space apart."""
    parts = [_ASCII_HEAD % head]
    parts.append(b"0" if header.encoder is None else b"1 %X %X" % header.encoder)
    runs = iter(hex_token_runs([channel.values for channel in wide + narrow]))
    for chosen in (wide, narrow):
        parts.append(b"%X" % len(chosen))
        for channel in chosen:
            parts.append(b"%s %08X 00000000 %X %X %X" % (
                channel.content.encode("ascii"), _U32.unpack(_F32.pack(channel.scale))[0],
                channel.start_ticks & 0xFFFF_FFFF, channel.step_ticks, len(channel.values)))
            tokens = next(runs)
            if tokens:
                parts.append(tokens)
    parts.append(b"0")  # no position block
    if header.device_name is None:
        parts.append(b"0")
    else:
        name = header.device_name.encode("ascii")
        parts.append(b"1 %X %s" % (len(name), name))
    parts.append(b"0")  # no comment
    parts.append(b"0" if header.time is None else b"1 %X %X %X %X %X %X %X" % header.time)
    parts.append(b"0")  # no event block
    return b" ".join(parts)
