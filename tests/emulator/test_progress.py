"""`record` and `plot` show a progress bar on a terminal and stay silent when piped."""

from __future__ import annotations

import fcntl
import os
import pty
import struct
import subprocess
import termios
from pathlib import Path

from emulator.bench.serve_process import serve_command


def stderr_of(args: list[str], *, terminal: bool) -> bytes:
    if not terminal:
        return subprocess.run([*serve_command(), *args], capture_output=True, timeout=120).stderr
    master, slave = pty.openpty()
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 24, 100, 0, 0))
    process = subprocess.Popen([*serve_command(), *args], stdout=subprocess.DEVNULL, stderr=slave)
    os.close(slave)
    received = b""
    while True:
        try:
            chunk = os.read(master, 4096)
        except OSError:  # EIO: the command closed its end
            break
        if not chunk:
            break
        received += chunk
    process.wait(120)
    os.close(master)
    return received


def test_record_shows_progress_on_a_terminal_only(tmp_path: Path) -> None:
    args = ["record", "railway", "--sensor", "urg", "--end", "20", "--out", str(tmp_path / "log.txt")]
    assert b"record urg:" in stderr_of(args, terminal=True) and b"/201" in stderr_of(args, terminal=True)
    assert stderr_of(args, terminal=False) == b""
