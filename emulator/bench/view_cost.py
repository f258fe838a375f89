"""What watching costs: a real `serve` streaming URG-04LX scans with the browser view off, on with no
browser, on with a headless chromium connected, and with `--mcap` recording the session.

Each case is `serve_load`'s measurement (N URG-04LX in railway's world, each
streamed to its own TCP client; rate, scan-period jitter p50/p99, lateness,
CPU per scan of the daemon and its child processes: workers and the view's)
with different `serve` options, plus the daemon's own count of its timer
wake-ups more than 2 and 5 ms late in the window (SIGUSR1 `stats`): the
client's figures include this process's own scheduling on a shared machine,
the daemon's do not. chromium runs at normal priority, as a user's would, and
once more at nice 19: on a 2-core machine its software WebGL competes with the
daemon for a core, and this shows what lowering its priority buys.
The browser is Debian's chromium driven by playwright (a test dependency):
without them that case is reported as not measured. One run per case, no
best-of; the load average is printed beside each row.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
from pathlib import Path
from typing import Iterator

from emulator.bench.serve_load import _figures, _stream_all, fleet_scene_text
from emulator.bench.serve_process import ServeProcess
from emulator.transport.timer import LATE_THRESHOLDS_MS

CHROMIUM_ARGS = ["--no-sandbox", "--disable-gpu", "--disable-background-networking", "--disable-component-update",
                 "--disable-sync", "--no-first-run", "--enable-unsafe-swiftshader"]
BROWSER_NICE = 19
CASES = (  # name, serve options, browser: None, or the nice value chromium runs at
    ("view off", ("--view", "off"), None),
    ("view, no browser", ("--view", "127.0.0.1:0"), None),
    ("view + chromium", ("--view", "127.0.0.1:0"), 0),
    (f"view + chromium nice {BROWSER_NICE}", ("--view", "127.0.0.1:0"), BROWSER_NICE),
    ("--mcap", ("--view", "off", "--mcap", "{folder}/session.mcap"), None),
)


@contextlib.contextmanager
def _browser(url: str, folder: Path, nice: int) -> Iterator[None]:
    """A headless chromium with the view open (and rendering) while the block runs, at `nice`
    (through a two-line launcher script: every chromium process inherits it)."""
    from playwright.sync_api import sync_playwright

    launcher = folder / "chromium"
    launcher.write_text(f'#!/bin/sh\nexec nice -n {nice} {shutil.which("chromium")} "$@"\n')
    launcher.chmod(0o700)
    with sync_playwright() as playwright:
        context = playwright.chromium.launch_persistent_context(
            str(folder / "profile"), executable_path=str(launcher), headless=True, args=CHROMIUM_ARGS,
            viewport={"width": 1280, "height": 800},
        )
        try:
            page = context.pages[0] if context.pages else context.new_page()
            page.goto(url)
            page.get_by_text("Connected").wait_for(timeout=60_000)
            yield
        finally:
            context.close()


def browser_available() -> bool:
    try:
        import playwright  # noqa: F401
    except ImportError:
        return False
    return shutil.which("chromium") is not None


def measure_case(name: str, options: tuple[str, ...], browser: int | None, count: int, duration_s: float) -> dict:
    with tempfile.TemporaryDirectory(prefix="lrf-bench-view-") as folder:
        scene = Path(folder) / f"urg-x{count}.toml"
        scene.write_text(fleet_scene_text(count))
        endpoints = [f"urg{index:02d}=tcp:127.0.0.1:0" for index in range(count)]
        extra = ["--model", "formsma2011", *(option.format(folder=folder) for option in options)]
        with ServeProcess(scene, endpoints, extra_args=extra, timeout_s=120.0) as daemon:
            watching = (_browser(daemon.service("view"), Path(folder), browser) if browser is not None
                        else contextlib.nullcontext())
            counters: list[dict[str, int]] = []
            with watching:
                streams = _stream_all(daemon, count, 0, duration_s, on_window=lambda: counters.append(daemon.stats()))
                load = os.getloadavg()
        mcap_bytes = (Path(folder) / "session.mcap").stat().st_size if "--mcap" in options else None
    row = {"case": name, **_figures(count, 0, duration_s, None, streams, load), **_loop_lateness(*counters)}
    if mcap_bytes is not None:
        row["mcap_bytes"] = mcap_bytes
    return row


def _loop_lateness(before: dict[str, int], after: dict[str, int]) -> dict:
    """The daemon's own view of its timer wake-ups in the window (SIGUSR1 stats, timer.py):
    how many, and the share more than 1, 2, 5 ms late."""
    wakes = after["wakes"] - before["wakes"]
    return {"loop_wakes": wakes, **{
        f"loop_late_{ms}ms": (after[f"late_{ms}ms"] - before[f"late_{ms}ms"]) / wakes if wakes else float("nan")
        for ms in LATE_THRESHOLDS_MS
    }}


def bench_section(quick: bool) -> tuple[dict, list[str]]:
    """`lrf-emulator bench --section view`: 2 URG-04LX streamed, 10 s per case (quick: 5 s)."""
    duration = 5.0 if quick else 10.0
    rows = []
    for name, options, browser in CASES:
        if browser is not None and not browser_available():
            rows.append({"case": name, "measured": False, "why": "chromium or playwright missing"})
            continue
        rows.append(measure_case(name, options, browser, 2, duration))
    lines = [
        "view: what watching costs a real serve streaming 2 URG-04LX (railway's world, formsma2011) to TCP clients;"
        " one run per case, no best-of; CPU = daemon + workers + view process",
        "  jitter/late: seen by the client (this process); loop >2 ms: the daemon's timer wake-ups more than 2 ms late;"
        f" chromium at normal priority, then at nice {BROWSER_NICE}",
        f"  {'case':<24} {'rate':>7} {'jitter p50':>10} {'p99 ms':>7} {'late p99':>8} {'loop >2ms':>9} {'>5ms':>6}"
        f" {'CPU ms/scan':>11} {'of it daemon':>12} {'cores':>6}  load avg",
    ]
    for row in rows:
        if row.get("measured") is False:
            lines.append(f"  {row['case']:<24} not measured: {row['why']}")
            continue
        lines.append(
            f"  {row['case']:<24} {row['rate']:>7.1%} {row['jitter_p50_ms']:>10.2f} {row['jitter_p99_ms']:>7.2f}"
            f" {row['lateness_p99_ms']:>8.2f} {row['loop_late_2ms']:>9.1%} {row['loop_late_5ms']:>6.1%}"
            f" {row['cpu_ms_per_scan']:>11.2f} {row['daemon_cpu_ms_per_scan']:>12.2f} {row['cpu_cores']:>6.2f}"
            f"  {' '.join(f'{value:g}' for value in row['load_average'])}"
            + (f"  ({row['mcap_bytes'] / 1e6:.1f} MB written)" if "mcap_bytes" in row else "")
        )
    return {"view": rows}, lines
