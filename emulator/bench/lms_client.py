"""A minimal LMS200 host over a serial port, written from SICK's telegram listing.

It talks to the emulator the way sicktoolbox, Player and MRPT talk to a real
unit (framing, CRC, ACK, following the device's baud rate on the port's
termios), and deliberately shares no code with `protocols/lms2xx`, so that it
checks the device rather than agreeing with it. Used by the interop tests and
by the scans/s measurement in `emulator.bench.lms_rates`.
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
import serial

STX = 0x02
ACK = 0x06
NAK = 0x15
HOST_ADDRESS = 0x00
DEVICE_ADDRESS = 0x80
MAX_TELEGRAM_BYTES = 812
BAUD_COMMANDS = {9600: 0x42, 19200: 0x41, 38400: 0x40, 500000: 0x48}


def lms_crc(data: bytes) -> int:
    """SICK's CRC-16 (telegram listing §9), over STX … STATUS."""
    crc = 0
    previous = 0
    for byte in data:
        if crc & 0x8000:
            crc = ((crc & 0x7FFF) << 1) ^ 0x8005
        else:
            crc = (crc << 1) & 0xFFFF
        crc ^= byte | (previous << 8)
        previous = byte
    return crc


def host_telegram(payload: bytes) -> bytes:
    """STX, address 00, LEN, command + data, CRC (low byte first)."""
    head = bytes([STX, HOST_ADDRESS, len(payload) & 0xFF, len(payload) >> 8]) + payload
    return head + lms_crc(head).to_bytes(2, "little")


@dataclass(frozen=True)
class Telegram:
    """A CRC-valid device telegram and when its last byte arrived (time.monotonic)."""

    command: int
    data: bytes
    status: int
    raw: bytes
    arrived: float

    def b0_values(self) -> tuple[int, np.ndarray]:
        """(count word, value words with their flag bits) of a B0 measured-values telegram."""
        count_word = int.from_bytes(self.data[0:2], "little")
        count = count_word & 0x3FF
        return count_word, np.frombuffer(self.data, dtype="<u2", count=count, offset=2).astype(np.int64)


class TelegramReader:
    """Splits received bytes into ACK/NAK bytes and CRC-valid device telegrams.

    Bytes outside a telegram that are neither ACK nor NAK are skipped; a frame
    with a bad CRC or an impossible length loses only its STX, and the search
    restarts at the next byte. A frame whose bytes stop for longer than
    `stall_s` was cut short (a host command interrupts the device's output):
    it too loses its STX, so the ACK and reply behind it are found.
    """

    def __init__(self, stall_s: float = 0.05) -> None:
        self._buffer = bytearray()
        self._last_arrival = 0.0
        self.stall_s = stall_s  # the device's bytes are at most 14 ms apart
        self.skipped_bytes = 0
        self.bad_frames = 0
        self.torn_frames = 0

    def feed(self, data: bytes, now: float) -> Iterator[int | Telegram]:
        """Yield ACK / NAK (as ints) and Telegrams completed by `data` (b"" checks for a stall)."""
        if data:
            self._last_arrival = now
        elif self._buffer and now - self._last_arrival > self.stall_s:
            self.torn_frames += 1
            del self._buffer[0]
        self._buffer += data
        while self._buffer:
            first = self._buffer[0]
            if first in (ACK, NAK):
                del self._buffer[0]
                yield first
                continue
            if first != STX:
                start = self._next_candidate()
                self.skipped_bytes += start
                del self._buffer[:start]
                continue
            if len(self._buffer) < 4:
                return
            length = self._buffer[2] | (self._buffer[3] << 8)
            if self._buffer[1] != DEVICE_ADDRESS or not 2 <= length <= MAX_TELEGRAM_BYTES - 6:
                self._drop_stx()
                continue
            total = length + 6
            if len(self._buffer) < total:
                return
            frame = bytes(self._buffer[:total])
            if lms_crc(frame[:-2]) != int.from_bytes(frame[-2:], "little"):
                self._drop_stx()
                continue
            del self._buffer[:total]
            yield Telegram(frame[4], frame[5:-3], frame[-3], frame, now)

    def _next_candidate(self) -> int:
        positions = [self._buffer.find(byte) for byte in (STX, ACK, NAK)]
        found = [position for position in positions if position > 0]
        return min(found) if found else len(self._buffer)

    def _drop_stx(self) -> None:
        self.bad_frames += 1
        self.skipped_bytes += 1
        del self._buffer[0]


class LmsTimeout(TimeoutError):
    """The device did not answer in time."""


class LmsSerialClient:
    """A host on a serial port (a pty from `lrf-emulator serve`, or a real one)."""

    def __init__(self, port: str, baud: int = 9600) -> None:
        self.port = serial.Serial(port, baudrate=baud, timeout=0.02)
        self.reader = TelegramReader()

    @property
    def baud(self) -> int:
        return self.port.baudrate

    def close(self) -> None:
        self.port.close()

    def __enter__(self) -> LmsSerialClient:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    def set_port_baud(self, baud: int) -> None:
        """Change the host side's line rate (tcsetattr), as a driver does."""
        self.port.baudrate = baud

    def send(self, payload: bytes) -> None:
        self.port.write(host_telegram(payload))
        self.port.flush()

    def events(self, timeout_s: float) -> Iterator[int | Telegram]:
        """ACK/NAK bytes and telegrams as they arrive, for up to `timeout_s`."""
        deadline = time.monotonic() + timeout_s
        yield from self.reader.feed(b"", time.monotonic())  # left over from an earlier call
        while time.monotonic() < deadline:
            data = self.port.read(max(1, self.port.in_waiting))
            yield from self.reader.feed(data, time.monotonic())

    def discard_input(self, quiet_s: float = 0.05) -> None:
        """Drop whatever arrives until the line has been quiet for `quiet_s`."""
        self.port.reset_input_buffer()
        while self.port.read(max(1, self.port.in_waiting)):
            pass
        time.sleep(quiet_s)
        self.port.reset_input_buffer()
        self.reader = TelegramReader()

    def request(self, payload: bytes, timeout_s: float = 3.0) -> tuple[bool, Telegram]:
        """Send a command; return (ACK seen first, the reply telegram `command | 0x80`).

        Streamed telegrams that arrive meanwhile are skipped. Raises LmsTimeout.
        """
        expected = payload[0] | 0x80
        self.send(payload)
        acknowledged = False
        for event in self.events(timeout_s):
            if event == ACK:
                acknowledged = True
            elif isinstance(event, Telegram) and event.command == expected:
                return acknowledged, event
        raise LmsTimeout(f"no {expected:02X} reply to {payload.hex(' ')} within {timeout_s} s "
                         f"at {self.baud} Bd")

    def acknowledges(self, payload: bytes, timeout_s: float = 0.3) -> bool:
        """Whether the device ACKs `payload` at the port's current rate (a baud probe)."""
        self.send(payload)
        return any(event == ACK for event in self.events(timeout_s))

    def find_device_baud(self, rates: tuple[int, ...] = (9600, 19200, 38400, 500000)) -> int:
        """Probe like sicktoolbox: at each rate ask for the status (32) until ACKed."""
        for rate in rates:
            self.set_port_baud(rate)
            self.discard_input()
            if self.acknowledges(b"\x32"):
                self.discard_input()
                return rate
        raise LmsTimeout(f"no ACK at any of {rates}")

    def switch_baud(self, baud: int) -> Telegram:
        """20 4x at the current rate (the A0 comes back at the old rate), then follow."""
        _, reply = self.request(bytes([0x20, BAUD_COMMANDS[baud]]))
        self.set_port_baud(baud)
        return reply
