"""Bench sections: each `(quick: bool) -> (data, lines)`; `data` is merged into the JSON
object and `lines` are printed in the table. Add a section by adding it to `SECTIONS`.

- rays: plain Embree INTERSECT versus our full cast (`World.cast`) on the same
  beams of every bundled scene's sensors with the smoke removed; several scans
  are batched per call, as a daemon with several clients would. `ratio` is
  ours/raw in rays per second over all scenes.
- scans: compute time per scan for each bundled scene, sensor and smoke/sensor
  preset (each scene under every preset, as `--model` would serve it), with
  smoke, against the sensor's period: URG-04LX 100 ms; LMS200 the scan its
  scene options select against the time the mirror needs for it (1° → 1
  revolution of 13.33 ms, 0.5° → 2, 0.25° → 4; the default 361-value scan: 26.67 ms).
  `rescue`'s sensors ride on a moving robot: each scan casts new beams, every
  one from the pose at its own instant, and meets a door that moves.
  `fraction` is the cost of a steady stream as the daemon computes it
  (`sensor.scans` of SCAN_BATCH consecutive scans, divided by SCAN_BATCH);
  one scan computed alone (a request nobody foresaw) is its own column.
  `railway-10k` is railway with its plume's rate raised until 10 000 particles
  are alive at once (rate × lifetime), a plume at scale.
- transport: command latency and MD scan jitter through a served daemon
  (`transport_latency`).
- lms-rates: LMS200 scans/s per baud and resolution through a served daemon
  (`lms_rates`).
- control: live control through a served daemon (`control_latency`): change →
  first scan showing it, and a 100 Hz pose stream's cost on MD jitter.
- fairness: the LMS200's scan rate and command latency while one client floods
  the URG with GDs and another writes 64 KiB/s of junk (`fairness`).
- cola: CoLa-B streams through a served daemon (`cola_streams`): an LMS511 at
  0.1667° under `physical`, and 4 TiM571 + 2 LMS111 at 50 Hz from one daemon.
- slam: `rescue`'s loop in its smoke, mapped by MRPT's icp-slam from the URG-04LX and from a
  UTM-30LX-EW on the same mount with its first and then its last echo (`slam_echoes`): ATE of each.
- memory: peak resident set size of this process (last, so it covers the others).

Long sections run only when named (`--section soak`): `soak` (`emulator.bench.soak`)
runs the daemon under everything at once for `--minutes` (default 60; `make soak`).
"""

from __future__ import annotations

import dataclasses
import resource
import time
from typing import Callable

import numpy as np

from emulator.daemon.memory import keep_freed_memory
from emulator.daemon.scan_cache import SCAN_BATCH
from emulator.optics import World
from emulator.scene import bundled_scenes, load_scene
from emulator.scene.model import Scene, SensorSpec
from emulator.scene.sick_models import MODELS as SICK_MODELS
from emulator.sensors import HOKUYO_MODELS, configured_scans, create_sensor, hokuyo_model, lms200, sick_cola
from emulator.sensors.beam_geometry import scan_plane_rays
from emulator.sensors.mount import SensorMount
from emulator.sensors.response import PRESET_MODULES, apply_model_override

SCANS_PER_BATCH = 16
SCAN_REPEATS = 3  # each instant is timed this often and the fastest kept


Section = tuple[dict, list[str]]


def _scenes() -> list[Scene]:
    return [load_scene(bundled.name) for bundled in bundled_scenes()]


DENSE_PLUME_SCENE = "railway"
DENSE_PLUME_PARTICLES = 10_000


def dense_plume_scene() -> Scene:
    """`railway-10k`: railway with every plume's rate raised so DENSE_PLUME_PARTICLES live at once
    (rate × lifetime; railway's one plume lives 10 s, so 1000 particles a second): what particles cost at scale."""
    scene = load_scene(DENSE_PLUME_SCENE)
    plumes = tuple(dataclasses.replace(plume, rate=DENSE_PLUME_PARTICLES / plume.lifetime / len(scene.plumes)) for plume in scene.plumes)
    return dataclasses.replace(scene, plumes=plumes)


