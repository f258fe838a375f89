"""LMS2xx telegram framing: the CRC of TL §9, building telegrams, and a reader
that finds host telegrams in a byte stream and resynchronises after garbage.

A telegram is `STX ADDR LEN_lo LEN_hi CMD DATA… [STATUS] CRC_lo CRC_hi`; LEN
counts CMD through STATUS, so a telegram is LEN + 6 bytes, at most 812 (814
for a 0.25° scan with real-time indices, TL Table 10-16).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

STX = 0x02
ACK = b"\x06"
NAK = b"\x15"
HOST_ADDRESS = 0x00
REPLY_ADDRESS_FLAG = 0x80  # device → host telegrams carry the address + 0x80
MAX_TELEGRAM_BYTES = 812  # the bound on what the reader accepts from a host
MAX_REPLY_BYTES = 814  # 100°/0.25° scan (812 bytes) plus the two real-time indices
FRAME_OVERHEAD = 6  # STX, ADDR, LEN (2), CRC (2)
MAX_LENGTH_FIELD = MAX_TELEGRAM_BYTES - FRAME_OVERHEAD
HEADER_BYTES = 4

# Host bytes of one telegram may be up to 6 ms apart (TL §4.3); drivers under
# load exceed that, so the partial telegram is only abandoned after this gap.
DEFAULT_GAP_TOLERANCE_S = 0.2

_CRC_POLYNOMIAL = 0x8005


def _power_table(rows: int) -> np.ndarray:
    """table[k, b] = b · x^k modulo x^16 + x^15 + x^2 + 1: one CRC register shift per row.

    The LMS CRC is linear: after n bytes the register holds the XOR over i of
    (b_i | b_{i-1} << 8) · x^(n-1-i), so a table lookup per byte and one XOR
    reduction replace the per-byte loop of TL §9.
    """
    table = np.empty((rows, 256), dtype=np.uint16)
    row = np.arange(256, dtype=np.uint32)
    for power in range(rows):
        table[power] = row
        carry = (row & 0x8000) != 0
        row = ((row & 0x7FFF) << 1) ^ np.where(carry, _CRC_POLYNOMIAL, 0)
    return table


_POWERS = _power_table(MAX_REPLY_BYTES + 8)


def crc16(data: bytes) -> int:
    """The LMS2xx CRC (TL §9) of `data` (STX through STATUS), at most 814 bytes."""
    if len(data) > MAX_REPLY_BYTES:
        raise ValueError(f"crc16 covers at most {MAX_REPLY_BYTES} bytes, got {len(data)}")
    octets = np.frombuffer(data, dtype=np.uint8)
    if octets.size == 0:
        return 0
    powers = np.arange(octets.size - 1, -1, -1)
    terms = _POWERS[powers, octets]
    terms[1:] ^= _POWERS[powers[1:] + 8, octets[:-1]]
    return int(np.bitwise_xor.reduce(terms))


def build_telegram(address: int, body: bytes) -> bytes:
    """Frame `body` (CMD, DATA and, for device replies, STATUS) with STX, ADDR, LEN and CRC.

    Host telegrams use address 0x00; device replies use 0x80 (address + 0x80).
    """
    if not 0 <= address <= 0xFF:
        raise ValueError(f"address must be a byte, got {address}")
    longest = MAX_REPLY_BYTES - FRAME_OVERHEAD
    if not 1 <= len(body) <= longest:
        raise ValueError(f"telegram body must be 1..{longest} bytes, got {len(body)}")
    head = bytes((STX, address)) + len(body).to_bytes(2, "little") + body
    return head + crc16(head).to_bytes(2, "little")


@dataclass(frozen=True)
class Telegram:
    """A host telegram with a correct CRC: `body` is CMD + DATA."""

    address: int
    body: bytes


@dataclass(frozen=True)
class CorruptTelegram:
    """A complete host frame whose CRC is wrong (the device answers NAK if it is addressed)."""

    address: int


FrameEvent = Telegram | CorruptTelegram


class TelegramReader:
    """Host telegrams out of a byte stream, never trusting sizes from the wire.

    A candidate starts at STX; an address with bit 7 set (a device telegram,
    not a host one) or a LEN outside 1..806 rejects it at once. A rejected or
    corrupt candidate costs only its STX: scanning resumes at the next byte, so
    a valid telegram hidden behind garbage is still found. When the next byte
    of a partial telegram is more than `gap_tolerance_s` late, the partial is
    abandoned (any complete telegram among the waiting bytes still counts).
    """

    def __init__(self, gap_tolerance_s: float = DEFAULT_GAP_TOLERANCE_S) -> None:
        self.gap_tolerance_s = gap_tolerance_s
        self._buffer = bytearray()
        self._last_byte_at = 0.0

    def feed(self, data: bytes, now: float) -> list[FrameEvent]:
        """Bytes received at `now`: the telegrams they complete, in order."""
        events = self.expire(now)
        if data:
            self._buffer += data
            self._last_byte_at = now
        events += self._extract(final=False)
        return events

    def expire(self, now: float) -> list[FrameEvent]:
        """Abandon a partial telegram whose next byte is overdue at `now`."""
        if not self._buffer or now - self._last_byte_at <= self.gap_tolerance_s:
            return []
        events = self._extract(final=True)
        self._buffer.clear()
        return events

    def deadline(self) -> float | None:
        """When a waiting partial telegram will be abandoned, or None."""
        return self._last_byte_at + self.gap_tolerance_s if self._buffer else None

    def clear(self) -> None:
        self._buffer.clear()

    def _extract(self, *, final: bool) -> list[FrameEvent]:
        """Complete frames in the buffer; with `final`, incomplete candidates are skipped."""
        buffer = self._buffer
        events: list[FrameEvent] = []
        position = 0
        while True:
            start = buffer.find(STX, position)
            if start < 0:
                position = len(buffer)
                break
            if len(buffer) - start < HEADER_BYTES:
                if final:
                    position = start + 1
                    continue
                position = start
                break
            address = buffer[start + 1]
            length = int.from_bytes(buffer[start + 2 : start + 4], "little")
            if address & REPLY_ADDRESS_FLAG or not 1 <= length <= MAX_LENGTH_FIELD:
                position = start + 1
                continue
            end = start + length + FRAME_OVERHEAD
            if end > len(buffer):
                if final:
                    position = start + 1
                    continue
                position = start
                break
            frame = bytes(buffer[start:end])
            if crc16(frame[:-2]) == int.from_bytes(frame[-2:], "little"):
                events.append(Telegram(address, frame[HEADER_BYTES:-2]))
                position = end
            else:
                events.append(CorruptTelegram(address))
                position = start + 1
        del buffer[:position]
        return events
