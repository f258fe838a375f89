"""Arbitrary bytes in arbitrary chunks: the device never raises, answers every
complete line exactly once with a well-formed reply, and chunking changes nothing."""

from __future__ import annotations

import re

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from emulator.sensors.scan import Scan
from protocols.device import Output
from protocols.scip import UrgDevice
from protocols.scip.encoding import checksum

STEPS = 769
MAX_LINE = 64
COMMANDS = [
    b"BM", b"QT", b"RS", b"VV", b"PP", b"II", b"TM0", b"TM1", b"TM2", b"HS1", b"CR05", b"SS115200",
    b"GD0044072501", b"GS0000076810", b"MD0044072501000", b"MS0100020003105;t", b"MD0000076800003",
    b"SCIP2.0", b"V", b"G00076801",
]  # fmt: skip
FRAGMENTS = [b";", b";tag", b"\n", b"\r", b"0", b"9"]
TERMINATORS = [b"\n", b"\r", b"\r\n"]


def noisy_source(t: float) -> Scan:
    rng = np.random.default_rng(round(t * 10))
    return Scan("urg", "URG-04LX", t, np.zeros(STEPS), rng.integers(0, 6000, STEPS))


whole_commands = st.tuples(st.sampled_from(COMMANDS), st.sampled_from(TERMINATORS)).map(b"".join)
parts = st.lists(st.one_of(whole_commands, st.sampled_from(COMMANDS + FRAGMENTS), st.binary(max_size=90)), max_size=40)
streams = parts.map(b"".join)


def complete_lines(stream: bytes) -> list[bytes]:
    """What each reply must echo: non-empty terminated lines, cut to the device's bound."""
    return [line[:MAX_LINE] for line in re.split(rb"[\r\n]", stream)[:-1] if line]


def replies_to(device: UrgDevice, chunks: list[bytes], now: float) -> list[Output]:
    """The replies (not streamed scans) to `chunks` received at `now`, once every GD/GS has
    had the revolution it waits for (a GD/GS reports a scan no earlier GD/GS reported)."""
    outputs = []
    for chunk in chunks:
        outputs += device.receive(chunk, now=now)
    outputs += device.poll(now + 0.1 * (len(complete_lines(b"".join(chunks))) + 1))
    return [output for output in outputs if not output.droppable]


def chunked(stream: bytes, cuts: list[int]) -> list[bytes]:
    points = sorted({min(c, len(stream)) for c in cuts})
    return [stream[a:b] for a, b in zip([0, *points], [*points, len(stream)])]


def well_formed_scip2(reply: bytes, echo: bytes) -> bool:
    """Echo, status + sum, lines each carrying a valid sum, empty line."""
    if not reply.startswith(echo + b"\n") or not reply.endswith(b"\n\n"):
        return False
    lines = reply[len(echo) + 1 : -2].split(b"\n")
    for line in lines:
        plain = len(line) >= 2 and checksum(line[:-1]) == line[-1:]
        info = len(line) >= 3 and line[-2:-1] == b";" and checksum(line[:-2]) == line[-1:]
        if not (plain or info):
            return False
    return len(lines[0]) == 3


@settings(max_examples=150, deadline=None)
@given(stream=streams, cuts=st.lists(st.integers(0, 4000), max_size=12))
def test_every_line_gets_one_well_formed_reply_whatever_the_chunking(stream, cuts):
    outputs = replies_to(UrgDevice(noisy_source, timing="fast"), chunked(stream, cuts), now=10.0)
    lines = complete_lines(stream)
    assert len(outputs) == len(lines)
    for output, line in zip(outputs, lines):
        assert well_formed_scip2(output.data, line), (line, output.data)

    whole = replies_to(UrgDevice(noisy_source, timing="fast"), [stream], now=10.0)
    assert [o.data for o in whole] == [o.data for o in outputs]


def well_formed_scip1(reply: bytes, echo: bytes) -> bool:
    """Echo, `E` + empty line, or `0` + unchecked lines + empty line."""
    return reply == echo + b"\nE\n\n" or (reply.startswith(echo + b"\n0\n") and reply.endswith(b"\n\n"))


@settings(max_examples=100, deadline=None)
@given(stream=streams, cuts=st.lists(st.integers(0, 4000), max_size=12))
def test_scip1_boot_answers_in_1_1_until_switched_then_in_2_0(stream, cuts):
    outputs = replies_to(UrgDevice(noisy_source, timing="fast", boot_protocol="scip1"), chunked(stream, cuts), now=10.0)
    lines = complete_lines(stream)
    assert len(outputs) == len(lines)
    switched = False
    for output, line in zip(outputs, lines):
        if switched:
            assert well_formed_scip2(output.data, line), (line, output.data)
        elif line == b"SCIP2.0":
            assert output.data == b"SCIP2.0\n0\n\n"
            switched = True
        else:
            assert well_formed_scip1(output.data, line), (line, output.data)

    whole = replies_to(UrgDevice(noisy_source, timing="fast", boot_protocol="scip1"), [stream], now=10.0)
    assert [o.data for o in whole] == [o.data for o in outputs]


@settings(max_examples=100, deadline=None)
@given(pieces=parts, step_ms=st.integers(1, 400))
def test_streaming_while_time_advances_stays_well_formed(pieces, step_ms):
    device = UrgDevice(noisy_source, timing="fast")
    replies, scans = [], []
    for position, piece in enumerate(pieces):
        for output in device.receive(piece, now=position * step_ms / 1000):
            (scans if output.droppable else replies).append(output.data)
    for output in device.poll(1e4):  # GD/GS replies waiting for their revolution, and the stream
        (scans if output.droppable else replies).append(output.data)
    lines = complete_lines(b"".join(pieces))
    assert len(replies) == len(lines)
    assert all(well_formed_scip2(reply, line) for reply, line in zip(replies, lines))
    for scan in scans:
        echo = scan.split(b"\n", 1)[0]
        assert echo[:2] in (b"MD", b"MS") and scan.split(b"\n", 2)[1] == b"99b"
        assert well_formed_scip2(scan, echo)
