"""CoLa argument values: typed scalars and strings, as CoLa-A text or CoLa-B bytes; hex tokens of arrays.

CoLa-A writes integers in upper-case hex without leading zeros (signed ones
as their two's complement: -45° = -450000 = FFF92230), floats as the eight
hex digits of their IEEE 754 bits, and a string with a length as `LEN TEXT`
(the length in hex). A host may also write decimals with a sign (`+2500`,
`-450000`). CoLa-B writes every value big-endian at its width, and a string
with a length as a u16 length and its bytes. LMDscandata, sent per scan, is
written in one piece by protocols.cola.scandata (with `hex_tokens` for its
channels in CoLa-A).
"""

from __future__ import annotations

import re
import struct
from dataclasses import dataclass

import numpy as np

from protocols.cola.framing import Dialect

# kind → (struct code, signed)
SCALARS = {"u8": ("B", False), "u16": ("H", False), "u32": ("I", False),
           "i8": ("b", True), "i16": ("h", True), "i32": ("i", True)}
_HEX_DIGITS = np.frombuffer(b"0123456789ABCDEF", np.uint8)


class BadArguments(ValueError):
    """A request's arguments do not parse (too few, not a number, out of range)."""


@dataclass(frozen=True)
class Value:
    """One argument: `kind` is a scalar kind of SCALARS or "flex" (a string with its length)."""

    kind: str
    value: object


def u8(value: int) -> Value:
    return Value("u8", value)


def u16(value: int) -> Value:
    return Value("u16", value)


def u32(value: int) -> Value:
    return Value("u32", value)


def i16(value: int) -> Value:
    return Value("i16", value)


def i32(value: int) -> Value:
    return Value("i32", value)


def flex(text: str) -> Value:
    return Value("flex", text.encode("ascii"))


def _u16_table() -> tuple[np.ndarray, np.ndarray]:
    """Every u16's CoLa-A token, left-aligned with its trailing space ((65536, 5) chars), and which of
    the five are its own (digits and space)."""
    values = np.arange(1 << 16, dtype=np.uint64)
    digits = np.maximum(_digit_counts(values), 1)
    nibbles = (values[:, None] >> (np.arange(3, -1, -1, dtype=np.uint64) * np.uint64(4))[None, :]) & np.uint64(0xF)
    right_aligned = _HEX_DIGITS[nibbles.astype(np.intp)]  # "003F"
    shift = (4 - digits)[:, None]  # drop the leading zeros: column j takes column j + shift
    columns = np.minimum(np.arange(5)[None, :] + shift, 4)
    table = np.take_along_axis(np.concatenate([right_aligned, np.full((len(values), 1), ord(" "), np.uint8)], axis=1),
                               columns, axis=1)
    table[np.arange(5)[None, :] == digits[:, None]] = ord(" ")
    return table, np.arange(5)[None, :] <= digits[:, None]


def _u16_tokens() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """`_u16_table`, built on first use, and each u16's token length (digits and space)."""
    global _U16_TOKENS
    if _U16_TOKENS is None:
        table, own = _u16_table()
        _U16_TOKENS = table, own, own.sum(axis=1)
    return _U16_TOKENS


def prepare_tables() -> None:
    """Build the u16 token table now: 15–20 ms of numpy (70 ms on a busy machine) that the first scan
    telegram would otherwise pay, late for a driver polling with a 40 ms timeout (MRPT's CLMS100Eth
    then stores empty scans). A device calls it when it is made, before any client asks."""
    _u16_tokens()


def _fits_u16(values: np.ndarray) -> bool:
    return values.dtype == np.uint16 or (int(values.max()) <= 0xFFFF and int(values.min()) >= 0)


