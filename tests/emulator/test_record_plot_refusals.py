"""`record` and `plot` at their edges, through the real command line: what they cannot do well is refused
in one line (exit 2, no traceback) before any work, naming the option the user gave; what they can, they do.

- a rosbag2 bag is a directory named without a suffix (`--out x.mcap` made `x.mcap/x.mcap.mcap`), and a
  suffix that names a format must be that format's;
- `--out` in a directory that is not there names `--out` (not the ground truth's `.tum` beside it), and
  nothing is created on the way (the rosbag2 writer made the missing directories);
- `plot --map --start/--end` draws the span's scans (they were ignored), `--time` goes with `--map` alone;
- a huge `--end` is refused at once (`record` past `--max-scans`, `plot` past its beams), never gigabytes
  of memory (each huge span is run under an address-space limit, which the old code broke at once);
- the map's legend counts "1 beam".
"""

from __future__ import annotations

import math
import os
import subprocess
import sys
from pathlib import Path

import matplotlib
import matplotlib.image
import numpy as np
import pytest

from emulator.errors import UserError
from emulator.plots.map import SCAN_RGB, draw_map
from emulator.plots.waterfall import sensor_series
from emulator.scene import load_scene
from emulator.sensors.series import scan_times

CLI = [sys.executable, "-m", "emulator.cli"]
MEMORY_LIMIT_BYTES = 2 * 2**30  # the old code asked for 3.2 GB of scan times alone for `--end 1e7` of a UTM-30LX


def run_cli(*args: str, cwd: Path, memory_limit: int | None = None, env: dict[str, str] | None = None) -> subprocess.CompletedProcess[str]:
    def limit() -> None:
        import resource

        resource.setrlimit(resource.RLIMIT_AS, (memory_limit, memory_limit))

    environment = {**os.environ, "MALLOC_ARENA_MAX": "2", **(env or {})}
    return subprocess.run([*CLI, *args], capture_output=True, text=True, timeout=120, cwd=cwd, env=environment,
                          preexec_fn=limit if memory_limit is not None else None)


def refused(result: subprocess.CompletedProcess[str], *words: str) -> str:
    """The one error line of a refused command, checked to hold every one of `words`."""
    assert "Traceback" not in result.stderr, result.stderr
    assert result.returncode == 2, (result.returncode, result.stderr)
    lines = result.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("lrf-emulator "), result.stderr
    for word in words:
        assert word in lines[0], (word, lines[0])
    return lines[0]


