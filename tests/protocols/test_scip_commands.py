"""Every SCIP 2.0 command of the fact sheet, and every status it can answer."""

from __future__ import annotations

import numpy as np
import pytest

from emulator.sensors.scan import Scan
from protocols.scip import UrgDevice
from protocols.scip.encoding import checksum, decode_values, join_data_lines

STEPS = 769


def ramp_source(t: float) -> Scan:
    """Scan k = round(10 t): step s reads 100 + s + k mm, so replies show which scan they carry."""
    index = round(t * 10)
    return Scan("urg", "URG-04LX", t, np.zeros(STEPS), 100 + np.arange(STEPS) + index)


def send(device: UrgDevice, line: bytes, now: float = 1.0) -> bytes:
    [output] = device.receive(line + b"\n", now)
    return output.data


def status_of(reply: bytes) -> bytes:
    status_line = reply.split(b"\n")[1]
    assert checksum(status_line[:2]) == status_line[2:], reply
    return status_line[:2]


def scan_values(reply: bytes, width: int) -> tuple[np.ndarray, int]:
    """(values, timestamp) of a GD/GS/MD/MS message."""
    _, _, stamp_line, blocks = reply.split(b"\n", 3)
    assert checksum(stamp_line[:4]) == stamp_line[4:]
    assert blocks.endswith(b"\n\n")
    return decode_values(join_data_lines(blocks[:-1]), width), int(decode_values(stamp_line[:4], 4)[0])


def info(reply: bytes, key: bytes) -> bytes:
    for line in reply.split(b"\n"):
        if line.startswith(key + b":"):
            return line[len(key) + 1 : -2]
    raise AssertionError(f"no {key!r} in {reply!r}")


@pytest.fixture
def device() -> UrgDevice:
    return UrgDevice(ramp_source, timing="fast")


@pytest.mark.parametrize(
    "line", [b"%ST", b"ME0044072501000", b"ND", b"NE", b"GE0044072501", b"HD", b"RB", b"RT", b"SCIP2.0", b"V", b"xx", b"vv"]
)
def test_unknown_commands_get_0E_and_an_exact_echo(device, line):
    assert send(device, line) == line + b"\n0Ee\n\n"


@pytest.mark.parametrize("line", [b"TM", b"HS", b"CR0", b"SS01920", b"GD004407250", b"GS", b"MD004407250100", b"MS0044"])
def test_too_short_parameters_get_0C(device, line):
    assert send(device, line) == line + b"\n0Cc\n\n"


@pytest.mark.parametrize("line", [b"BM0", b"QT1", b"VV2", b"TM00", b"CR000", b"GD004407250100", b"MD00440725010000"])
def test_too_long_parameters_get_0D(device, line):
    assert send(device, line) == line + b"\n0Dd\n\n"


def test_tag_is_echoed_with_the_reply(device):
    assert send(device, b"BM;a.b_c+d@e 1") == b"BM;a.b_c+d@e 1\n00P\n\n"
    assert send(device, b"QT;") == b"QT;\n00P\n\n"


def test_tag_longer_than_16_gets_0G(device):
    assert send(device, b"VV;" + b"x" * 16).startswith(b"VV;" + b"x" * 16 + b"\n00P\n")
    assert send(device, b"VV;" + b"x" * 17) == b"VV;" + b"x" * 17 + b"\n0Gg\n\n"


@pytest.mark.parametrize("tag", [b"a-b", b"a;b", b"\xff", b"tab\t"])
def test_tag_with_a_bad_character_gets_0H(device, tag):
    assert send(device, b"BM;" + tag) == b"BM;" + tag + b"\n0Hh\n\n"
    assert not device.laser_on


def test_bm_then_qt(device):
    assert send(device, b"BM") == b"BM\n00P\n\n"
    assert device.laser_on
    assert send(device, b"BM") == b"BM\n02R\n\n"
    assert send(device, b"QT") == b"QT\n00P\n\n"
    assert not device.laser_on
    assert status_of(send(device, b"GD0044072501")) == b"10"


def test_gd_serves_the_latest_completed_scan_with_its_stamp(device):
    send(device, b"BM")
    values, stamp = scan_values(send(device, b"GD0044072501", now=1.234), 3)
    assert values.tolist() == (100 + np.arange(44, 726) + 12).tolist()
    assert stamp == 1200


def test_gd_accepts_every_step_0_to_768(device):
    send(device, b"BM")
    values, _ = scan_values(send(device, b"GD0000076800", now=1.0), 3)
    assert values.tolist() == (110 + np.arange(STEPS)).tolist()


