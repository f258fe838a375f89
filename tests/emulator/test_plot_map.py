"""`plot --map`: the top-down picture shows each thing where it is, read back pixel by pixel."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import matplotlib
import matplotlib.image
import numpy as np
import pytest

from emulator.scene.smoke_scale import scale_smoke
from emulator.plots.map import (
    ERROR_CODE_RGB,
    MAX_SMOKE_ALPHA,
    TRAJECTORY_RGB,
    PLUME_ALPHA,
    PLUME_RGB,
    SCAN_RGB,
    SMOKE_RGB,
    draw_map,
    solid_grey,
)
from emulator.scene import load_scene

CLI = [sys.executable, "-m", "emulator.cli"]

# A pillar east of the sensor, a block of smoke that thickens from 0 to 0.01 d between 0 and 10 s
# to the north-west, and a plume that stays on its source (no velocity, wind or spread) to the south-west.
MAP_SCENE = """\
[scene]
name = "map test"
seed = 3

[[objects]]
name = "pillar"
box = { size = [1.0, 1.0, 2.0] }
position = [3.0, 0.0, 1.0]

[[objects]]
name = "wall"
box = { size = [0.2, 12.0, 2.0] }
position = [-6.0, 0.0, 1.0]

[[smoke.regions]]
name = "block"
box = { size = [2.0, 2.0, 2.0] }
position = [-3.0, 3.0, 1.0]
density = { keyframes = [[0.0, 0.0], [10.0, 0.01]] }

[[smoke.plumes]]
name = "fire"
source = [-3.0, -3.0, 0.3]
rate = 5.0
lifetime = 20.0
size = 0.4
growth = 0.0
velocity = [0.0, 0.0, 0.0]
spread = 0.0
wind = [0.0, 0.0, 0.0]
density = 0.05

[[sensors]]
name = "urg"
model = "urg-04lx"
position = [0.0, 0.0, 0.3]

[[bodies]]
name = "cart"
trajectory = { keyframes = [[0.0, -1.0, -4.0, 0.0], [10.0, 1.0, -4.0, 90.0]] }

