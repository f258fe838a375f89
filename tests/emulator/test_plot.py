"""`lrf-emulator plot`: a waterfall PNG of the requested size with visible structure."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import matplotlib.image
import numpy as np
import pytest

from emulator.plots.waterfall import (
    ERROR_RGB,
    NO_RETURN_RGB,
    saturation,
    sensor_series,
    waterfall_rgb,
)
from emulator.scene import load_scene

CLI = [sys.executable, "-m", "emulator.cli"]


def plot(tmp_path: Path, *args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([*CLI, "plot", *args], capture_output=True, text=True, timeout=180, cwd=tmp_path)


def pixels_near(image: np.ndarray, rgb: tuple[float, float, float]) -> int:
    return int(np.sum(np.all(np.abs(image[:, :, :3] - np.array(rgb)) < 0.02, axis=2)))


def test_bocas_plot_has_the_requested_size_and_shows_the_error_onset(tmp_path: Path) -> None:
    out = tmp_path / "bocas.png"
    result = plot(tmp_path, "bocas", "--sensor", "urg", "--start", "60", "--end", "90",
                  "--out", str(out), "--width", "640", "--height", "480")
    assert result.returncode == 0, result.stderr
    image = matplotlib.image.imread(out)
    assert image.shape[:2] == (480, 640)
    assert image[:, :, :3].std() > 0.1
    colours = np.unique(np.round(image[:, :, :3] * 255).astype(int).reshape(-1, 3), axis=0)
    assert len(colours) > 20
    assert pixels_near(image, ERROR_RGB) > 5000  # the smoke errors from 71.6 s on


def test_marulan_plot_shows_plumes_and_no_return(tmp_path: Path) -> None:
    out = tmp_path / "marulan.png"
    result = plot(tmp_path, "marulan", "--sensor", "lms", "--start", "70", "--end", "80",
                  "--out", str(out), "--width", "900", "--height", "500")
    assert result.returncode == 0, result.stderr
    image = matplotlib.image.imread(out)
    assert image.shape[:2] == (500, 900)
    assert pixels_near(image, NO_RETURN_RGB) > 5000
    assert pixels_near(image, ERROR_RGB) < 400  # formsma2011: the LMS200 sees smoke as an obstacle (legend only)


def test_waterfall_colours_follow_the_values() -> None:
    series = sensor_series(load_scene("bocas"), "urg", 71.0, 72.0)
    image = waterfall_rgb(series)
    assert image.shape == (len(series.times_s), len(series.angles_rad), 3)
    assert np.all(image[series.errors] == ERROR_RGB)
    shades = image[~series.errors & ~series.no_return]
    assert np.all(shades[:, 0] == shades[:, 1])  # ranges are grey
    ranges = series.ranges_m[~series.errors & ~series.no_return]
    assert np.all(np.diff(shades[np.argsort(ranges), 0]) >= 0)  # darker = shorter
    assert np.allclose(series.saturation, saturation(series.mean_density))
    centre = len(series.angles_rad) // 2
    assert series.errors[:, centre].any() and not series.errors[:, centre].all()


def test_missing_matplotlib_is_one_clear_line(tmp_path: Path) -> None:
    code = (
        "import sys; sys.modules['matplotlib'] = None\n"
        "from emulator.cli import main\n"
        f"sys.exit(main(['plot', 'bocas', '--sensor', 'urg', '--end', '1', '--out', '{tmp_path / 'x.png'}']))\n"
    )
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert result.returncode == 2
    assert result.stderr.strip() == "lrf-emulator plot: plotting needs matplotlib: pip install 'lrf-emulator[plot]'"
    assert not (tmp_path / "x.png").exists()


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["bocas", "--sensor", "urg", "--end", "1", "--out", "x.png", "--width", "10"], "--width must be between 200"),
        (["bocas", "--sensor", "lms", "--end", "1", "--out", "x.png"], "no sensor named 'lms'"),
        (["bocas", "--sensor", "urg", "--end", "0.05", "--out", "x.png"], "fewer than two scans"),
        (["bocas", "--sensor", "urg", "--end", "1", "--out", "no/such/dir/x.png"], "cannot write no/such/dir/x.png"),
    ],
)
def test_plot_errors_are_one_line(tmp_path: Path, args: list[str], message: str) -> None:
    result = plot(tmp_path, *args)
    assert result.returncode == 2
    assert message in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1
