"""The real unit's command cycle (docs/scip.md, "Time"): replies at the
100 ms cycle points, GD/GS with a revolution measured after the command,
RS stamps, and the `fast` option. Simulated time only: no sleeping."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from emulator.sensors.scan import Scan
from protocols.scip import UrgDevice
from protocols.scip.encoding import checksum, decode_values

STEPS = 769


def ramp_source(t: float) -> Scan:
    return Scan("urg", "URG-04LX", t, np.zeros(STEPS), 100 + np.arange(STEPS) + round(t * 10))


def stamp_of(reply: bytes) -> int:
    stamp_line = reply.split(b"\n")[2]
    assert checksum(stamp_line[:4]) == stamp_line[4:]
    return int(decode_values(stamp_line[:4], 4)[0])


def answer(device: UrgDevice, line: bytes, now: float) -> tuple[float, bytes]:
    """Send `line` at `now`, poll at each deadline until the reply: (reply time, reply)."""
    outputs = device.receive(line + b"\n", now)
    while not outputs:
        now = device.next_deadline()
        assert now is not None, f"no reply to {line!r} and nothing scheduled"
        outputs = device.poll(now)
    [output] = outputs
    return now, output.data


@pytest.fixture
def device() -> UrgDevice:
    return UrgDevice(ramp_source)


@pytest.mark.parametrize("sent", [1.0001, 1.03, 1.0999])
def test_a_command_is_answered_at_the_next_cycle_point(device, sent):
    assert device.receive(b"VV\n", sent) == []
    assert device.next_deadline() == pytest.approx(1.1)
    assert device.poll(1.09) == []
    [output] = device.poll(1.1)
    assert output.data.startswith(b"VV\n00P\n")


def test_a_command_on_a_cycle_point_is_answered_at_once(device):
    [output] = device.receive(b"VV\n", 2.0)
    assert output.data.startswith(b"VV\n00P\n")


def test_gd_reports_the_first_revolution_measured_after_it(device):
    answer(device, b"BM", 0.95)
    replied, reply = answer(device, b"GD0044072501", 1.05)  # the revolution 1.0-1.1 began before it
    assert replied == pytest.approx(1.2) and stamp_of(reply) == 1200


def test_back_to_back_gds_get_distinct_scans_100_ms_apart(device):
    """hokuyo_node throws "timestamp has not changed for 3 reads" otherwise."""
    answer(device, b"BM", 0.95)
    now, stamps = 1.0, []
    for _ in range(4):
        now, reply = answer(device, b"GD0044072501", now + 0.0005)  # the client asks again at once
        stamps.append(stamp_of(reply))
    assert np.diff(stamps).tolist() == [100, 100, 100]
    assert stamps[0] == 1100


def test_replies_leave_in_command_order(device):
    answer(device, b"BM", 0.95)
    assert device.receive(b"GD0044072501\nVV\n", 1.05) == []
    assert device.poll(1.1) == []  # VV is handled at 1.1 but waits behind the GD's scan
    gd, vv = device.poll(1.2)
    assert gd.data.startswith(b"GD") and vv.data.startswith(b"VV")


def test_rs_restarts_stamps_from_a_small_positive_value(device):
    """The issue's BM, GD after RS read 16777211: a scan from before the reset."""
    answer(device, b"BM", 4.95)
    answer(device, b"GD0044072501", 5.0)
    reset_at, _ = answer(device, b"RS", 5.3)
    answer(device, b"BM", reset_at + 0.001)
    _, reply = answer(device, b"GD0044072501", reset_at + 0.002)
    assert 0 < stamp_of(reply) <= 200


@pytest.mark.parametrize("timing", ["real", "fast"])
def test_rs_and_gd_sent_together_never_report_a_scan_from_before_the_reset(timing):
    device = UrgDevice(ramp_source, timing=timing)
    answer(device, b"BM", 4.95)
    device.receive(b"RS\nBM\n", 5.3)
    _, reply = answer(device, b"GD0044072501", 5.3)
    assert 0 < stamp_of(reply) <= 200


def test_fast_timing_answers_at_once_with_the_newest_scan():
    device = UrgDevice(ramp_source, timing="fast")
    device.receive(b"BM\n", 1.0)
    [output] = device.receive(b"GD0044072501\n", 1.05)
    assert stamp_of(output.data) == 1000


