"""MRPT's command-line tools, unmodified (Debian `mrpt-apps`): record, export, map.

`grab` runs `rawlog-grabber` with one sensor section (the driver thread runs
until a key arrives on its stdin, then the log is written and it exits 0);
`export_2d_scans` turns a .rawlog into arrays through `rawlog-edit
--export-2d-scans-txt`; `carmen_to_rawlog` turns a CARMEN log into a rawlog
(`carmen2rawlog`); `icp_slam` runs `icp-slam` on a rawlog and reads the
path it writes (`log_estimated_path.txt`: one `step x y yaw` line per
observation) and its final point map.
"""

from __future__ import annotations

import re
import shutil
import subprocess
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

INSTALL_HINT = "apt-get install mrpt-apps (.ci/run installs it)"


class MrptError(RuntimeError):
    """An MRPT tool is missing, failed, or wrote something unexpected."""


def program(name: str) -> str:
    """The tool's path, or MrptError saying how to install it."""
    path = shutil.which(name)
    if path is None:
        raise MrptError(f"{name} not found: {INSTALL_HINT}")
    return path


@dataclass(frozen=True)
class Grabbed:
    """What one rawlog-grabber run left: its log file, exit status and output."""

    rawlog: Path | None
    returncode: int
    output: str

    def scans(self, label: str) -> ExportedScans:
        """`export_2d_scans` of the log; when it fails, the error also holds what rawlog-grabber
        printed (its driver's own account of why it saved nothing)."""
        if self.rawlog is None:
            raise MrptError(f"rawlog-grabber left no single log (exit {self.returncode}):\n{self.output[-3000:]}")
        try:
            return export_2d_scans(self.rawlog, label)
        except MrptError as error:
            raise MrptError(f"{error}\nrawlog-grabber said:\n{self.output[-3000:]}") from None


def grab(
    folder: Path, section: str, *, until: Callable[[int], bool], timeout_s: float, kill: bool = False
) -> Grabbed:
    """Run rawlog-grabber with one INI sensor section until `until(saved_scans)` is true or
    `timeout_s` passes, then press a key (or, with `kill`, SIGKILL it mid-stream)."""
    grabber = program("rawlog-grabber")
    folder.mkdir(parents=True, exist_ok=True)
    config = folder / "grab.ini"
    config.write_text(
        "[global]\n"
        f"rawlog_prefix = {folder / 'grab'}\n"
        "time_between_launches = 100\n"
        "use_sensoryframes = 0\n"
        "GRABBER_PERIOD_MS = 100\n\n" + section
    )
    line_buffered = ["stdbuf", "-oL"] if shutil.which("stdbuf") else []  # its progress, as it happens
    process = subprocess.Popen(
        [*line_buffered, grabber, str(config)], cwd=folder, text=True,
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
    )
    lines: list[str] = []
    saved = [0]

    def follow() -> None:
        assert process.stdout is not None
        for line in process.stdout:
            lines.append(line)
            found = re.search(r"Saved (\d+) objects", line)
            saved[0] += int(found.group(1)) if found else 0

    reader = threading.Thread(target=follow, daemon=True)
    reader.start()
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline and process.poll() is None and not until(saved[0]):
        time.sleep(0.05)
    assert process.stdin is not None
    if kill:  # a driver that dies mid-stream, leaving the device streaming
        process.kill()
    else:
        try:
            process.stdin.write("\n")  # os::kbhit(): stop, flush the log, exit 0
            process.stdin.close()
        except BrokenPipeError:
            pass
    try:
        process.wait(20)
    except subprocess.TimeoutExpired:
        process.kill()
        process.wait()
        raise MrptError(f"rawlog-grabber did not stop on a key press:\n{''.join(lines)[-3000:]}") from None
    reader.join(5)
    logs = sorted(folder.glob("grab_*.rawlog"))
    return Grabbed(logs[0] if len(logs) == 1 else None, process.returncode, "".join(lines))


@dataclass(frozen=True)
class ExportedScans:
    """The 2-D scans of a rawlog: time stamps (s, MRPT's clock), ranges (m), validity."""

    times_s: np.ndarray  # (n,)
    ranges_m: np.ndarray  # (n, beams)
    valid: np.ndarray  # (n, beams) bool
    intensity: np.ndarray | None = None  # (n, beams), when the scans carry it


def export_2d_scans(rawlog: Path, label: str) -> ExportedScans:
    """`rawlog-edit --export-2d-scans-txt`: one line per scan (time, N ranges, N flags, and N intensities
    when the scans have them: its header then names INTENSITY[i])."""
    editor = program("rawlog-edit")
    # Run beside the log: rawlog-edit 2.5 joins an absolute input's folder and
    # the output name without a "/".
    result = subprocess.run([editor, "--export-2d-scans-txt", "-i", rawlog.name], cwd=rawlog.parent,
                            capture_output=True, text=True, timeout=120, stdin=subprocess.DEVNULL)
    export = rawlog.with_name(f"{rawlog.stem}_{label}.txt")
    if result.returncode != 0 or not export.exists():
        raise MrptError(f"rawlog-edit exported no {label} scans from {rawlog}:\n{result.stdout[-2000:]}{result.stderr[-2000:]}")
    with export.open() as text:
        blocks = 3 if "INTENSITY" in text.readline() else 2
    rows = np.loadtxt(export, comments="%", ndmin=2)
    if rows.shape[0] == 0 or rows.shape[1] < 1 + blocks or (rows.shape[1] - 1) % blocks:
        raise MrptError(f"{export}: expected `time ranges... flags...` rows, got shape {rows.shape}")
    count = (rows.shape[1] - 1) // blocks
    intensity = rows[:, 1 + 2 * count :] if blocks == 3 else None
    return ExportedScans(rows[:, 0], rows[:, 1 : 1 + count], rows[:, 1 + count : 1 + 2 * count] == 1, intensity)


