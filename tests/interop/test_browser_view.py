"""The browser view in a real browser: Debian's chromium, headless, driven by playwright.

The real `serve` process runs railway with `--view`; chromium opens the page
viser serves (its bundled client, nothing fetched from elsewhere), renders the
scene with WebGL in software, and the screenshot must show the scene and the
scans' points in their range colours (near: yellow). Then a person's move of a
density slider (keyboard on the slider's thumb) must reach the daemon through
its control API: `GET /api/state` shows the new density. A missing chromium
fails the test: it is part of the test set-up (.ci/run installs it).

The rest of the panel is tried on a room written here (no bundled scene has a
live body): a person's click on a plume's toggle, a new clock speed typed in
and the pause box clicked, and a mouse drag of a live body's gizmo must each
show in `GET /api/state`; the drag must also move the body's crate in the
scans an unmodified client (hokuyolx) reads over TCP.
"""

from __future__ import annotations

import json
import os
import shutil
import time
import urllib.request
from pathlib import Path

from typing import Any, Callable

import numpy as np
import pytest
from hokuyolx import HokuyoLX
from PIL import Image
from playwright.sync_api import Page, sync_playwright

from emulator.view.browser import GIZMO_SCALE_M, INITIAL_CAMERA

CHROMIUM_ARGS = [
    "--no-sandbox", "--disable-gpu", "--disable-background-networking", "--disable-component-update",
    "--disable-sync", "--no-first-run", "--enable-unsafe-swiftshader",
]
VIEWPORT = {"width": 1280, "height": 800}
FIGURE = Path(__file__).resolve().parents[2] / "docs" / "figures" / "view-railway.png"


def chromium() -> str:
    path = shutil.which("chromium") or shutil.which("chromium-browser")
    if path is None:
        pytest.fail("chromium is not installed (Debian: apt-get install chromium; .ci/run does it)")
    return path


def open_view(playwright, url: str, profile: Path) -> Page:
    browser = playwright.chromium.launch_persistent_context(
        str(profile), executable_path=chromium(), headless=True, args=CHROMIUM_ARGS, viewport=VIEWPORT,
    )
    page = browser.pages[0] if browser.pages else browser.new_page()
    page.goto(url)
    page.get_by_text("Connected").wait_for(timeout=30_000)
    return page


def dismiss_notifications(page: Page) -> None:
    """viser warns that WebGL runs in software (no GPU here): close it so it hides nothing."""
    for button in page.locator("button.mantine-Notification-closeButton").all():
        button.click()


def scan_colour_pixels(image: np.ndarray) -> int:
    """Pixels in the near end of the scans' range colours (yellow) within the 3D scene, leaving out
    the panel (top right) and the axes gizmo (bottom left, whose centre is yellow too)."""
    red, green, blue = (image[..., channel].astype(int) for channel in range(3))
    yellow = (red > 200) & (green > 150) & (blue < 90)
    yellow[-150:, :150] = False
    yellow[:300, -420:] = False
    return int(np.count_nonzero(yellow))


def wait_for_scan_points(page: Page, path: Path, attempts: int = 20) -> np.ndarray:
    for _ in range(attempts):
        page.wait_for_timeout(500)
        page.screenshot(path=str(path))
        image = np.asarray(Image.open(path).convert("RGB"))
        if scan_colour_pixels(image) >= 30:
            return image
    return image


def region_density(control_url: str, region: str) -> float:
    with urllib.request.urlopen(f"{control_url}/api/state", timeout=10) as response:
        return json.load(response)["regions"][region]["density"]


def wait_for_density(control_url: str, region: str, wanted: float, timeout_s: float = 30.0) -> float:
    deadline = time.monotonic() + timeout_s
    density = region_density(control_url, region)
    while abs(density - wanted) > 1e-9 and time.monotonic() < deadline:
        time.sleep(0.2)
        density = region_density(control_url, region)
    return density


