"""Scip22Device (UTM-30LX, UTM-30LX-EW, UST-10LX, UST-20LX) against the units' bytes.

Golden replies are written out literally from published transcripts
(docs/scip.md); data replies are checked with a decoder written here, line by
line as urg_library's `receive_length_data` reads them, independent of the
device's encoder.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from emulator.sensors.scan import Scan
from protocols.scip import UrgDevice
from protocols.scip.scip22 import Scip22Device

STEPS = 1081


@dataclass(frozen=True)
class FakeScan:
    time_s: float
    values: np.ndarray
    intensities: np.ndarray | None = None
    echoes: np.ndarray | None = None
    echo_intensities: np.ndarray | None = None


def source_of(values, intensities=None, echoes=None, echo_intensities=None):
    asked = []

    def source(t: float) -> FakeScan:
        asked.append(t)
        return FakeScan(t, np.asarray(values), intensities, echoes, echo_intensities)

    source.asked = asked
    return source


def flat(value: int = 1000):
    return source_of(np.full(STEPS, value), np.full(STEPS, 7))


def answer(device, command: bytes, now: float = 1.0) -> bytes:
    """The reply to one command, once its data have left."""
    outputs = device.receive(command + b"\n", now)
    outputs += device.poll(now + 0.1)
    replies = [o.data for o in outputs if not o.droppable]
    assert len(replies) == 1, replies
    return replies[0]


# --- an independent reader -------------------------------------------------------


def sum_char(text: bytes) -> int:
    return (sum(text) & 0x3F) + 0x30


def decode(chars: bytes) -> int:
    value = 0
    for char in chars:
        value = (value << 6) | (char - 0x30)
    return value


def read_reply(reply: bytes, *, width: int = 3, intensity: bool = False):
    """(echo, status, stamp, steps) where steps is a list of [(range, intensity|None), ...] per step."""
    lines = reply.split(b"\n")
    assert lines[-2:] == [b"", b""], "a reply ends with an empty line"
    echo, status_line, stamp_line, *data = lines[:-2]
    assert status_line[2] == sum_char(status_line[:2])
    assert stamp_line[4] == sum_char(stamp_line[:4])
    steps: list[list[tuple[int, int | None]]] = []
    pending = b""
    size = width * (2 if intensity else 1)
    for line in data:
        assert len(line) <= 65 and line[-1] == sum_char(line[:-1]), line
        pending += line[:-1]
        while True:
            further = pending[:1] == b"&"
            need = size + (1 if further else 0)
            if len(pending) < need:
                break
            body = pending[1:need] if further else pending[:need]
            value = (decode(body[:width]), decode(body[width:]) if intensity else None)
            if further:
                steps[-1].append(value)
            else:
                steps.append([value])
            pending = pending[need:]
    assert pending == b""
    return echo, status_line[:2], decode(stamp_line[:4]), steps


# --- identity -----------------------------------------------------------------------


def test_utm_30lx_ew_pp_is_the_published_transcript():
    device = Scip22Device(flat(), "utm-30lx-ew")
    assert answer(device, b"PP") == (
        b"PP\n00P\n"
        b"MODL:UTM-30LX-EW;I\nDMIN:23;7\nDMAX:60000;J\nARES:1440;^\n"
        b"AMIN:0;?\nAMAX:1080;Z\nAFRT:540;0\nSCAN:2400;U\n\n"
    )


@pytest.mark.parametrize("model,modl,dmin,dmax", [("ust-10lx", "UST-10LX", 20, 30000), ("ust-20lx", "UST-20LX", 20, 60000), ("utm-30lx", "UTM-30LX", 23, 60000)])
def test_pp_of_the_other_units(model, modl, dmin, dmax):
    reply = answer(Scip22Device(flat(), model), b"PP")
    fields = [line.split(b";")[0] for line in reply.split(b"\n")[2:-2]]
    assert fields == [
        b"MODL:" + modl.encode(), b"DMIN:%d" % dmin, b"DMAX:%d" % dmax, b"ARES:1440", b"AMIN:0", b"AMAX:1080", b"AFRT:540", b"SCAN:2400",
    ]  # fmt: skip
    for line in reply.split(b"\n")[2:-2]:
        text, _, check = line.partition(b";")
        assert check == bytes([sum_char(text)])


def test_vv_says_scip_2_2_and_the_scene_serial():
    reply = answer(Scip22Device(flat(), "ust-10lx", serial="H1614934"), b"VV")
    texts = [b"VEND:Hokuyo Automatic Co., Ltd.", b"PROD:UST-10LX", b"FIRM:2.23.0000", b"PROT:SCIP 2.2", b"SERI:H1614934"]
    assert reply == b"VV\n00P\n" + b"".join(text + b";" + bytes([sum_char(text)]) + b"\n" for text in texts) + b"\n"


@pytest.mark.parametrize("model,mesm,stat", [
    ("utm-30lx-ew", b"000 Idle", b"Stable 000 no error."),
    ("ust-10lx", b"Measuring by Sensitive Mode", b"sensor is working normally"),
])  # fmt: skip
def test_ii_carries_mesm_stat_sbps_and_an_encoded_time(model, mesm, stat):
    device = Scip22Device(flat(), model, start_time=0.0)
    reply = answer(device, b"II", now=0x123456 / 1000)
    fields = dict(line.split(b";")[0].split(b":", 1) for line in reply.split(b"\n")[2:-2])
    assert list(fields) == [b"MODL", b"LASR", b"SCSP", b"MESM", b"SBPS", b"TIME", b"STAT"]
    assert fields[b"MESM"] == mesm and fields[b"STAT"] == stat and fields[b"LASR"] == b"OFF"
    assert fields[b"SBPS"] == b"Ethernet 100 [Mbps]"
    assert decode(fields[b"TIME"]) == 0x123456


def test_ii_reports_the_streaming_state_of_a_utm():
    device = Scip22Device(flat(), "utm-30lx-ew")
    device.receive(b"MD0000108001000\n", 0.0)
    reply = [o.data for o in device.receive(b"II\n", 0.01) if not o.droppable][0]
    assert b"MESM:004 Multi_scan;" in reply and b"LASR:ON;" in reply


# --- refusals ---------------------------------------------------------------------------


def test_nd_is_refused_by_units_without_multi_echo_and_served_by_the_others():
    urg = UrgDevice(lambda t: None, timing="fast")
    assert [o.data for o in urg.receive(b"ND0000076800000\n", 0.0)] == [b"ND0000076800000\n0Ee\n\n"]
    assert answer(Scip22Device(flat(), "utm-30lx"), b"ND0000108000000") == b"ND0000108000000\n0Ee\n\n"
    assert answer(Scip22Device(flat(), "utm-30lx"), b"HD0000108000") == b"HD0000108000\n0Ee\n\n"
    assert answer(Scip22Device(flat(), "utm-30lx-ew"), b"ND0000108000001").startswith(b"ND0000108000001\n00P\n")


@pytest.mark.parametrize("command,status", [
    (b"GD0000108101", b"04"),  # end past AMAX
    (b"GD0100005001", b"05"),  # end before start
    (b"GDx000108001", b"01"), (b"GD0000x08001", b"02"), (b"GD00001080x1", b"03"),
    (b"MD0000108000x00", b"06"), (b"MD00001080010x0", b"07"),
    (b"GD00001080", b"0C"), (b"GD0000108001000", b"0D"), (b"XX", b"0E"), (b"CR01", b"0E"),
    (b"GD0000108001;" + b"a" * 17, b"0G"), (b"GD0000108001;a!b", b"0H"), (b"TM9", b"01"),
])  # fmt: skip
def test_malformed_requests_get_the_units_statuses(command, status):
    device = Scip22Device(flat(), "utm-30lx-ew")
    device.receive(b"BM\n", 0.0)
    reply = answer(device, command)
    assert reply == command + b"\n" + status + bytes([sum_char(status)]) + b"\n\n"


def test_gd_needs_the_laser_on():
    assert answer(Scip22Device(flat(), "ust-10lx"), b"GD0000108001") == b"GD0000108001\n10Q\n\n"


def test_time_adjust_mode():
    device = Scip22Device(flat(), "ust-10lx", start_time=0.0)
    assert answer(device, b"TM2") == b"TM2\n03S\n\n"
    assert answer(device, b"TM0") == b"TM0\n00P\n\n"
    assert answer(device, b"TM0") == b"TM0\n02R\n\n"
    assert answer(device, b"BM") == b"BM\n10Q\n\n"
    reply = answer(device, b"TM1", now=0xABCDE / 1000)
    assert decode(reply.split(b"\n")[2][:4]) == 0xABCDE
    assert answer(device, b"TM2") == b"TM2\n00P\n\n"
    assert answer(device, b"BM") == b"BM\n00P\n\n"


def test_rb_reboots_on_the_second_request_within_a_second():
    device = Scip22Device(flat(), "ust-10lx")
    assert answer(device, b"RB", now=1.0) == b"RB\n01Q\n\n"
    assert answer(device, b"RB", now=1.5) == b"RB\n00P\n\n"
    assert answer(device, b"RB", now=1.6) == b"RB\n01Q\n\n"


def test_a_confirmed_rb_hangs_up_a_second_later_and_the_unit_boots_with_its_timer_from_zero():
    """The unit waits a second for the host to disconnect, then drops the connection (after the scans
    due before), boots with the laser off and its timer restarted, and answers what came meanwhile
    once it is up (urg_sim's reboot, written against real units)."""
    from protocols.scip.scip22 import BOOT_S, REBOOT_DELAY_S

    device = Scip22Device(flat(), "ust-10lx")
    assert answer(device, b"BM", now=0.5) == b"BM\n00P\n\n"
    device.receive(b"MD0000108000000\n", now=0.6)  # streaming until the reboot
    assert answer(device, b"RB", now=1.0) == b"RB\n01Q\n\n"
    assert answer(device, b"RB", now=1.5) == b"RB\n00P\n\n"
    reboot_s = 1.5 + REBOOT_DELAY_S
    assert device.next_deadline() <= reboot_s
    before = device.poll(reboot_s - 0.01)
    assert before and all(not output.hang_up for output in before)  # the stream goes on meanwhile
    down = device.poll(reboot_s + 0.01)
    assert [output.hang_up for output in down][-1:] == [True] and sum(output.hang_up for output in down) == 1
    assert not device.laser_on and device.scan_stride_s() is None  # laser off, no stream
    assert device.booting(reboot_s + 0.5) and not device.booting(reboot_s + BOOT_S + 0.01)
    assert device.receive(b"TM1\n", now=reboot_s + 0.5) == []  # booting: answered once it is up
    assert device.next_deadline() == pytest.approx(reboot_s + BOOT_S)
    (reply,) = device.poll(reboot_s + BOOT_S)
    assert reply.data.startswith(b"TM1\n00P\n")
    assert decode(reply.data.split(b"\n")[2][:4]) == round(BOOT_S * 1000)  # the timer restarted at the reboot
    assert answer(device, b"BM", now=reboot_s + BOOT_S + 0.1) == b"BM\n00P\n\n"  # the laser was off


def test_ust_state_query():
    device = Scip22Device(flat(), "ust-10lx")
    assert answer(device, b"%ST") == b"%ST\n00P\n000@\n\n"
    device.receive(b"BM\n", 1.0)
    assert answer(device, b"%ST").split(b"\n")[2] == b"003C"
    assert answer(Scip22Device(flat(), "utm-30lx-ew"), b"%ST") == b"%ST\n0Ee\n\n"


# --- data --------------------------------------------------------------------------------


def test_ge_sends_range_and_intensity_three_characters_each():
    values = np.arange(STEPS) + 100
    device = Scip22Device(source_of(values, values * 2), "utm-30lx-ew")
    device.receive(b"BM\n", 0.0)
    echo, status, _, steps = read_reply(answer(device, b"GE0010002002"), intensity=True)
    assert (echo, status) == (b"GE0010002002", b"00")
    assert steps == [[(v, 2 * v)] for v in (110, 112, 114, 116, 118, 120)]


def test_multi_echo_with_an_echo_wrapping_over_a_line():
    """Step 0 has three echoes: 3 + 4 + 4 = 11 characters; five steps fill 55, the sixth's
    '&'-prefixed second echo starts at character 59 and ends on the next line."""
    echoes = np.full((STEPS, 3), -1)
    echoes[:, 0] = 4000
    echoes[:6, 1] = 5000
    echoes[:6, 2] = 6000
    device = Scip22Device(source_of(echoes[:, 0], echoes=echoes), "ust-10lx")
    device.receive(b"BM\n", 0.0)
    reply = answer(device, b"HD0000000601")
    lines = reply.split(b"\n")
    a, b, c = b"0nP", b"1>8", b"1M`"  # 4000, 5000, 6000 in three characters
    step = a + b"&" + b + b"&" + c
    payload = step * 6 + a  # steps 0..5 with three echoes, step 6 with one
    assert lines[3] == payload[:64] + bytes([sum_char(payload[:64])])
    assert lines[4] == payload[64:] + bytes([sum_char(payload[64:])])
    assert lines[3][62:64] == b"&1" and lines[4][:2] == b"M`"  # step 5's third echo straddles the lines
    _, _, _, steps = read_reply(reply)
    assert steps == [[(4000, None), (5000, None), (6000, None)]] * 6 + [[(4000, None)]]


@settings(max_examples=60, deadline=None)
@given(
    data=st.data(),
    start=st.integers(0, 1080),
    cluster=st.integers(0, 4),
    with_intensity=st.booleans(),
)
def test_multi_echo_round_trip(data, start, cluster, with_intensity):
    end = data.draw(st.integers(start, min(start + 300, 1080)))
    echo_count = data.draw(hnp.arrays(np.int64, STEPS, elements=st.integers(0, 3)))
    ranges = data.draw(hnp.arrays(np.int64, (STEPS, 3), elements=st.integers(23, 60000)))
    ranges.sort(axis=1)
    ranges[np.arange(3)[None, :] >= np.maximum(echo_count, 1)[:, None]] = -1
    ranges[echo_count == 0, 0] = 1  # nothing came back: the code
    strengths = data.draw(hnp.arrays(np.int64, (STEPS, 3), elements=st.integers(0, 262143)))
    strengths[ranges < 0] = -1
    device = Scip22Device(source_of(ranges[:, 0], strengths[:, 0], ranges, strengths), "utm-30lx-ew")
    device.receive(b"BM\n", 0.0)
    command = b"H" + (b"E" if with_intensity else b"D") + b"%04d%04d%02d" % (start, end, cluster)
    _, status, _, steps = read_reply(answer(device, command), intensity=with_intensity)
    assert status == b"00"
    size = max(cluster, 1)
    first = ranges[start : end + 1, 0]
    keyed = np.where(first < 20, first + (1 << 40), first)
    expected = []
    for begin in range(0, len(first), size):
        chosen = start + begin + int(np.argmin(keyed[begin : begin + size]))
        present = [k for k in range(3) if k == 0 or ranges[chosen, k] >= 0]
        expected.append([(int(ranges[chosen, k]), int(strengths[chosen, k]) if with_intensity else None) for k in present])
    assert steps == expected


# --- timing -------------------------------------------------------------------------------


def test_scans_are_stamped_at_their_first_step_and_leave_when_the_last_requested_step_is_swept():
    source = flat()
    device = Scip22Device(source, "utm-30lx-ew", phase_ms=3)
    device.receive(b"BM\n", 0.0)
    assert device.receive(b"GD0000054001\n", 0.030) == []  # waits for the sweep starting at 53 ms
    assert device.next_scan_time() == pytest.approx(0.053)
    assert device.next_deadline() == pytest.approx(0.053 + 0.025 * 540 / 1440)
    assert device.poll(0.053 + 0.009) == []
    [output] = device.poll(0.053 + 0.0094)
    assert read_reply(output.data)[2] == 53
    assert source.asked == [pytest.approx(0.053)]


def test_md_streams_every_25_ms_with_counts_and_wrapping_stamps():
    start = 16777.200  # a sweep starts here; the timer counts from 16 ms
    device = Scip22Device(flat(), "ust-10lx", start_time=0.016)
    device.receive(b"MD0000108001003\n", start)
    outputs = []
    while (deadline := device.next_deadline()) is not None:
        outputs += device.poll(deadline)
    scans = [o for o in outputs if o.droppable]
    assert [read_reply(o.data)[0] for o in scans] == [b"MD0000108001002", b"MD0000108001001", b"MD0000108001000"]
    stamps = [read_reply(o.data)[2] for o in scans]
    assert stamps == [16777184, 16777209, 18]
    assert not device.laser_on


def test_qt_ends_a_stream():
    device = Scip22Device(flat(), "ust-10lx")
    device.receive(b"ME0000108000000\n", 0.0)
    assert device.scan_stride_s() == 0.025
    sent = [o for step in range(4) for o in device.poll(step * 0.025 + 0.019) if o.droppable]
    assert len(sent) == 4
    device.receive(b"QT\n", 0.1)
    assert device.poll(1.0) == [] and device.next_deadline() is None and device.scan_stride_s() is None


def test_a_late_poll_sends_only_the_newest_scan():
    """A host that fell behind gets the newest scan due, not a burst of old ones (skipped revolutions)."""
    device = Scip22Device(flat(), "ust-10lx")
    device.receive(b"MD0000108001005\n", 0.0)
    [late] = [o for o in device.poll(0.080) if o.droppable]
    echo, _, stamp, _ = read_reply(late.data)
    assert (echo, stamp) == (b"MD0000108001002", 50)  # sweeps 0 and 25 skipped, two sent
    assert [read_reply(o.data)[0] for o in device.poll(1.0) if o.droppable] == [b"MD0000108001000"]


def test_commands_pipelined_behind_a_gd_run_one_at_a_time_after_it():
    """`GD…MD…` in one write sent the MD's first scan before the GD's reply and the MD's own echo (a
    driver checking the echo threw it away); commands behind a GD took effect when they arrived, so a
    TM1 read the timer ~30 ms before its reply left. Now each runs when the reply ahead of it has left."""
    device = Scip22Device(flat(), "ust-20lx")
    device.receive(b"BM\n", 0.0)
    outputs = device.receive(b"GD0000108000\nTM1\nMD0000001000003\n", 5.0101)
    while (deadline := device.next_deadline()) is not None:
        outputs += device.poll(deadline)
    echoes = [o.data.split(b"\n")[0] for o in outputs]
    assert echoes == [b"GD0000108000", b"TM1", b"MD0000001000003", *[b"MD000000100000%d" % n for n in (2, 1, 0)]]
    gd_stamp = read_reply(outputs[0].data)[2]
    gd_left_ms = gd_stamp + 25 * 1080 / 1440  # the GD's data leave once the mirror has swept step 1080
    tm1_timer = decode(outputs[1].data.split(b"\n")[2][:4])
    assert abs(tm1_timer - gd_left_ms) <= 1  # read when the GD was done, not when it arrived
    assert [read_reply(o.data)[2] for o in outputs[3:]] == [gd_stamp + 25 * k for k in (1, 2, 3)]


def test_a_qt_behind_a_gd_lets_the_gd_measure_first():
    device = Scip22Device(flat(), "utm-30lx-ew")
    device.receive(b"BM\n", 0.0)
    outputs = device.receive(b"GD0000108000\nQT\nGD0000108000\n", 1.0)
    assert device.laser_on  # the QT waits for the GD (it switched the laser off while the GD measured)
    outputs += device.poll(2.0)
    assert not device.laser_on
    statuses = [o.data.split(b"\n")[:2] for o in outputs]
    assert [echo for echo, _ in statuses] == [b"GD0000108000", b"QT", b"GD0000108000"]
    assert [status[:2] for _, status in statuses] == [b"00", b"00", b"10"]  # the laser went off between the two


# --- fuzzing ------------------------------------------------------------------------------

COMMANDS = [
    b"BM", b"QT", b"RS", b"RT", b"RB", b"VV", b"PP", b"II", b"TM0", b"TM1", b"TM2", b"%ST", b"%SL",
    b"GD0000108001", b"GE0000108003", b"HD0100020002", b"HE0000108000", b"MD0000108001000",
    b"ME0000108000002", b"ND0500054000103", b"NE0000108000001;t",
]  # fmt: skip
FRAGMENTS = [b";", b";tag", b"\n", b"\r", b"&", b"%", b"0", b"9"]


@settings(max_examples=150, deadline=None)
@given(
    model=st.sampled_from(["utm-30lx", "utm-30lx-ew", "ust-10lx", "ust-20lx"]),
    parts=st.lists(st.one_of(st.sampled_from(COMMANDS + FRAGMENTS), st.binary(max_size=90)), max_size=40),
    cuts=st.lists(st.integers(0, 4000), max_size=8),
)
def test_arbitrary_bytes_get_one_well_formed_reply_per_line(model, parts, cuts):
    stream = b"\n".join(parts) + b"\n"
    lines = [line[:64] for line in re.split(rb"[\r\n]", stream)[:-1] if line]
    points = sorted({min(c, len(stream)) for c in cuts})
    device = Scip22Device(flat(), model)
    outputs = []
    for a, b in zip([0, *points], [*points, len(stream)]):
        outputs += device.receive(stream[a:b], 1.0)
    outputs += device.poll(10.0)
    replies = [o.data for o in outputs if not o.droppable and not o.hang_up]  # a reboot's hang-up is no message
    assert len(replies) + device.lost_commands == len(lines)
    echoed = lines if device.lost_commands == 0 else [reply.split(b"\n")[0] for reply in replies]
    for reply, line in zip(replies, echoed):
        assert reply.startswith(line + b"\n") and reply.endswith(b"\n\n")
        status = reply[len(line) + 1 :].split(b"\n")[0]
        assert len(status) == 3 and status[2] == sum_char(status[:2])


def test_ss_sets_a_usb_units_rate_and_an_ethernet_unit_has_none():
    """urg_library's change_sensor_baudrate expects 00, 03 or 04 over serial and takes 0F as an
    Ethernet sensor's answer."""
    usb = Scip22Device(flat(), "utm-30lx")
    assert answer(usb, b"SS115200") == b"SS115200\n03S\n\n"
    assert answer(usb, b"SS500000") == b"SS500000\n00P\n\n"
    assert answer(usb, b"SS123456") == b"SS123456\n02R\n\n"
    assert answer(usb, b"SS11520x") == b"SS11520x\n01Q\n\n"
    assert usb.baud is None  # USB: never paced
    assert answer(Scip22Device(flat(), "ust-10lx"), b"SS115200") == b"SS115200\n0Ff\n\n"


def _varying_scans(steps: int = STEPS):
    """A scan per instant, the same object each time it is asked for (as the daemon's scan cache
    gives it): ranges, intensities and three echoes that change with the instant."""
    kept = {}

    def source(t: float) -> Scan:
        tick = round(t * 1e6)
        if tick not in kept:
            rng = np.random.default_rng(tick)
            echoes = np.sort(rng.integers(20, 30000, (steps, 3)), axis=1)
            echoes[rng.random(steps) < 0.3, 1:] = -1
            kept[tick] = Scan("s", "m", t, np.zeros(steps), echoes[:, 0].copy(), intensities=rng.integers(0, 5000, steps),
                              echoes=echoes, echo_intensities=rng.integers(0, 5000, (steps, 3)))
        return kept[tick]

    return source


@pytest.mark.parametrize("model, command", [
    *((model, command) for model in ("ust-10lx", "utm-30lx-ew")
      for command in (b"MD0044072501000", b"ME0000108002000", b"ND0000108000000", b"NE0100090003000")),
    ("urg-04lx", b"MD0044072501000"), ("urg-04lx", b"MS0100050002000"),
])
def test_a_scan_encoded_ahead_sends_the_same_bytes(model, command):
    """`prepare_next` (the daemon calls it after each send) encodes the stream's next scan early; the
    deadline reuses those lines only for that very scan. Every message is byte-identical to a device
    that never prepares: with the right scan ready, with a stale one offered instead (a live change
    replaced it), and with none."""
    steps = 769 if model == "urg-04lx" else STEPS

    def stream(offer):
        source = _varying_scans(steps)
        device = UrgDevice(source) if model == "urg-04lx" else Scip22Device(source, model)
        device.receive(command + b"\n", 0.0)
        sent = []
        for _ in range(12):
            deadline = device.next_deadline()
            sent += [o.data for o in device.poll(deadline)]
            if offer is not None:
                device.prepare_next(lambda t: offer(source, t))
        return sent

    plain = stream(None)
    assert len(plain) >= 10
    assert stream(lambda source, t: source(t)) == plain
    stale = _varying_scans(steps)  # equal-looking scans of other objects, with other values
    assert stream(lambda source, t: stale(t + 0.5)) == plain
    assert stream(lambda source, t: None) == plain


def test_the_lines_encoded_ahead_are_the_ones_sent():
    """The reuse is real: encoding at the deadline is skipped for the scan prepared."""
    source = _varying_scans()
    device = Scip22Device(source, "ust-10lx")
    device.receive(b"ME0000108000000\n", 0.0)
    device.poll(device.next_deadline())
    device.prepare_next(source)
    encoded = []
    original = device._encode_data
    device._encode_data = lambda *args: encoded.append(args) or original(*args)  # type: ignore[method-assign]
    [message] = [o.data for o in device.poll(device.next_deadline())]
    assert encoded == [] and b"ME0000108000000" in message


def test_a_scan_prepared_twice_before_its_deadline_is_encoded_once():
    """A reply delivered between two scans makes the daemon offer the same next scan again: no second encoding."""
    source = _varying_scans()
    device = Scip22Device(source, "ust-10lx")
    device.receive(b"ME0000108000000\n", 0.0)
    device.poll(device.next_deadline())
    encoded = []
    original = device._encode_data
    device._encode_data = lambda *args: encoded.append(args) or original(*args)  # type: ignore[method-assign]
    device.prepare_next(source)
    device.prepare_next(source)
    assert len(encoded) == 1
