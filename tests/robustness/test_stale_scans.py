"""A reader that stalls and resumes gets fresh scans, not the backlog of its stall; a poller that
pauses gets the scan of the moment it asks.

Scans written into the kernel's buffers cannot be recalled, so the daemon keeps no
more than about one scan there ahead of the reader; the rest wait in its outbox,
where a newer scan replaces them. Once the reader resumes, it reads what was
already in its end's buffers (one or two scans from when it stopped), then scans
from now. Before, it read ten or more scans as old as the stall first.
"""

from __future__ import annotations

import os
import socket
import time
import tty
from collections.abc import Callable, Iterator
from pathlib import Path

from emulator.bench.cola_client import ColaClient, ScanTelegram, parse_scandata
from emulator.bench.serve_process import ServeProcess
from protocols.scip.encoding import decode_values
from tests.support.interop import write_room

STALL_S = 5.0
STREAM = b"MD0044072501000\n"  # URG-04LX: every scan, all 682 steps, until QT
# What a reader may find on resuming before a fresh scan: the scans already in its end's
# buffers when it stopped (a socket receive buffer of ≈ 2 scans, the pty's 4 KiB), and a
# partial one it had read.
MOST_STALE_SCANS = 3


def scan_timestamps(read: Callable[[], bytes]) -> Iterator[int]:
    """The SCIP time stamp (ms) of every MD scan data block read."""
    pending = b""
    while True:
        while b"\n\n" not in pending:
            data = read()
            assert data, "the daemon closed the stream"
            pending += data
        block, pending = pending.split(b"\n\n", 1)
        lines = block.split(b"\n")
        if lines[0].startswith(b"MD") and len(lines) > 3 and lines[1].startswith(b"99"):
            yield int(decode_values(lines[2][:4], 4)[0])


def stale_scans_after_a_stall(scans: Iterator[int]) -> list[int]:
    """Stream, stop reading for STALL_S, resume: the ages (ms, relative to the last scan
    read before the stall) of the scans read before the first one taken late in the stall."""
    before = [next(scans) for _ in range(5)][-1]
    time.sleep(STALL_S)
    stale = []
    for stamp in scans:
        if stamp - before >= STALL_S * 1000 / 2:
            return stale
        stale.append(stamp - before)
        assert len(stale) < 100, "no fresh scan after 100 stale ones"
    raise AssertionError("the stream ended")


def test_a_tcp_reader_resuming_after_a_stall_gets_fresh_scans() -> None:
    """A driver with a small receive buffer (an embedded one; a big one holds its own stale
    scans, which no sender can recall) stalls: it used to get 12+ scans 5 s old first."""
    with ServeProcess("railway", ["urg=tcp:127.0.0.1:0"]) as daemon:
        client = socket.socket()
        client.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
        client.settimeout(10)
        client.connect(daemon.endpoint("urg", "tcp").address)
        with client:
            client.sendall(STREAM)
            stale = stale_scans_after_a_stall(scan_timestamps(lambda: client.recv(65536)))
    assert len(stale) <= MOST_STALE_SCANS, f"{len(stale)} stale scans (ms after the stall began): {stale}"


def test_a_pty_reader_resuming_after_a_stall_gets_fresh_scans(tmp_path: Path) -> None:
    """The same on the URG's serial device: it used to get 11+ stale scans first."""
    link = tmp_path / "ttyURG0"
    with ServeProcess("railway", [f"urg=pty:{link}"]):
        fd = os.open(link, os.O_RDWR | os.O_NOCTTY)
        try:
            tty.setraw(fd)
            os.write(fd, STREAM)
            stale = stale_scans_after_a_stall(scan_timestamps(lambda: os.read(fd, 65536)))
        finally:
            os.close(fd)
    assert len(stale) <= MOST_STALE_SCANS, f"{len(stale)} stale scans (ms after the stall began): {stale}"


POLLER_SPEED = 10  # simulated seconds a wall second: a pause of 0.4 s is 4 s of the unit's time
POLLS = 20
POLL_GAP_S = 0.01  # wall: 0.1 s of the unit's time, as a 10 Hz poller
PAUSE_S = 0.4  # wall: 4 s of the unit's time


def test_a_cola_poller_after_a_pause_gets_the_scan_of_now(tmp_path: Path) -> None:
    """A client polling `sRN LMDscandata` that pauses, then polls again, gets the scan measured
    when it asked, as a unit answers: it used to get the scan foreseen right after its last
    poll, seconds to minutes old (4 s, 67 s, 741 s seen), with that scan's stamp and counter."""
    with ServeProcess(write_room(tmp_path, "tim"), (), extra_args=["--speed", str(POLLER_SPEED)]) as daemon:
        host, port = daemon.endpoint("tim", "tcp").address
        with ColaClient(host, port) as client:
            def poll() -> ScanTelegram:
                client.send(b"sRN LMDscandata")
                telegram, received = client.next_telegram()
                return parse_scandata(telegram.payload, telegram.dialect, received)

            for _ in range(POLLS):
                before = poll()
                time.sleep(POLL_GAP_S)
            time.sleep(PAUSE_S)
            after = poll()
    unit_pause_s = (after.power_up_us - before.power_up_us) / 1e6
    # the pause in the unit's time, less the daemon's own reply latency; a scan foreseen after the
    # last poll is at most a batch of 8 polls (0.8 s) after it
    assert unit_pause_s >= PAUSE_S * POLLER_SPEED, f"the scan after a {PAUSE_S * POLLER_SPEED:g} s pause is {unit_pause_s:g} s after the last"
    assert after.scan_counter - before.scan_counter >= PAUSE_S * POLLER_SPEED * 15  # a TiM561 measures at 15 Hz
