"""Live control while an unmodified client streams: hokuyolx (PyPI) on the real daemon over TCP.

Raising the room's smoke density through the control API turns the URG-04LX's
front beams into error codes from the first scan measured after the change
(the paper's rule, `formsma2011`), and hokuyolx stays connected and streaming
through it; `lrf-emulator ctl` makes the change, as a person at a terminal would.
"""

from __future__ import annotations

import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
from hokuyolx import HokuyoLX

from emulator.bench.serve_process import ServeProcess, serve_command

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "emulator"))
from control_support import write_live_room  # noqa: E402

FRONT = slice(384 - 44 - 10, 384 - 44 + 11)  # the 21 steps around straight ahead, in hokuyolx's 44..725 array


def test_raising_the_density_blanks_the_front_beams_from_the_first_scan_after_it(tmp_path: Path) -> None:
    room = write_live_room(tmp_path)
    with ServeProcess(room, ["urg=tcp:127.0.0.1:0"]) as daemon:
        laser = HokuyoLX(addr=daemon.endpoint("urg", "tcp").address, tsync=False, convert_time=False)
        applied: list[str] = []

        def change_later() -> None:
            time.sleep(1.2)
            result = subprocess.run(
                [*serve_command(), "ctl", "--url", daemon.control_url, "set", "region", "room", "density", "0.004"],
                capture_output=True, text=True, timeout=30,
            )
            applied.append(result.stdout + result.stderr)

        changer = threading.Thread(target=change_later)
        changer.start()
        try:
            scans = [(stamp, values) for values, stamp, _ in laser.iter_dist(30)]
        finally:
            changer.join()
        assert applied and applied[0].startswith("applied "), applied
        change_s = float(applied[0].split('"t": ')[1].split(",")[0])
        stamps = np.array([stamp for stamp, _ in scans])
        assert np.all(np.diff(stamps) == 100), stamps  # no scan lost across the change
        for stamp, values in scans:
            front = values[FRONT]
            if stamp / 1000.0 < change_s:
                assert np.all(front > 2800), (stamp, front)  # the wall, 2.9 m ahead
            else:
                assert np.all(front == 1), (stamp, front)  # low intensity: the smoke ate the beam
        assert stamps[0] / 1000 < change_s < stamps[-1] / 1000
        laser.activate()  # MD with a count switches the laser off after its last scan
        timestamp, values = laser.get_dist()  # still connected, still answering
        assert timestamp >= stamps[-1] and np.all(values[FRONT] == 1)
        laser.close()
