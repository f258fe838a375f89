"""SCIP character encodings, checksums and data blocks, vectorised with numpy.

SCIP sends numbers as groups of 6 bits, most significant first, each + 0x30
(spec C-42-03320B §6): 2 characters for GS/MS and SCIP 1.1 (max 4095),
3 for GD/MD (max 262143), 4 for timestamps (24 bits). Every line the device
sends after the status carries a one-character checksum: the low 6 bits of
the byte sum, + 0x30. A scan's encoded values are cut into 64-character
lines, each with its own checksum; values straddle lines.
"""

from __future__ import annotations

import numpy as np

CHAR_OFFSET = 0x30
BLOCK_CHARS = 64
LF = 0x0A
MAX_WIDTH = 4  # 24 bits (a time stamp): the widest group SCIP sends
_SHIFTS = {width: np.arange(6 * (width - 1), -1, -6, dtype=np.uint32) for width in range(1, MAX_WIDTH + 1)}
ERROR_CODE_LIMIT = 20  # URG-04LX values below this are error codes, not mm


def checksum(data: bytes) -> bytes:
    """The SCIP sum character of `data`."""
    return bytes((((sum(data) & 0x3F) + CHAR_OFFSET),))


def max_value(width: int) -> int:
    """The largest value `width` characters can carry."""
    return (1 << (6 * width)) - 1


def encode_values(values: np.ndarray, width: int) -> bytes:
    """Values as `width`-character groups, concatenated.

    Values outside 0..max_value(width) saturate at the nearest bound: the
    URG-04LX cannot report a distance beyond what the encoding can carry, and
    wrapping would turn a far wall into a near one.
    """
    return encode_chars(values, width).tobytes()


def encode_chars(values: np.ndarray, width: int) -> np.ndarray:
    """`encode_values` as an array: shape (*values.shape, width), uint8, so callers
    can interleave fields before one `tobytes` (a whole scan in a few numpy passes)."""
    values = np.asarray(values)
    saturated = np.minimum(np.maximum(values, 0), max_value(width)).astype(np.uint32)
    chars = (saturated[..., None] >> _SHIFTS[width]) & 0x3F
    chars = chars.astype(np.uint8)
    chars += CHAR_OFFSET
    return chars


def encode_value(value: int, width: int) -> bytes:
    """One value (a time stamp, the timer) as `encode_values` sends it, without numpy's per-call cost."""
    value = min(max(int(value), 0), max_value(width))
    return bytes(((value >> (6 * place)) & 0x3F) + CHAR_OFFSET for place in range(width - 1, -1, -1))


def decode_values(text: bytes, width: int) -> np.ndarray:
    """The inverse of `encode_values`; `len(text)` must be a multiple of `width`."""
    if len(text) % width:
        raise ValueError(f"{len(text)} characters are not a whole number of {width}-character values")
    groups = (np.frombuffer(text, dtype=np.uint8).astype(np.int64) - CHAR_OFFSET).reshape(-1, width)
    shifts = 6 * np.arange(width - 1, -1, -1, dtype=np.int64)
    return (groups << shifts).sum(axis=1)


def data_lines(encoded: bytes, *, with_checksums: bool = True) -> bytes:
    """Encoded values cut into 64-character lines, each + checksum (SCIP 2.0) + LF.

    SCIP 1.1 sends the same lines without checksums.
    """
    chars = np.frombuffer(encoded, dtype=np.uint8)
    full_count, rest = divmod(len(chars), BLOCK_CHARS)
    suffix = 2 if with_checksums else 1
    full = chars[: full_count * BLOCK_CHARS].reshape(full_count, BLOCK_CHARS)
    out = np.empty((full_count, BLOCK_CHARS + suffix), dtype=np.uint8)
    out[:, :BLOCK_CHARS] = full
    if with_checksums:
        out[:, BLOCK_CHARS] = (full.sum(axis=1, dtype=np.int64) & 0x3F) + CHAR_OFFSET
    out[:, -1] = LF
    lines = out.tobytes()
    if rest:
        tail = encoded[full_count * BLOCK_CHARS :]
        lines += tail + (checksum(tail) if with_checksums else b"") + b"\n"
    return lines


