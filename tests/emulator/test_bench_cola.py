"""`bench --section cola`: its rows (daemon and floor), and the floor's telegrams read like the daemon's."""

from __future__ import annotations

import json
import subprocess
import sys

from emulator.bench.cola_floor import telegram_payload
from protocols.cola.framing import ColaReader, Dialect, frame


def test_the_cola_section_reports_each_case_and_its_floor_with_the_load():
    result = subprocess.run([sys.executable, "-m", "emulator.cli", "bench", "--quick", "--json", "--section", "cola"],
                            capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stderr
    rows = json.loads(result.stdout)["cola"]
    six = ["tim0", "tim1", "tim2", "tim3", "lms0", "lms1"]
    assert [(row["case"], row["client"]) for row in rows] == [("lms511-fine", "lms511"), ("floor", "lms511")] + [
        ("six-units", name) for name in six] + [("floor", name) for name in six]
    for row in rows:
        assert row["telegrams"] > 0 and row["load"] > 0 and 0 <= row["jitter_p99_ms"] <= row["jitter_max_ms"], row
        if row["case"] == "floor":  # a bare sender sends every scan: 3 s of them with --quick
            assert row["missed"] == 0 and abs(row["telegrams"] - 3000 / row["period_ms"]) <= 2, row
            assert "loop_wakes" not in row
        else:  # the daemon's own count of its timer wake-ups in the window (SIGUSR1 stats)
            assert row["loop_wakes"] > 0 and 0 <= row["loop_late_5ms"] <= row["loop_late_2ms"] <= row["loop_late_1ms"] <= 1


def test_a_floor_telegram_is_a_daemons_telegram_of_the_same_size():
    payload = telegram_payload(811, 1000 / 15)  # a TiM571's
    telegrams = ColaReader().feed(frame(bytes(payload), Dialect.BINARY))
    assert len(telegrams) == 1 and telegrams[0].payload.startswith(b"sSN LMDscandata ")
    assert len(frame(bytes(payload), Dialect.BINARY)) == 1720  # what the daemon sends a TiM571 client (DIST1 only)