HOKUYO_MOUNT_SCENES = ("rescue", "railway")
SCIP22_MODELS = tuple(name for name in HOKUYO_MODELS if name != "urg-04lx")


def hokuyos_on_the_urgs_mount(scene: Scene) -> Scene:
    """`scene`'s SCIP 2.2 Hokuyos it lacks, each where its URG-04LX is (same body and pose: on `rescue`,
    the robot), served nowhere; the scene's own sensors left out (their rows come from the scene itself)."""
    urg = next(spec for spec in scene.sensors if spec.model == "urg-04lx")
    present = {spec.model for spec in scene.sensors}
    added = tuple(
        dataclasses.replace(urg, name=model, model=model, endpoints=(), options={}) for model in SCIP22_MODELS if model not in present
    )
    return dataclasses.replace(scene, sensors=added)


def _scan_scenes() -> list[tuple[str, Scene]]:
    """The scans section's scenes by label: every bundled scene, `railway-10k`, and `rescue-hokuyos` and
    `railway-hokuyos` (the SCIP 2.2 models each scene lacks, on its URG's mount)."""
    scenes = _scenes()
    bundled = [(scene.path.stem if scene.path else scene.name, scene) for scene in scenes]
    mounted = [(f"{label}-hokuyos", hokuyos_on_the_urgs_mount(scene)) for label, scene in bundled if label in HOKUYO_MOUNT_SCENES]
    return [*bundled, (f"{DENSE_PLUME_SCENE}-10k", dense_plume_scene()), *mounted]


def _sensor_beams(scene: Scene, spec: SensorSpec, world: World) -> tuple[np.ndarray, np.ndarray, float]:
    """Origins, directions and cast range of one scan of the sensor (a Hokuyo's valid steps; the LMS's window),
    from its pose at t = 0 (a sensor on a moving body: where the body starts)."""
    pose = SensorMount(scene, spec, world.bodies).frames(np.zeros(1)).at(0)
    if spec.model in SICK_MODELS:
        sick = SICK_MODELS[spec.model]
        resolution_ticks = sick_cola.configured_request(spec.options)["resolution_ticks"]
        origins, directions = scan_plane_rays(pose, np.radians(sick_cola.device_angles_deg(sick, resolution_ticks) - 90.0))
        return origins, directions, sick.max_range_m
    hokuyo = hokuyo_model(spec.model)
    if hokuyo is not None:
        angles = hokuyo.step_angles_rad()[hokuyo.valid_steps]
        origins, directions = scan_plane_rays(pose, angles)
        return origins, directions, hokuyo.max_range_m
    window = lms200.configured_window(spec.options)
    angles = np.radians(lms200.device_angles_deg(window["start_deg"], window["step_deg"], window["count"]) - 90.0)
    origins, directions = scan_plane_rays(pose, angles)
    return origins, directions, lms200.REACH_M


def _best_seconds(function: Callable[[], object], repeats: int) -> float:
    """The fastest of `repeats` timed calls: the machine's speed, not its other load."""
    best = np.inf
    for _ in range(repeats):
        start = time.perf_counter()
        function()
        best = min(best, time.perf_counter() - start)
    return best