def hex_tokens(values: np.ndarray) -> bytes:
    """Non-negative integers as upper-case hex without leading zeros, each followed by a space
    (vectorised: u16 values read their tokens off a table; wider ones get their digits computed
    all at once, the significant ones kept)."""
    values = np.asarray(values)
    if values.size == 0:
        return b""
    if _fits_u16(values):
        table, own, _ = _u16_tokens()
        index = values.astype(np.intp)
        return np.take(table, index, axis=0).ravel()[np.take(own, index, axis=0).ravel()].tobytes()
    values = values.astype(np.uint64)
    width = max(1, (int(values.max()).bit_length() + 3) // 4)
    shifts = np.arange(width - 1, -1, -1, dtype=np.uint64) * np.uint64(4)
    nibbles = (values[:, None] >> shifts[None, :]) & np.uint64(0xF)
    digits = (width - np.arange(width))[None, :] <= np.maximum(_digit_counts(values), 1)[:, None]
    chars = np.empty((len(values), width + 1), np.uint8)
    chars[:, :width] = _HEX_DIGITS[nibbles.astype(np.intp)]
    chars[:, width] = ord(" ")
    keep = np.ones((len(values), width + 1), bool)
    keep[:, :width] = digits
    return chars[keep].tobytes()


_U16_TOKENS: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None


def hex_token_runs(arrays: list[np.ndarray]) -> list[bytes]:
    """`hex_tokens` of each array without its last space, all u16 arrays read off the table in one
    pass (a telegram's ten channels cost one numpy call, not ten)."""
    arrays = [np.asarray(values) for values in arrays]
    sized = [values for values in arrays if values.size]
    if len(sized) < 2 or not all(_fits_u16(values) for values in sized):
        return [hex_tokens(values)[:-1] for values in arrays]
    table, own, lengths = _u16_tokens()
    index = np.concatenate(sized).astype(np.intp)
    text = np.take(table, index, axis=0).ravel()[np.take(own, index, axis=0).ravel()].tobytes()
    ends = iter(np.cumsum(np.take(lengths, index))[np.cumsum([len(values) for values in sized]) - 1].tolist())
    runs, start = [], 0
    for values in arrays:
        if not values.size:
            runs.append(b"")
            continue
        end = next(ends)
        runs.append(text[start:end - 1])
        start = end
    return runs


def _digit_counts(values: np.ndarray) -> np.ndarray:
    """Hex digits each value needs (0 for 0)."""
    bits = np.zeros(len(values), np.int64)
    remaining = values.copy()
    for shift in (32, 16, 8, 4, 2, 1):  # a binary search of the bit length, all values at once
        step = np.uint64(shift)
        high = remaining >= (np.uint64(1) << step)
        bits += np.where(high, shift, 0)
        remaining = np.where(high, remaining >> step, remaining)
    bits += (remaining > 0).astype(np.int64)
    return (bits + 3) // 4


def _ascii_scalar(kind: str, value: int) -> bytes:
    code, signed = SCALARS[kind]
    bits = struct.calcsize(code) * 8
    if signed and value < 0:
        value += 1 << bits
    return f"{value:X}".encode("ascii")


def encode(values: list[Value], dialect: Dialect) -> bytes:
    """The arguments as they follow a command name (and its space) in a telegram."""
    if dialect is Dialect.ASCII:
        return _encode_ascii(values)
    return b"".join(_binary(value) for value in values)


def _encode_ascii(values: list[Value]) -> bytes:
    parts = []
    for value in values:
        kind = value.kind
        if kind in SCALARS:
            parts.append(_ascii_scalar(kind, int(value.value)))
        elif kind == "flex":
            parts.append(f"{len(value.value):X} ".encode("ascii") + value.value)
        else:
            raise ValueError(f"unknown value kind {kind!r}")
    return b" ".join(parts)


def _binary(value: Value) -> bytes:
    kind = value.kind
    if kind in SCALARS:
        return struct.pack(">" + SCALARS[kind][0], int(value.value))
    if kind == "flex":
        return struct.pack(">H", len(value.value)) + value.value
    raise ValueError(f"unknown value kind {kind!r}")


def decode(arguments: bytes, kinds: tuple[str, ...], dialect: Dialect) -> list[object]:
    """A request's arguments of the given scalar kinds (or "flex"); BadArguments if they do not parse."""
    if dialect is Dialect.ASCII:
        return _decode_ascii(arguments.split(), kinds)
    return _decode_binary(arguments, kinds)


def _decode_ascii(tokens: list[bytes], kinds: tuple[str, ...]) -> list[object]:
    values: list[object] = []
    position = 0
    for kind in kinds:
        if position >= len(tokens):
            raise BadArguments(f"{len(kinds)} arguments expected")
        token = tokens[position]
        position += 1
        if kind == "flex":
            length = _ascii_number(token, "u16")
            text = b" ".join(tokens[position:])[:length]
            values.append(text.decode("ascii", "replace"))
            position = len(tokens)
            continue
        values.append(_ascii_number(token, kind))
    return values


_DECIMAL = re.compile(rb"[+-][0-9]+")  # CoLa-A: a sign makes a number decimal
_HEX = re.compile(rb"[0-9A-Fa-f]+")


def _ascii_number(token: bytes, kind: str) -> int:
    code, signed = SCALARS[kind]
    bits = struct.calcsize(code) * 8
    if _DECIMAL.fullmatch(token):
        value = int(token, 10)
    elif _HEX.fullmatch(token):
        value = int(token, 16)
        if signed and value >= 1 << (bits - 1) and len(token) * 4 >= bits:
            value -= 1 << bits  # FFF92230: a negative i32 written as its two's complement
    else:  # Python's int() would also take 1_0, 0x10 and ０ (a full-width digit)
        raise BadArguments(f"not a number: {token[:20]!r}")
    low, high = (-(1 << (bits - 1)), (1 << (bits - 1)) - 1) if signed else (0, (1 << bits) - 1)
    if not low <= value <= high:
        raise BadArguments(f"{value} does not fit a {kind}")
    return value


def _decode_binary(arguments: bytes, kinds: tuple[str, ...]) -> list[object]:
    values: list[object] = []
    offset = 0
    for kind in kinds:
        if kind == "flex":
            if offset + 2 > len(arguments):
                raise BadArguments("string length missing")
            length = struct.unpack_from(">H", arguments, offset)[0]
            offset += 2
            if offset + length > len(arguments):
                raise BadArguments("string shorter than its length")
            values.append(arguments[offset:offset + length].decode("ascii", "replace"))
            offset += length
            continue
        code = ">" + SCALARS[kind][0]
        size = struct.calcsize(code)
        if offset + size > len(arguments):
            raise BadArguments(f"{len(kinds)} arguments expected")
        values.append(struct.unpack_from(code, arguments, offset)[0])
        offset += size
    return values