def test_the_view_shows_the_scene_and_the_scans_and_its_slider_acts(serve, tmp_path: Path, tcp_port: int) -> None:
    daemon = serve("railway", f"urg=tcp:127.0.0.1:{tcp_port}", f"lms=pty:{tmp_path / 'lms'}",
                   extra_args=("--view", "127.0.0.1:0"))
    url = daemon.service("view")
    assert url.startswith("http://127.0.0.1:") and daemon.control_url is not None
    assert region_density(daemon.control_url, "car_end_smoke") == 0.0  # railway's keyframes: 0 until 5 s
    with sync_playwright() as playwright:
        page = open_view(playwright, url, tmp_path / "profile")
        dismiss_notifications(page)
        image = wait_for_scan_points(page, tmp_path / "view.png")
        # the first region's slider ("car_end_smoke", 0 .. 0.012): drag it to its end with the keyboard
        thumb = page.get_by_role("slider").first
        thumb.focus()
        thumb.press("End")
        density = wait_for_density(daemon.control_url, "car_end_smoke", 0.012)
        page.context.close()
    assert density == 0.012, "the slider did not change the region's density through the control API"
    assert scan_colour_pixels(image) >= 30, "no scan points in the screenshot"
    background = np.all(image > 235, axis=2)
    assert background.mean() < 0.5, "the scene's solids do not fill the view"
    if os.environ.get("LRF_WRITE_FIGURES"):
        FIGURE.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(tmp_path / "view.png", FIGURE)


# A URG-04LX at the origin looking along +x at a wall 4.4 m away; a crate on a
# live body stands in its beams at (3, 1), right where the view's initial camera
# looks; a plume emits off to the side.
PANEL_ROOM = """\
[scene]
name = "view panel room"
seed = 7
model = "formsma2011"

[[objects]]
name = "front wall"
box = { size = [0.2, 10.0, 3.0] }
position = [4.5, 0.0, 1.5]

[[bodies]]
name = "robot"
position = [3.0, 1.0, 0.0]
trajectory = "live"

[[objects]]
name = "crate"
body = "robot"
box = { size = [0.4, 0.4, 1.0] }
position = [0.0, 0.0, 0.5]

[[smoke.plumes]]
name = "fire"
source = [1.5, -1.5, 0.3]
rate = 8.0
lifetime = 4.0
size = 0.3
growth = 0.05
velocity = [0.0, 0.0, 0.1]
density = 1.0

[[sensors]]
name = "urg"
model = "urg-04lx"
position = [0.0, 0.0, 0.3]
"""
CAMERA_FOV_DEG = 75.0  # viser's initial vertical field of view
HOVER = "the gizmo handle under the mouse turns yellow"


def state(control_url: str) -> dict[str, Any]:
    with urllib.request.urlopen(f"{control_url}/api/state", timeout=10) as response:
        return json.load(response)


def wait_for_state(control_url: str, done: Callable[[dict[str, Any]], bool], timeout_s: float = 30.0) -> dict[str, Any]:
    """The daemon's state once `done` holds (or the last one seen when the time is up)."""
    deadline = time.monotonic() + timeout_s
    seen = state(control_url)
    while not done(seen) and time.monotonic() < deadline:
        time.sleep(0.2)
        seen = state(control_url)
    return seen


@pytest.fixture
def panel_view(serve, tmp_path: Path, tcp_port: int):
    """(daemon, page): the panel room served with the view, open in headless chromium."""
    room = tmp_path / "panel-room.toml"
    room.write_text(PANEL_ROOM)
    daemon = serve(room, f"urg=tcp:127.0.0.1:{tcp_port}", extra_args=("--view", "127.0.0.1:0"))
    with sync_playwright() as playwright:
        page = open_view(playwright, daemon.service("view"), tmp_path / "profile")
        dismiss_notifications(page)
        yield daemon, page
        page.context.close()


def test_the_plume_toggle_switches_the_plume_through_the_control_api(panel_view) -> None:
    daemon, page = panel_view
    assert state(daemon.control_url)["plumes"]["fire"]["emitting"] is True
    page.get_by_label("fire emitting").click()
    seen = wait_for_state(daemon.control_url, lambda now: now["plumes"]["fire"]["emitting"] is False)
    assert seen["plumes"]["fire"]["emitting"] is False, "the toggle did not stop the plume"
    page.get_by_label("fire emitting").click()
    seen = wait_for_state(daemon.control_url, lambda now: now["plumes"]["fire"]["emitting"] is True)
    assert seen["plumes"]["fire"]["emitting"] is True, "the toggle did not restart the plume"