def help_text(command: str, tmp_path: Path) -> str:
    result = run_cli(command, "--help", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    return " ".join(result.stdout.split())


# 1. a rosbag2 bag is a directory named without a suffix; a format's suffix is that format's


@pytest.mark.parametrize(("fmt", "out", "words"), [
    ("rosbag2", "x.mcap", ["--out x.mcap", "--format rosbag2 writes a bag directory", "--out x makes x/metadata.yaml and x/x.mcap"]),
    ("rosbag2", "x.db3", ["--out x.db3", "named without a suffix", "--out x makes"]),
    ("rosbag2", "x.bag", ["--out x.bag", "named without a suffix"]),
    ("text", "x.mcap", ["--out x.mcap", "a .mcap name is for --format mcap, not --format text"]),
    ("rosbag1", "x.mcap", ["--out x.mcap", "not --format rosbag1"]),
    ("mcap", "x.bag", ["--out x.bag", "a .bag name is for --format rosbag1, not --format mcap"]),
    ("text", "x.db3", ["--out x.db3", "SQLite", "--format rosbag2 --out x"]),
])
def test_an_out_whose_suffix_is_another_formats_is_refused(tmp_path: Path, fmt: str, out: str, words: list[str]) -> None:
    result = run_cli("record", "rescue", "--sensor", "urg", "--end", "0.2", "--format", fmt, "--out", out, cwd=tmp_path)
    refused(result, *words)
    assert list(tmp_path.iterdir()) == []  # no x.mcap/x.mcap.mcap, nothing at all


def test_a_rosbag2_bag_is_the_directory_named_and_the_help_says_so(tmp_path: Path) -> None:
    result = run_cli("record", "rescue", "--sensor", "urg", "--end", "0.2", "--format", "rosbag2", "--out", "run", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert sorted(path.name for path in (tmp_path / "run").iterdir()) == ["metadata.yaml", "run.mcap"]
    assert "rosbag2: a new bag directory DIR named without a suffix (DIR/metadata.yaml, DIR/DIR.mcap)" in help_text("record", tmp_path)


# 2. a missing directory names --out, and nothing is made on the way


@pytest.mark.parametrize(("fmt", "out"), [
    ("text", "missing/x.log"), ("mcap", "missing/x.mcap"), ("rosbag2", "missing/x"), ("rosbag1", "missing/x.bag"),
])
def test_an_out_in_a_missing_directory_names_out_and_creates_nothing(tmp_path: Path, fmt: str, out: str) -> None:
    result = run_cli("record", "rescue", "--sensor", "urg", "--end", "0.2", "--format", fmt, "--out", out, cwd=tmp_path)
    line = refused(result, f"--out {out}", "its directory missing does not exist")
    assert ".tum" not in line
    assert list(tmp_path.iterdir()) == []  # the rosbag2 writer made missing/x and everything above it


def test_an_out_below_a_file_says_it_is_not_a_directory(tmp_path: Path) -> None:
    (tmp_path / "notes").write_text("a file")
    result = run_cli("record", "railway", "--sensor", "urg", "--end", "0.2", "--out", "notes/x.log", cwd=tmp_path)
    assert ".tum" not in refused(result, "--out notes/x.log", "its directory notes is not a directory")
    assert sorted(path.name for path in tmp_path.iterdir()) == ["notes"]



@pytest.mark.parametrize("kind", ["fifo", "directory"])
def test_a_ground_truth_path_that_is_no_regular_file_is_refused_before_anything_is_written(tmp_path: Path, kind: str) -> None:
    """x.log.tum a FIFO (opening it blocked record for ever) or a directory: one line, and no x.log left behind."""
    truth = tmp_path / "x.log.tum"
    os.mkfifo(truth) if kind == "fifo" else truth.mkdir()
    result = run_cli("record", "railway", "--sensor", "urg", "--end", "0.2", "--out", "x.log", cwd=tmp_path)
    refused(result, "x.log.tum", "is not a regular file")
    assert sorted(path.name for path in tmp_path.iterdir()) == ["x.log.tum"]

# 3. plot --map draws the span's scans


CART_SCENE = """\
[scene]
name = "cart"

[[sensors]]
name = "urg"
model = "urg-04lx"
position = [0.0, 0.0, 0.3]

[[bodies]]
name = "cart"
trajectory = { keyframes = [[0.0, -1.0, -4.0, 0.0], [10.0, 1.0, -4.0, 0.0]] }

[[objects]]
name = "cart box"
body = "cart"
box = { size = [0.6, 0.6, 1.0] }
position = [0.0, 0.0, 0.5]
"""


def scanned_near(image: np.ndarray, pixel: tuple[int, int]) -> bool:
    row, column = pixel
    patch = image[row - 4:row + 5, column - 4:column + 5, :3]
    return bool(np.all(np.abs(patch - np.array(SCAN_RGB)) < 0.1, axis=2).any())


def test_plot_map_draws_every_scan_of_its_span(tmp_path: Path) -> None:
    """The cart's north face (y = -3.7) is at x = -1 at 0 s and x = +1 at 10 s: a span's map shows the
    scans of both; the map of one instant (or the old code, which drew 0 s for any span) one of them."""
    (tmp_path / "cart.toml").write_text(CART_SCENE)
    size = ["--width", "800", "--height", "600"]
    span = run_cli("plot", "cart.toml", "--map", "--sensor", "urg", "--start", "0", "--end", "10", "--out", "span.png", *size, cwd=tmp_path)
    assert span.returncode == 0, span.stderr
    now = run_cli("plot", "cart.toml", "--map", "--sensor", "urg", "--time", "10", "--out", "now.png", *size, cwd=tmp_path)
    assert now.returncode == 0, now.stderr
    view = draw_map(load_scene(tmp_path / "cart.toml"), 10.0, tmp_path / "view.png", sensor="urg", width_px=800, height_px=600)
    spanned, instant = (matplotlib.image.imread(tmp_path / name) for name in ("span.png", "now.png"))
    assert scanned_near(spanned, view.pixel(-1.0, -3.7)) and scanned_near(spanned, view.pixel(1.0, -3.7))
    assert scanned_near(instant, view.pixel(1.0, -3.7)) and not scanned_near(instant, view.pixel(-1.0, -3.7))
    assert "with the scans of urg from 0 s" in span.stdout


@pytest.mark.parametrize(("args", "words"), [
    (["--map", "--sensor", "urg", "--time", "3", "--end", "5"], ["--time and --start/--end", "not both"]),
    (["--map", "--sensor", "urg", "--start", "1"], ["--map --start needs --end"]),
    (["--map", "--start", "1", "--end", "2"], ["--map --start/--end", "name the --sensor"]),
    (["--sensor", "urg", "--end", "1", "--time", "3"], ["--time is the instant of a --map"]),
])
def test_plot_refuses_times_it_would_ignore(tmp_path: Path, args: list[str], words: list[str]) -> None:
    refused(run_cli("plot", "bocas", *args, "--out", "x.png", cwd=tmp_path), *words)
    assert list(tmp_path.iterdir()) == []


def test_plot_help_says_what_a_span_does_with_map(tmp_path: Path) -> None:
    text = help_text("plot", tmp_path)
    assert "with --map: draw every scan of --sensor from T0 to --end" in text
    assert "with --map: the one simulated time drawn (s, default 0); not with --start/--end" in text


# 4. a huge --end: one line at once, within a memory limit


@pytest.mark.parametrize("args", [
    ["--sensor", "utm", "--out", "x.log"],
    ["--sensor", "urg,utm", "--format", "rosbag2", "--out", "bag"],
])
def test_record_refuses_a_span_past_max_scans_at_once(tmp_path: Path, args: list[str]) -> None:
    result = run_cli("record", "rescue", "--end", "10000000", *args, cwd=tmp_path, memory_limit=MEMORY_LIMIT_BYTES)
    refused(result, "--start 0 to --end 10000000 holds", "more than --max-scans 100000", "raise --max-scans")
    assert list(tmp_path.iterdir()) == []


def test_max_scans_sets_the_cap_and_the_help_names_it(tmp_path: Path) -> None:
    over = run_cli("record", "railway", "--sensor", "urg", "--end", "1", "--max-scans", "5", "--out", "x.log", cwd=tmp_path)
    refused(over, "holds 11 scans of urg, more than --max-scans 5 allows (that many span 0.5 s here)")
    assert list(tmp_path.iterdir()) == []
    within = run_cli("record", "railway", "--sensor", "urg", "--end", "0.4", "--max-scans", "5", "--out", "x.log", cwd=tmp_path)
    assert within.returncode == 0 and "recorded 5 scans of urg" in within.stdout, within.stderr
    assert len([line for line in (tmp_path / "x.log").read_text().splitlines() if not line.startswith("#")]) == 5
    assert "refuse a span of more than N scans of all --sensor together, before writing anything (default 100000" in help_text("record", tmp_path)


@pytest.mark.parametrize(("args", "words"), [
    (["--sensor", "utm"], ["holds 400000001 scans of utm", "a waterfall draws at most 6000000 beams",
                           "5550 of its 1081-beam scans (--end 138.725 at the latest from this --start)"]),
    (["--map", "--sensor", "utm"], ["a map draws at most 1000000 beams", "925 of its 1081-beam scans (--end 23.1 at the latest"]),
])
def test_plot_refuses_a_span_past_its_beams_at_once(tmp_path: Path, args: list[str], words: list[str]) -> None:
    result = run_cli("plot", "rescue", *args, "--end", "10000000", "--out", "x.png", cwd=tmp_path, memory_limit=MEMORY_LIMIT_BYTES)
    refused(result, "--start 0 to --end 10000000", "plot a shorter span", *words)
    assert list(tmp_path.iterdir()) == []


def test_the_latest_end_a_refusal_names_fits() -> None:
    bocas = load_scene("bocas")
    with pytest.raises(UserError, match=r"5 of its 682-beam scans \(--end 0\.4 at the latest from this --start\)"):
        sensor_series(bocas, "urg", 0.0, 0.5, max_beams=682 * 5)
    assert len(sensor_series(bocas, "urg", 0.0, 0.4, max_beams=682 * 5).times_s) == 5


@pytest.mark.parametrize(("period_s", "start_s", "end_s", "phase_s"), [
    (0.1, 0.0, 0.3, 0.0), (0.1, 70.05, 73.0, 0.0), (0.1, 0.0, 0.2, 0.066), (1 / 75, 80.0, 81.0, 0.0),
    (2 / 75, 75.0, 75.1, 0.004), (0.025, 0.0, 500.0, 0.0), (0.1, 5.01, 5.02, 0.0), (0.1, 3.0, 3.0, 0.0),
])
def test_record_times_a_span_lazily_and_exactly(period_s: float, start_s: float, end_s: float, phase_s: float) -> None:
    from emulator.sensors.series import scan_count, span_times

    expected = scan_times(period_s, start_s, end_s, phase_s).tolist()
    assert list(span_times(period_s, start_s, end_s, phase_s)) == expected
    assert scan_count(period_s, start_s, end_s, phase_s) == len(expected)


@pytest.mark.parametrize(("start_s", "end_s"), [(0.0, 0.2), (0.93, 13.0), (2.0, 3.0), (123.456, 4000.1), (9999.99, 10000.0)])
def test_a_bags_tf_instants_are_made_a_chunk_at_a_time_exactly(start_s: float, end_s: float) -> None:
    from emulator.recording.rosbag import TF_RATE_HZ, tf_count, tf_times

    step = 1.0 / TF_RATE_HZ
    whole = np.round(np.arange(math.floor(start_s / step) * step, end_s + step / 2, step), 9)
    assert tf_count(start_s, end_s) == len(whole)
    assert np.array_equal(tf_times(start_s, end_s), whole)
    chunks = [tf_times(start_s, end_s, low, low + 7) for low in range(0, len(whole), 7)]
    assert np.array_equal(np.concatenate(chunks), whole)


# 5. one beam is "1 beam"


ONE_BEAM_SCENE = """\
[scene]
name = "one beam"

[[objects]]
name = "wall"
box = { size = [0.2, 4.0, 2.0] }
position = [3.0, 0.0, 1.0]

# 1.4 m of thick smoke 4 mm wide straight ahead: the URG-04LX's beam at 0° returns an error code, its
# neighbours 0.35° off pass beside it
[[smoke.regions]]
name = "sliver"
box = { size = [1.4, 0.004, 2.0] }
position = [1.5, 0.0, 1.0]
density = 0.01

[[sensors]]
name = "urg"
model = "urg-04lx"
position = [0.0, 0.0, 0.3]
"""


def test_the_map_legend_counts_one_beam_and_one_scan_in_the_singular(tmp_path: Path) -> None:
    (tmp_path / "one.toml").write_text(ONE_BEAM_SCENE)
    (tmp_path / "matplotlibrc").write_text("svg.fonttype: none\n")  # text kept as text, to be read back
    env = {"MATPLOTLIBRC": str(tmp_path / "matplotlibrc")}
    result = run_cli("plot", "one.toml", "--map", "--sensor", "urg", "--out", "one.svg", cwd=tmp_path, env=env)
    assert result.returncode == 0, result.stderr
    svg = (tmp_path / "one.svg").read_text()
    assert ">error codes (1 beam)<" in svg and "1 beams" not in svg
    result = run_cli("plot", "one.toml", "--map", "--sensor", "urg", "--start", "0", "--end", "0.05", "--out", "span.svg",
                     cwd=tmp_path, env=env)
    assert result.returncode == 0, result.stderr
    svg = (tmp_path / "span.svg").read_text()
    assert ">scan points of urg (1 scan)<" in svg and ">error codes (1 beam)<" in svg


@pytest.mark.parametrize(
    ("frames", "words"),
    [
        (["--map-frame", ""], "--map-frame '': expected a frame name"),
        (["--base-frame", "base link"], "--base-frame 'base link': expected a frame name"),
        (["--map-frame", "odom"], "the three frames must differ"),
        (["--odom-frame", "base_link"], "the three frames must differ"),
        (["--map-frame", "/map"], "--map-frame '/map': expected a frame name (not empty, no spaces, not starting with /"),
        (["--base-frame", "urg"], "--base-frame urg: the sensor urg's own frame"),  # urg -> urg in /tf_static
    ],
)
def test_a_bags_frames_are_named_and_apart(tmp_path: Path, frames: list[str], words: str) -> None:
    """An empty frame id or a frame that is its own parent makes a bag no tf lookup can use."""
    result = run_cli("record", "rescue", "--sensor", "urg", "--end", "0.2", "--format", "rosbag2", "--out", "bag", *frames, cwd=tmp_path)
    assert result.returncode == 2, result.stderr
    assert words in result.stderr and len(result.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "bag").exists()



@pytest.mark.parametrize(("fmt", "options", "named"), [
    ("text", ["--epoch", "1700000000"], "--epoch"),
    ("mcap", ["--map-frame", "world", "--base-frame", "robot"], "--map-frame, --base-frame"),
])
def test_a_bags_options_given_to_another_format_are_refused(tmp_path: Path, fmt: str, options: list[str], named: str) -> None:
    """They were taken and ignored: the user thought the recording held them."""
    out = "x.log" if fmt == "text" else "x.mcap"
    result = run_cli("record", "railway", "--sensor", "urg", "--end", "0.2", "--format", fmt, "--out", out, *options, cwd=tmp_path)
    refused(result, f"{named}: for --format rosbag2 or rosbag1 only (a {fmt} recording has no ROS time or frames)")
    assert list(tmp_path.iterdir()) == []
