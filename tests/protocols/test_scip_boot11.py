"""The SCIP 1.1 boot option: V, G, unknown commands, and the switch to 2.0."""

from __future__ import annotations

import numpy as np
import pytest

from emulator.sensors.scan import Scan
from protocols.scip import UrgDevice
from protocols.scip.encoding import decode_values

STEPS = 769


def ramp_source(t: float) -> Scan:
    """Scan k = round(10 t): step s reads 10 s + k mm (so some exceed 4095)."""
    return Scan("urg", "URG-04LX", t, np.zeros(STEPS), 10 * np.arange(STEPS) + round(t * 10))


@pytest.fixture
def device() -> UrgDevice:
    return UrgDevice(ramp_source, timing="fast", boot_protocol="scip1", serial="H0706400")


def send(device: UrgDevice, line: bytes, now: float = 1.0) -> bytes:
    [output] = device.receive(line + b"\n", now)
    return output.data


def test_v_reports_scip_1_1_identity_without_checksums(device):
    assert send(device, b"V") == (
        b"V\n0\n"
        b"VEND:Hokuyo Automatic Co.,Ltd.\n"
        b"PROD:SOKUIKI Sensor URG-04LX\n"
        b"FIRM:3.1.04,07/08/02(20-4095[mm],240[deg],44-725[step],600[rpm])\n"
        b"PROT:SCIP 1.1\n"
        b"SERI:H0706400\n"
        b"\n"
    )


def test_g_sends_the_latest_scan_two_character_encoded_in_plain_64_char_lines(device):
    reply = send(device, b"G04472501", now=2.34)
    assert reply.startswith(b"G04472501\n0\n") and reply.endswith(b"\n\n")
    rows = reply[len(b"G04472501\n0\n") : -2].split(b"\n")
    assert [len(row) for row in rows] == [64] * 21 + [2 * 682 - 21 * 64]
    values = decode_values(b"".join(rows), 2)
    assert values.tolist() == np.minimum(10 * np.arange(44, 726) + 23, 4095).tolist()


def test_g_clusters_to_the_minimum(device):
    reply = send(device, b"G00000903", now=0.0)
    assert decode_values(reply.split(b"\n")[2], 2).tolist() == [20, 30, 60, 90]  # 0 and 10 are error codes


@pytest.mark.parametrize("line", [b"G0447250", b"G044725010", b"G04472x01", b"G04476901", b"G72504401", b"QT", b"VV", b"BM", b"L1", b"Vx"])
def test_unknown_or_malformed_commands_get_E(device, line):
    assert send(device, line) == line + b"\nE\n\n"


def test_switch_to_scip2_then_2_0_rules_apply(device):
    assert send(device, b"SCIP2.0") == b"SCIP2.0\n0\n\n"
    assert send(device, b"SCIP2.0") == b"SCIP2.0\n0Ee\n\n"
    assert send(device, b"V") == b"V\n0Ee\n\n"
    assert send(device, b"GD0044072501") == b"GD0044072501\n10Q\n\n"  # 2.0 starts with the laser off
    assert send(device, b"VV").startswith(b"VV\n00P\nVEND:")


def test_the_switch_to_scip_2_0_outlives_the_connection(device):
    """urg_c, hokuyo-python-lib and BreezyLidar reopen the port and expect 2.0."""
    send(device, b"SCIP2.0")
    device.connection_lost()
    assert send(device, b"VV").startswith(b"VV\n00P\nVEND:")
    assert send(device, b"V") == b"V\n0Ee\n\n"


def test_overlong_line_gets_E_with_the_kept_part_echoed(device):
    [output] = device.receive(b"G" * 100 + b"\n", now=0.0)
    assert output.data == b"G" * 64 + b"\nE\n\n"


def test_rs_after_the_switch_stays_in_scip2(device):
    send(device, b"SCIP2.0")
    assert send(device, b"RS") == b"RS\n00P\n\n"
    assert send(device, b"VV").startswith(b"VV\n00P\n")
