"""MD/MS streaming against an independent model of which scans go out when."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from emulator.sensors.scan import Scan
from protocols.scip import UrgDevice
from protocols.scip.encoding import checksum, decode_values, join_data_lines

STEPS = 769


def ramp_source(t: float) -> Scan:
    """Scan k = round(10 t): step s reads 100 + 3 s + k mm (errors where s % 50 == 7)."""
    index = round(t * 10)
    values = 100 + 3 * np.arange(STEPS) + index
    values[7::50] = 7
    return Scan("urg", "URG-04LX", t, np.zeros(STEPS), values)


def expected_values(index: int, start: int, end: int, cluster: int) -> list[int]:
    """The clustered values of scan `index`, computed one cluster at a time."""
    raw = ramp_source(index / 10).values[start : end + 1].tolist()
    out = []
    for first in range(0, len(raw), cluster):
        run = raw[first : first + cluster]
        distances = [v for v in run if v >= 20]
        out.append(min(distances) if distances else min(run))
    return out


def parse_scan_message(data: bytes, width: int) -> tuple[bytes, list[int], int]:
    """(echo, values, stamp) of one streamed message, checking every checksum."""
    echo, status, stamp_line, blocks = data.split(b"\n", 3)
    assert status == b"99b"
    assert checksum(stamp_line[:4]) == stamp_line[4:]
    assert blocks.endswith(b"\n\n")
    values = decode_values(join_data_lines(blocks[:-1]), width).tolist()
    return echo, values, int(decode_values(stamp_line[:4], 4)[0])


@settings(max_examples=60, deadline=None)
@given(
    code=st.sampled_from([b"MD", b"MS"]),
    start=st.integers(0, 768),
    span=st.integers(0, 768),
    cluster=st.integers(0, 99),
    interval=st.integers(0, 9),
    count=st.integers(0, 12),
    request_ms=st.integers(0, 5000),
    poll_steps_ms=st.lists(st.integers(1, 900), min_size=1, max_size=25),
    tag=st.sampled_from([b"", b";", b";tag 1"]),
)
def test_md_streams_the_right_scans_counts_and_stops(
    code, start, span, cluster, interval, count, request_ms, poll_steps_ms, tag
):
    end = min(start + span, 768)
    width = 3 if code == b"MD" else 2
    params = b"%04d%04d%02d%d%02d" % (start, end, cluster, interval, count)
    device = UrgDevice(ramp_source, timing="fast")
    [ack] = device.receive(code + params + tag + b"\n", now=request_ms / 1000)
    assert ack.data == code + params + tag + b"\n00P\n\n"
    assert device.laser_on

    # the model: first scan wholly measured after the request, then every (interval + 1) scans
    first = -(-request_ms // 100) + 1
    planned = [first + j * (interval + 1) for j in range(count if count else 10_000)]
    sent: list[int] = []
    now_ms = request_ms
    for step in poll_steps_ms:
        now_ms += step
        due = [k for k in planned if k * 100 <= now_ms and k not in sent]
        expected_now = due[-1:]  # a poll later than one scan sends only the newest due: the others are skipped
        outputs = device.poll(now_ms / 1000)
        assert len(outputs) == len(expected_now)
        for output, index in zip(outputs, expected_now):
            assert output.droppable
            echo, values, stamp = parse_scan_message(output.data, width)
            remaining = 0 if count == 0 else count - 1 - planned.index(index)
            assert echo == code + params[:11] + b"%02d" % remaining + tag
            assert stamp == index * 100
            assert values == [min(v, 4095) if width == 2 else v for v in expected_values(index, start, end, max(cluster, 1))]
        sent += due
        done = count and len(sent) == count
        assert device.laser_on == (not done)
        upcoming = [k for k in planned if k not in sent]
        assert device.next_deadline() == (None if done else upcoming[0] / 10)


def test_qt_stops_the_stream_after_scans_already_due():
    device = UrgDevice(ramp_source, timing="fast")
    device.receive(b"MD0044072501000\n", now=1.0)
    outputs = device.receive(b"QT\n", now=1.15)
    assert [o.droppable for o in outputs] == [True, False]
    assert outputs[0].data.startswith(b"MD0044072501000\n99b\n")
    assert outputs[1].data == b"QT\n00P\n\n"
    assert device.poll(5.0) == [] and device.next_deadline() is None and not device.laser_on


def test_a_late_poll_sends_only_the_newest_scan_but_counts_all():
    """A host that falls behind skips revolutions: one message with the newest scan and its own
    stamp, the remaining count lowered by every scan skipped; never a backlog in one burst."""
    device = UrgDevice(ramp_source, timing="fast")
    device.receive(b"MD0044004501050\n", now=0.0)
    outputs = device.poll(3.0)  # 30 scans due, 50 requested
    assert len(outputs) == 1
    assert outputs[0].data.split(b"\n", 1)[0] == b"MD0044004501020"
    assert parse_scan_message(outputs[0].data, 3)[2] == 3000
    assert device.next_deadline() == 3.1
    device.receive(b"MD0044004501003\n", now=3.0)
    (last,) = device.poll(9.0)  # 3 requested, all due: the third and last is sent, then the laser goes off
    assert last.data.split(b"\n", 1)[0] == b"MD0044004501000" and parse_scan_message(last.data, 3)[2] == 3300
    assert not device.laser_on


def test_a_new_md_replaces_the_running_one():
    device = UrgDevice(ramp_source, timing="fast")
    device.receive(b"MD0044072501000\n", now=0.0)
    device.receive(b"MS0100010102003\n", now=0.3)
    outputs = device.poll(0.5)  # a poll one scan late: the newest only (0.4 s skipped)
    assert [o.data.split(b"\n", 1)[0] for o in outputs] == [b"MS0100010102001"]
    assert [parse_scan_message(o.data, 2)[2] for o in outputs] == [500]


def test_gd_while_streaming_is_answered_between_scans():
    device = UrgDevice(ramp_source, timing="fast")
    device.receive(b"MD0044072501003\n", now=0.0)
    outputs = device.receive(b"GD0044072501\n", now=0.2)  # not polled at 0.1: that scan is skipped
    assert [o.data.split(b"\n", 2)[1] for o in outputs] == [b"99b", b"00P"]
    assert [o.droppable for o in outputs] == [True, False]
    assert device.laser_on and device.next_deadline() == 0.3
