"""A real `serve` past what its one worker computes: clients see skipped revolutions (stamps only
ever increasing), the daemon says it is behind, an LMS200 still ACKs at once, and once most
clients leave it says it caught up and the others get every revolution again."""

from __future__ import annotations

import selectors
import socket
import time
from pathlib import Path

import numpy as np

from emulator.bench.serve_load import _Stream, fleet_scene_text, lms_name, md_unlimited, urg_name
from emulator.bench.serve_process import ServeProcess
from protocols.lms2xx import build_telegram

FLEET = 120  # URG-04LX under `physical` on one worker: ~2.5 ms a scan, so ~3 cores' worth at 10 Hz
STAY = 3


def _read(selector: selectors.BaseSelector, seconds: float) -> None:
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        for key, _ in selector.select(timeout=0.05):
            data = key.fileobj.recv(65536)
            assert data, "the daemon closed a stream"
            key.data.feed(data, time.monotonic())


def _ack_ms(address: tuple[str, int]) -> float:
    """Milliseconds from an LMS200 status request (31) to its ACK byte."""
    with socket.create_connection(address, timeout=5) as client:
        sent = time.perf_counter()
        client.sendall(build_telegram(0x00, b"\x31"))
        while b"\x06" not in client.recv(4096):
            pass
        return (time.perf_counter() - sent) * 1000


def test_a_daemon_past_its_capacity_skips_revolutions_says_so_and_catches_up(tmp_path: Path) -> None:
    scene = tmp_path / "fleet.toml"
    scene.write_text(fleet_scene_text(FLEET, lms_count=1))
    endpoints = [f"{urg_name(index)}=tcp:127.0.0.1:0" for index in range(FLEET)] + [f"{lms_name(0)}=tcp:127.0.0.1:0"]
    with ServeProcess(scene, endpoints, extra_args=["--model", "physical", "--workers", "1"], timeout_s=300) as daemon:
        selector = selectors.DefaultSelector()
        streams = []
        for index in range(FLEET):
            sock = socket.create_connection(daemon.endpoint(urg_name(index)).address, timeout=5)
            sock.sendall(md_unlimited("urg-04lx"))
            sock.setblocking(False)
            streams.append(_Stream(sock))
            selector.register(sock, selectors.EVENT_READ, streams[-1])
        _read(selector, 4.0)
        for stream in streams:
            stream.forget()
        _read(selector, 4.0)
        acks = sorted(_ack_ms(daemon.endpoint(lms_name(0)).address) for _ in range(5))
        stats = daemon.stats()
        assert "behind: " in daemon.stderr and stats["skipped"] > 0
        for stream in streams:
            assert len(stream.stamps) >= 1  # every sensor gets scans: none starved (on a busy machine 1 in 15)
            stamps = np.array(stream.stamps)
            assert np.all(np.diff(stamps) > 0) and np.all(stamps % 100 == stamps[0] % 100)  # whole revolutions, in order
        assert acks[2] <= 60.0, acks  # the LMS200 answers as it always does, however busy the workers
        for stream in streams[STAY:]:
            selector.unregister(stream.sock)
            stream.sock.close()
        _read(selector, 3.0)
        assert "caught up: " in daemon.stderr, daemon.stderr[-2000:]
        for stream in streams[:STAY]:
            stream.forget()
        _read(selector, 2.0)
        for stream in streams[:STAY]:  # every revolution again (a shared machine may delay one or two)
            assert len(stream.stamps) >= 18, stream.stamps
            assert np.all(np.diff(stream.stamps) > 0)
        for stream in streams[:STAY]:
            stream.sock.close()
        selector.close()
