"""SLAM in smoke with a multi-echo unit: `rescue`'s URG-04LX against a UTM-30LX-EW on the same mount,
mapping with its first echo and then its last echo, each through MRPT's icp-slam.

MRPT's CHokuyoURG reads the single-echo commands (GD/MD) only, so a last-echo run cannot go through
it. Every run here takes the emulator's own scans instead (`sensor.scans` at each scan instant: what
the daemon serves), writes them as a CARMEN log (`ROBOTLASER1` lines, invalid ranges as 0), turns it
into a rawlog with MRPT's `carmen2rawlog` and maps it with `icp-slam`: the three runs share
everything but the sensor and the echo. The truth is the sensor's pose at each scan's middle beam
instant (the sweep takes a period; icp-slam treats a scan as instantaneous). The UTM-30LX-EW sweeps
at 40 Hz; every fourth scan is used, 10 Hz like the URG's, so icp-slam registers as many scans.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from emulator.bench.mrpt import MrptError, carmen_to_rawlog, icp_slam
from emulator.bench.trajectory import TrajectoryError, absolute_trajectory_error
from emulator.optics import World
from emulator.plots.map import draw_map, sensor_poses_2d
from emulator.scene import Scene, load_scene
from emulator.scene.smoke_scale import scale_smoke
from emulator.sensors import Scan, beam_times_s, create_sensor, ranges_m
from emulator.sensors.response import apply_model_override

SCENE = "rescue"
URG = "urg"
UTM = "utm"  # the UTM-30LX-EW added on the URG's mount
UTM_MODEL = "utm-30lx-ew"
START_S = 10.0  # as the real-driver runs of docs/slam-in-smoke.md
RATE_HZ = 10.0  # scans mapped per second, every sensor
BATCH = 8  # scans computed together
MAX_RANGE_M = {URG: 5.6, UTM: 60.0}
LOOP_END_S = 62.0  # rescue's last keyframe (60 s) and a little more


@dataclass(frozen=True)
class Run:
    """One sensor and echo: `label` ("URG-04LX", "UTM-30LX-EW first echo", ...), the scans' middle-beam
    instants, the share of invalid beams, icp-slam's path scored against the truth, and its map."""

    label: str
    times_s: np.ndarray
    invalid_share: float
    error: TrajectoryError
    map_points: np.ndarray


def with_utm_on_the_urgs_mount(scene: Scene) -> Scene:
    """`scene` with a UTM-30LX-EW named `utm` where its URG-04LX is (same body, same pose), served nowhere
    (`rescue` carries one there already: then the scene as it is)."""
    urg = scene.sensor(URG)
    present = next((spec for spec in scene.sensors if spec.name == UTM), None)
    if present is not None and (present.model, present.body, present.pose) == (UTM_MODEL, urg.body, urg.pose):
        return scene
    utm = dataclasses.replace(urg, name=UTM, model=UTM_MODEL, endpoints=(), options={})
    return dataclasses.replace(scene, sensors=(*scene.sensors, utm))


def scan_instants(period_s: float, phase_s: float, start_s: float, end_s: float) -> np.ndarray:
    """The sensor's scan stamps from `start_s` to `end_s`, at RATE_HZ (every k-th of its scans)."""
    every = max(1, round(1.0 / (RATE_HZ * period_s)))
    first = math.ceil((start_s - phase_s) / period_s - 1e-9)
    last = math.floor((end_s - phase_s) / period_s + 1e-9)
    return phase_s + np.arange(first, last + 1, every) * period_s


def echo_ranges(scan: Scan, echo: str | None) -> np.ndarray:
    """The scan's ranges (m, NaN where invalid): its single-echo values, or its `first` / `last` echo."""
    if echo is None:
        return ranges_m(scan)
    if scan.echoes is None:
        raise MrptError(f"{scan.model} reports no echoes")
    present = scan.echoes >= 0
    column = 0 if echo == "first" else np.maximum(present.sum(axis=1) - 1, 0)
    values = scan.echoes[np.arange(len(scan.echoes)), column]
    metres = ranges_m(dataclasses.replace(scan, values=np.where(present.any(axis=1), values, 0)))
    return np.where(present.any(axis=1), metres, np.nan)


def write_carmen(path: Path, scans: list[Scan], ranges: list[np.ndarray], max_range_m: float) -> None:
    """One `ROBOTLASER1` line per scan (laser and robot poses 0: icp-slam gets no odometry)."""
    angles = scans[0].angles_rad
    resolution = float(angles[1] - angles[0])
    with path.open("w") as out:
        out.write("# CARMEN Logfile written by lrf-emulator (emulator.bench.slam_echoes)\n")
        for scan, row in zip(scans, ranges):
            readings = " ".join(f"{r:.3f}" for r in np.where(np.isfinite(row), row, 0.0))
            stamp = 1000.0 + scan.time_s
            out.write(
                f"ROBOTLASER1 0 {angles[0]:.6f} {angles[-1] - angles[0]:.6f} {resolution:.6f} {max_range_m:g} 0.01 0 "
                f"{len(row)} {readings} 0 0 0 0 0 0 0 0 0 0 0 0 {stamp:.6f} lrf-emulator {stamp:.6f}\n"
            )