def test_the_clock_panel_sets_the_speed_and_pauses(panel_view) -> None:
    daemon, page = panel_view
    before = state(daemon.control_url)
    assert before["speed"] == 1.0 and before["paused"] is False
    speed = page.get_by_label("speed")
    speed.fill("2.5")
    speed.press("Enter")
    seen = wait_for_state(daemon.control_url, lambda now: now["speed"] == 2.5)
    assert seen["speed"] == 2.5, "typing a speed did not change the clock's speed"
    page.get_by_label("paused").click()
    seen = wait_for_state(daemon.control_url, lambda now: now["paused"] is True)
    assert seen["paused"] is True, "the pause box did not pause the clock"
    time.sleep(0.5)
    assert state(daemon.control_url)["time_s"] == seen["time_s"], "a paused clock moved"


def screen_point(world: tuple[float, float, float], width: int = VIEWPORT["width"], height: int = VIEWPORT["height"]) -> tuple[float, float]:
    """Where a world point shows on the page: a pinhole projection from the view's initial camera."""
    eye, target = (np.asarray(point, dtype=float) for point in INITIAL_CAMERA)
    forward = (target - eye) / np.linalg.norm(target - eye)
    right = np.cross(forward, (0.0, 0.0, 1.0))
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    offset = np.asarray(world, dtype=float) - eye
    depth, half_height = offset @ forward, np.tan(np.radians(CAMERA_FOV_DEG) / 2)
    x = offset @ right / (depth * half_height * width / height)
    y = offset @ up / (depth * half_height)
    return (x + 1) / 2 * width, (1 - y) / 2 * height


def drag(page: Page, start: tuple[float, float], end: tuple[float, float], steps: int = 12) -> None:
    page.mouse.move(*start)
    page.mouse.down()
    for step in range(1, steps + 1):
        page.mouse.move(start[0] + (end[0] - start[0]) * step / steps, start[1] + (end[1] - start[1]) * step / steps)
        page.wait_for_timeout(40)
    page.mouse.up()


def urg_range_mm(laser: HokuyoLX, bearing_deg: float) -> int:
    """The range hokuyolx reads on the step nearest `bearing_deg` (its array starts at step 44)."""
    _, values = laser.get_dist()
    return int(values[round(384 + bearing_deg / (360 / 1024)) - 44])


def test_dragging_a_live_bodys_gizmo_moves_the_body_and_the_scans(panel_view, tmp_path: Path) -> None:
    daemon, page = panel_view
    laser = HokuyoLX(addr=daemon.endpoint("urg", "tcp").address, tsync=False, convert_time=False)
    old_bearing, new_bearing = np.degrees(np.arctan2(1.0, 3.0)), np.degrees(np.arctan2(1.0, 2.0))
    assert 2900 < urg_range_mm(laser, old_bearing) < 3000  # the crate's face at x = 2.8
    # The gizmo's x-z plane handle (its square between the x and z arrows, drawn on top of the crate)
    # is dragged 1 m towards -x: the body must land at (2, 1, 0).
    handle = 0.2554 * GIZMO_SCALE_M  # the square's centre along x and z (drei's PivotControls layout)
    grab, release = screen_point((3.0 + handle, 1.0, handle)), screen_point((2.0 + handle, 1.0, handle))
    page.wait_for_timeout(1000)  # the first frames (software WebGL)
    page.mouse.move(*grab)
    page.wait_for_timeout(500)
    page.screenshot(path=str(tmp_path / "hover.png"))
    red, green, blue = np.asarray(Image.open(tmp_path / "hover.png").convert("RGB"))[round(grab[1]), round(grab[0])].astype(int)
    assert red > 200 and green > 200 and blue < 160, f"no gizmo handle at {grab}: {HOVER} (pixel {red, green, blue})"
    drag(page, grab, release)
    seen = wait_for_state(daemon.control_url, lambda now: abs(now["bodies"]["robot"]["position"][0] - 3.0) > 0.5)
    position = seen["bodies"]["robot"]["position"]
    assert position == pytest.approx([2.0, 1.0, 0.0], abs=0.05), f"the drag did not move the body: {position}"
    deadline = time.monotonic() + 30.0
    while (old := urg_range_mm(laser, old_bearing)) < 4500 and time.monotonic() < deadline:
        pass
    new = urg_range_mm(laser, new_bearing)
    laser.close()
    assert old > 4500, f"the crate still stands in the old beam ({old} mm)"  # the wall behind, 4.64 m
    assert 1950 < new < 2100, f"the crate is not in the new beam ({new} mm)"  # its face at x = 1.8
