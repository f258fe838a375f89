"""LMS200 sessions as drivers run them: sicktoolbox's start-up, streaming modes over
simulated time, interrupts, interlaced partial scans, disconnects and garbage."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from protocols.device import Output
from protocols.lms2xx import Lms200Device, Mode, build_telegram

ACK = b"\x06"
A0_OK = bytes.fromhex("02 80 03 00 A0 00 10 16 0A")


def source(time_s: float, *, start_deg: float, step_deg: float, count: int, unit: str, field_bits: int = 13):
    return SimpleNamespace(values=expected_values(time_s, start_deg, step_deg, count))


def expected_values(time_s: float, start_deg: float, step_deg: float, count: int) -> np.ndarray:
    angles = start_deg + step_deg * np.arange(count)
    return 2000 + np.round(angles * 4).astype(int) + round(time_s * 75) % 61


def host(body: bytes) -> bytes:
    return build_telegram(0x00, body)


def powered(**kwargs) -> Lms200Device:
    device = Lms200Device(source, **kwargs)
    device.poll(0.0)
    return device


def run(device: Lms200Device, until: float) -> list[tuple[float, Output]]:
    """Poll the device at each deadline it names, up to `until`: (time, output) pairs."""
    outputs = []
    while (deadline := device.next_deadline()) is not None and deadline <= until:
        outputs += [(deadline, output) for output in device.poll(deadline)]
    return outputs


def values_of(telegram: bytes, offset: int = 7) -> np.ndarray:
    return np.frombuffer(telegram[offset:-3], dtype="<u2")


def test_sicktoolbox_start_up_and_stream() -> None:
    device = powered()
    baud_change = device.receive(host(b"\x20\x40"), 1.0)  # asked at 9600
    assert [o.data for o in baud_change] == [ACK, A0_OK]  # status 0x10: MRPT insists
    assert [o.baud for o in baud_change] == [9600, 9600]  # the reply goes out at the old rate
    assert device.baud == 38400
    now = 1.1
    for body, code in ((b"\x20\x25", 0xA0), (b"\x3a", 0xBA), (b"\x31", 0xB1), (b"\x74", 0xF4)):
        ack, answer = device.receive(host(body), now)
        assert ack.data == ACK and answer.data[4] == code and answer.data[-3] == 0x10
        assert ack.baud == answer.baud == 38400 and not answer.droppable
        now += 0.1
    ack, started = device.receive(host(b"\x20\x24"), now)
    assert started.data == A0_OK
    scans = [(time, output) for time, output in run(device, now + 2.0) if output.droppable]
    assert 9 <= len(scans) <= 11  # ≈ 38400 / 7320 = 5.25 scans/s
    for time, output in scans:
        assert output.baud == 38400 and len(output.data) == 732 and output.data[4] == 0xB0
        completed = int(time * 75 // 2) * 2 / 75  # the newest scan complete when it goes out
        np.testing.assert_array_equal(values_of(output.data), expected_values(completed, 0.0, 0.5, 361))


def test_a_host_command_interrupts_the_stream_and_replies_never_do() -> None:
    device = powered(baud=500_000)
    ack, _ = device.receive(host(b"\x20\x24"), 1.0)
    assert not ack.interrupt  # nothing was streaming
    streamed = run(device, 1.2)
    assert streamed and streamed[-1][1].droppable
    ack, status = device.receive(host(b"\x31"), 1.2)
    assert ack.interrupt and not status.interrupt
    ack_again, _ = device.receive(host(b"\x3a"), 1.2)
    assert not ack_again.interrupt  # the B1 reply is still going out: never dropped
    assert any(output.droppable for _, output in run(device, 1.3))  # still streaming
    stop = device.receive(host(b"\x20\x25"), 1.3)
    assert stop[0].interrupt and stop[1].data == A0_OK
    assert device.next_deadline() is None and device.mode is Mode.ON_REQUEST


def test_the_reply_starts_at_once_when_a_scan_is_cut_off() -> None:
    device = powered(baud=9600)
    device.receive(host(b"\x20\x24"), 1.0)
    first_scan_at = run(device, 1.1)[0][0]
    device.receive(host(b"\x20\x25"), first_scan_at + 0.01)  # 0.76 s of B0 cut after 10 ms
    assert device.receive(host(b"\x31"), first_scan_at + 0.02)[0].data == ACK
    # the model's line is free again about 0.17 s later (ACK + A0 + ACK + B1 at 9600), not 0.76 s
    device.receive(host(b"\x20\x24"), first_scan_at + 0.2)
    assert device.next_deadline() < first_scan_at + 0.5


def test_interlaced_partial_scans_cycle_through_the_quarter_degrees() -> None:
    device = powered(baud=500_000)
    device.receive(host(b"\x20\x2a"), 1.0)
    scans = [(time, output.data) for time, output in run(device, 1.0 + 12 / 75 + 1e-6) if output.droppable]
    assert len(scans) == 12  # one partial scan per revolution at 500 kBd
    for time, data in scans:
        revolution = round(time * 75)
        partial = revolution % 4
        word = int.from_bytes(data[5:7], "little")
        assert word & 0x2000 and (word >> 11) & 0b11 == partial and word >> 14 == 0b01
        count = 181 if partial == 0 else 180
        assert word & 0x3FF == count
        np.testing.assert_array_equal(values_of(data), expected_values(revolution / 75, partial * 0.25, 1.0, count))
    assert [(round(time * 75)) % 4 for time, _ in scans] == [(round(scans[0][0] * 75) + i) % 4 for i in range(12)]


def test_continuous_means_equal_the_independent_mean() -> None:
    device = powered(baud=500_000, resolution_deg=1.0)
    device.receive(host(b"\x20\x26\x04"), 1.0)
    means = [(time, output.data) for time, output in run(device, 1.3) if output.droppable]
    assert means
    first_index = int(1.0 * 75) + 1
    for time, data in means:
        last = round(time * 75)
        assert last >= first_index + 3  # a full window of 4 scans after the mode switch
        assert data[4] == 0xB6 and data[5] == 4
        window = [expected_values(index / 75, 0.0, 1.0, 181) for index in range(last - 3, last + 1)]
        np.testing.assert_array_equal(values_of(data, 8), np.floor(np.mean(window, axis=0) + 0.5))


def test_means_report_an_error_code_when_too_many_readings_fail() -> None:
    def flaky(time_s, *, start_deg, step_deg, count, unit, field_bits=13):
        values = expected_values(time_s, start_deg, step_deg, count)
        revolution = round(time_s * 75)
        values[0] = 8191  # always: no echo
        values[1] = 8190 if revolution % 5 == 0 else values[1]  # one reading in five
        return SimpleNamespace(values=values)

    device = Lms200Device(flaky, baud=500_000, resolution_deg=1.0)
    device.poll(0.0)
    device.receive(host(b"\x36\x0a"), 1.0)
    (mean,) = [output.data for _, output in run(device, 2.0)]
    values = values_of(mean, 8)
    assert values[0] == 8191  # all ten readings failed
    assert values[1] < 8183  # two failures in ten: 20 %, not more, so a distance


def test_continuous_sub_range() -> None:
    device = powered(baud=500_000)
    device.receive(host(bytes.fromhex("20 27 1B 00 2B 01")), 1.0)  # Table 7-14: values 27..299
    (time, output), *_ = [(t, o) for t, o in run(device, 1.2) if o.droppable]
    data = output.data
    assert data[4:10] == bytes.fromhex("B7 1B 00 2B 01") + bytes(((273 | 0x4000) & 0xFF,))
    completed = round(time * 75 / 2) * 2 / 75
    np.testing.assert_array_equal(values_of(data, 11), expected_values(completed, 0.0, 0.5, 361)[26:299])


def test_connection_lost_stops_streaming_and_keeps_the_rate() -> None:
    device = powered()
    device.receive(host(b"\x20\x48"), 1.0)
    device.receive(host(b"\x20\x24"), 1.1)
    assert run(device, 1.3)
    device.connection_lost()
    assert device.next_deadline() is None and device.mode is Mode.ON_REQUEST
    assert device.baud == 500_000
    assert device.receive(host(b"\x31"), 2.0)[1].data[5 + 7] == 0x25


def test_variant_switch_while_streaming_changes_the_scans() -> None:
    device = powered(baud=500_000)
    device.receive(host(b"\x20\x24"), 1.0)
    run(device, 1.1)
    device.receive(host(bytes.fromhex("3B 64 00 19 00")), 1.1)  # 100°, 0.25°: four revolutions
    scans = [(t, o.data) for t, o in run(device, 1.5) if o.droppable]
    assert {len(data) for _, data in scans} == {10 + 2 * 401}
    gaps = np.diff([t for t, _ in scans])
    np.testing.assert_allclose(gaps, 4 / 75)


@settings(max_examples=100, deadline=None)
@given(
    garbage=st.lists(st.binary(max_size=30), min_size=1, max_size=5),
    chunk=st.integers(1, 50),
)
def test_garbage_never_stops_the_device_answering(garbage: list[bytes], chunk: int) -> None:
    device = powered(baud=38400)
    request = host(b"\x3a")
    stream = b"".join(junk + request for junk in garbage)
    answers, now = [], 1.0
    for start in range(0, len(stream), chunk):
        answers += device.receive(stream[start : start + chunk], now)
        now += 0.001
    answers += device.poll(now + 1.0)  # abandons a bogus partial telegram, if garbage left one
    replies = [output.data for output in answers if len(output.data) > 1 and output.data[4] == 0xBA]
    assert len(replies) == len(garbage)
    assert device.receive(request, now + 2.0)[1].data[4] == 0xBA