def test_gs_sends_two_character_values_and_cluster_minima(device):
    send(device, b"BM", now=0.5)
    reply = send(device, b"GS0100010903", now=0.5)
    assert reply.startswith(b"GS0100010903\n00P\n")
    values, _ = scan_values(reply, 2)
    assert values.tolist() == [105 + 100, 105 + 103, 105 + 106, 105 + 109]


@pytest.mark.parametrize(
    "params,status",
    [
        (b"x044072501", b"01"),
        (b"00 4072501", b"01"),
        (b"0044x72501", b"02"),
        (b"004407250x", b"03"),
        (b"0044076901", b"04"),
        (b"0769099901", b"04"),
        (b"0769076801", b"05"),
        (b"0100009901", b"05"),
    ],
)
@pytest.mark.parametrize("code", [b"GD", b"GS"])
def test_gd_parameter_statuses(device, code, params, status):
    send(device, b"BM")
    assert send(device, code + params) == code + params + b"\n" + status + checksum(status) + b"\n\n"


@pytest.mark.parametrize(
    "params,status",
    [
        (b"-044072501000", b"01"),
        (b"00440a2501000", b"02"),
        (b"00440725o1000", b"03"),
        (b"0044080001000", b"04"),
        (b"0725004401000", b"05"),
        (b"004407250100x", b"07"),
        (b"0044072501x00", b"06"),
    ],
)
@pytest.mark.parametrize("code", [b"MD", b"MS"])
def test_md_parameter_statuses_leave_the_laser_off(device, code, params, status):
    assert status_of(send(device, code + params)) == status
    assert not device.laser_on and device.next_deadline() is None


def test_tm_adjust_mode_cycle(device):
    send(device, b"BM")
    assert send(device, b"TM1") == b"TM1\n04T\n\n"
    assert send(device, b"TM2") == b"TM2\n03S\n\n"
    assert send(device, b"TM0", now=2.0) == b"TM0\n00P\n\n"
    assert not device.laser_on
    assert send(device, b"TM0") == b"TM0\n02R\n\n"
    reply = send(device, b"TM1;x", now=2.5)
    assert reply.startswith(b"TM1;x\n00P\n") and reply.endswith(b"\n\n")
    timer_line = reply.split(b"\n")[2]
    assert decode_values(timer_line[:4], 4).tolist() == [2500]
    assert checksum(timer_line[:4]) == timer_line[4:]
    assert send(device, b"TM9") == b"TM9\n01Q\n\n"
    assert send(device, b"TM2") == b"TM2\n00P\n\n"


def test_adjust_mode_refuses_measurement_commands(device):
    send(device, b"TM0")
    for line in (b"BM", b"GD0044072501", b"MD0044072501000", b"CR05", b"SS115200", b"HS1", b"QT"):
        assert status_of(send(device, line)) == b"0E"
    assert not device.laser_on
    assert status_of(send(device, b"VV")) == b"00"
    assert status_of(send(device, b"II")) == b"00"
    send(device, b"TM2")
    assert status_of(send(device, b"BM")) == b"00"


@pytest.mark.parametrize("rate", [b"038400", b"057600", b"115200", b"250000", b"500000", b"750000"])
def test_ss_accepts_the_listed_rates_and_ii_reports_them(device, rate):
    assert send(device, b"SS" + rate) == b"SS" + rate + b"\n00P\n\n"
    assert info(send(device, b"II"), b"SBPS") == b"%d[bps]" % int(rate)
    assert send(device, b"SS" + rate) == b"SS" + rate + b"\n03S\n\n"
    assert device.baud is None


@pytest.mark.parametrize("params,status", [(b"019200", b"03"), (b"12345a", b"01"), (b"009600", b"02"), (b"230400", b"02")])
def test_ss_statuses(device, params, status):
    assert status_of(send(device, b"SS" + params)) == status
    assert info(send(device, b"II"), b"SBPS") == b"19200[bps]<-Default setting by user"


