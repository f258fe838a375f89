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
    telegram with a wrong checksum or a length beyond MAX_TELEGRAM, a CoLa-A telegram longer
    than MAX_TELEGRAM, a CoLa-A telegram cut short by a new STX (the half before it)."""

    def __init__(self) -> None:
        self._buffer = bytearray()
        self.dropped = 0

    def clear(self) -> None:
        self._buffer.clear()

    def feed(self, data: bytes) -> list[Telegram]:
        buffer = self._buffer
        buffer += data
        telegrams: list[Telegram] = []
        while True:
            start = buffer.find(STX)
            if start < 0:
                buffer.clear()
                return telegrams
            del buffer[:start]
            if len(buffer) < 4 and buffer == BINARY_START[: len(buffer)]:
                return telegrams  # could still open a CoLa-B telegram
            if buffer.startswith(BINARY_START):
                if not self._binary(telegrams):
                    return telegrams
            elif not self._ascii(telegrams):
                return telegrams

    def _binary(self, telegrams: list[Telegram]) -> bool:
        """One CoLa-B telegram off the buffer's head; False when it is not all here yet."""
        buffer = self._buffer
        if len(buffer) < BINARY_HEADER:
            return False
        length = int.from_bytes(buffer[4:8], "big")
        if length > MAX_TELEGRAM:
            self.dropped += 1
            del buffer[:BINARY_HEADER]
            return True
        end = BINARY_HEADER + length + 1
        if len(buffer) < end:
            return False
        payload = bytes(buffer[BINARY_HEADER:end - 1])
        if checksum(payload) == buffer[end - 1] and payload:
            telegrams.append(Telegram(Dialect.BINARY, payload))
        else:
            self.dropped += 1
        del buffer[:end]
        return True

    def _ascii(self, telegrams: list[Telegram]) -> bool:
        """One CoLa-A telegram off the buffer's head; False when its ETX has not come yet."""
        buffer = self._buffer
        end = buffer.find(ETX, 1)
        restart = buffer.find(STX, 1, end if end >= 0 else len(buffer))
        if restart >= 0:
            self.dropped += 1
            del buffer[:restart]
            return True
        if end < 0:
            if len(buffer) > MAX_TELEGRAM:
                self.dropped += 1
                buffer.clear()
            return False
        payload = bytes(buffer[1:end])
        del buffer[:end + 1]
        if payload:
            telegrams.append(Telegram(Dialect.ASCII, payload))
        return True
