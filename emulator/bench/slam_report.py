"""`python -m emulator.bench.slam_report [FILE.md]`: SLAM in smoke, measured (docs/slam-in-smoke.md).

For each smoke preset and each smoke scale (`serve --smoke-scale F`: every
density times F), the real `serve` streams the `rescue` robot's URG-04LX to
MRPT's rawlog-grabber, icp-slam maps the log, and the report gives the
absolute trajectory error against the ground truth, the share of beams that
carried an error code, and a picture of each preset's map at the scene's own
smoke (PNG under docs/figures/). Prints the markdown table; with FILE.md,
replaces the part of FILE.md between its two `<!-- slam-table -->` markers.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from emulator.bench.slam import SlamRun, record, slam
from emulator.scene.smoke_scale import scale_smoke
from emulator.plots.map import draw_map
from emulator.scene import load_scene
from emulator.sensors.response import apply_model_override

SCENE = "rescue"
SENSOR = "urg"
PRESETS = ("formsma2011", "physical")
SMOKE_SCALES = (0.0, 0.5, 1.0, 2.0, 4.0)
MAPPED_SCALE = 1.0  # the scene as written: its map is drawn
SPEED = 1.0  # CHokuyoURG takes ~3 s of wall clock to start: at 1x it misses the least of the loop
START_S = 10.0  # icp-slam starts here in every run, so runs differ by smoke alone (a loaded machine
# has taken up to 6.7 s to get serve and the driver going)
ATTEMPTS = 2  # a run whose driver started after START_S is recorded again
MARKER = "<!-- slam-table -->"
ESTIMATE_RGB = (0.0, 0.0, 0.0)


@dataclass(frozen=True)
class Row:
    preset: str
    smoke_scale: float
    scans: int
    error_share: float
    ate_rmse_m: float
    ate_max_m: float
    heading_rmse_deg: float
    seconds: float

    def markdown(self) -> str:
        return (
            f"| {self.preset} | {self.smoke_scale:g} | {self.scans} | {100 * self.error_share:.1f} % | "
            f"{100 * self.ate_rmse_m:.1f} | {100 * self.ate_max_m:.1f} | {self.heading_rmse_deg:.1f} | {self.seconds:.0f} |"
        )


HEADER = (
    "| preset | smoke scale | scans compared | beams with an error code | ATE RMSE (cm) | ATE max (cm) "
    "| heading RMSE (deg) | run time (s) |\n|---|---|---|---|---|---|---|---|"
)


def measure(scene_name: str, preset: str, smoke_scale: float, folder: Path, until_s: float) -> tuple[Row, SlamRun]:
    scene = scale_smoke(apply_model_override(load_scene(scene_name), preset), smoke_scale)
    for attempt in range(ATTEMPTS):
        started = time.monotonic()
        recording = record(scene_name, SENSOR, folder / str(attempt), until_s=until_s, speed=SPEED,
                           serve_args=("--model", preset, "--smoke-scale", repr(smoke_scale)))
        if recording.times_s[~np.isnan(recording.times_s)][0] <= START_S or attempt == ATTEMPTS - 1:
            break
    run = slam(recording, scene, SENSOR, folder / str(attempt), start_s=START_S)
    row = Row(preset, smoke_scale, len(run.times_s), recording.error_share, run.error.rmse_m, run.error.max_m,
              float(np.degrees(run.error.heading_rmse_rad)), time.monotonic() - started)
    return row, run


def draw_slam_map(scene_name: str, run: SlamRun, preset: str, smoke_scale: float, out: Path) -> None:
    """The scene at the run's last scan, icp-slam's map (red) and path (black) over the truth (blue)."""
    scene = scale_smoke(apply_model_override(load_scene(scene_name), preset), smoke_scale)
    draw_map(scene, float(run.times_s[-1]), out, extra_points=run.map_points,
             extra_paths=((run.error.aligned[:, :2], ESTIMATE_RGB, "icp-slam path"),),
             title=f"{scene.name}, {preset}, smoke x{smoke_scale:g}: icp-slam map (red) and path (black), "
                   f"truth (blue); ATE {100 * run.error.rmse_m:.1f} cm")


def loop_end_s(scene_name: str) -> float:
    """Simulated time the last keyframe is reached, and a little more."""
    scene = load_scene(scene_name)
    ends = [float(body.trajectory.times[-1]) for body in scene.bodies if hasattr(body.trajectory, "times")]
    return max(ends) + 2.0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m emulator.bench.slam_report")
    parser.add_argument("report", nargs="?", type=Path, help="markdown file whose table to replace")
    parser.add_argument("--figures", type=Path, default=Path("docs/figures"), help="where the map PNGs go")
    parser.add_argument("--scene", default=SCENE, help=f"scene name or path (default {SCENE})")
    parser.add_argument("--presets", nargs="+", default=list(PRESETS))
    parser.add_argument("--scales", type=float, nargs="+", default=list(SMOKE_SCALES))
    args = parser.parse_args(argv)
    until_s = loop_end_s(args.scene)
    name = load_scene(args.scene).name
    rows = []
    with tempfile.TemporaryDirectory(prefix="slam-report-") as work:
        for preset in args.presets:
            for scale in args.scales:
                row, run = measure(args.scene, preset, scale, Path(work) / f"{preset}-{scale:g}", until_s)
                rows.append(row)
                print(row.markdown(), file=sys.stderr, flush=True)
                if scale == MAPPED_SCALE:
                    args.figures.mkdir(parents=True, exist_ok=True)
                    draw_slam_map(args.scene, run, preset, scale, args.figures / f"slam-{name}-{preset}.png")
    table = "\n".join([HEADER, *(row.markdown() for row in rows)])
    print(table)
    if args.report is not None:
        text = args.report.read_text()
        before, middle, after = text.split(MARKER, 2)
        args.report.write_text(f"{before}{MARKER}\n{table}\n{MARKER}{after}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
