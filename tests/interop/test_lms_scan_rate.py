"""The LMS200 scans/s measurement (emulator.bench.lms_rates), in a short version.

This checks the measurement's structure and arithmetic, not timing
thresholds: the full table (5 s per cell) is in docs/interop.md.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from emulator.bench.lms_rates import (
    b0_telegram_bytes,
    line_rate_limit,
    lms_scan_rates,
    table_lines,
)


def test_line_rate_limits() -> None:
    assert (b0_telegram_bytes(0.5), b0_telegram_bytes(1.0)) == (732, 372)
    assert line_rate_limit(9600, 0.5) == pytest.approx(9600 / 7320)
    assert line_rate_limit(38400, 1.0) == pytest.approx(38400 / 3720)
    assert line_rate_limit(500000, 0.5) == 37.5  # the mirror, not the line
    assert line_rate_limit(500000, 1.0) == 75.0


def test_short_measurement_through_the_daemon(lms_room: Path) -> None:
    result = lms_scan_rates(lms_room, bauds=(38400, 500000), resolutions_deg=(1.0,), duration_s=1.0)
    rows = result["rows"]
    assert [(row["baud"], row["resolution_deg"]) for row in rows] == [(38400, 1.0), (500000, 1.0)]
    for row in rows:
        assert row["telegram_bytes"] == 372
        assert row["limit_per_s"] == pytest.approx(line_rate_limit(row["baud"], 1.0))
        assert row["scans"] >= 2, row
        assert row["measured_per_s"] > 0
        assert row["ratio"] == pytest.approx(row["measured_per_s"] / row["limit_per_s"])
    lines = table_lines(result)
    assert len(lines) == 2 + len(rows)
    assert lines[2].split()[0] == "38400"