[[objects]]
name = "cart box"
body = "cart"
box = { size = [0.6, 0.6, 1.0] }
position = [0.0, 0.0, 0.5]
"""


@pytest.fixture
def scene_path(tmp_path: Path) -> Path:
    path = tmp_path / "map.toml"
    path.write_text(MAP_SCENE)
    return path


def blend(rgb: tuple[float, float, float], alpha: float) -> np.ndarray:
    """`rgb` at `alpha` over the white background."""
    return alpha * np.array(rgb) + (1 - alpha) * np.ones(3)


def rgb_at(image: np.ndarray, pixel: tuple[int, int]) -> np.ndarray:
    return image[pixel[0], pixel[1], :3]


def near(image: np.ndarray, rgb: np.ndarray | tuple[float, ...], tolerance: float = 0.03) -> np.ndarray:
    return np.all(np.abs(image[:, :, :3] - np.asarray(rgb)) < tolerance, axis=2)


def test_solids_smoke_by_density_plume_particles_and_scan_are_where_they_are(scene_path: Path, tmp_path: Path) -> None:
    scene = load_scene(scene_path)
    out = tmp_path / "map.png"
    view = draw_map(scene, 10.0, out, sensor="urg", width_px=800, height_px=600)
    image = matplotlib.image.imread(out)
    assert image.shape[:2] == (600, 800)
    np.testing.assert_allclose(rgb_at(image, view.pixel(3.0, 0.3)), [solid_grey(2.0)] * 3, atol=0.02)
    np.testing.assert_allclose(rgb_at(image, view.pixel(-3.0, 3.0)), blend(SMOKE_RGB, MAX_SMOKE_ALPHA), atol=0.02)
    plume = rgb_at(image, view.pixel(-3.0, -3.0))  # 50 particles stacked on the source: at least one's shade
    assert np.all(plume <= blend(PLUME_RGB, PLUME_ALPHA) + 0.02) and plume[2] > plume[1] + 0.2 and plume[0] > plume[1], plume
    np.testing.assert_allclose(rgb_at(image, view.pixel(-3.0, -2.5)), [1.0, 1.0, 1.0], atol=0.01)  # 0.2 m boxes
    np.testing.assert_allclose(rgb_at(image, view.pixel(1.0, 2.0)), [1.0, 1.0, 1.0], atol=0.01)  # open floor
    # The pillar's near face at x = 2.5 is scanned: red points along it, none in open floor.
    row, column = view.pixel(2.5, 0.0)
    assert near(image[row - 3:row + 4, column - 4:column + 3], SCAN_RGB, 0.1).any()
    red = near(image, SCAN_RGB, 0.1)
    red[:, view.left_px + view.width_px:] = False  # the legend's scan point
    south = view.pixel(0.0, -2.0)[0]  # below: the cart, 4.1 m off at 10 s, scanned where it is then
    cart_rows, cart_columns = np.nonzero(red[south:])
    assert len(cart_rows) > 10
    top, left = view.pixel(0.65, -3.65)
    bottom, right = view.pixel(1.35, -4.35)
    assert np.all((cart_rows + south >= top) & (cart_rows + south <= bottom) & (cart_columns >= left) & (cart_columns <= right))
    rows, columns = np.nonzero(red[:south])  # the wall is 6 m off, past the URG's 5.6 m: only the face
    assert len(rows) > 50 and np.all(np.abs(columns - column) <= 4), (len(rows), columns.min(), columns.max(), column)
    assert np.ptp(rows) == pytest.approx(view.pixel(2.5, -0.5)[0] - view.pixel(2.5, 0.5)[0], abs=8)


def test_smoke_follows_the_time_asked_and_the_scale(scene_path: Path, tmp_path: Path) -> None:
    scene = load_scene(scene_path)
    early = tmp_path / "early.png"
    view = draw_map(scene, 0.0, early, width_px=800, height_px=600)
    image = matplotlib.image.imread(early)
    np.testing.assert_allclose(rgb_at(image, view.pixel(-3.0, 3.0)), [1.0, 1.0, 1.0], atol=0.01)  # density 0 at 0 s
    assert not near(image, SCAN_RGB, 0.1).any()  # no --sensor, no scan (nor its legend entry)
    halfway = tmp_path / "halfway.png"
    view = draw_map(scene, 5.0, halfway, width_px=800, height_px=600)
    np.testing.assert_allclose(rgb_at(matplotlib.image.imread(halfway), view.pixel(-3.0, 3.0)),
                               blend(SMOKE_RGB, MAX_SMOKE_ALPHA / 2), atol=0.02)
    clear = tmp_path / "clear.png"
    view = draw_map(scale_smoke(scene, 0.0), 10.0, clear, width_px=800, height_px=600)
    image = matplotlib.image.imread(clear)
    for where in ((-3.0, 3.0), (-3.0, -3.0)):
        np.testing.assert_allclose(rgb_at(image, view.pixel(*where)), [1.0, 1.0, 1.0], atol=0.01)


def test_a_body_shows_its_trajectory_and_carries_its_solid(scene_path: Path, tmp_path: Path) -> None:
    scene = load_scene(scene_path)
    corner = (0.25, 0.25)  # off the body's centre, where its dot is drawn
    for time_s, here, gone in ((0.0, (-1.0, -4.0), (1.0, -4.0)), (10.0, (1.0, -4.0), (-1.0, -4.0))):
        out = tmp_path / f"body-{time_s:g}.png"
        view = draw_map(scene, time_s, out, width_px=800, height_px=600)
        image = matplotlib.image.imread(out)
        np.testing.assert_allclose(rgb_at(image, view.pixel(here[0] + corner[0], here[1] + corner[1])),
                                   [solid_grey(1.0)] * 3, atol=0.02)
        np.testing.assert_allclose(rgb_at(image, view.pixel(gone[0] + corner[0], gone[1] + corner[1])),
                                   [1.0, 1.0, 1.0], atol=0.01)
        np.testing.assert_allclose(rgb_at(image, view.pixel(*here)), TRAJECTORY_RGB, atol=0.05)  # the body's dot
        np.testing.assert_allclose(rgb_at(image, view.pixel(0.0, -4.0)), TRAJECTORY_RGB, atol=0.05)  # its path


def test_plot_map_command(scene_path: Path, tmp_path: Path) -> None:
    out = tmp_path / "cli.png"
    result = subprocess.run([*CLI, "plot", str(scene_path), "--map", "--time", "10", "--sensor", "urg",
                             "--out", str(out), "--width", "640", "--height", "480"],
                            capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    image = matplotlib.image.imread(out)
    assert image.shape[:2] == (480, 640)
    assert near(image, SCAN_RGB, 0.1).sum() > 100
    assert near(image, blend(SMOKE_RGB, MAX_SMOKE_ALPHA), 0.03).sum() > 1000


@pytest.mark.parametrize(("args", "message"), [
    (["--sensor", "nope"], "--sensor: no sensor named 'nope'"),
    (["--time", "-1"], "argument --time: must be a time in 0..1e+07 s"),
    (["--smoke-scale", "-2"], "--smoke-scale must be between 0 and"),
])
def test_plot_map_refuses_bad_options_in_one_line(scene_path: Path, tmp_path: Path, args: list[str], message: str) -> None:
    result = subprocess.run([*CLI, "plot", str(scene_path), "--map", "--out", str(tmp_path / "x.png"), *args],
                            capture_output=True, text=True, timeout=60)
    assert result.returncode == 2
    assert message in result.stderr and len(result.stderr.strip().splitlines()) == 1, result.stderr
    assert not (tmp_path / "x.png").exists()


def test_the_map_has_axes_in_metres_and_a_legend_of_what_it_draws(scene_path: Path, tmp_path: Path) -> None:
    scene = load_scene(scene_path)
    out = tmp_path / "map.svg"
    with matplotlib.rc_context({"svg.fonttype": "none"}):  # text kept as text, to be read back
        draw_map(scene, 10.0, out, sensor="urg", width_px=800, height_px=600)
    svg = out.read_text()
    for label in ("x (m)", "y (m)", "solids", "smoke density (darkest: 0.01)", "plume particles",
                  "trajectories", "scan points of urg", "error codes"):
        assert f">{label}" in svg, label
    for tick in ("\u22124", "0", "2"):  # metres along the axes (matplotlib writes a true minus sign)
        assert f">{tick}<" in svg, tick
    png = tmp_path / "map.png"
    view = draw_map(scene, 10.0, png, sensor="urg", width_px=800, height_px=600)
    legend = matplotlib.image.imread(png)[:, view.left_px + view.width_px:]
    for colour in (blend(SMOKE_RGB, MAX_SMOKE_ALPHA), blend(PLUME_RGB, PLUME_ALPHA), TRAJECTORY_RGB, SCAN_RGB,
                   ERROR_CODE_RGB, [solid_grey(2.0)] * 3):
        assert near(legend, colour, 0.03).any(), colour


ERROR_SCENE = """\
[[objects]]
name = "post behind the smoke"
box = { size = [0.4, 0.4, 2.0] }
position = [3.0, 3.0, 1.0]