def carmen_to_rawlog(carmen: Path, rawlog: Path) -> Path:
    """`carmen2rawlog` on a CARMEN log, then `rawlog-edit --remove-label ODOMETRY`: a rawlog of its laser
    scans alone (one icp-slam pose per scan; the odometry it writes from the log's robot poses is dropped)."""
    converted = rawlog.with_name(f"{rawlog.stem}_with_odometry.rawlog")
    result = subprocess.run([program("carmen2rawlog"), "-q", "-w", "-i", str(carmen), "-o", str(converted)],
                            capture_output=True, text=True, timeout=300, stdin=subprocess.DEVNULL)
    if result.returncode != 0 or not converted.exists():
        raise MrptError(f"carmen2rawlog failed ({result.returncode}) on {carmen}:\n{result.stdout[-2000:]}{result.stderr[-2000:]}")
    result = subprocess.run([program("rawlog-edit"), "-w", "--remove-label", "ODOMETRY", "-i", str(converted), "-o", str(rawlog)],
                            capture_output=True, text=True, timeout=300, stdin=subprocess.DEVNULL)
    if result.returncode != 0 or not rawlog.exists():
        raise MrptError(f"rawlog-edit --remove-label failed ({result.returncode}):\n{result.stdout[-2000:]}{result.stderr[-2000:]}")
    return rawlog


# icp-slam's own demo (share/mrpt/config_files/icp-slam/icp-slam_demo_classic.ini) with
# the 3-D views and scene dumps off, every scan registered (decimation 1) and map
# insertions every 0.5 m / 20 deg, which suits rooms a few metres across.
ICP_SLAM_INI = """\
[ICP]
maxIterations = 80
minAbsStep_trans = 1e-6
minAbsStep_rot = 1e-6
thresholdDist = 0.3
thresholdAng_DEG = 5
ALFA = 0.8
smallestThresholdDist = 0.05
onlyClosestCorrespondences = true
onlyUniqueRobust = true
ICP_algorithm = icpClassic
corresponding_points_decimation = 1

[MappingApplication]
rawlog_file = {rawlog}
rawlog_offset = {skip}
logOutput_dir = {output}
LOG_FREQUENCY = 0
SAVE_3D_SCENE = 0
SAVE_POSE_LOG = 0
CAMERA_3DSCENE_FOLLOWS_ROBOT = 0
SHOW_PROGRESS_3D_REAL_TIME = 0
SHOW_LASER_SCANS_3D = 0
localizationLinDistance = 0.2
localizationAngDistance = 5
insertionLinDistance = 0.5
insertionAngDistance = 20
minICPgoodnessToAccept = 0.40
matchAgainstTheGrid = 0
occupancyGrid_count = 0
gasGrid_count = 0
landmarksMap_count = 0
beaconMap_count = 0
pointsMap_count = 1
likelihoodMapSelection = -1

[MappingApplication_pointsMap_00_insertOpts]
minDistBetweenLaserPoints = 0.05
fuseWithExisting = false
isPlanarMap = 1
"""


@dataclass(frozen=True)
class IcpSlamResult:
    """icp-slam's estimate: one (x, y, yaw rad) per rawlog observation, and its point map."""

    path: np.ndarray  # (n, 3), in the frame of the first scan
    map_points: np.ndarray  # (m, 2)
    output_dir: Path


def icp_slam(rawlog: Path, output_dir: Path, *, skip: int = 0, timeout_s: float = 600.0) -> IcpSlamResult:
    """Run icp-slam on `rawlog` from its observation `skip` on; its path (one pose per observation
    processed) and final point map."""
    slam = program("icp-slam")
    output_dir.mkdir(parents=True, exist_ok=True)
    config = output_dir.parent / f"{output_dir.name}.ini"
    # icp-slam skips entries while its 1-based count of entries read is below rawlog_offset.
    offset = int(skip) + 1 if skip > 0 else 0
    config.write_text(ICP_SLAM_INI.format(rawlog=rawlog.resolve(), output=output_dir.resolve(), skip=offset))
    # stdin from /dev/null: it polls the keyboard (Esc stops it) and pauses on an error.
    result = subprocess.run([slam, str(config)], capture_output=True, text=True, timeout=timeout_s,
                            stdin=subprocess.DEVNULL)
    path_file = output_dir / "log_estimated_path.txt"
    if result.returncode != 0 or not path_file.exists():
        raise MrptError(f"icp-slam failed ({result.returncode}) on {rawlog}:\n{result.stdout[-2000:]}{result.stderr[-2000:]}")
    rows = np.loadtxt(path_file, ndmin=2)
    if rows.shape[1] != 4 or not np.array_equal(rows[:, 0], np.arange(len(rows))):
        raise MrptError(f"{path_file}: expected `step x y yaw` lines for steps 0, 1, ...")
    return IcpSlamResult(rows[:, 1:4], _point_map(output_dir), output_dir)


def _point_map(output_dir: Path) -> np.ndarray:
    """The final points map icp-slam dumps as text (`x y z` per line)."""
    found = sorted(output_dir.glob("_finalmaps_*PointsMap*.txt"))
    if not found:
        raise MrptError(f"icp-slam left no point map in {output_dir}: {sorted(p.name for p in output_dir.iterdir())}")
    points = np.loadtxt(found[0], ndmin=2)
    return points[:, :2]