def rays_section(quick: bool) -> Section:
    repeats = 3 if quick else 30
    rows, raw_total, ours_total, rays_total = [], 0.0, 0.0, 0
    for scene in _scenes():
        world = World(dataclasses.replace(scene, regions=(), plumes=()))
        for spec in scene.sensors:
            origins, directions, max_range = _sensor_beams(scene, spec, world)
            origins = np.ascontiguousarray(np.tile(origins, (SCANS_PER_BATCH, 1)), dtype=np.float32)
            directions = np.ascontiguousarray(np.tile(directions, (SCANS_PER_BATCH, 1)), dtype=np.float32)
            raw = _best_seconds(lambda: world.first_triangles(origins, directions, max_range), repeats)
            ours = _best_seconds(lambda: world.cast(origins, directions, max_range, 0.0), repeats)
            rays = len(origins)
            rows.append({
                "scene": scene.path.stem if scene.path else scene.name,
                "sensor": spec.name,
                "rays": rays,
                "raw_rays_per_s": rays / raw,
                "ours_rays_per_s": rays / ours,
                "ratio": raw / ours,
            })
            raw_total, ours_total, rays_total = raw_total + raw, ours_total + ours, rays_total + rays
    ratio = raw_total / ours_total
    lines = [f"rays: plain Embree INTERSECT vs our cast, smoke removed, {SCANS_PER_BATCH} scans per call"]
    lines.append(f"  {'scene':<10} {'sensor':<8} {'rays':>6} {'raw Mrays/s':>12} {'ours Mrays/s':>13} {'ratio':>6}")
    for row in rows:
        lines.append(
            f"  {row['scene']:<10} {row['sensor']:<8} {row['rays']:>6} {row['raw_rays_per_s'] / 1e6:>12.2f}"
            f" {row['ours_rays_per_s'] / 1e6:>13.2f} {row['ratio']:>6.2f}"
        )
    lines.append(f"  overall ratio (ours/raw): {ratio:.2f} (target >= 0.5)")
    return {"ratio": ratio, "rays": rows}, lines


def scans_section(quick: bool) -> Section:
    """Compute time per scan at instants spread over the first minute of each scene (smoke on) under each
    preset: one scan alone, and a steady stream (SCAN_BATCH consecutive scans from that instant in one
    `scans` call, per scan). Per instant the fastest of SCAN_REPEATS wall-clock timings, so other load on
    the machine counts as little as it can; the mean over instants, and the slowest instant (and when it
    is). `fraction` / `max_fraction` are the mean / slowest streamed cost against the period."""
    keep_freed_memory()  # as the daemon's scan workers do: temporaries reused, not faulted in each scan
    times = np.linspace(1.0, 60.0, 5 if quick else 60)
    rows = []
    for label, bundled in _scan_scenes():
        for preset in PRESET_MODULES:
            scene = apply_model_override(bundled, preset)
            world = World(scene)
            for spec in scene.sensors:
                sensor = create_sensor(scene, spec.name, world)
                sensor.configured_scan(0.0)  # the first call pays one-off set-up
                period_s = sensor.configured_period_s
                alone = [_best_seconds(lambda: sensor.configured_scan(float(t)), SCAN_REPEATS) for t in times]
                streamed = [
                    _best_seconds(
                        lambda: configured_scans(sensor, [float(t) + j * period_s for j in range(SCAN_BATCH)]),
                        SCAN_REPEATS,
                    )
                    / SCAN_BATCH
                    for t in times
                ]
                streamed_ms = float(np.mean(streamed)) * 1000.0
                period_ms = period_s * 1000.0
                rows.append({
                    "scene": label,
                    "sensor": spec.name,
                    "model": spec.model,
                    "preset": preset,
                    "scan_ms": float(np.mean(alone)) * 1000.0,
                    "max_scan_ms": float(np.max(alone)) * 1000.0,
                    "streamed_ms": streamed_ms,
                    "max_streamed_ms": float(np.max(streamed)) * 1000.0,
                    "slowest_at_s": float(times[int(np.argmax(streamed))]),
                    "period_ms": period_ms,
                    "fraction": streamed_ms / period_ms,
                    "max_fraction": float(np.max(streamed)) * 1000.0 / period_ms,
                })
    lines = [
        f"scans: compute time per scan with smoke, mean and slowest (max, at s) over {len(times)} instants in"
        f" 1..60 s, each instant the best of {SCAN_REPEATS} wall-clock timings; streamed = {SCAN_BATCH}"
        " consecutive scans per call as the daemon computes a steady stream, alone = one scan by itself;"
        " fraction = streamed / period (mean, slowest)",
        f"  {'scene':<15} {'sensor':<11} {'model':<11} {'preset':<12} {'stream ms':>9} {'max ms':>7} {'at s':>5}"
        f" {'alone ms':>9} {'max ms':>7} {'period ms':>10} {'fraction':>9} {'max frac':>9}",
    ]
    for row in rows:
        lines.append(
            f"  {row['scene']:<15} {row['sensor']:<11} {row['model']:<11} {row['preset']:<12}"
            f" {row['streamed_ms']:>9.2f} {row['max_streamed_ms']:>7.2f} {row['slowest_at_s']:>5.1f} {row['scan_ms']:>9.2f}"
            f" {row['max_scan_ms']:>7.2f} {row['period_ms']:>10.2f} {row['fraction']:>8.1%} {row['max_fraction']:>8.1%}"
        )
    return {"scans": rows}, lines