def test_cr_levels_and_statuses(device):
    assert send(device, b"CR00") == b"CR00\n03S\n\n"
    assert send(device, b"CR99") == b"CR99\n03S\n\n"
    assert send(device, b"CR05") == b"CR05\n00P\n\n"
    assert info(send(device, b"II"), b"SCSP") == b"Changed(570[rpm])"
    assert send(device, b"CR05") == b"CR05\n03S\n\n"
    assert send(device, b"CR10") == b"CR10\n00P\n\n"
    assert status_of(send(device, b"CR11")) == b"02"
    assert status_of(send(device, b"CR98")) == b"02"
    assert status_of(send(device, b"CR+1")) == b"01"
    assert send(device, b"CR99") == b"CR99\n00P\n\n"
    assert info(send(device, b"II"), b"SCSP") == b"Initial(600[rpm])<-Default setting by user"


def test_hs_statuses(device):
    assert send(device, b"HS0") == b"HS0\n02R\n\n"
    assert send(device, b"HS1") == b"HS1\n00P\n\n"
    assert device.high_sensitivity
    assert send(device, b"HS1") == b"HS1\n02R\n\n"
    assert send(device, b"HS2") == b"HS2\n01Q\n\n"
    assert send(device, b"HS0") == b"HS0\n00P\n\n"
    assert not device.high_sensitivity


def test_rs_resets_laser_stream_settings_and_timer(device):
    send(device, b"BM")
    send(device, b"CR03")
    send(device, b"SS115200")
    send(device, b"HS1")
    send(device, b"MD0044072501000", now=3.0)
    *streamed, reset = device.receive(b"RS\n", now=7.25)
    assert len(streamed) == 1 and streamed[0].droppable  # scans 3.1 .. 7.2 s due: a late poll sends only the newest
    assert reset.data == b"RS\n00P\n\n"
    assert not device.laser_on and not device.high_sensitivity
    assert device.next_deadline() is None
    assert device.poll(60.0) == []
    reply = send(device, b"II", now=7.5)
    assert info(reply, b"TIME") == b"0000FA"
    assert info(reply, b"SCSP").startswith(b"Initial(") and info(reply, b"SBPS").startswith(b"19200[bps]<-")
    send(device, b"BM", now=7.5)
    _, stamp = scan_values(send(device, b"GD0044004501", now=7.5), 3)
    assert stamp == 250  # scan 7.5 s on a timer reset at 7.25 s


@pytest.mark.parametrize("terminator", [b"\n", b"\r", b"\r\n"])
def test_each_terminator_gives_the_same_reply_and_empty_lines_are_ignored(terminator):
    device = UrgDevice(ramp_source, timing="fast")
    outputs = device.receive(b"\n\r\n" + b"VV" + terminator + terminator + b"BM" + terminator, now=0.0)
    assert [o.data for o in outputs] == [send(UrgDevice(ramp_source, timing="fast"), b"VV"), b"BM\n00P\n\n"]


def test_overlong_line_is_refused_with_0B_and_the_next_line_still_works(device):
    outputs = device.receive(b"VV" + b"x" * 10_000 + b"\nBM\n", now=0.0)
    assert [o.data for o in outputs] == [b"VV" + b"x" * 62 + b"\n0Bb\n\n", b"BM\n00P\n\n"]


def test_a_line_split_across_receives_is_answered_once_complete(device):
    assert device.receive(b"V", now=0.0) == []
    assert device.receive(b"V", now=0.0) == []
    [output] = device.receive(b"\n", now=0.0)
    assert output.data.startswith(b"VV\n00P\nVEND:")


def test_connection_lost_stops_the_stream_but_the_unit_keeps_its_settings(device):
    """A real unit lives as long as its power, not its client's connection."""
    send(device, b"CR02")
    send(device, b"SS115200")
    send(device, b"MD0044072501000", now=1.0)
    device.receive(b"GD00", now=1.0)  # half a line left behind
    device.connection_lost()
    assert device.next_deadline() is None and device.laser_on  # the stream stopped, the laser stays on
    assert send(device, b"BM", now=2.0) == b"BM\n02R\n\n"  # as the capture's first BM
    assert send(device, b"VV", now=2.0).startswith(b"VV\n00P\n")  # the half line is gone
    status = send(device, b"II", now=2.0)
    assert info(status, b"TIME") == b"0007D0"  # the timer runs on
    assert info(status, b"SCSP").startswith(b"Changed(")
    assert info(status, b"SBPS").startswith(b"115200")


def test_connection_lost_leaves_time_adjust_mode(device):
    send(device, b"TM0")
    device.connection_lost()
    assert status_of(send(device, b"BM", now=2.0)) == b"00"


def test_unknown_boot_protocol_is_rejected():
    with pytest.raises(ValueError, match="boot_protocol"):
        UrgDevice(ramp_source, timing="fast", boot_protocol="scip3")
