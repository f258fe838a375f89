"""CoLa framing: CoLa-A `STX text ETX`, CoLa-B `02 02 02 02, length (u32 BE), payload, XOR checksum`.

One reader serves both, as the units' ports do: a telegram that opens with
four STX bytes is CoLa-B, one STX followed by anything else is CoLa-A. Bytes
outside a telegram are ignored (MRPT's TiM driver sends a NUL after each
ETX). Whole-buffer searches (`bytes.find`), never a Python call per byte.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum

import numpy as np

STX, ETX = 0x02, 0x03
BINARY_START = b"\x02\x02\x02\x02"
BINARY_HEADER = 8  # the four STX and the length
MAX_TELEGRAM = 16_384  # a request longer than this is dropped (no command needs near as much)
MAX_SCAN_TELEGRAM = 1 << 20  # what a host reading the unit takes: an LMS5xx scan of every echo and RSSI in CoLa-A is ~60 KB


class Dialect(Enum):
    ASCII = "A"
    BINARY = "B"


@dataclass(frozen=True)
class Telegram:
    """One request: its payload (command and arguments), and the dialect the answer must use."""

    dialect: Dialect
    payload: bytes


def checksum(payload: bytes) -> int:
    """CoLa-B's checksum: the XOR of the payload's bytes."""
    return int(np.bitwise_xor.reduce(np.frombuffer(payload, np.uint8))) if payload else 0


def frame(payload: bytes, dialect: Dialect) -> bytes:
    if dialect is Dialect.ASCII:
        return b"\x02" + payload + b"\x03"
    return BINARY_START + len(payload).to_bytes(4, "big") + payload + bytes((checksum(payload),))


class ColaReader:
    """Cuts a byte stream into telegrams. Dropped silently, as a unit drops them: a CoLa-B
    telegram with a wrong checksum or a length beyond `max_telegram` (a unit's: MAX_TELEGRAM), a
    CoLa-A telegram longer than that, a CoLa-A telegram cut short by a new STX (the half before it)."""

    def __init__(self, max_telegram: int = MAX_TELEGRAM) -> None:
        self._buffer = bytearray()
        self.dropped = 0
        self.max_telegram = max_telegram  # a host's reader of the unit's telegrams takes its scans (MAX_SCAN_TELEGRAM)

    def clear(self) -> None:
        self._buffer.clear()

    def feed(self, data: bytes) -> list[Telegram]:
        """The whole telegrams `data` completes, in order; what is left waits for more (read from an
        offset and cut once, so thousands of telegrams in one chunk cost no quadratic copying)."""
        buffer = self._buffer
        buffer += data
        telegrams: list[Telegram] = []
        at = 0
        while True:
            start = buffer.find(STX, at)
            if start < 0:
                at = len(buffer)
                break
            at = start
            if len(buffer) - at < 4 and buffer[at:] == BINARY_START[: len(buffer) - at]:
                break  # could still open a CoLa-B telegram
            taken = self._binary(at, telegrams) if buffer.startswith(BINARY_START, at) else self._ascii(at, telegrams)
            if taken is None:
                break
            at = taken
        del buffer[:at]
        return telegrams

    def _binary(self, at: int, telegrams: list[Telegram]) -> int | None:
        """The CoLa-B telegram at `at`: where the next byte to read is, None when it is not all here yet."""
        buffer = self._buffer
        if len(buffer) - at < BINARY_HEADER:
            return None
        length = int.from_bytes(buffer[at + 4:at + 8], "big")
        if length > self.max_telegram:
            self.dropped += 1
            return at + BINARY_HEADER
        end = at + BINARY_HEADER + length + 1
        if len(buffer) < end:
            return None
        payload = bytes(buffer[at + BINARY_HEADER:end - 1])
        if payload and checksum(payload) == buffer[end - 1]:
            telegrams.append(Telegram(Dialect.BINARY, payload))
        else:
            self.dropped += 1
        return end

    def _ascii(self, at: int, telegrams: list[Telegram]) -> int | None:
        """The CoLa-A telegram at `at`: where the next byte to read is, None when its ETX has not come yet."""
        buffer = self._buffer
        end = buffer.find(ETX, at + 1)
        restart = buffer.find(STX, at + 1, end if end >= 0 else len(buffer))
        if restart >= 0:
            self.dropped += 1
            return restart
        if end < 0:
            if len(buffer) - at > self.max_telegram:
                self.dropped += 1
                return len(buffer)
            return None
        if end - at > self.max_telegram:  # all here at once: counted as the pieces are above (its STX on)
            self.dropped += 1
            return end + 1
        payload = bytes(buffer[at + 1:end])
        if payload:
            telegrams.append(Telegram(Dialect.ASCII, payload))
        return end + 1