def join_data_lines(lines: bytes) -> bytes:
    """The inverse of `data_lines` (with checksums): the encoded characters.

    Raises ValueError on a line whose checksum does not match.
    """
    if not lines.endswith(b"\n"):
        raise ValueError("data lines must end with LF")
    bodies = []
    for line in lines[:-1].split(b"\n"):
        if not line or checksum(line[:-1]) != line[-1:]:
            raise ValueError(f"bad checksum on data line {line!r}")
        bodies.append(line[:-1])
    return b"".join(bodies)


def cluster_minimum(values: np.ndarray, cluster: int) -> np.ndarray:
    """Each run of `cluster` adjacent steps reduced to one value.

    Spec p.10: the step with the minimum value, excluding errors (values
    below 20). A run made only of error codes reports its smallest code.
    The last run may be shorter. Error codes are lifted above every
    distance, so one `minimum.reduceat` picks a distance whenever the run
    has one.
    """
    values = np.asarray(values, dtype=np.int64)
    if cluster <= 1:
        return values
    lift = np.int64(1) << 40
    keyed = np.where(values < ERROR_CODE_LIMIT, values + lift, values)
    smallest = np.minimum.reduceat(keyed, np.arange(0, len(values), cluster))
    return np.where(smallest >= lift, smallest - lift, smallest)



ECHO_SEPARATOR = ord("&")


def encode_steps(ranges: np.ndarray, intensities: np.ndarray | None, width: int = 3) -> bytes:
    """Per step its echoes, nearest first: range (+ intensity) in `width` characters each;
    every echo after a step's first is prefixed by '&' (SCIP 2.2 HD/HE/ND/NE).

    `ranges` is (N,) for one echo per step or (N, E) with -1 where a step has fewer
    than E echoes (its first echo is always sent: an error code when nothing came
    back). The '&' characters are data like any other: `data_lines` cuts the result
    into 64-character lines, so an echo may straddle two lines.
    """
    ranges = np.asarray(ranges)
    fields = ranges[..., None] if intensities is None else np.stack([ranges, np.asarray(intensities).reshape(ranges.shape)], axis=-1)
    if ranges.ndim == 1 or ranges.shape[1] == 1:  # one echo per step: no '&' at all
        return encode_chars(fields, width).tobytes()
    steps, echoes, count = fields.shape
    group = width * count
    slot = np.empty((steps, echoes, 1 + group), dtype=np.uint8)
    slot[:, :, 0] = ECHO_SEPARATOR
    slot[:, :, 1:] = encode_chars(fields, width).reshape(steps, echoes, group)
    present = ranges >= 0
    present[:, 0] = True
    keep = np.broadcast_to(present[:, :, None], slot.shape).copy()
    keep[:, 0, 0] = False  # no '&' before a step's first echo
    return slot[keep].tobytes()


def cluster_choice(values: np.ndarray, cluster: int) -> np.ndarray:
    """Index of the step `cluster_minimum` reports in each run of `cluster` steps: the
    nearest distance, or when the run holds only error codes its smallest code (the
    step whose intensity and further echoes go with it)."""
    values = np.asarray(values, dtype=np.int64)
    if cluster <= 1:
        return np.arange(len(values))
    lift = np.int64(1) << 40
    keyed = np.where(values < ERROR_CODE_LIMIT, values + lift, values)
    runs = -(-len(values) // cluster)
    padded = np.full(runs * cluster, np.iinfo(np.int64).max, dtype=np.int64)
    padded[: len(values)] = keyed
    return np.arange(runs) * cluster + padded.reshape(runs, cluster).argmin(axis=1)
