"""LMS200 measuring modes on the wire, against the real `serve`: the clients that
ask for a mode and do not check the answer (Player's sicklms200: mode 01,
reflector bits as intensity; ARIA's ArLMS2xx: mode 05, 32 m) get what a real
unit sends, reflector bits from a retro-reflective material in the scene."""

from __future__ import annotations

import time

import numpy as np
import pytest
import serial

from emulator.bench.serve_process import ServeProcess
from protocols.lms2xx import build_telegram, crc16

SCENE = """
[[objects]]
name = "tape"
box = { size = [0.05, 0.6, 2.0] }
position = [3.0, 0.0, 0.0]
material = "retro_reflector"

[[objects]]
name = "far_wall"
box = { size = [0.2, 60.0, 2.0] }
position = [20.1, 0.0, 0.0]

[[sensors]]
name = "lms"
model = "lms200"
angle_deg = 180
resolution_deg = 1.0
endpoints = ["pty:ttyLMS0"]
"""


def exchange(port: serial.Serial, body: bytes, reply_bytes: int) -> bytes:
    """One command at 9600: its ACK, then a reply telegram of `reply_bytes` (CRC checked)."""
    port.reset_input_buffer()
    port.write(build_telegram(0x00, body))
    assert port.read(1) == b"\x06", f"no ACK to {body.hex()}"
    telegram = port.read(reply_bytes)
    assert len(telegram) == reply_bytes and crc16(telegram[:-2]).to_bytes(2, "little") == telegram[-2:]
    return telegram


def scan(port: serial.Serial) -> np.ndarray:
    telegram = exchange(port, b"\x30\x01", 6 + 1 + 2 + 181 * 2 + 1)  # 180°/1°: 181 values
    return np.frombuffer(telegram[7:-3], dtype="<u2").astype(np.int64)


@pytest.fixture(scope="module")
def lms(tmp_path_factory: pytest.TempPathFactory):
    folder = tmp_path_factory.mktemp("lms-modes")
    (folder / "modes.toml").write_text(SCENE)
    with ServeProcess(folder / "modes.toml", [f"lms=pty:{folder / 'ttyLMS0'}"], cwd=folder):
        port = serial.Serial(str(folder / "ttyLMS0"), 9600, timeout=3)
        time.sleep(0.2)
        exchange(port, b"\x20\x00SICK_LMS", 9)  # installation mode: A0 00
        yield port
        port.close()


def configure(port: serial.Serial, measuring_mode: int) -> None:
    """Player's 7-byte 77: blanking, sensitivity 46h, availability, measuring mode, mm."""
    confirmation = exchange(port, bytes([0x77, 0, 0, 0x46, 0, 0, measuring_mode, 0x01]), 6 + 1 + 1 + 34 + 1)
    assert confirmation[5] == 0x01, f"mode {measuring_mode:02X} refused"


def test_player_mode_01_sees_the_retro_reflector_in_the_reflector_bits(lms: serial.Serial) -> None:
    configure(lms, 0x01)
    words = scan(lms)
    reflector = words >> 13
    ahead = slice(88, 93)  # device angles 88..92°: the tape, 3 m ahead
    assert np.all(reflector[ahead] == 7)
    assert np.all(np.abs((words[ahead] & 0x1FFF) - 2975) < 60)
    assert np.all(reflector[:80] == 0) and np.all(reflector[101:] == 0)


def test_aria_mode_05_reads_the_far_wall_in_metres_not_the_too_far_code(lms: serial.Serial) -> None:
    configure(lms, 0x05)
    words = scan(lms)
    distances = words & 0x7FFF
    beside = np.r_[60:80, 101:121]  # the wall at 20 m beside the tape (farther off-axis)
    assert np.all((distances[beside] > 20_000) & (distances[beside] < 32_000))
    assert np.all(words[88:93] >> 15 == 1)  # the reflector's one bit
    assert 8183 not in distances.tolist()


def test_mode_00_sends_no_reflector_bits(lms: serial.Serial) -> None:
    configure(lms, 0x00)
    words = scan(lms)
    assert np.all(words >> 13 == 0)
    assert np.all(words[60:80] == 8183)  # the 20 m wall is beyond the 8 m field
