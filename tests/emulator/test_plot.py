"""`lrf-emulator plot`: a waterfall PNG of the requested size with visible structure."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import matplotlib
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
from emulator.errors import UserError
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


# What each format's file starts with (pgf: LaTeX text; raw and rgba: bare pixels, 4 bytes each).
MAGIC = {
    "png": b"\x89PNG", "jpg": b"\xff\xd8\xff", "jpeg": b"\xff\xd8\xff", "gif": b"GIF8", "webp": b"RIFF",
    "tif": b"II*\x00", "tiff": b"II*\x00", "pdf": b"%PDF", "eps": b"%!PS", "ps": b"%!PS", "svg": b"<?xml",
    "svgz": b"\x1f\x8b", "avif": b"\x00\x00\x00", "pgf": b"%%", "raw": b"", "rgba": b"",
}


def test_every_format_matplotlib_writes_is_written(tmp_path: Path) -> None:
    from emulator.plots.output import supported_formats
    from emulator.plots.waterfall import draw_waterfall

    series = sensor_series(load_scene("bocas"), "urg", 71.0, 71.5)
    assert {"png", "jpg", "svg", "pdf"} <= set(supported_formats()) <= set(MAGIC)
    for fmt in supported_formats():
        out = tmp_path / f"waterfall.{fmt}"
        if fmt == "pgf" and shutil.which("xelatex") is None:  # pgf measures its text with LaTeX
            with pytest.raises(UserError, match=r"cannot write .*waterfall\.pgf as pgf: 'xelatex' not found"):
                draw_waterfall(series, out, width_px=300, height_px=200)
            assert not out.exists()
            continue
        draw_waterfall(series, out, width_px=300, height_px=200)
        data = out.read_bytes()
        assert data.startswith(MAGIC[fmt]), fmt
        if fmt in ("raw", "rgba"):
            assert len(data) == 300 * 200 * 4
    assert not [path for path in tmp_path.iterdir() if path.name.startswith(".")]  # no partial file left


@pytest.mark.parametrize(("name", "magic"), [("x.jpg", b"\xff\xd8\xff"), ("x.svg", b"<?xml"), ("map.svg", b"<?xml")])
def test_plot_writes_jpg_and_svg(tmp_path: Path, name: str, magic: bytes) -> None:
    args = ["bocas", "--map"] if name.startswith("map") else ["bocas", "--sensor", "urg", "--end", "1"]
    result = plot(tmp_path, *args, "--out", name, "--width", "400", "--height", "300")
    assert result.returncode == 0 and result.stderr == "", result.stderr
    assert (tmp_path / name).read_bytes().startswith(magic)
    assert [path.name for path in tmp_path.iterdir()] == [name]


def test_an_unknown_format_is_one_line_before_any_work(tmp_path: Path) -> None:
    result = plot(tmp_path, "bocas", "--sensor", "urg", "--end", "60", "--out", "x.doc")
    assert result.returncode == 2
    assert result.stderr.startswith("lrf-emulator plot: --out x.doc: cannot write .doc files (known: ")
    assert "png" in result.stderr and "svg" in result.stderr and len(result.stderr.splitlines()) == 1
    assert list(tmp_path.iterdir()) == []


def test_a_write_that_fails_midway_leaves_the_old_file_whole(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The figure goes to a partial file renamed over the target only once complete."""
    from matplotlib.figure import Figure

    from emulator.plots.output import save_figure

    out = tmp_path / "x.svg"
    out.write_text("the old picture")

    def half_written(self: Figure, file, **kwargs) -> None:
        file.write(b"<?xml half")
        raise ValueError("broken on the way")

    monkeypatch.setattr(Figure, "savefig", half_written)
    with pytest.raises(UserError, match=r"^cannot write .*x\.svg as svg: broken on the way$"):
        save_figure(Figure(), out)
    assert out.read_text() == "the old picture"
    assert [path.name for path in tmp_path.iterdir()] == ["x.svg"]


def waterfall_texts(tmp_path: Path, scene: str, start_s: float) -> str:
    """The waterfall of the scene's urg as SVG with its text kept as text."""
    from emulator.plots.waterfall import draw_waterfall

    out = tmp_path / f"{scene}.svg"
    with matplotlib.rc_context({"svg.fonttype": "none"}):
        draw_waterfall(sensor_series(load_scene(scene), "urg", start_s, start_s + 0.5), out, width_px=900, height_px=500)
    return out.read_text()


def test_the_waterfall_has_a_range_colour_bar(tmp_path: Path) -> None:
    svg = waterfall_texts(tmp_path, "bocas", 71.0)
    assert ">range (m)<" in svg
    for tick in range(6):  # the URG-04LX's 0 to 5.6 m
        assert f">{tick}<" in svg


def test_camera_saturation_only_where_the_scene_has_a_camera_reference(tmp_path: Path) -> None:
    """BOCAS had a camera on the paper target; the rescue arena has smoke regions but no camera."""
    assert load_scene("bocas").camera_reference and not load_scene("rescue").camera_reference
    bocas, rescue = waterfall_texts(tmp_path, "bocas", 71.0), waterfall_texts(tmp_path, "rescue", 30.0)
    assert ">camera saturation" in bocas
    assert ">mean density" in rescue and "camera saturation" not in rescue


def test_camera_reference_is_true_or_false(tmp_path: Path) -> None:
    scene = tmp_path / "x.toml"
    scene.write_text('[scene]\ncamera_reference = "yes"\n[[sensors]]\nname = "urg"\nmodel = "urg-04lx"\n')
    with pytest.raises(UserError, match=r'^x\.toml: scene\.camera_reference: expected true or false, got "yes"$'):
        load_scene(scene)
