"""Measured-value replies B0, B6, B7 and BF (TL §7.5.2, 7.11.2, 7.12.2, 7.20.2) and scan means.

Values are WORDs, already encoded for the measuring mode (`measuring.py`):
the distance field (13, 14 or 15 bits, error codes at its top) and the flags
above it. Means are computed from the raw field values and carry no flags.
"""

from __future__ import annotations

import numpy as np

DISTANCE_MASK = 0x1FFF
FIRST_ERROR_CODE = 8183
UNIT_BITS = {"cm": 0x0000, "mm": 0x4000}  # bits 14–15 of the count word
PARTIAL_SCAN_BIT = 0x2000  # bit 13
PARTIAL_INDEX_SHIFT = 11  # bits 11–12: 0 → x.00°, 1 → x.25°, 2 → x.50°, 3 → x.75°
# TL §7.20.2: when more than 20 % of a beam's readings have no distance, the
# mean is an error code instead.
MAX_INVALID_FRACTION = 0.2

Indices = tuple[int, int]  # (scan index, telegram index), each modulo 256


def count_word(count: int, unit: str, partial_index: int | None = None) -> int:
    """The word before the values: count, unit bits, and the partial-scan bits of mode 2A."""
    word = count | UNIT_BITS[unit]
    if partial_index is not None:
        word |= PARTIAL_SCAN_BIT | (partial_index << PARTIAL_INDEX_SHIFT)
    return word


def _word(value: int) -> bytes:
    return value.to_bytes(2, "little")


def _values_and_indices(values: np.ndarray, indices: Indices | None) -> bytes:
    words = np.clip(np.asarray(values), 0, 0xFFFF).astype("<u2").tobytes()
    return words + (bytes((indices[0] & 0xFF, indices[1] & 0xFF)) if indices else b"")


def scan_body(values: np.ndarray, unit: str, *, partial_index: int | None = None, indices: Indices | None = None) -> bytes:
    """B0: count word, values, optional real-time indices."""
    return b"\xb0" + _word(count_word(len(values), unit, partial_index)) + _values_and_indices(values, indices)


def mean_body(scans: int, values: np.ndarray, unit: str, *, indices: Indices | None = None) -> bytes:
    """B6: number of scans averaged, count word (bits 0–13), mean values."""
    return b"\xb6" + bytes((scans,)) + _word(count_word(len(values), unit)) + _values_and_indices(values, indices)


def subrange_body(
    first: int, last: int, values: np.ndarray, unit: str, *, partial_index: int | None = None, indices: Indices | None = None
) -> bytes:
    """B7: first and last value numbers (1-based, inclusive), count word (with the
    partial-scan bits when the values are one partial scan's), values."""
    count = _word(count_word(len(values), unit, partial_index))
    return b"\xb7" + _word(first) + _word(last) + count + _values_and_indices(values, indices)


def mean_subrange_body(
    scans: int, first: int, last: int, values: np.ndarray, unit: str, *, indices: Indices | None = None
) -> bytes:
    """BF: scans averaged, first and last value numbers, count word, mean values."""
    header = b"\xbf" + bytes((scans,)) + _word(first) + _word(last) + _word(count_word(len(values), unit))
    return header + _values_and_indices(values, indices)


def mean_of_scans(scans: np.ndarray, field_bits: int = 13) -> np.ndarray:
    """Per-beam mean of a (scans, beams) array of distance-field values (`field_bits` wide).

    A beam's mean is the rounded mean (halves up) of its distances; when more
    than 20 % of its readings are error codes (the field's top nine values),
    it is the most frequent of those codes (the lowest on a tie).
    """
    top = (1 << field_bits) - 1
    first_code = top - (DISTANCE_MASK - FIRST_ERROR_CODE)
    codes = np.arange(first_code, top + 1)
    distances = np.asarray(scans, dtype=np.int64) & top
    invalid = distances >= first_code
    valid_counts = (~invalid).sum(axis=0)
    sums = np.where(invalid, 0, distances).sum(axis=0)
    means = np.floor(sums / np.maximum(valid_counts, 1) + 0.5).astype(np.int64)
    code_counts = (distances[:, :, None] == codes).sum(axis=0)
    most_frequent_code = codes[code_counts.argmax(axis=1)]
    too_many_invalid = invalid.sum(axis=0) > MAX_INVALID_FRACTION * distances.shape[0]
    return np.where(too_many_invalid, most_frequent_code, means)
