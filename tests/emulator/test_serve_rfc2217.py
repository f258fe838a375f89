"""RFC 2217 endpoints against the real `serve`, with pyserial's own `rfc2217://`
client: the client sets the baud over the network, the LMS200 paces at its own
rate, and bytes sent at another rate are dropped, as on a pty."""

from __future__ import annotations

import time
from pathlib import Path

import serial

from emulator.bench.serve_process import ServeProcess
from protocols.lms2xx import build_telegram, crc16

ACK = b"\x06"


def streamed_rate(port: serial.SerialBase, seconds: float) -> tuple[float, bytes]:
    """Bytes per second the line carries, and the bytes."""
    port.reset_input_buffer()
    started = time.monotonic()
    received = b""
    while time.monotonic() - started < seconds:
        received += port.read(port.in_waiting or 1)
    return len(received) / (time.monotonic() - started), received


def b0_telegrams(data: bytes) -> list[bytes]:
    """Whole B0 telegrams (732 bytes at 180°/0.5°) found in a stream."""
    telegrams, start = [], data.find(b"\x02\x80\xd6\x02\xb0")
    while start >= 0 and start + 732 <= len(data):
        telegrams.append(data[start : start + 732])
        start = data.find(b"\x02\x80\xd6\x02\xb0", start + 732)
    return telegrams


def test_pyserial_rfc2217_client_sets_the_baud_and_the_lms200_paces_at_it(tmp_path: Path) -> None:
    with ServeProcess("railway", ["urg=tcp:127.0.0.1:0", "lms=rfc2217:127.0.0.1:0"]) as daemon:
        ready = daemon.endpoint("lms", "rfc2217")
        host, port_number = ready.address
        port = serial.serial_for_url(f"rfc2217://{host}:{port_number}", baudrate=9600, timeout=1.0)
        try:
            port.write(build_telegram(0x00, b"\x20\x24"))  # every scan, continuously
            assert port.read(1) == ACK
            slow, slow_bytes = streamed_rate(port, 2.0)
            port.write(build_telegram(0x00, b"\x20\x40"))  # to 38400: A0 at the old rate, then the switch
            time.sleep(0.5)
            port.reset_input_buffer()
            port.write(build_telegram(0x00, b"\x31"))  # still at 9600 on the client's side: garbled, dropped
            time.sleep(0.3)
            port.baudrate = 38400  # RFC 2217 SET-BAUDRATE over the network
            time.sleep(0.5)
            after_status_request = port.read(port.in_waiting)
            fast, fast_bytes = streamed_rate(port, 2.0)
            port.write(build_telegram(0x00, b"\x31"))  # at the device's rate now: answered
            answered = port.read(2000)
        finally:
            port.close()
    assert 0.85 * 960 <= slow <= 1.1 * 960, f"{slow:.0f} B/s at 9600"
    assert 0.85 * 3840 <= fast <= 1.1 * 3840, f"{fast:.0f} B/s at 38400"
    status_header = bytes.fromhex("02 80 9A 00 B1")  # B1: 152 data bytes and the status
    assert status_header not in after_status_request  # the 31 sent at the wrong rate was dropped
    assert status_header in answered
    telegrams = b0_telegrams(slow_bytes) + b0_telegrams(fast_bytes)
    assert len(telegrams) >= 4
    for telegram in telegrams:  # IAC (0xFF) bytes inside arrive unescaped, CRCs intact
        assert crc16(telegram[:-2]).to_bytes(2, "little") == telegram[-2:]


def test_rfc2217_endpoint_serves_the_urg_too(tmp_path: Path) -> None:
    with ServeProcess("railway", ["urg=rfc2217:127.0.0.1:0", f"lms=pty:{tmp_path / 'lms'}"]) as daemon:
        host, port_number = daemon.endpoint("urg", "rfc2217").address
        port = serial.serial_for_url(f"rfc2217://{host}:{port_number}", baudrate=115200, timeout=2.0)
        try:
            port.write(b"VV\n")
            reply = port.read_until(b"\n\n")
        finally:
            port.close()
    assert reply.startswith(b"VV\n00P\nVEND:Hokuyo")


def test_an_endless_telnet_subnegotiation_is_not_buffered(tmp_path: Path) -> None:
    """Hostile input at bounded cost: IAC SB followed by megabytes without IAC SE."""
    import socket

    with ServeProcess("railway", ["urg=rfc2217:127.0.0.1:0", f"lms=pty:{tmp_path / 'lms'}"]) as daemon:
        address = daemon.endpoint("urg", "rfc2217").address
        with socket.create_connection(address, timeout=5) as client:
            client.sendall(b"\xff\xfa\x2c" + b"x" * 2_000_000)
            client.sendall(b"\nVV\n")  # the x's after the dropped subnegotiation are one overlong line
            received = b""
            while b"VV\n00P" not in received:
                chunk = client.recv(65536)
                assert chunk, "connection closed"
                received += chunk
        rss_kib = int(next(line for line in open(f"/proc/{daemon.pid}/status") if line.startswith("VmRSS")).split()[1])
    assert rss_kib < 400_000