def test_fast_timing_never_repeats_a_scan_a_gd_has_sent():
    device = UrgDevice(ramp_source, timing="fast")
    device.receive(b"BM\n", 1.0)
    [first] = device.receive(b"GD0044072501\n", 1.05)
    assert device.receive(b"GD0044072501\n", 1.06) == []  # waits for the next revolution
    assert device.next_deadline() == pytest.approx(1.1)
    [second] = device.poll(1.1)
    assert stamp_of(second.data) - stamp_of(first.data) == 100


def test_md_acknowledges_at_the_cycle_point_and_streams_the_revolutions_after(device):
    replied, ack = answer(device, b"MD0044072501000", 1.02)
    assert replied == pytest.approx(1.1) and ack == b"MD0044072501000\n00P\n\n"
    [scan] = device.poll(1.2)
    assert stamp_of(scan.data) == 1200


def test_unknown_timing_is_rejected():
    with pytest.raises(ValueError, match="timing"):
        UrgDevice(ramp_source, timing="slow")


def test_a_flood_of_commands_is_bounded(device):
    """A client that sends thousands of GDs without reading: at most 32 wait, the rest are lost."""
    answer(device, b"BM", 0.95)
    device.receive(b"GD0044072501\n" * 5000, 1.001)
    assert device.lost_commands == 5000 - 32
    replies, now = 0, 1.001
    while device.next_deadline() is not None:
        now = device.next_deadline()
        replies += len(device.poll(now))
    assert replies == 32 and now == pytest.approx(4.2)  # one fresh revolution each


# --- a unit whose revolutions complete `phase_ms` past each 100 ms ------------------------------


def test_a_phased_unit_answers_at_its_own_cycle_points():
    device = UrgDevice(ramp_source, phase_ms=37)
    assert device.receive(b"VV\n", 1.03) == []
    assert device.next_deadline() == pytest.approx(1.037)
    [vv] = device.poll(1.037)
    assert vv.data.startswith(b"VV\n00P\n")
    assert device.receive(b"VV\n", 1.04) == [] and device.next_deadline() == pytest.approx(1.137)


def test_a_phased_unit_stamps_and_streams_its_own_revolutions():
    asked: list[float] = []
    device = UrgDevice(lambda t: asked.append(t) or ramp_source(t), phase_ms=37)
    answer(device, b"BM", 0.95)
    replied, reply = answer(device, b"GD0044072501", 1.05)  # the revolution 0.937-1.037... began before it
    assert replied == pytest.approx(1.237) and stamp_of(reply) == 1237 and asked == [1.237]
    replied, ack = answer(device, b"MD0044072501000", 1.3)
    assert replied == pytest.approx(1.337)
    assert device.next_deadline() == pytest.approx(1.437)
    [scan] = device.poll(1.437)
    assert stamp_of(scan.data) == 1437 and asked[-1] == 1.437


def test_a_phase_outside_one_revolution_is_refused():
    with pytest.raises(ValueError, match="phase_ms must be 0..99, got 100"):
        UrgDevice(ramp_source, phase_ms=100)


COMMANDS = [b"VV", b"BM", b"QT", b"TM0", b"TM1", b"TM2", b"GD0044072501", b"GS0100020002", b"MD0044072501003", b"MS0100020000"]


@settings(max_examples=60, deadline=None)
@given(
    phase_ms=st.integers(1, 99),
    script=st.lists(st.tuples(st.floats(0.0005, 0.35), st.sampled_from(COMMANDS)), min_size=1, max_size=12),
    timing=st.sampled_from(["real", "fast"]),
)
def test_a_phased_unit_is_the_unphased_one_shifted_by_its_phase(phase_ms, script, timing):
    """Everything a unit does happens `phase` later, byte for byte (after an RS both count from their reset)."""

    def run(phase: int) -> list[tuple[float, bytes]]:
        shift = phase / 1000
        def source(t: float) -> Scan:  # the same values for the same revolution; the stamp is the unit's own
            return Scan("urg", "URG-04LX", t, np.zeros(STEPS), ramp_source(round(t - shift, 6)).values)

        device = UrgDevice(source, phase_ms=phase, timing=timing)
        now, seen = 2.05 + shift, []

        def drain(until: float) -> None:
            while (deadline := device.next_deadline()) is not None and deadline <= until + 1e-9:
                seen.extend((round(deadline - shift, 6), output.data) for output in device.poll(deadline))

        seen.extend((round(now - shift, 6), output.data) for output in device.receive(b"RS\n", now))
        for gap, line in script:
            drain(now + gap)
            now += gap
            seen.extend((round(now - shift, 6), output.data) for output in device.receive(line + b"\n", now))
        drain(now + 1.0)
        return seen

    assert run(phase_ms) == run(0)
