"""LMS2xx framing: the CRC against verified vectors and the listing's examples,
build → read round trips, resynchronisation after garbage, and the host byte-gap rule."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from protocols.lms2xx import (
    CorruptTelegram,
    Telegram,
    TelegramReader,
    build_telegram,
    crc16,
)


def reference_crc(data: bytes) -> int:
    """TL §9's CreateCRC, byte by byte, independent of the table-driven crc16."""
    crc, previous = 0, 0
    for byte in data:
        crc = (((crc & 0x7FFF) << 1) ^ 0x8005) if crc & 0x8000 else (crc << 1) & 0xFFFF
        crc ^= byte | (previous << 8)
        previous = byte
    return crc


VERIFIED_TELEGRAMS = [
    "02 00 0A 00 20 00 53 49 43 4B 5F 4C 4D 53 BE C5",  # installation mode, SICK_LMS
    "02 80 03 00 A0 00 10 16 0A",
    "02 00 02 00 30 01 31 18",
    "02 00 05 00 3B B4 00 32 00 3B 1F",
    "02 80 02 00 91 10 79 30",
]

LISTING_EXAMPLES = [  # complete telegrams printed in the telegram listing whose CRC checks
    "02 00 01 00 10 34 12",  # Table 7-3
    "02 80 02 00 92 10 7F 33",  # Table 7-9
    "02 00 02 00 20 24 34 08",  # Table 6-13
    "02 00 06 00 20 27 1B 00 2B 01 FF FE",  # Table 7-14
    "02 00 0A 00 20 30 53 49 43 4B 5F 4C 4D 53 EE F5",  # Table 7-16
    "02 00 02 00 20 48 58 08",  # Table 7-18
    "02 00 01 00 31 15 12",  # Table 7-31
    "02 00 01 00 32 16 12",  # Table 7-36
    "02 80 02 00 B2 10 3F 13",  # Table 7-39
    "02 00 02 00 36 02 3E 1E",  # Table 7-45
    "02 00 05 00 37 01 00 69 01 EB 75",  # Table 7-50
    "02 00 01 00 3A 1E 12",  # Table 7-55
    "02 80 07 00 BB 01 B4 00 32 00 10 03 9D",  # Table 7-61
    "02 00 06 00 3F 02 01 00 2A 01 9D 4E",  # Table 7-67
    "02 00 02 00 66 00 9C 4E",  # Table 7-100
    "02 00 01 00 74 50 12",  # Table 7-109
]


@pytest.mark.parametrize("telegram", VERIFIED_TELEGRAMS + LISTING_EXAMPLES)
def test_crc_of_known_telegrams(telegram: str) -> None:
    raw = bytes.fromhex(telegram)
    assert crc16(raw[:-2]).to_bytes(2, "little") == raw[-2:]
    assert build_telegram(raw[1], raw[4:-2]) == raw


def test_manual_table_6_4_prints_a_wrong_crc() -> None:
    """The fact sheet warns that Table 6-4 misprints the install-mode CRC (5F B2)."""
    assert crc16(bytes.fromhex("02 00 0A 00 20 00 53 49 43 4B 5F 4C 4D 53")) != 0xB25F


@given(st.binary(min_size=0, max_size=814))
def test_crc_equals_the_listing_algorithm(data: bytes) -> None:
    assert crc16(data) == reference_crc(data)


def test_crc_refuses_more_than_a_telegram() -> None:
    with pytest.raises(ValueError):
        crc16(bytes(815))


@given(address=st.integers(0, 0x7F), body=st.binary(min_size=1, max_size=806), chunk=st.integers(1, 900))
def test_build_then_read_round_trip(address: int, body: bytes, chunk: int) -> None:
    raw = build_telegram(address, body)
    assert len(raw) == len(body) + 6
    reader = TelegramReader()
    events = []
    for start in range(0, len(raw), chunk):
        events += reader.feed(raw[start : start + chunk], now=0.0)
    assert events == [Telegram(address, body)]


def test_bad_crc_is_reported_and_the_next_telegram_still_read() -> None:
    good = build_telegram(0, b"\x31")
    corrupt = bytearray(good)
    corrupt[-1] ^= 0xFF
    events = TelegramReader().feed(bytes(corrupt) + good, now=0.0)
    assert events == [CorruptTelegram(0), Telegram(0, b"\x31")]


@pytest.mark.parametrize(
    "header",
    [
        b"\x02\x00\x00\x00",  # LEN 0: no command
        b"\x02\x00\x27\x03",  # LEN 807: more than 812 bytes in all
        b"\x02\x00\xff\xff",
        b"\x02\x80\x01\x00",  # a device telegram's address
    ],
)
def test_impossible_headers_cost_only_their_stx(header: bytes) -> None:
    good = build_telegram(0, b"\x3a")
    assert TelegramReader().feed(header + good, now=0.0) == [Telegram(0, b"\x3a")]


def test_a_long_bogus_length_cannot_swallow_a_later_telegram() -> None:
    """Garbage claiming 500 bytes, then a valid request and silence: the request
    is honoured when the bogus telegram's next byte is overdue."""
    reader = TelegramReader(gap_tolerance_s=0.2)
    good = build_telegram(0, b"\x31")
    assert reader.feed(b"\x02\x00\xf4\x01" + good, now=1.0) == []
    assert reader.deadline() == pytest.approx(1.2)
    assert reader.expire(1.1) == []
    assert reader.expire(1.25) == [Telegram(0, b"\x31")]
    assert reader.deadline() is None


def test_byte_gap_discards_the_partial_telegram() -> None:
    good = build_telegram(0, b"\x32")
    slow = TelegramReader(gap_tolerance_s=0.2)
    assert slow.feed(good[:3], now=0.0) == []
    assert slow.feed(good[3:], now=0.25) == []  # the first half was abandoned
    assert slow.feed(good, now=0.3) == [Telegram(0, b"\x32")]

    tolerant = TelegramReader(gap_tolerance_s=0.2)
    assert tolerant.feed(good[:3], now=0.0) == []
    assert tolerant.feed(good[3:], now=0.15) == [Telegram(0, b"\x32")]  # drivers exceed 6 ms


VALID_REQUESTS = [b"\x31", b"\x32", b"\x3a", b"\x74", b"\x30\x01", b"\x20\x25"]


@settings(max_examples=200, deadline=None)
@given(
    pieces=st.lists(st.tuples(st.binary(max_size=40), st.sampled_from(VALID_REQUESTS)), min_size=1, max_size=6),
    trailing=st.binary(max_size=40),
    cuts=st.lists(st.integers(1, 60), min_size=1, max_size=20),
)
def test_garbage_between_telegrams_never_hides_them(pieces, trailing: bytes, cuts: list[int]) -> None:
    stream = b"".join(garbage + build_telegram(0, body) for garbage, body in pieces) + trailing
    reader = TelegramReader(gap_tolerance_s=0.2)
    events, position, now = [], 0, 0.0
    for cut in cuts * (len(stream) // sum(cuts) + 1):
        if position >= len(stream):
            break
        events += reader.feed(stream[position : position + cut], now)
        position += cut
        now += 0.01
    events += reader.expire(now + 1.0)
    found = [event.body for event in events if isinstance(event, Telegram) and event.address == 0]
    assert _is_subsequence([body for _, body in pieces], found)


def _is_subsequence(wanted: list[bytes], found: list[bytes]) -> bool:
    remaining = iter(found)
    return all(any(body == item for item in remaining) for body in wanted)
