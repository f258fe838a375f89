"""`bench --section serve`'s capacity curve: a fleet of URG-04LX (railway's world) past what one
worker computes, from half its capacity to three times it.

First a small fleet (well within capacity) measures what a scan costs the worker in CPU time
(/proc/PID/stat of the daemon and its worker; the worker's share is the whole minus the
daemon's own process), so one worker core computes `capacity` scans a second. Then N =
load × capacity / 10 URGs stream unlimited MD, each to its own TCP client, for each load.
Per row:

- on time: the share of due scans delivered within 10 ms of their slot (as the other rows);
- delivered: scans a second received, and against `capacity` × the worker's CPU actually
  used in the window (`of computable`: what that CPU could have computed at the small
  fleet's cost per scan; on a shared machine the worker gets less than a core, and this
  figure does not count that against the daemon);
- fairness: the slowest sensor's rate over the mean rate;
- late p99: how long after its own stamp a scan arrived (a device that is behind sends its
  freshest scan, stamped when it was measured);
- ms/inst: the worker's CPU per instant it computed in the window (the probe's is 1000 / capacity:
  a larger fleet's scans may cost more each, which `of computable` counts against the daemon);
- per job: the instants a worker job computed on average (a batch of 8 shares its numpy passes;
  one alone costs ~1.5x as much an instant), and unsent: the share of computed instants no
  device sent (the daemon's counters over the measuring window; jobs in flight at its edges make
  this a few tenths of a per cent uncertain).
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numpy as np

from emulator.bench.serve_load import ON_TIME_MS, _figures, _stream_all, fleet_scene_text, measure_serve, sensor_name
from emulator.bench.serve_process import ServeProcess
from emulator.bench.steal import StealMeter, steal_text

CURVE_LOADS = (0.5, 1.0, 1.5, 2.0, 3.0)
PROBE_SENSORS = 4  # the small fleet that measures a scan's cost
MAX_SENSORS = 256  # a scene's bound
SCANS_PER_SECOND = 10.0  # URG-04LX


def worker_capacity(model: str, duration_s: float) -> float:
    """Scans a second one worker core computes for a small fleet of URGs under `model`."""
    row = measure_serve(PROBE_SENSORS, duration_s, workers=1, model=model)
    worker_ms = row["cpu_ms_per_scan"] - row["daemon_cpu_ms_per_scan"]
    return 1000.0 / worker_ms


# the daemon's counters read as their change over the measuring window
WINDOW_COUNTERS = ("late", "skipped", "jobs_computed", "instants_computed", "served_scans")


def measure_load(model: str, count: int, duration_s: float, capacity: float) -> dict:
    """`count` URGs on one worker under `model`: on time, delivered, fairness, lateness."""
    with tempfile.TemporaryDirectory(prefix="lrf-bench-capacity-") as folder:
        scene = Path(folder) / f"urg-x{count}.toml"
        scene.write_text(fleet_scene_text(count))
        endpoints = [f"{sensor_name('urg-04lx', index)}=tcp:127.0.0.1:0" for index in range(count)]
        with ServeProcess(scene, endpoints, extra_args=["--model", model, "--workers", "1"], timeout_s=300.0) as daemon:
            steal = StealMeter()
            counters: list[dict[str, int]] = []
            measured = _stream_all(daemon, count, 0, duration_s, on_window=lambda: (counters.append(daemon.stats()), steal.mark()))
            load = os.getloadavg()
    stats = {key: counters[-1][key] - counters[0][key] for key in WINDOW_COUNTERS}  # the window's, not the start-up's
    streams, _, (cpu, daemon_cpu) = measured
    row = _figures(count, 0, duration_s, 1, measured, load, 1.0 / SCANS_PER_SECOND)
    rates = np.array([len(stream.arrivals) / duration_s for stream in streams])
    worker_cores = max(cpu - daemon_cpu, 1e-9) / duration_s
    return {
        "model": model,
        "sensors": count,
        "load_factor": count * SCANS_PER_SECOND / capacity,
        "on_time": row["on_time"],
        "delivered_per_s": float(rates.sum()),
        "of_capacity": float(rates.sum()) / capacity,
        "of_computable": float(rates.sum()) / (capacity * worker_cores),
        "worker_cores": worker_cores,
        "fairness": float(rates.min() / rates.mean()) if rates.mean() > 0 else float("nan"),
        "lateness_p99_ms": row["lateness_p99_ms"],
        "late": stats.get("late", 0),
        "instants_per_job": stats.get("instants_computed", 0) / max(1, stats.get("jobs_computed", 0)),
        "unsent": 1.0 - stats.get("served_scans", 0) / max(1, stats.get("instants_computed", 0)),
        # the worker's CPU per instant it computed in the window, against the probe's 1000 / capacity
        "worker_ms_per_instant": (cpu - daemon_cpu) * 1000.0 / max(1, stats.get("instants_computed", 0)),
        "skipped": stats.get("skipped", 0),
        "load_average": row["load_average"],
        "steal": steal.share,
    }


def capacity_curve(model: str, duration_s: float, loads: tuple[float, ...] = CURVE_LOADS) -> tuple[float, list[dict]]:
    capacity = worker_capacity(model, duration_s)
    counts = sorted({max(1, min(MAX_SENSORS, round(load * capacity / SCANS_PER_SECOND))) for load in loads})
    return capacity, [measure_load(model, count, duration_s, capacity) for count in counts]


def curve_lines(curves: dict[str, tuple[float, list[dict]]]) -> list[str]:
    lines = [
        "capacity curve: N URG-04LX (railway's world) on one worker, from half to 3x what it computes; one run each;"
        f" on time = within {ON_TIME_MS:g} ms of its slot",
        f"  {'model':<11} {'capacity':>8} {'N':>4} {'load':>5} {'on time':>8} {'scans/s':>8} {'of cap.':>7}"
        f" {'of comp.':>8} {'worker':>6} {'fair':>5} {'late p99':>8} {'per job':>7} {'unsent':>6} {'ms/inst':>7}  load avg",
    ]
    for model, (capacity, rows) in curves.items():
        for row in rows:
            lines.append(
                f"  {model:<11} {capacity:>6.0f}/s {row['sensors']:>4} {row['load_factor']:>4.1f}x {row['on_time']:>8.1%}"
                f" {row['delivered_per_s']:>8.1f} {row['of_capacity']:>7.1%} {row['of_computable']:>8.1%}"
                f" {row['worker_cores']:>6.2f} {row['fairness']:>5.2f} {row['lateness_p99_ms']:>6.0f}ms"
                f" {row['instants_per_job']:>7.1f} {row['unsent']:>6.1%} {row['worker_ms_per_instant']:>7.2f}"
                f"  {' '.join(f'{value:g}' for value in row['load_average'])}, {steal_text(row['steal'])}"
            )
    return lines


def bench_curves(quick: bool) -> tuple[dict, list[str]]:
    """The capacity curve for `formsma2011` and `physical` (quick: `physical` only, at 1.5x and 3x, 4 s a run;
    else 10 s)."""
    duration = 4.0 if quick else 10.0
    models = ("physical",) if quick else ("formsma2011", "physical")
    loads = (1.5, 3.0) if quick else CURVE_LOADS
    curves = {model: capacity_curve(model, duration, loads) for model in models}
    data = {model: {"capacity_per_s": capacity, "rows": rows} for model, (capacity, rows) in curves.items()}
    return {"capacity_curve": data}, curve_lines(curves)