[[objects]]
name = "pillar in clear air"
box = { size = [0.4, 0.4, 2.0] }
position = [3.0, -1.0, 1.0]

[[smoke.regions]]
name = "block"
box = { size = [1.0, 1.0, 2.0] }
position = [1.5, 1.5, 1.0]
density = 0.01

[[sensors]]
name = "urg"
model = "urg-04lx"
position = [0.0, 0.0, 0.3]
"""


def test_error_codes_are_ticks_towards_the_beams_that_returned_them(tmp_path: Path) -> None:
    """The beams to the post cross 1.4 m of smoke at 0.01 d: error codes, drawn as ticks
    pointing their way; those to the pillar measure it, those south meet nothing within
    range (no return: not an error)."""
    path = tmp_path / "errors.toml"
    path.write_text(ERROR_SCENE)
    out = tmp_path / "map.png"
    view = draw_map(load_scene(path), 0.0, out, sensor="urg", width_px=800, height_px=600)
    image = matplotlib.image.imread(out)
    radius = 0.045 * (view.x_range[1] - view.x_range[0])
    for degrees, failed in ((45.0, True), (-18.4, False), (-90.0, False)):
        x, y = radius * np.cos(np.radians(degrees)), radius * np.sin(np.radians(degrees))
        row, column = view.pixel(x, y)
        assert near(image[row - 2:row + 3, column - 2:column + 3], ERROR_CODE_RGB, 0.1).any() == failed, degrees