def transport_section(quick: bool) -> Section:
    from emulator.bench.transport_latency import transport_bench  # starts a daemon: imported only when run

    return transport_bench(quick)


def lms_rates_section(quick: bool) -> Section:
    from emulator.bench.lms_rates import bench_section  # starts a daemon: imported only when run

    return bench_section(quick)


def serve_section(quick: bool) -> Section:
    from emulator.bench.serve_load import bench_section  # starts daemons: imported only when run

    return bench_section(quick)


def control_section(quick: bool) -> Section:
    from emulator.bench.control_latency import control_bench  # starts a daemon: imported only when run

    return control_bench(quick)


def fairness_section(quick: bool) -> Section:
    from emulator.bench.fairness import fairness_bench  # starts a daemon and attackers: imported only when run

    return fairness_bench(quick)


def view_section(quick: bool) -> Section:
    from emulator.bench.view_cost import bench_section  # starts daemons and a browser: imported only when run

    return bench_section(quick)


def cola_section(quick: bool) -> Section:
    from emulator.bench.cola_streams import bench_section  # starts daemons: imported only when run

    return bench_section(quick)


def slam_section(quick: bool) -> Section:
    import tempfile
    from pathlib import Path

    from emulator.bench.slam_echoes import LOOP_END_S, runs  # runs MRPT's tools: imported only when run

    with tempfile.TemporaryDirectory(prefix="bench-slam-") as work:
        results = runs(Path(work), end_s=25.0 if quick else LOOP_END_S)
    data = [{"sensor": r.label, "scans": len(r.times_s), "invalid_share": r.invalid_share, "ate_rmse_m": r.error.rmse_m,
             "ate_max_m": r.error.max_m, "heading_rmse_deg": float(np.degrees(r.error.heading_rmse_rad))} for r in results]
    lines = [f"slam rescue physical: {r.label}: ATE {100 * r.error.rmse_m:.1f} cm RMS ({100 * r.error.max_m:.1f} max), "
             f"heading {np.degrees(r.error.heading_rmse_rad):.1f} deg, {100 * r.invalid_share:.1f} % beams invalid" for r in results]
    return {"slam": data}, lines


def memory_section(quick: bool) -> Section:
    peak_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # Linux reports KiB
    return {"peak_rss_mb": peak_mb}, [f"memory: peak RSS {peak_mb:.1f} MB (this process)"]


def soak_section(quick: bool, minutes: float | None = None) -> Section:
    from emulator.bench.soak import soak_section as soak  # starts daemons and clients: imported only when run

    return soak(quick, minutes)


SECTIONS: dict[str, Callable[[bool], Section]] = {
    "rays": rays_section,
    "scans": scans_section,
    "transport": transport_section,
    "lms-rates": lms_rates_section,
    "serve": serve_section,
    "control": control_section,
    "fairness": fairness_section,
    "view": view_section,
    "cola": cola_section,
    "slam": slam_section,
    "memory": memory_section,
}

# sections run only when asked for by name, given `--minutes`
LONG_SECTIONS: dict[str, Callable[[bool, float | None], Section]] = {
    "soak": soak_section,
}
