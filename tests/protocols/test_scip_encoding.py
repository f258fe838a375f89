"""SCIP encodings, checksums, data blocks and cluster minima."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from protocols.scip.encoding import (
    checksum,
    cluster_minimum,
    data_lines,
    decode_values,
    encode_steps,
    encode_value,
    encode_values,
    join_data_lines,
    max_value,
)


def reference_checksum(data: bytes) -> bytes:
    return chr((sum(data) & 0x3F) + 0x30).encode("latin-1")


@pytest.mark.parametrize(
    "value,width,text",
    [(1234, 2, b"CB"), (5432, 3, b"1Dh"), (16_000_000, 4, b"m2@0"), (0, 3, b"000"), (4095, 2, b"oo")],
)
def test_spec_encoding_examples(value, width, text):
    assert encode_values(np.array([value]), width) == text
    assert decode_values(text, width).tolist() == [value]


def widths_with_values():
    """A width and values that fit in it."""
    return st.integers(2, 4).flatmap(
        lambda width: st.tuples(
            st.just(width),
            hnp.arrays(np.int64, st.integers(0, 800), elements=st.integers(0, max_value(width))),
        )
    )


@given(widths_with_values())
def test_encode_decode_round_trip(width_and_values):
    width, values = width_and_values
    text = encode_values(values, width)
    assert len(text) == width * len(values)
    assert all(0x30 <= byte <= 0x6F for byte in text)
    assert np.array_equal(decode_values(text, width), values)


@given(hnp.arrays(np.int64, st.integers(1, 50), elements=st.integers(-10, 10**7)))
def test_two_char_values_saturate_instead_of_wrapping(values):
    decoded = decode_values(encode_values(values, 2), 2)
    assert np.array_equal(decoded, np.clip(values, 0, 4095))


@given(st.binary(max_size=200))
def test_checksum_matches_the_definition(data):
    assert checksum(data) == reference_checksum(data)


@pytest.mark.parametrize("text,sum_char", [(b"00", b"P"), (b"99", b"b"), (b"DMIN:20", b"4"), (b"TIME:6A5404", b"]")])
def test_checksums_seen_on_the_real_unit(text, sum_char):
    assert checksum(text) == sum_char


@given(hnp.arrays(np.int64, st.integers(1, 769), elements=st.integers(0, max_value(3))))
def test_data_lines_round_trip_with_64_char_lines_and_straddling_values(values):
    encoded = encode_values(values, 3)
    lines = data_lines(encoded)
    rows = lines.split(b"\n")[:-1]
    assert all(len(row) == 65 for row in rows[:-1])
    assert 2 <= len(rows[-1]) <= 65
    assert all(reference_checksum(row[:-1]) == row[-1:] for row in rows)
    assert b"".join(row[:-1] for row in rows) == encoded
    assert join_data_lines(lines) == encoded
    assert np.array_equal(decode_values(join_data_lines(lines), 3), values)


def test_real_gd_block_layout():
    lines = data_lines(encode_values(np.arange(682), 3))
    assert len(lines) == 31 * 66 + 64


def test_data_lines_without_checksums_for_scip_1_1():
    lines = data_lines(b"0" * 130, with_checksums=False)
    assert lines == b"0" * 64 + b"\n" + b"0" * 64 + b"\n" + b"00\n"


@given(st.binary(min_size=1, max_size=64).filter(lambda b: b"\n" not in b))
def test_join_rejects_a_corrupted_line(body):
    corrupted = body + bytes([(ord(checksum(body)) + 1) % 256]) + b"\n"
    with pytest.raises(ValueError):
        join_data_lines(corrupted)


def reference_cluster_minimum(values: list[int], cluster: int) -> list[int]:
    """One cluster at a time, plainly: the smallest distance, else the smallest error code."""
    out = []
    for start in range(0, len(values), max(cluster, 1)):
        run = values[start : start + max(cluster, 1)]
        distances = [v for v in run if v >= 20]
        out.append(min(distances) if distances else min(run))
    return out


@given(
    st.lists(st.one_of(st.integers(0, 19), st.integers(20, 5600)), min_size=1, max_size=769),
    st.integers(1, 99),
)
def test_cluster_minimum_matches_a_plain_reference(values, cluster):
    result = cluster_minimum(np.array(values), cluster)
    assert result.tolist() == reference_cluster_minimum(values, cluster)
    assert len(result) == -(-len(values) // cluster)


def test_cluster_minimum_ignores_errors_unless_all_are_errors():
    assert cluster_minimum(np.array([0, 3000, 1200, 7, 19, 2]), 3).tolist() == [1200, 2]


@given(st.integers(1, 4), st.integers(-(10**9), 10**9))
def test_one_value_encodes_as_an_array_of_one(width, value):
    assert encode_value(value, width) == encode_values(np.array([value]), width)


@given(
    hnp.arrays(np.int64, st.integers(0, 60), elements=st.integers(-1, 300_000)),
    st.booleans(),
)
def test_single_echo_steps_are_range_then_intensity_per_step(ranges, with_intensity):
    """The one-echo fast path against the plain definition: per step its range, then its intensity."""
    intensities = (ranges * 7) % 5000 if with_intensity else None
    expected = b"".join(
        encode_values(np.array([value]), 3) + (b"" if intensities is None else encode_values(np.array([intensities[i]]), 3))
        for i, value in enumerate(ranges)
    )
    assert encode_steps(ranges, intensities) == expected
    assert encode_steps(ranges[:, None], None if intensities is None else intensities[:, None]) == expected