def run(scene: Scene, sensor: str, echo: str | None, label: str, folder: Path, *, start_s: float = START_S,
        end_s: float = LOOP_END_S) -> Run:
    """Scan `sensor` of `scene` from `start_s` to `end_s`, map its `echo` with icp-slam, score the path."""
    world = World(scene)
    device = create_sensor(scene, sensor, world)
    times = scan_instants(device.configured_period_s, device.configured_phase_s, start_s, end_s)
    scans = [scan for k in range(0, len(times), BATCH) for scan in device.scans(list(times[k:k + BATCH]))]
    ranges = [echo_ranges(scan, echo) for scan in scans]
    usable = [np.isfinite(r) & (r > 0) & (r < MAX_RANGE_M[sensor]) for r in ranges]
    folder.mkdir(parents=True, exist_ok=True)
    carmen = folder / "scans.log"
    write_carmen(carmen, scans, [np.where(u, r, 0.0) for u, r in zip(usable, ranges)], MAX_RANGE_M[sensor])
    result = icp_slam(carmen_to_rawlog(carmen, folder / "scans.rawlog"), folder / "icp-slam")
    if len(result.path) != len(scans):
        raise MrptError(f"icp-slam wrote {len(result.path)} poses for {len(scans)} scans")
    middles = np.array([float(np.median(beam_times_s(scan))) for scan in scans])
    error = absolute_trajectory_error(result.path, sensor_poses_2d(scene, sensor, middles))
    map_points = result.map_points @ error.transform.rotation.T + error.transform.translation
    return Run(label, middles, 1.0 - float(np.mean(np.concatenate(usable))), error, map_points)


RUNS = ((URG, None, "URG-04LX"), (UTM, "first", "UTM-30LX-EW first echo"), (UTM, "last", "UTM-30LX-EW last echo"))


def runs(folder: Path, *, preset: str = "physical", smoke_scale: float = 1.0, end_s: float = LOOP_END_S) -> list[Run]:
    """The three runs on `rescue` under `preset` with its smoke times `smoke_scale`."""
    scene = with_utm_on_the_urgs_mount(scale_smoke(apply_model_override(load_scene(SCENE), preset), smoke_scale))
    return [run(scene, sensor, echo, label, folder / f"{sensor}-{echo or 'single'}", end_s=end_s) for sensor, echo, label in RUNS]


PATH_COLOURS = {"URG-04LX": (0.0, 0.0, 0.0), "UTM-30LX-EW first echo": (0.85, 0.45, 0.0), "UTM-30LX-EW last echo": (0.0, 0.6, 0.2)}


def draw_paths(results: list[Run], out: Path, *, preset: str = "physical", smoke_scale: float = 1.0) -> None:
    """The scene at the last scan with each run's icp-slam path over the truth (blue)."""
    scene = scale_smoke(apply_model_override(load_scene(SCENE), preset), smoke_scale)
    draw_map(scene, float(results[0].times_s[-1]), out,
             extra_paths=tuple((r.error.aligned[:, :2], PATH_COLOURS[r.label], f"{r.label}: ATE {100 * r.error.rmse_m:.0f} cm")
                               for r in results),
             title=f"rescue, {preset}, smoke x{smoke_scale:g}: icp-slam paths of the URG-04LX (black), the UTM-30LX-EW's "
                   f"first echo (orange) and last echo (green); truth (blue)")


HEADER = ("| smoke scale | sensor, echo | scans | invalid beams | ATE RMSE (cm) | ATE max (cm) | heading RMSE (deg) |\n"
          "|---|---|---|---|---|---|---|")


def table_row(result: Run, smoke_scale: float) -> str:
    error = result.error
    return (f"| {smoke_scale:g} | {result.label} | {len(result.times_s)} | {100 * result.invalid_share:.1f} % "
            f"| {100 * error.rmse_m:.1f} | {100 * error.max_m:.1f} | {math.degrees(error.heading_rmse_rad):.1f} |")


MARKER = "<!-- slam-echo-table -->"
FIGURE = "slam-rescue-echoes.png"
SMOKE_SCALES = (0.0, 1.0, 2.0)
MAPPED_SCALE = 1.0


def main(argv: list[str] | None = None) -> int:
    """`python -m emulator.bench.slam_echoes [FILE.md]`: the three runs on `rescue` (physical) at each smoke
    scale; prints the table, draws docs/figures/slam-rescue-echoes.png (the scene's own smoke), and
    with FILE.md replaces the part between its two `<!-- slam-echo-table -->` markers."""
    import argparse
    import sys
    import tempfile

    parser = argparse.ArgumentParser(prog="python -m emulator.bench.slam_echoes")
    parser.add_argument("report", nargs="?", type=Path, help="markdown file whose table to replace")
    parser.add_argument("--figures", type=Path, default=Path("docs/figures"), help="where the map PNG goes")
    parser.add_argument("--scales", type=float, nargs="+", default=list(SMOKE_SCALES))
    args = parser.parse_args(argv)
    rows = []
    with tempfile.TemporaryDirectory(prefix="slam-echoes-") as work:
        for scale in args.scales:
            results = runs(Path(work) / f"{scale:g}", smoke_scale=scale)
            rows += [table_row(r, scale) for r in results]
            print("\n".join(rows[-len(results):]), file=sys.stderr, flush=True)
            if scale == MAPPED_SCALE:
                args.figures.mkdir(parents=True, exist_ok=True)
                draw_paths(results, args.figures / FIGURE, smoke_scale=scale)
    table = "\n".join([HEADER, *rows])
    print(table)
    if args.report is not None:
        before, _, after = args.report.read_text().split(MARKER, 2)
        args.report.write_text(f"{before}{MARKER}\n{table}\n{MARKER}{after}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
