"""MRPT's rawlog-grabber (Debian mrpt-apps, unmodified) recording from the daemon's ptys.

rawlog-grabber runs one driver thread per INI section until a key arrives on
its stdin (os::kbhit), then writes the rest of the log and exits 0; we send
that key through a pipe once it reports enough saved scans. `rawlog-edit --export-2d-scans-txt` turns the
.rawlog into one text line per scan: time, N ranges (m), N validity flags.
"""

from __future__ import annotations

import re
import shutil
import subprocess
import threading
from pathlib import Path

import numpy as np
import pytest

from emulator.interop_bench import line_rate_limit
from interop_support import require_program, scan_values, urg_step_values

MRPT_HINT = "apt-get install mrpt-apps (.ci/run installs it)"


def grab(tmp_path: Path, section: str, scans: int, timeout_s: float) -> subprocess.CompletedProcess[str]:
    """Run rawlog-grabber with one sensor section until it has saved `scans` observations
    (its "Saved N objects." lines) or `timeout_s` passed, then press a key."""
    grabber = require_program("rawlog-grabber", MRPT_HINT)
    config = tmp_path / "grab.ini"
    config.write_text(
        "[global]\n"
        f"rawlog_prefix = {tmp_path / 'grab'}\n"
        "time_between_launches = 100\n"
        "use_sensoryframes = 0\n"
        "GRABBER_PERIOD_MS = 100\n\n" + section
    )
    line_buffered = ["stdbuf", "-oL"] if shutil.which("stdbuf") else []  # its progress, as it happens
    process = subprocess.Popen(
        [*line_buffered, grabber, str(config)], cwd=tmp_path, text=True,
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
    )
    lines: list[str] = []
    enough = threading.Event()

    def follow() -> None:
        saved = 0
        for line in process.stdout:
            lines.append(line)
            found = re.search(r"Saved (\d+) objects", line)
            saved += int(found.group(1)) if found else 0
            if saved >= scans:
                enough.set()

    reader = threading.Thread(target=follow, daemon=True)
    reader.start()
    enough.wait(timeout_s)
    process.stdin.write("\n")  # os::kbhit(): stop, flush the log, exit 0
    process.stdin.close()
    try:
        process.wait(20)
    except subprocess.TimeoutExpired:
        process.kill()
        process.wait()
        pytest.fail(f"rawlog-grabber did not stop on a key press:\n{''.join(lines)[-3000:]}")
    reader.join(5)
    return subprocess.CompletedProcess(process.args, process.returncode, "".join(lines), "")


def exported_scans(tmp_path: Path, label: str, grabbed: subprocess.CompletedProcess[str]):
    """(times, ranges_m, valid) of the recorded scans, via rawlog-edit."""
    logs = sorted(tmp_path.glob("grab_*.rawlog"))
    assert grabbed.returncode == 0 and len(logs) == 1, grabbed.stdout[-3000:]
    editor = require_program("rawlog-edit", MRPT_HINT)
    # Run beside the log: rawlog-edit 2.5 joins an absolute input's folder and
    # the output name without a "/".
    subprocess.run([editor, "--export-2d-scans-txt", "-i", logs[0].name],
                   cwd=logs[0].parent, check=True, capture_output=True, timeout=60)
    export = logs[0].with_name(f"{logs[0].stem}_{label}.txt")
    assert export.exists(), grabbed.stdout[-3000:]
    rows = np.loadtxt(export, comments="%", ndmin=2)
    assert rows.shape[0] > 0, grabbed.stdout[-3000:]
    count = (rows.shape[1] - 1) // 2
    return rows[:, 0], rows[:, 1:1 + count], rows[:, 1 + count:]


def test_chokuyourg_over_pty(serve, urg_room: Path, tmp_path: Path) -> None:
    daemon = serve(urg_room, f"urg=pty:{tmp_path / 'ttyURG0'}")
    section = (
        "[URG]\ndriver = CHokuyoURG\nprocess_rate = 90\nsensorLabel = URG\n"
        f"COM_port_LIN = {daemon.endpoint('urg', 'pty').path}\n"
    )
    times, ranges, valid = exported_scans(tmp_path, "URG", grab(tmp_path, section, scans=25, timeout_s=20))
    assert len(times) >= 20
    assert ranges.shape[1] == 682
    period = np.median(np.diff(times))
    assert 0.09 <= period <= 0.11, np.diff(times)
    expected = urg_step_values(urg_room, 1.0)
    np.testing.assert_array_equal(np.rint(ranges * 1000).astype(int), np.tile(expected, (len(times), 1)))
    np.testing.assert_array_equal(valid[0] == 1, expected >= 20)


@pytest.mark.parametrize(("baud", "timeout_s"), [(38400, 30.0), (500000, 20.0)])
def test_csicklaserserial_over_pty(serve, lms_room: Path, tmp_path: Path, baud: int, timeout_s: float) -> None:
    daemon = serve(lms_room, f"lms=pty:{tmp_path / 'ttyLMS0'}")
    section = (
        "[LMS]\ndriver = CSickLaserSerial\nprocess_rate = 90\nsensorLabel = LMS\n"
        f"COM_port_LIN = {daemon.endpoint('lms', 'pty').path}\n"
        f"COM_baudRate = {baud}\nFOV = 180\nresolution = 50\nmm_mode = 0\n"
    )
    times, ranges, _ = exported_scans(tmp_path, "LMS", grab(tmp_path, section, scans=25, timeout_s=timeout_s))
    assert len(times) >= 20
    assert ranges.shape[1] == 361
    # Stamped on arrival: the line (38400) or the mirror (500 k, 37.5/s at 0.5°) sets the pace.
    rate = (len(times) - 1) / (times[-1] - times[0])
    assert rate == pytest.approx(line_rate_limit(baud, 0.5), rel=0.1)
    _, expected_mm = scan_values(lms_room, "lms", 1.0)
    # cm mode (mm_mode = 0): each range within 1 cm of the scene's value.
    np.testing.assert_allclose(ranges, np.tile(expected_mm / 1000.0, (len(times), 1)), atol=0.0101)
