"""The browser view in a real browser: Debian's chromium, headless, driven by playwright.

The real `serve` process runs railway with `--view`; chromium opens the page
viser serves (its bundled client, nothing fetched from elsewhere), renders the
scene with WebGL in software, and the screenshot must show the scene and the
scans' points in their range colours (near: yellow). Then a person's move of a
density slider (keyboard on the slider's thumb) must reach the daemon through
its control API: `GET /api/state` shows the new density. A missing chromium
fails the test: it is part of the test set-up (.ci/run installs it).
"""

from __future__ import annotations

import json
import os
import shutil
import time
import urllib.request
from pathlib import Path

import numpy as np
import pytest
from PIL import Image
from playwright.sync_api import Page, sync_playwright

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
