"""A driver-like CoLa client over TCP: requests in CoLa-A or CoLa-B, LMDscandata read field by field.

Shared by the bench (streaming rates, jitter) and the tests (a client's scans
against `lrf-emulator scan`). It reads the telegrams with the field table of
SICK's listing (docs/cola.md), not with the emulator's encoder.
"""

from __future__ import annotations

import socket
import struct
import time
from dataclasses import dataclass

from protocols.cola.framing import MAX_SCAN_TELEGRAM, ColaReader, Dialect, Telegram, frame

READ_CHUNK = 1 << 16


@dataclass(frozen=True)
class ScanTelegram:
    """The fields of one LMDscandata telegram a client needs, and when it arrived (monotonic s)."""

    telegram_counter: int
    scan_counter: int
    power_up_us: int
    transmission_us: int
    scan_frequency: int
    start_ticks: int
    step_ticks: int
    distances: list[int]
    channels: list[str]
    received_s: float
    rssi: list[int] | None = None  # RSSI1, if the telegram has it


class ColaClient:
    """One TCP connection to a CoLa endpoint."""

    def __init__(self, host: str, port: int, dialect: Dialect = Dialect.ASCII, timeout_s: float = 5.0) -> None:
        self.dialect = dialect
        self._sock = socket.create_connection((host, port), timeout=timeout_s)
        self._sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self._reader = ColaReader(MAX_SCAN_TELEGRAM)  # the unit's scans, not a request's bound
        self._queue: list[tuple[Telegram, float]] = []

    def close(self) -> None:
        self._sock.close()

    def __enter__(self) -> ColaClient:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    def send(self, payload: bytes) -> None:
        self._sock.sendall(frame(payload, self.dialect))

    def send_at_once(self, payloads: list[bytes]) -> None:
        """Several requests in one write, as a driver's burst or a hostile client sends them."""
        self._sock.sendall(b"".join(frame(payload, self.dialect) for payload in payloads))

    def next_telegram(self, timeout_s: float = 5.0) -> tuple[Telegram, float]:
        deadline = time.monotonic() + timeout_s
        while not self._queue:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise TimeoutError("no telegram")
            self._sock.settimeout(remaining)
            data = self._sock.recv(READ_CHUNK)
            if not data:
                raise ConnectionError("the endpoint closed the connection")
            now = time.monotonic()
            self._queue += [(telegram, now) for telegram in self._reader.feed(data)]
        return self._queue.pop(0)

    def ask(self, payload: bytes, timeout_s: float = 5.0) -> bytes:
        """Send a request; the payload of the first answer that is not a streamed scan."""
        self.send(payload)
        while True:
            telegram, _ = self.next_telegram(timeout_s)
            if not telegram.payload.startswith(b"sSN "):
                return telegram.payload

    def scan(self, timeout_s: float = 5.0) -> ScanTelegram:
        """The next streamed LMDscandata telegram."""
        while True:
            telegram, received = self.next_telegram(timeout_s)
            if telegram.payload.startswith(b"sSN LMDscandata ") or telegram.payload.startswith(b"sRA LMDscandata "):
                return parse_scandata(telegram.payload, telegram.dialect, received)


def parse_scandata(payload: bytes, dialect: Dialect, received_s: float = 0.0) -> ScanTelegram:
    """The header fields, DIST1 and RSSI1 of an LMDscandata telegram (channel names listed)."""
    fields = _Fields(payload.split(b" ", 2)[2], dialect)
    fields.skip(["u16", "u16", "u32", "u8", "u8"])
    telegram, scan = fields.take("u16"), fields.take("u16")
    power_up, transmission = fields.take("u32"), fields.take("u32")
    fields.skip(["u8", "u8", "u8", "u8", "u16"])
    frequency = fields.take("u32")
    fields.skip(["u32"])
    for _ in range(fields.take("u16")):
        fields.skip(["u32", "u16"])
    channels: list[str] = []
    distances: list[int] = []
    rssi: list[int] | None = None
    start = step = 0
    for width in ("u16", "u8"):
        for _ in range(fields.take("u16")):
            name = fields.name()
            fields.skip(["u32", "u32"])
            channel_start, channel_step, count = fields.take("i32"), fields.take("u16"), fields.take("u16")
            values = [fields.take(width) for _ in range(count)]
            channels.append(name)
            if name == "DIST1":
                start, step, distances = channel_start, channel_step, values
            elif name == "RSSI1":
                rssi = values
    return ScanTelegram(telegram, scan, power_up, transmission, frequency, start, step, distances, channels, received_s, rssi)


class _Fields:
    _CODES = {"u8": ">B", "u16": ">H", "u32": ">I", "i32": ">i"}

    def __init__(self, data: bytes, dialect: Dialect) -> None:
        self._dialect = dialect
        self._tokens = data.split(b" ") if dialect is Dialect.ASCII else None
        self._data = data
        self._at = 0

    def take(self, kind: str) -> int:
        if self._tokens is not None:
            value = int(self._tokens[self._at], 16)
            self._at += 1
            if kind == "i32" and value >= 1 << 31:
                value -= 1 << 32
            return value
        code = self._CODES[kind]
        value = struct.unpack_from(code, self._data, self._at)[0]
        self._at += struct.calcsize(code)
        return value

    def skip(self, kinds: list[str]) -> None:
        for kind in kinds:
            self.take(kind)

    def name(self) -> str:
        if self._tokens is not None:
            self._at += 1
            return self._tokens[self._at - 1].decode("ascii")
        self._at += 5
        return self._data[self._at - 5:self._at].decode("ascii")
