"""MRPT's rawlog-grabber (Debian mrpt-apps, unmodified) recording from the daemon's ptys.

rawlog-grabber runs one driver thread per INI section until a key arrives on
its stdin (os::kbhit), then writes the rest of the log and exits 0; we send
that key through a pipe once it reports enough saved scans. `rawlog-edit --export-2d-scans-txt` turns the
.rawlog into one text line per scan: time, N ranges (m), N validity flags. Both
tools are driven by emulator/bench/mrpt.py, which the SLAM pipeline shares.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from support.interop import scan_values, urg_step_values
from support.ports import free_tcp_port

from emulator.bench import mrpt
from emulator.scene import load_scene
from emulator.sensors import create_sensor
from emulator.bench.lms_rates import line_rate_limit

def grab(folder: Path, section: str, scans: int, timeout_s: float, *, kill: bool = False) -> mrpt.Grabbed:
    """rawlog-grabber with one sensor section until it has saved `scans` observations or
    `timeout_s` passed, then a key press (or SIGKILL)."""
    return mrpt.grab(folder, section, until=lambda saved: saved >= scans, timeout_s=timeout_s, kill=kill)


def exported_scans(folder: Path, label: str, grabbed: mrpt.Grabbed):
    """(times, ranges_m, valid) of the recorded scans, via rawlog-edit."""
    assert grabbed.returncode == 0 and grabbed.rawlog is not None, grabbed.output[-3000:]
    scans = grabbed.scans(label)
    return scans.times_s, scans.ranges_m, scans.valid


def urg_section(link: str, port: int) -> str:
    where = f"IP_DIR = 127.0.0.1\nPORT_DIR = {port}\n" if link == "tcp" else f"COM_port_LIN = {port}\n"
    return "[URG]\ndriver = CHokuyoURG\nprocess_rate = 90\nsensorLabel = URG\n" + where


def serve_urg(serve, scene: Path, folder: Path, link: str) -> str | int:
    """The daemon with the URG on `link`; what rawlog-grabber connects to (pty path or port)."""
    if link == "tcp":
        port = free_tcp_port()
        serve(scene, f"urg=tcp:127.0.0.1:{port}")
        return port
    return serve(scene, f"urg=pty:{folder / 'ttyURG0'}").endpoint("urg", "pty").path


@pytest.mark.parametrize("link", ["pty", "tcp"])
def test_chokuyourg(serve, urg_room: Path, tmp_path: Path, link: str) -> None:
    section = urg_section(link, serve_urg(serve, urg_room, tmp_path, link))
    times, ranges, valid = exported_scans(tmp_path, "URG", grab(tmp_path, section, scans=25, timeout_s=20))
    assert len(times) >= 20
    assert ranges.shape[1] == 682
    period = np.median(np.diff(times))
    assert 0.09 <= period <= 0.11, np.diff(times)
    expected = urg_step_values(urg_room, 1.0)
    np.testing.assert_array_equal(np.rint(ranges * 1000).astype(int), np.tile(expected, (len(times), 1)))
    np.testing.assert_array_equal(valid[0] == 1, expected >= 20)


def test_chokuyourg_after_a_driver_killed_mid_stream(serve, urg_room: Path, tmp_path: Path) -> None:
    section = urg_section("pty", serve_urg(serve, urg_room, tmp_path, "pty"))
    killed = grab(tmp_path / "killed", section, scans=5, timeout_s=20, kill=True)
    assert "Saved" in killed.output, killed.output[-3000:]
    times, _, _ = exported_scans(tmp_path / "next", "URG", grab(tmp_path / "next", section, scans=25, timeout_s=20))
    assert len(times) >= 20


def lms_section(port: str, baud: int) -> str:
    return (
        "[LMS]\ndriver = CSickLaserSerial\nprocess_rate = 90\nsensorLabel = LMS\n"
        f"COM_port_LIN = {port}\nCOM_baudRate = {baud}\nFOV = 180\nresolution = 50\nmm_mode = 0\n"
    )


@pytest.mark.parametrize(("baud", "timeout_s"), [(38400, 30.0), (500000, 20.0)])
def test_csicklaserserial_over_pty(serve, lms_room: Path, tmp_path: Path, baud: int, timeout_s: float) -> None:
    daemon = serve(lms_room, f"lms=pty:{tmp_path / 'ttyLMS0'}")
    section = lms_section(daemon.endpoint("lms", "pty").path, baud)
    times, ranges, _ = exported_scans(tmp_path, "LMS", grab(tmp_path, section, scans=25, timeout_s=timeout_s))
    assert len(times) >= 20
    assert ranges.shape[1] == 361
    # Stamped on arrival: the line (38400) or the mirror (500 k, 37.5/s at 0.5°) sets the pace.
    rate = (len(times) - 1) / (times[-1] - times[0])
    assert rate == pytest.approx(line_rate_limit(baud, 0.5), rel=0.1)
    _, expected_mm = scan_values(lms_room, "lms", 1.0)
    # cm mode (mm_mode = 0): each range within 1 cm of the scene's value.
    np.testing.assert_allclose(ranges, np.tile(expected_mm / 1000.0, (len(times), 1)), atol=0.0101)


def test_csicklaserserial_after_a_driver_killed_mid_stream(serve, lms_room: Path, tmp_path: Path) -> None:
    """The device keeps 38400 when its host dies; the next driver must find it there and move it."""
    port = serve(lms_room, f"lms=pty:{tmp_path / 'ttyLMS0'}").endpoint("lms", "pty").path
    killed = grab(tmp_path / "killed", lms_section(port, 38400), scans=5, timeout_s=30, kill=True)
    assert "Saved" in killed.output, killed.output[-3000:]
    folder = tmp_path / "next"
    times, ranges, _ = exported_scans(folder, "LMS", grab(folder, lms_section(port, 500000), scans=25, timeout_s=40))
    assert len(times) >= 20 and ranges.shape[1] == 361
    assert (len(times) - 1) / (times[-1] - times[0]) == pytest.approx(37.5, rel=0.1)  # at 500 k


def test_chokuyourg_records_a_utm_30lx_ew_over_tcp_with_intensity(serve, utm_room: Path, tmp_path: Path) -> None:
    """CHokuyoURG with `intensity = true` asks for ME (range + intensity) at the unit's 40 Hz; the
    rawlog holds the scene's ranges and the simulated intensities of all 1081 steps."""
    port = free_tcp_port()
    serve(utm_room, f"utm=tcp:127.0.0.1:{port}")
    section = f"[UTM]\ndriver = CHokuyoURG\nprocess_rate = 90\nsensorLabel = UTM\nIP_DIR = 127.0.0.1\nPORT_DIR = {port}\nintensity = true\n"
    grabbed = grab(tmp_path, section, scans=60, timeout_s=20)
    assert grabbed.returncode == 0 and grabbed.rawlog is not None, grabbed.output[-3000:]
    scans = grabbed.scans("UTM")
    assert len(scans.times_s) >= 40 and scans.ranges_m.shape[1] == 1081
    period = np.median(np.diff(scans.times_s))
    assert 0.02 <= period <= 0.03, np.diff(scans.times_s)
    _, expected = scan_values(utm_room, "utm", 1.0)
    np.testing.assert_array_equal(np.rint(scans.ranges_m * 1000).astype(int), np.tile(expected, (len(scans.times_s), 1)))
    np.testing.assert_array_equal(scans.valid[0], expected >= 23)
    assert scans.intensity is not None
    intensities = create_sensor(load_scene(utm_room), "utm").scan(1.0).intensities
    np.testing.assert_array_equal(scans.intensity, np.tile(intensities, (len(scans.times_s), 1)))
    assert np.all(intensities[expected >= 23] > 0)
