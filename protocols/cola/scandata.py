"""The LMDscandata telegram's arguments: every field a unit sends, in its order.

version, device number, serial number, device status (2 bytes), telegram
counter, scan counter, time since power-up and time of transmission (µs),
digital inputs and outputs (2 bytes each), a reserved u16, scan frequency
(1/100 Hz), measurement frequency (100 Hz), encoders, the 16-bit channels
(DIST1..DIST5, RSSI when 16 bits wide), the 8-bit channels (RSSI1..RSSI5),
then the position, name, comment, time and event blocks (docs/cola.md).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from protocols.cola.values import Value, array, f32, flex, i32, raw, u8, u16, u32

VERSION = 1
DEVICE_NUMBER = 1


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


def scandata_values(header: ScanHeader, channels: list[Channel]) -> list[Value]:
    values = [
        u16(VERSION), u16(DEVICE_NUMBER), u32(header.serial_number), u8(header.device_status), u8(0),
        u16(header.telegram_counter & 0xFFFF), u16(header.scan_counter & 0xFFFF),
        u32(header.power_up_us & 0xFFFF_FFFF), u32(header.transmission_us & 0xFFFF_FFFF),
        u8(0), u8(0), u8(0), u8(0), u16(0),
        u32(header.scan_frequency_ticks), u32(header.measurement_frequency),
    ]
    if header.encoder is None:
        values.append(u16(0))
    else:
        values += [u16(1), u32(header.encoder[0]), u16(header.encoder[1])]
    for wide in (True, False):
        chosen = [channel for channel in channels if channel.sixteen_bits == wide]
        values.append(u16(len(chosen)))
        for channel in chosen:
            values += [
                raw(channel.content), f32(channel.scale), f32(0.0), i32(channel.start_ticks), u16(channel.step_ticks),
                u16(len(channel.values)), array(channel.values, "u16[]" if wide else "u8[]"),
            ]
    values.append(u16(0))  # no position block
    values += [u16(1), flex(header.device_name)] if header.device_name is not None else [u16(0)]
    values.append(u16(0))  # no comment
    if header.time is None:
        values.append(u16(0))
    else:
        year, month, day, hour, minute, second, micros = header.time
        values += [u16(1), u16(year), u8(month), u8(day), u8(hour), u8(minute), u8(second), u32(micros)]
    values.append(u16(0))  # no event block
    return values
