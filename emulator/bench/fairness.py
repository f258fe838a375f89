"""Fairness under attack: the LMS200's scan rate and command latency while other clients flood.

One client writes 64 KiB of junk a second to the URG's pty, another floods
the URG's TCP port with 64 KiB bursts of `GD0000076801` (each in its own
process); an LMS200 host on the daemon's LMS pty, at 500 kBd and 180°/0.5°,
measures its streamed scans per second against the nominal 37.5 and the
time from a status request (31) to its whole reply. The same is measured
first with nobody attacking. Targets: within 1 % of the nominal
rate, replies within 50 ms.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numpy as np

from emulator.bench.hostile import (
    NOMINAL_SCANS_PER_S,
    Flood,
    attach_lms,
    lms_command_latencies,
    lms_scan_rate,
)
from emulator.bench.serve_process import ServeProcess

RATE_TARGET = 0.99
LATENCY_TARGET_MS = 50.0


def _measure(lms, duration_s: float, commands: int) -> dict:
    rate = lms_scan_rate(lms, duration_s)
    latencies_ms = lms_command_latencies(lms, commands) * 1000
    return {
        "scans_per_s": round(rate, 3),
        "rate_fraction": round(rate / NOMINAL_SCANS_PER_S, 4),
        "reply_p50_ms": round(float(np.percentile(latencies_ms, 50)), 2),
        "reply_p99_ms": round(float(np.percentile(latencies_ms, 99)), 2),
    }


def fairness_bench(quick: bool = False, scene: str = "railway") -> tuple[dict, list[str]]:
    duration_s, commands = (3.0, 20) if quick else (20.0, 200)
    with tempfile.TemporaryDirectory(prefix="lrf-bench-") as folder:
        endpoints = [f"urg=pty:{Path(folder) / 'ttyURG'}", "urg=tcp:127.0.0.1:0", f"lms=pty:{Path(folder) / 'ttyLMS'}"]
        with ServeProcess(scene, endpoints) as daemon, attach_lms(daemon.endpoint("lms", "pty").path) as lms:
            quiet = _measure(lms, duration_s, commands)
            with Flood(daemon.endpoint("urg", "pty").uri, "junk", period_s=1.0) as junk, \
                    Flood(daemon.endpoint("urg", "tcp").uri, "gd") as gd:
                attacked = _measure(lms, duration_s, commands)
            attacked.update(gd_flood_bytes=gd.sent, junk_bytes=junk.sent)
    data = {"fairness": {"nominal_scans_per_s": NOMINAL_SCANS_PER_S, "duration_s": duration_s,
                         "load_average": round(os.getloadavg()[0], 2), "quiet": quiet, "attacked": attacked}}
    lines = [
        f"LMS200 beside a GD flood and 64 KiB/s of junk on the URG ({scene}, {duration_s:g} s, {commands} status"
        f" requests), target ≥ {RATE_TARGET:.0%} of {NOMINAL_SCANS_PER_S:g} scans/s and replies ≤ {LATENCY_TARGET_MS:g} ms",
    ]
    for name, row in (("quiet", quiet), ("attacked", attacked)):
        lines.append(
            f"  {name:<8} {row['scans_per_s']:6.2f} scans/s ({row['rate_fraction']:.1%})"
            f"   reply p50 {row['reply_p50_ms']:6.2f} ms   p99 {row['reply_p99_ms']:6.2f} ms"
        )
    lines.append(f"  load average {data['fairness']['load_average']}")
    return data, lines
