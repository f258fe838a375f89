"""Nothing one client leaves behind harms the next: line time, an idle connection."""

from __future__ import annotations

import socket
import time
from pathlib import Path

from emulator.bench.hostile import open_raw
from emulator.bench.lms_client import Telegram, TelegramReader, host_telegram
from emulator.bench.serve_process import ServeProcess


def corrupt_frame() -> bytes:
    """A host telegram addressed to the device with a wrong CRC: the device answers NAK."""
    good = host_telegram(b"\x31")
    return good[:-2] + bytes([good[-2] ^ 0xFF, good[-1]])


def first_scan_delay(uri: str) -> float:
    """Seconds from asking a fresh client's stream (20 24) to the end of its first B0 scan
    (at 9600 Bd a 361-value scan takes 0.76 s of line time)."""
    client = open_raw(uri, 9600)
    reader = TelegramReader()
    try:
        started = time.monotonic()
        client.send(host_telegram(b"\x20\x24"))
        while time.monotonic() - started < 30:
            for event in reader.feed(client.drain(0.05), time.monotonic()):
                if isinstance(event, Telegram) and event.command == 0xB0:
                    return time.monotonic() - started
        return float("inf")
    finally:
        client.close()


def test_a_client_that_filled_the_lms_line_leaves_it_free_for_the_next(tmp_path: Path) -> None:
    """16 000 bad frames (16.7 s of NAKs at 9600 Bd) then a disconnect: the next client's
    stream starts at once, not after the old client's line time."""
    with ServeProcess("railway", ["lms=tcp:127.0.0.1:0"]) as daemon:
        uri = daemon.endpoint("lms", "tcp").uri
        attacker = open_raw(uri)
        attacker.send(corrupt_frame() * 16_000, timeout_s=5)
        time.sleep(0.3)
        attacker.close()
        time.sleep(0.3)
        assert first_scan_delay(uri) < 5.0


def test_an_idle_tcp_client_gives_way_to_a_newcomer(tmp_path: Path) -> None:
    """A connection that says nothing (a half-open peer) locked every other client out."""
    with ServeProcess("railway", ["urg=tcp:127.0.0.1:0", "lms=pty:" + str(tmp_path / "ttyLMS0")],
                      extra_args=["--idle-timeout", "1"]) as daemon:
        address = daemon.endpoint("urg", "tcp").address
        squatter = socket.create_connection(address)
        try:
            time.sleep(0.2)
            refused = socket.create_connection(address, timeout=2)
            assert refused.recv(100) == b"", "a busy endpoint refuses a second client at first"
            refused.close()
            time.sleep(1.3)
            newcomer = socket.create_connection(address, timeout=2)
            with newcomer:
                newcomer.sendall(b"VV\n")
                reply = b""
                while not reply.endswith(b"\n\n"):
                    chunk = newcomer.recv(4096)
                    assert chunk, "the newcomer was refused although the first client was idle"
                    reply += chunk
                assert reply.startswith(b"VV\n00P\n")
            assert squatter.recv(100) == b"", "the idle client is closed when it is taken over"
        finally:
            squatter.close()
