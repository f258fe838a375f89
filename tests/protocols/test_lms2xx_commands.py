"""Each LMS200 command's reply, byte by byte against the telegram listing where it prints one."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from protocols.lms2xx import Lms200Device, build_telegram, crc16

ACK, NAK = b"\x06", b"\x15"
TYPE_STRING = "4C 4D 53 32 30 30 3B 33 30 31 30 36 33 3B 56 30 32 2E 31 30 20"  # LMS200;301063;V02.10␠
A0_OK = bytes.fromhex("02 80 03 00 A0 00 10 16 0A")  # Table 6-6
NOT_ACKNOWLEDGED = bytes.fromhex("02 80 02 00 92 10 7F 33")  # Table 7-9
PASSWORD = b"SICK_LMS"
# Tables 6-8 / 6-11: the listing's 77 example and the F7 that confirms it.
CONFIG_77 = bytes.fromhex("00 00 70 00 00 00 01 00 00 02 02" + " 00" * 21 + " 02 00")
F7_EXAMPLE = bytes.fromhex("02 80 25 00 F7 01") + CONFIG_77 + bytes.fromhex("10 C5 7A")


class Source:
    """A scan source whose values depend on angle and revolution, recording each call."""

    def __init__(self) -> None:
        self.calls: list[tuple[float, float, float, int, str]] = []

    def __call__(self, time_s: float, *, start_deg: float, step_deg: float, count: int, unit: str, field_bits: int = 13):
        self.calls.append((time_s, start_deg, step_deg, count, unit))
        return SimpleNamespace(values=expected_values(time_s, start_deg, step_deg, count, unit))


def expected_values(time_s: float, start_deg: float, step_deg: float, count: int, unit: str) -> np.ndarray:
    angles = start_deg + step_deg * np.arange(count)
    millimetres = 1000 + np.round(angles * 10).astype(int) + round(time_s * 75) % 97
    return millimetres if unit == "mm" else millimetres // 10


def host(body: bytes) -> bytes:
    return build_telegram(0x00, body)


def reply(body_hex: str) -> bytes:
    """A device reply telegram with status 0x10 and its CRC."""
    return build_telegram(0x80, bytes.fromhex(body_hex) + b"\x10")


@pytest.fixture
def source() -> Source:
    return Source()


@pytest.fixture
def device(source: Source) -> Lms200Device:
    lms = Lms200Device(source)
    assert len(lms.poll(0.0)) == 1  # the power-on 90
    return lms


def ask(device: Lms200Device, body: bytes, now: float = 1.0) -> list[bytes]:
    return [output.data for output in device.receive(host(body), now)]


def install(device: Lms200Device, now: float = 1.0) -> None:
    assert ask(device, b"\x20\x00" + PASSWORD, now) == [ACK, A0_OK]


def test_power_on_telegram(source: Source) -> None:
    device = Lms200Device(source, start_time=2.0)
    assert device.next_deadline() == 2.0
    assert device.poll(1.0) == []
    (power_on,) = device.poll(2.0)
    # Table 7-5 prints these bytes with CRC 63 56; its BA twin (Table 7-57, same
    # data) verifies, so 63 56 is a misprint of 63 5E.
    assert power_on.data[:-2] == bytes.fromhex("02 80 17 00 90" + TYPE_STRING + "10")
    assert power_on.data[-2:] == bytes.fromhex("63 5E")
    assert power_on.baud == 9600 and not power_on.droppable
    assert device.poll(3.0) == []


def test_deaf_before_power_on(source: Source) -> None:
    device = Lms200Device(source, start_time=2.0)
    assert device.receive(host(b"\x31"), 1.0) == []


def test_type_request_matches_the_listing(device: Lms200Device) -> None:
    assert ask(device, b"\x3a") == [ACK, bytes.fromhex("02 80 17 00 BA" + TYPE_STRING + "10 22 61")]  # Table 7-57


def test_error_request_of_a_healthy_unit(device: Lms200Device) -> None:
    assert ask(device, b"\x32") == [ACK, bytes.fromhex("02 80 02 00 B2 10 3F 13")]  # Table 7-39


def test_installation_mode_and_wrong_password(device: Lms200Device) -> None:
    assert ask(device, b"\x20\x00SICK_LMX") == [ACK, reply("A0 01")]
    assert ask(device, b"\x31")[1][5 + 7] == 0x25  # still mode 25
    install(device)
    assert ask(device, b"\x31")[1][5 + 7] == 0x00
    assert ask(device, b"\x20\x30" + PASSWORD) == [ACK, A0_OK]  # test password: no mode change
    assert ask(device, b"\x31")[1][5 + 7] == 0x00


def test_configuration_on_delivery_matches_the_listing(device: Lms200Device) -> None:
    # Table 7-111: LEN 24h, status 10h, CRC 3C FB; the block is the one of Table 6-8.
    assert ask(device, b"\x74") == [ACK, bytes.fromhex("02 80 24 00 F4") + CONFIG_77 + bytes.fromhex("10 3C FB")]


def test_configure_matches_the_listing(device: Lms200Device) -> None:
    assert ask(device, b"\x77" + CONFIG_77) == [ACK, NOT_ACKNOWLEDGED]  # not in installation mode
    install(device)
    assert ask(device, b"\x77" + CONFIG_77) == [ACK, F7_EXAMPLE]


def test_short_configure_updates_only_the_bytes_given(device: Lms200Device) -> None:
    install(device)
    player_block = bytes.fromhex("00 00 46 00 02 00 01")  # Player sends 7 bytes
    (_, confirmation) = ask(device, b"\x77" + player_block)
    assert confirmation[5] == 0x01
    assert confirmation[6:-3] == player_block + CONFIG_77[7:]
    assert ask(device, b"\x74")[1][5:-3] == player_block + CONFIG_77[7:]


def test_rejected_configure_keeps_the_block(device: Lms200Device) -> None:
    install(device)
    unsupported = bytearray(CONFIG_77)
    unsupported[5] = 0x0A  # measuring mode 0A: reserved
    assert ask(device, b"\x77" + bytes(unsupported)) == [ACK, reply("F7 00" + CONFIG_77.hex())]


def test_thirty_two_byte_profile(source: Source) -> None:
    device = Lms200Device(source, firmware_profile="32-byte-config")
    device.poll(0.0)
    assert ask(device, b"\x74")[1] == reply("F4" + CONFIG_77[:32].hex())
    install(device)
    assert ask(device, b"\x77" + CONFIG_77) == [ACK, reply("F7 01" + CONFIG_77[:32].hex())]


def test_unknown_commands_and_wrong_lengths_get_92(device: Lms200Device) -> None:
    for body in (b"\x35", b"\x99", b"\x31\x00", b"\x30", b"\x30\x02", b"\x36\x01", b"\x36\xfb", b"\x20", b"\x20\x2b"):
        assert ask(device, body) == [ACK, NOT_ACKNOWLEDGED], body.hex()


def test_nak_for_a_bad_crc_and_silence_for_another_address(device: Lms200Device) -> None:
    corrupt = bytearray(host(b"\x31"))
    corrupt[-2] ^= 0x01
    assert [o.data for o in device.receive(bytes(corrupt), 1.0)] == [NAK]
    assert device.receive(build_telegram(0x05, b"\x31"), 1.0) == []
    corrupt_elsewhere = bytearray(build_telegram(0x05, b"\x31"))
    corrupt_elsewhere[-1] ^= 0x01
    assert device.receive(bytes(corrupt_elsewhere), 1.0) == []


def test_one_scan_on_request(device: Lms200Device, source: Source) -> None:
    now = 1.0
    (ack, scan) = ask(device, b"\x30\x01", now)
    assert ack == ACK and len(scan) == 732 and scan[2:4] == bytes.fromhex("D6 02")  # Table 7-29
    assert scan[4] == 0xB0 and scan[-3] == 0x10
    assert int.from_bytes(scan[5:7], "little") == 361 | 0x4000  # 361 values, mm, full scan
    completed = (now * 75 // 2) * 2 / 75  # the last 0.5° scan complete at `now`
    values = np.frombuffer(scan[7:-3], dtype="<u2")
    np.testing.assert_array_equal(values, expected_values(completed, 0.0, 0.5, 361, "mm"))
    assert source.calls[-1] == pytest.approx((completed, 0.0, 0.5, 361, "mm"))
    assert crc16(scan[:-2]) == int.from_bytes(scan[-2:], "little")


def test_thinned_scans_on_request(device: Lms200Device) -> None:
    every_other = ask(device, b"\x30\x06")[1]
    every_twentieth = ask(device, b"\x30\x07")[1]
    assert int.from_bytes(every_other[5:7], "little") & 0x3FF == 181
    assert int.from_bytes(every_twentieth[5:7], "little") & 0x3FF == 19


@pytest.mark.parametrize("now", [1.0, 1.0 + 1 / 75, 1.0 + 2 / 75, 1.0 + 3 / 75])
def test_current_partial_scan_on_request(device: Lms200Device, now: float) -> None:
    scan = ask(device, b"\x30\x08", now)[1]
    partial = round(now * 75) % 4
    word = int.from_bytes(scan[5:7], "little")
    assert word == (181 if partial == 0 else 180) | 0x2000 | partial << 11 | 0x4000


def test_variant_switch_matches_the_listing(device: Lms200Device, source: Source) -> None:
    assert ask(device, bytes.fromhex("3B B4 00 32 00")) == [ACK, bytes.fromhex("02 80 07 00 BB 01 B4 00 32 00 10 03 9D")]
    assert ask(device, bytes.fromhex("3B B4 00 19 00")) == [ACK, reply("BB 00 B4 00 32 00")]  # 180°/0.25° refused
    assert ask(device, bytes.fromhex("3B 64 00 19 00")) == [ACK, reply("BB 01 64 00 19 00")]
    scan = ask(device, b"\x30\x01")[1]
    assert len(scan) == 10 + 2 * 401
    assert source.calls[-1][1:4] == (40.0, 0.25, 401)  # the 100° variant starts at 40°
    assert ask(device, bytes.fromhex("3B B4 00 64 00")) == [ACK, reply("BB 01 B4 00 64 00")]
    assert len(ask(device, b"\x30\x01")[1]) == 372  # Table 10-16: 1°, 180°


def test_sub_range_is_one_based_and_inclusive(device: Lms200Device) -> None:
    whole = ask(device, bytes.fromhex("37 01 00 69 01"))[1]
    assert whole[1:4] == bytes.fromhex("80 DA 02")  # Table 7-53
    assert whole[5:11] == bytes.fromhex("01 00 69 01") + (361 | 0x4000).to_bytes(2, "little")
    full = np.frombuffer(ask(device, b"\x30\x01")[1][7:-3], dtype="<u2")
    part = ask(device, bytes.fromhex("37 05 00 0A 00"))[1]
    np.testing.assert_array_equal(np.frombuffer(part[11:-3], dtype="<u2"), full[4:10])
    for bad in ("37 00 00 05 00", "37 06 00 05 00", "37 01 00 6A 01"):
        assert ask(device, bytes.fromhex(bad)) == [ACK, NOT_ACKNOWLEDGED], bad


def test_means_wait_for_their_scans(device: Lms200Device) -> None:
    now = 1.0
    assert ask(device, b"\x36\x02", now) == [ACK]
    last = now * 75 // 2 + 2  # the second 0.5° scan completed after the request
    due = last * 2 / 75
    # the window's scans are fetched one by one as they complete, never all at the reply
    assert device.next_deadline() == pytest.approx((last - 1) * 2 / 75)
    assert device.next_scan_time() == pytest.approx((last - 1) * 2 / 75)
    assert device.poll((last - 1) * 2 / 75) == []
    assert device.next_deadline() == pytest.approx(due)
    assert device.poll(due - 0.001) == []
    (mean,) = [o.data for o in device.poll(due)]
    assert mean[1:5] == bytes.fromhex("80 D7 02 B6")  # Table 7-48
    assert mean[5] == 2 and int.from_bytes(mean[6:8], "little") == 361 | 0x4000
    scans = [expected_values(index * 2 / 75, 0.0, 0.5, 361, "mm") for index in (last - 1, last)]
    independent = np.floor(np.mean(scans, axis=0) + 0.5)
    np.testing.assert_array_equal(np.frombuffer(mean[8:-3], dtype="<u2"), independent)


def test_mean_sub_range(device: Lms200Device) -> None:
    now = 1.0
    assert ask(device, bytes.fromhex("3F 03 0A 00 14 00"), now) == [ACK]
    last = now * 75 // 2 + 3
    (mean,) = [o.data for o in device.poll(last * 2 / 75)]
    assert mean[4:12] == bytes.fromhex("BF 03 0A 00 14 00") + (11 | 0x4000).to_bytes(2, "little")
    scans = [expected_values(index * 2 / 75, 0.0, 0.5, 361, "mm")[9:20] for index in (last - 2, last - 1, last)]
    np.testing.assert_array_equal(np.frombuffer(mean[12:-3], dtype="<u2"), np.floor(np.mean(scans, axis=0) + 0.5))


def test_a_new_request_cancels_a_waiting_mean(device: Lms200Device) -> None:
    assert ask(device, b"\x36\x05", 1.0) == [ACK]
    assert ask(device, b"\x3a", 1.01)[0] == ACK
    assert device.next_deadline() is None


def test_centimetres_switch_the_count_word_and_the_values(device: Lms200Device, source: Source) -> None:
    install(device)
    (_, confirmation) = ask(device, b"\x77" + CONFIG_77[:6] + b"\x00")
    assert confirmation[5] == 0x01
    assert ask(device, b"\x31")[1][5 + 121] == 0  # B1 unit byte: cm
    scan = ask(device, b"\x30\x01")[1]
    assert int.from_bytes(scan[5:7], "little") == 361  # bits 14–15 = 00: cm
    assert source.calls[-1][4] == "cm"


def test_real_time_indices(device: Lms200Device) -> None:
    install(device)
    with_indices = bytearray(CONFIG_77)
    with_indices[4] |= 0x02
    assert ask(device, b"\x77" + bytes(with_indices))[1][5] == 0x01
    now = 1.0
    first = ask(device, b"\x30\x01", now)[1]
    second = ask(device, b"\x30\x01", now + 2 / 75)[1]
    assert len(first) == 734  # Table 10-16: 0.5° with indices
    revolution = int(now * 75 // 2) * 2
    assert first[-5:-3] == bytes((revolution % 256, first[-4]))
    assert second[-5] == (revolution + 2) % 256 and second[-4] == (first[-4] + 1) % 256
    assert ask(device, bytes.fromhex("3B 64 00 19 00"))[1][5] == 0x01
    quarter_degree = ask(device, b"\x30\x01")[1]
    assert len(quarter_degree) == 814  # Table 10-16: 0.25° with indices, beyond the usual 812
    assert crc16(quarter_degree[:-2]) == int.from_bytes(quarter_degree[-2:], "little")


def test_status_block_live_fields(source: Source) -> None:
    device = Lms200Device(source, angle_deg=100, resolution_deg=1.0)
    device.poll(0.0)
    status = ask(device, b"\x31")[1]
    assert status[1:4] == bytes.fromhex("80 9A 00")  # Table 7-34: 152 data bytes
    data = status[5:-3]
    assert data[0:7] == b"V02.10 " and data[7] == 0x25 and data[8] == 0
    assert int.from_bytes(data[106:108], "little") == 100 and int.from_bytes(data[108:110], "little") == 100
    assert int.from_bytes(data[115:117], "little") == 0x8067 and data[118] == 0  # 9600, not permanent (TL: 80 67h)
    assert data[119] == 0 and data[121] == 1 and data[122] == 1  # address 0, mm, laser on
    for submode, word in ((0x41, 0x8033), (0x40, 0x8019), (0x48, 0x8001)):
        ask(device, bytes((0x20, submode)))
        assert int.from_bytes(ask(device, b"\x31")[1][5 + 115 : 5 + 117], "little") == word


def test_reset_sequence(source: Source) -> None:
    device = Lms200Device(source)
    device.poll(0.0)
    ask(device, b"\x20\x40", 1.0)
    outputs = device.receive(host(b"\x10") + host(b"\x31"), 2.0)
    assert [o.data for o in outputs] == [ACK, bytes.fromhex("02 80 02 00 91 10 79 30")]  # Table 7-7
    assert {o.baud for o in outputs} == {38400}
    assert device.baud == 9600
    assert device.next_deadline() == pytest.approx(3.0)
    assert device.receive(host(b"\x31"), 2.5) == []  # booting
    (power_on,) = device.poll(3.0)
    assert power_on.data[4] == 0x90 and power_on.baud == 9600
    assert ask(device, b"\x31", 3.1)[1][5 + 7] == 0x25


def test_permanent_baud_survives_a_reset(device: Lms200Device) -> None:
    assert ask(device, b"\x66\x01") == [ACK, NOT_ACKNOWLEDGED]  # installation mode only
    ask(device, b"\x20\x41")
    install(device)
    assert ask(device, b"\x66\x01") == [ACK, reply("E6 01 01")]
    assert ask(device, b"\x31")[1][5 + 118] == 1
    ask(device, b"\x10", 2.0)
    (power_on,) = device.poll(3.0)
    assert power_on.baud == 19200 and device.baud == 19200
    install(device, 3.1)
    assert ask(device, b"\x66\x00", 3.2) == [ACK, reply("E6 01 00")]
    assert ask(device, b"\x66\x07", 3.3) == [ACK, reply("E6 00 07")]


@pytest.mark.parametrize("kwargs", [{"baud": 4800}, {"angle_deg": 180, "resolution_deg": 0.25}, {"units": "m"}, {"firmware_profile": "v9"}])
def test_constructor_refuses_what_the_lms200_cannot_be(source: Source, kwargs: dict) -> None:
    with pytest.raises(ValueError):
        Lms200Device(source, **kwargs)


def test_a_mean_of_250_scans_asks_for_each_scan_as_it_completes_never_all_at_once(
    device: Lms200Device, source: Source
) -> None:
    """36 FA used to ask its source for 250 scans at the reply (0.1-0.4 s on a daemon's loop)."""
    assert ask(device, b"\x36\xfa") == [ACK]
    most_per_poll, reply_bytes = 0, b""
    while not reply_bytes:
        before = len(source.calls)
        deadline = device.next_deadline()
        reply_bytes = b"".join(output.data for output in device.poll(deadline))
        most_per_poll = max(most_per_poll, len(source.calls) - before)
    assert reply_bytes[4] == 0xB6 and reply_bytes[5] == 250
    assert most_per_poll == 1 and len(source.calls) == 250
