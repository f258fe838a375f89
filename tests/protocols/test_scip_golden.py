"""UrgDevice against the bytes of a real URG-04LX (firmware 3.1.04).

The capture (tests/protocols/data, copied from the contract's reference) is
parsed here: every reply below is compared with what the real unit sent.
"""

from __future__ import annotations

import ast
from pathlib import Path

import numpy as np
import pytest

from emulator.sensors.scan import Scan
from protocols.scip import UrgDevice
from protocols.scip.encoding import checksum, decode_values, join_data_lines

CAPTURE = Path(__file__).resolve().parent / "data" / "urg04lx-real-session.txt"
STEPS = 769


def capture_exchanges() -> list[tuple[bytes, bytes]]:
    """(command written, reply read) pairs of the real session, in order."""
    records = []
    for row in CAPTURE.read_text().splitlines():
        _, direction, literal = row.split(" ", 2)
        records.append((direction, ast.literal_eval(literal)))
    writes = [data for direction, data in records if direction == "W"]
    reads = [data for direction, data in records if direction == "R"]
    assert len(writes) == len(reads)
    return list(zip(writes, reads))


def real_reply(command: bytes, occurrence: int = 0) -> bytes:
    return [reply for written, reply in capture_exchanges() if written == command][occurrence]


def fixed_scan_source(values: np.ndarray):
    """Every grid time yields the same values, stamped with its own time."""

    def source(t: float) -> Scan:
        return Scan("urg", "URG-04LX", t, np.zeros(STEPS), values)

    return source


def test_capture_holds_the_expected_exchanges():
    commands = [written for written, _ in capture_exchanges()]
    assert commands == [b"VV\n", b"VV\n", b"PP\n", b"II\n", b"BM\n", b"CR00\n", b"VV\n", b"PP\n", b"II\n", b"GD0044072501\n"]


@pytest.mark.parametrize("command", [b"VV\n", b"PP\n"])
def test_identity_replies_are_byte_exact(command):
    device = UrgDevice(fixed_scan_source(np.zeros(STEPS, dtype=int)), timing="fast")
    [output] = device.receive(command, now=5.0)
    assert output.data == real_reply(command)
    assert not output.droppable


def test_serial_number_appears_in_vv_with_its_checksum():
    device = UrgDevice(fixed_scan_source(np.zeros(STEPS, dtype=int)), timing="fast", serial="H1234567")
    [output] = device.receive(b"VV\n", now=0.0)
    assert b"SERI:H1234567;" + checksum(b"SERI:H1234567") + b"\n\n" in output.data


@pytest.mark.parametrize("occurrence,timer_ms", [(0, 0x6A5404), (1, 0x6A55F8)])
def test_ii_reply_is_byte_exact_when_the_timer_reads_the_same(occurrence, timer_ms):
    start_time = 100.0
    device = UrgDevice(fixed_scan_source(np.zeros(STEPS, dtype=int)), timing="fast", start_time=start_time)
    device.receive(b"BM\n", now=start_time)
    [output] = device.receive(b"II\n", now=start_time + timer_ms / 1000)
    assert output.data == real_reply(b"II\n", occurrence)


@pytest.mark.parametrize("timer_ms", [0, 1, 0x081615, 0x6A5404, 0xFFFFFF])
def test_ii_time_line_is_live_upper_hex_with_checksum_of_the_text_before_the_semicolon(timer_ms):
    device = UrgDevice(fixed_scan_source(np.zeros(STEPS, dtype=int)), timing="fast")
    [output] = device.receive(b"II\n", now=timer_ms / 1000)
    lines = output.data.split(b"\n")
    assert len(lines) == 2 + 7 + 2  # echo, status, 7 info lines, empty line, trailing ''
    time_text = f"TIME:{timer_ms:06X}".encode()
    assert lines[7] == time_text + b";" + checksum(time_text)
    assert lines[3] == b"LASR:OFF;7"  # as Hokuyo's wiki shows for a laser that is off
    assert lines[5] == b"MESM:IDLE;:"


def test_timer_wraps_at_24_bits():
    device = UrgDevice(fixed_scan_source(np.zeros(STEPS, dtype=int)), timing="fast")
    [output] = device.receive(b"II\n", now=(1 << 24) / 1000 + 0.005)
    assert b"TIME:000005;" in output.data


def decoded_capture_scan() -> tuple[np.ndarray, int]:
    """Values of steps 44..725 and the timestamp, decoded from the real GD reply."""
    reply = real_reply(b"GD0044072501\n")
    head, _, rest = reply.partition(b"00P\n")
    stamp_line, _, blocks = rest.partition(b"\n")
    assert checksum(stamp_line[:4]) == stamp_line[4:]
    values = decode_values(join_data_lines(blocks[:-1]), 3)
    return values, int(decode_values(stamp_line[:4], 4)[0])


def test_gd_reply_is_rebuilt_byte_for_byte_from_its_decoded_values():
    capture_values, stamp = decoded_capture_scan()
    assert len(capture_values) == 682 and stamp == 0x6A55FE
    values = np.full(STEPS, 1, dtype=int)  # steps outside 44..725: an error code
    values[44:726] = capture_values
    scan_time_s = 7000.0
    start_time = scan_time_s - stamp / 1000  # so the scan's stamp reads 0x6A55FE
    device = UrgDevice(fixed_scan_source(values), timing="fast", start_time=start_time)
    device.receive(b"BM\n", now=scan_time_s)
    [output] = device.receive(b"GD0044072501\n", now=scan_time_s + 0.05)
    assert len(output.data) == 2134
    assert output.data == real_reply(b"GD0044072501\n")


@pytest.mark.parametrize("command", [b"BM\n", b"CR00\n"])
def test_already_in_that_state_statuses_match_the_capture(command):
    device = UrgDevice(fixed_scan_source(np.zeros(STEPS, dtype=int)), timing="fast")
    device.receive(b"BM\n", now=0.0)  # the real unit's laser was already on
    [output] = device.receive(command, now=0.1)
    assert output.data == real_reply(command)
