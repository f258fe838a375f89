"""Measuring modes of the 77 configuration (TL Table 7-122 block D): the distance
field, the reflector bits, what each request sends back; sub-ranges that do
not fit one telegram (TL §7.12.1)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from protocols.lms2xx import Lms200Device, build_telegram

ACK = b"\x06"
NOT_ACKNOWLEDGED = bytes.fromhex("02 80 02 00 92 10 7F 33")
CONFIG_77 = bytes.fromhex("00 00 70 00 00 00 01 00 00 02 02" + " 00" * 21 + " 02 00")
FAR_MM = 20_000  # beyond the 8 m and 16 m fields


class ReflectorSource:
    """Every 10th beam a reflector at 3.000 m, every 7th nothing within reach (no
    echo), the others a wall at 20 m: each answered in the field it is asked for."""

    def __init__(self) -> None:
        self.field_bits: list[int] = []

    def __call__(self, time_s, *, start_deg, step_deg, count, unit, field_bits=13):
        self.field_bits.append(field_bits)
        top = (1 << field_bits) - 1
        numbers = np.arange(count)
        reflector = numbers % 10 == 0
        distance = np.where(reflector, 3000, FAR_MM) // (1 if unit == "mm" else 10)
        values = np.where(distance > top - 9, top - 8, distance)  # above the maximum: 8183 in its field
        values = np.where(numbers % 7 == 3, top, values)  # no echo: 8191 in its field
        return SimpleNamespace(values=values, reflector=reflector & (numbers % 7 != 3))


def host(body: bytes) -> bytes:
    return build_telegram(0x00, body)


def ask(device: Lms200Device, body: bytes, now: float = 1.0) -> list[bytes]:
    return [output.data for output in device.receive(host(body), now)]


def configured(mode: int, **options) -> tuple[Lms200Device, ReflectorSource]:
    source = ReflectorSource()
    device = Lms200Device(source, **options)
    device.poll(0.0)
    assert ask(device, b"\x20\x00SICK_LMS")[1][5] == 0x00
    block = bytearray(CONFIG_77)
    block[5] = mode
    (ack, confirmation) = ask(device, b"\x77" + bytes(block))
    assert confirmation[5] == 0x01, f"mode {mode:02X} refused"
    return device, source


def scan_words(device: Lms200Device, now: float = 2.0) -> np.ndarray:
    (_, telegram) = ask(device, b"\x30\x01", now)
    return np.frombuffer(telegram[7:-3], dtype="<u2").astype(np.int64)


@pytest.mark.parametrize(
    ("mode", "field_bits", "reflector_word"),
    [
        (0x00, 13, 0),  # fields A, B and dazzle: none set
        (0x01, 13, 0b111 << 13),  # reflector in 8 levels: the top one
        (0x02, 13, 0),  # fields A, B, C
        (0x03, 14, 0b11 << 14),  # 16 m, reflector in 4 levels
        (0x04, 14, 0),  # 16 m, fields A, B
        (0x05, 15, 1 << 15),  # 32 m (ARIA's mode), reflector in 2 levels
        (0x06, 15, 0),  # 32 m, field A
        (0x0F, 15, 0),  # immediate transmission, 32 m, no flags
    ],
)
def test_each_mode_sends_its_distance_field_and_reflector_bits(mode, field_bits, reflector_word):
    device, source = configured(mode)
    words = scan_words(device)
    assert source.field_bits[-1] == field_bits
    top = (1 << field_bits) - 1
    numbers = np.arange(len(words))
    distance = words & top
    no_echo = numbers % 7 == 3
    reflector = (numbers % 10 == 0) & ~no_echo
    assert np.all(distance[no_echo] == top)  # 8191 moved to the field's top
    assert np.all(distance[reflector] == 3000)
    far = ~no_echo & ~reflector
    expected_far = FAR_MM if field_bits == 15 else top - 8  # 32 m fields hold 20 m; others: above maximum
    assert np.all(distance[far] == expected_far)
    assert np.all(words[reflector] >> field_bits << field_bits == reflector_word)
    assert np.all(words[~reflector] >> field_bits == 0)


def test_aria_in_mode_05_reads_too_far_as_7ff7_not_8183():
    device, _ = configured(0x05)
    words = scan_words(device)
    assert 8183 not in words.tolist()


@pytest.mark.parametrize("mode", [0x07, 0x0A, 0x0E, 0x10, 0x11, 0x3D, 0x3E, 0x3F, 0xFF])
def test_reserved_and_internal_modes_are_refused(mode):
    source = ReflectorSource()
    device = Lms200Device(source)
    device.poll(0.0)
    ask(device, b"\x20\x00SICK_LMS")
    block = bytearray(CONFIG_77)
    block[5] = mode
    assert ask(device, b"\x77" + bytes(block))[1][5] == 0x00


def test_means_in_a_32_m_field_keep_the_distances_and_drop_the_flags():
    device, _ = configured(0x05)
    ask(device, b"\x20\x25")
    assert ask(device, b"\x36\x02", 2.0) == [ACK]
    [telegram] = [output.data for output in device.poll(3.0)]
    means = np.frombuffer(telegram[8:-3], dtype="<u2").astype(np.int64)
    numbers = np.arange(len(means))
    assert np.all(means[(numbers % 10 == 0) & (numbers % 7 != 3)] == 3000)  # the reflector's flag is gone
    assert np.all(means[numbers % 7 == 3] == 0x7FFF)


def test_a_sub_range_too_long_for_one_telegram_comes_as_partial_scans():
    """A regression: 37 01 00 91 01 at 100°/0.25° raised and sent nothing."""
    device, _ = configured(0x00, angle_deg=100, resolution_deg=0.25)
    replies = ask(device, bytes.fromhex("37 01 00 91 01"), 2.0)
    assert replies[0] == ACK and len(replies) == 5
    values = {}
    for partial_index, telegram in enumerate(replies[1:]):
        assert len(telegram) <= 814 and telegram[4] == 0xB7
        assert telegram[5:9] == bytes.fromhex("01 00 91 01")
        count_word = int.from_bytes(telegram[9:11], "little")
        assert count_word & 0x2000 and (count_word >> 11) & 3 == partial_index
        count = count_word & 0x3FF
        assert count == (101 if partial_index == 0 else 100)
        values[partial_index] = np.frombuffer(telegram[11 : 11 + 2 * count], dtype="<u2")
    whole = scan_words(device, 2.0)
    for partial_index, partial in values.items():
        np.testing.assert_array_equal(partial, whole[partial_index::4])


def test_a_direct_sub_range_is_one_telegram_per_partial_scan():
    device, _ = configured(0x00)  # 180°/0.5°: partial scans x.00 and x.50
    replies = ask(device, bytes.fromhex("37 01 80 0A 00"), 2.0)
    assert replies[0] == ACK and len(replies) == 3
    words = [int.from_bytes(telegram[9:11], "little") for telegram in replies[1:]]
    assert [(word >> 11) & 3 for word in words] == [0, 2]
    assert [word & 0x3FF for word in words] == [5, 5]


def test_a_mean_sub_range_too_long_for_one_telegram_is_refused():
    """BF cannot be split into partial scans (its count word has no partial bits)."""
    device, _ = configured(0x00, angle_deg=100, resolution_deg=0.25)
    assert ask(device, bytes.fromhex("3F 02 01 00 90 01"), 2.0) == [ACK, NOT_ACKNOWLEDGED]
    assert ask(device, bytes.fromhex("20 28 02 00 01 00 91 01"), 2.0) == [ACK, NOT_ACKNOWLEDGED]
    assert ask(device, bytes.fromhex("3F 02 01 00 8F 01"), 2.0) == [ACK]  # 399 values fit
    [telegram] = [output.data for output in device.poll(3.0)]
    assert telegram[4] == 0xBF and len(telegram) <= 814


def test_a_streamed_full_range_sub_range_at_quarter_degrees_streams_partial_telegrams():
    device, _ = configured(0x00, angle_deg=100, resolution_deg=0.25)
    replies = ask(device, bytes.fromhex("20 27 01 00 91 01"), 2.0)
    assert replies[0] == ACK and replies[1][4:6] == b"\xa0\x00"
    streamed = []
    now = 2.0
    while len(streamed) < 8:
        now = device.next_deadline()
        streamed += [output.data for output in device.poll(now)]
    assert all(telegram[4] == 0xB7 and len(telegram) <= 814 for telegram in streamed)
    assert [(int.from_bytes(t[9:11], "little") >> 11) & 3 for t in streamed[:4]] == [0, 1, 2, 3]
