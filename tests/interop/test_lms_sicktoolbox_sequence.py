"""sicktoolbox's LMS200 session, replayed at the protocol level over the daemon's pty.

sicktoolbox (ROS sicklms) opens the port at 9600, asks for its target rate
with `20 40` before anything else, follows the device to 38400, then sends
20 25, 3A, 31, 74, 20 24 and reads streamed B0 telegrams. When a rate gets no
answer it probes the others with `32`. The client below is a pyserial host
that shares no code with the device (emulator.bench.lms_client).
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pytest
from support.interop import scan_values

from emulator.bench.lms_client import ACK, LmsSerialClient, Telegram

A0_OK = bytes.fromhex("02 80 03 00 A0 00 10 16 0A")  # verified vector: A0, OK, status 0x10


def first_events(client: LmsSerialClient, count: int, timeout_s: float = 3.0) -> list:
    events = []
    for event in client.events(timeout_s):
        events.append(event)
        if len(events) == count:
            break
    return events


@pytest.fixture
def client(serve, lms_room: Path, tmp_path: Path):
    daemon = serve(lms_room, f"lms=pty:{tmp_path / 'ttyLMS0'}")
    ready = daemon.endpoint("lms", "pty")
    assert ready.device is not None and ready.device.startswith("/dev/pts/")
    with LmsSerialClient(ready.path, baud=9600) as lms:
        lms.discard_input()  # the power-on 90 telegram, if it came while we opened
        yield lms


def test_sicktoolbox_session(client: LmsSerialClient, lms_room: Path) -> None:
    client.send(b"\x20\x40")  # at 9600: go to 38400
    ack, reply = first_events(client, 2)
    assert ack == ACK
    assert isinstance(reply, Telegram) and reply.raw == A0_OK
    client.set_port_baud(38400)

    acked, stop = client.request(b"\x20\x25")
    assert acked and stop.data == b"\x00" and stop.status == 0x10
    acked, kind = client.request(b"\x3A")
    assert acked and b"LMS200;30106" in kind.data
    acked, status = client.request(b"\x31")
    assert acked and len(status.data) == 152
    assert int.from_bytes(status.data[115:117], "little") == 0x8019  # B1 baud word: 38400
    acked, config = client.request(b"\x74")
    assert acked and len(config.data) == 34

    acked, stream = client.request(b"\x20\x24")
    assert acked and stream.data == b"\x00"
    scans = [event for event in client.events(1.5)
             if isinstance(event, Telegram) and event.command == 0xB0]
    assert len(scans) >= 3
    _, expected = scan_values(lms_room, "lms", 1.0)
    for scan in scans:
        count_word, values = scan.b0_values()
        assert count_word & 0x3FF == 361 and count_word & 0x3C00 == 0
        assert count_word >> 14 == 0b01  # mm
        assert scan.status == 0x10
        np.testing.assert_array_equal(values & 0x1FFF, expected)
    assert client.reader.bad_frames == 0


def test_baud_probe(client: LmsSerialClient) -> None:
    client.switch_baud(38400)
    client.request(b"\x20\x25")

    client.set_port_baud(19200)  # a wrong rate: the device hears garbage, answers nothing
    client.discard_input()
    client.send(b"\x32")
    started = time.monotonic()
    heard = client.port.read(64)
    while time.monotonic() - started < 0.3:
        heard += client.port.read(64)
    assert heard == b""

    client.set_port_baud(38400)  # the right rate: ACK + B2
    client.discard_input()
    client.send(b"\x32")
    ack, reply = first_events(client, 2)
    assert ack == ACK
    assert isinstance(reply, Telegram) and reply.command == 0xB2 and reply.status == 0x10
