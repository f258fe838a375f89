"""The seed dataset's log format, `record`, and the log-backed replay sensors."""

from __future__ import annotations

import io
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from emulator.bench.serve_load import fleet_scene_text
from emulator.errors import UserError
from emulator.recording.replay_sources import HokuyoReplay, LmsReplay, replay_sensor
from emulator.recording.textlog import LogHeader, format_scan, read_log, write_log
from emulator.scene import load_scene
from emulator.sensors import create_sensor
from emulator.sensors.scan import Scan
from emulator.sensors.series import scan_times
from emulator.sensors.urg04lx import revolution_phase_ms

CLI = [sys.executable, "-m", "emulator.cli"]


def run_cli(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([*CLI, *args], capture_output=True, text=True, timeout=120)


def urg_scan(time_s: float, values: np.ndarray) -> Scan:
    angles = (np.arange(769) - 384) * 2 * np.pi / 1024
    return Scan("urg", "urg-04lx", time_s, angles, values, "mm")


def test_log_line_is_timestamp_then_angle_value_pairs() -> None:
    scan = urg_scan(12.3, np.arange(769))
    words = format_scan(scan).split()
    assert words[0] == "12.300"
    assert len(words) == 1 + 2 * 769
    assert float(words[1 + 2 * 384]) == 0.0 and words[2 + 2 * 384] == "384"
    assert float(words[1]) == pytest.approx(-384 * 2 * np.pi / 1024, abs=1e-6)


def test_written_log_reads_back_exactly_and_rewrites_byte_for_byte(tmp_path: Path) -> None:
    rng = np.random.default_rng(5)
    scans = [urg_scan(0.1 * k, rng.integers(0, 5600, 769)) for k in range(1, 6)]
    path = tmp_path / "run.log"
    with path.open("w") as out:
        assert write_log(out, scans, LogHeader("urg", "urg-04lx", "mm")) == 5
    log = read_log(path)
    assert log.header == LogHeader("urg", "urg-04lx", "mm")
    assert np.array_equal(log.values, np.vstack([s.values for s in scans]))
    assert np.allclose(log.angles_rad, scans[0].angles_rad, atol=5e-7)
    assert [s.timestamp_ms for s in log.scans()] == [100, 200, 300, 400, 500]
    again = io.StringIO()
    write_log(again, log.scans(), log.header)
    assert again.getvalue() == path.read_text()


def test_reader_tolerates_comments_and_blank_lines(tmp_path: Path) -> None:
    path = tmp_path / "real.log"
    path.write_text("# a real sensor's log\n\n1.000 -0.5 1200 0.0 15 0.5 3000\n# note\n2.000 -0.5 1210 0.0 1 0.5 3001\n")
    log = read_log(path)
    assert log.header == LogHeader()
    assert log.values.tolist() == [[1200, 15, 3000], [1210, 1, 3001]]
    assert log.times_s.tolist() == [1.0, 2.0]


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("1.0 0.0\n", "line 1: expected a timestamp and (angle, distance) pairs"),
        ("1.0 0.0 12 0.1\n", "line 1: expected a timestamp and (angle, distance) pairs"),
        ("1.0 0.0 abc\n", "line 1: not a list of numbers"),
        ("1.0 0.0 12\n2.0 0.0 12 0.1 13\n", "line 2: 2 pairs, the first scan has 1"),
        ("1.0 0.0 12.5\n", "line 1: distances must be whole device values, 0..4294967295"),
        ("1.0 0.0 12\n2.0 0.0 1e300\n", "line 2: distances must be whole device values, 0..4294967295"),  # a numpy overflow warning
        ("2.0 0.0 12\n\n1.0 0.0 12\n", "line 3: timestamps must increase"),
        ("# only a comment\n", "no scans in log"),
    ],
)
def test_malformed_log_names_file_and_line(tmp_path: Path, text: str, message: str) -> None:
    path = tmp_path / "bad.log"
    path.write_text(text)
    with pytest.raises(UserError) as caught:
        read_log(path)
    assert str(caught.value) == f"bad.log: {message}"


def test_record_writes_the_sensors_scans_at_its_period(tmp_path: Path) -> None:
    out = tmp_path / "bocas.log"
    result = run_cli("record", "bocas", "--sensor", "urg", "--start", "70.05", "--end", "73", "--out", str(out))
    assert result.returncode == 0, result.stderr
    log = read_log(out)
    assert log.header == LogHeader("urg", "urg-04lx", "mm")
    expected_times = np.arange(701, 731) / 10
    assert np.allclose(log.times_s, expected_times)
    sensor = create_sensor(load_scene("bocas"), "urg")
    assert log.values.shape[1] == 682  # the measured steps 44..725
    assert log.angles_rad[0, 0] == pytest.approx(round((44 - 384) * 2 * np.pi / 1024, 6))
    for time_s, values in zip(expected_times, log.values):
        assert np.array_equal(values, sensor.scan(float(time_s)).values[44:726])
    assert len(set(log.values[:, 384 - 44].tolist())) == 2  # the onset (range → error 1) is inside this window


def test_record_takes_a_scenes_later_urgs_at_their_revolution_phase(tmp_path: Path) -> None:
    """The 2nd of 3 URGs turns 33 ms behind the 1st: `record` takes its scans where `serve` sends them."""
    scene = tmp_path / "three.toml"
    scene.write_text(fleet_scene_text(3))
    assert [revolution_phase_ms(load_scene(scene), name) for name in ("urg00", "urg01", "urg02")] == [0, 33, 66]
    out = tmp_path / "urg01.log"
    result = run_cli("record", str(scene), "--sensor", "urg01", "--start", "1.0", "--end", "1.5", "--out", str(out))
    assert result.returncode == 0, result.stderr
    assert np.round(read_log(out).times_s, 6).tolist() == [1.033, 1.133, 1.233, 1.333, 1.433]
    assert scan_times(0.1, 0.0, 0.2, 0.066).tolist() == [0.066, 0.166]


def test_record_lms_uses_the_scenes_window_and_two_revolutions_per_half_degree_scan(tmp_path: Path) -> None:
    out = tmp_path / "marulan.log"
    result = run_cli("record", "marulan", "--sensor", "lms", "--start", "80", "--end", "81", "--out", str(out))
    assert result.returncode == 0, result.stderr
    log = read_log(out)
    assert log.values.shape[1] == 361
    assert np.allclose(np.diff(log.times_s), 2 / 75, atol=1.001e-3)  # stamps keep whole milliseconds
    assert np.degrees(log.angles_rad[0, 0]) == pytest.approx(-90.0, abs=1e-4)
    sensor = create_sensor(load_scene("marulan"), "lms")
    k = int(np.ceil(80 * 75 / 2))
    assert np.array_equal(log.values[0], sensor.scan(k * 2 / 75).values)


def test_record_model_override_changes_the_response(tmp_path: Path) -> None:
    logs = {}
    for model in ("formsma2011", "physical"):
        out = tmp_path / f"{model}.log"
        result = run_cli("record", "marulan", "--sensor", "lms", "--start", "80", "--end", "80.1",
                         "--model", model, "--out", str(out))
        assert result.returncode == 0, result.stderr
        logs[model] = read_log(out).values
    expected = [create_sensor(load_scene("marulan"), "lms").scan(k * 2 / 75).values for k in range(3000, 3004)]
    assert np.array_equal(logs["formsma2011"], np.vstack(expected))
    assert not np.array_equal(logs["physical"], logs["formsma2011"])


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["record", "bocas", "--sensor", "nope", "--end", "1", "--out", "x.log"], "no sensor named 'nope'"),
        (["record", "bocas", "--sensor", "urg", "--start", "5", "--end", "1", "--out", "x.log"], "need 0 <= --start <= --end"),
        (["replay", "missing.log", "--device", "urg-04lx"], "no such log file"),
        (["record", "bocas", "--sensor", "urg", "--end", "1", "--model", "bogus", "--out", "x.log"],
         "unknown smoke model 'bogus'"),
    ],
)
def test_cli_errors_are_one_line_without_traceback(tmp_path: Path, args: list[str], message: str) -> None:
    result = subprocess.run([*CLI, *args], capture_output=True, text=True, timeout=60, cwd=tmp_path)
    assert result.returncode == 2
    assert message in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1
    assert "Traceback" not in result.stderr


def test_urg_replay_serves_the_row_recorded_at_or_before_t_and_loops(tmp_path: Path) -> None:
    scans = [urg_scan(5.0 + 0.1 * k, np.full(769, 100 + k)) for k in range(10)]
    path = tmp_path / "urg.log"
    with path.open("w") as out:
        write_log(out, scans, LogHeader("urg", "urg-04lx", "mm"))
    replay = HokuyoReplay(read_log(path))
    for k in range(25):
        scan = replay.scan(k * 0.1)
        assert scan.time_s == k * 0.1
        assert np.all(scan.values == 100 + k % 10)  # 10 rows, then it starts over
    assert replay.scan(0.15).values[0] == 101


def test_urg_replay_places_a_partial_log_on_its_steps(tmp_path: Path) -> None:
    path = tmp_path / "partial.log"
    steps = np.arange(44, 726)
    angles = (steps - 384) * 2 * np.pi / 1024
    pairs = " ".join(f"{a:.6f} {s}" for a, s in zip(angles, steps))
    path.write_text(f"0.000 {pairs}\n")
    values = HokuyoReplay(read_log(path)).scan(0.0).values
    assert values[44:726].tolist() == steps.tolist()
    assert np.all(values[:44] == 0) and np.all(values[726:] == 0)


def test_lms_replay_serves_any_window_and_converts_units(tmp_path: Path) -> None:
    degrees = np.arange(361) * 0.5
    values = np.where(np.arange(361) % 7 == 0, 8191, 1000 + np.arange(361))
    scan = Scan("lms", "lms200", 0.0, np.radians(degrees - 90.0), values, "mm")
    path = tmp_path / "lms.log"
    with path.open("w") as out:
        write_log(out, [scan], LogHeader("lms", "lms200", "mm"))
    replay = replay_sensor(read_log(path), "lms200", "lms")
    assert isinstance(replay, LmsReplay)
    assert np.array_equal(replay.scan(3.0).values, values)
    one_degree = replay.scan(0.0, start_deg=40.0, step_deg=1.0, count=101)
    assert np.array_equal(one_degree.values, values[80:281:2])
    in_cm = replay.scan(0.0, unit="cm")
    expected_cm = np.where(values == 8191, 8191, np.round(values / 10))
    assert np.array_equal(in_cm.values, expected_cm)
    quarter = replay.scan(0.0, start_deg=40.0, step_deg=0.25, count=401)
    assert np.all(quarter.values[1::2] == 8191)  # x.25° and x.75° were never recorded
    assert np.array_equal(quarter.values[::2], values[80:281])


@pytest.mark.parametrize(("model", "value", "most"), [("urg-04lx", 262144, 262143), ("lms200", 8192, 8191), ("tim571", 65536, 65535)])
def test_replay_refuses_a_value_the_units_wire_cannot_carry(tmp_path: Path, model: str, value: int, most: int) -> None:
    """A URG-04LX replaying 99999999 sent 262143 without a word (its 3-character field's most)."""
    path = tmp_path / "any.log"
    path.write_text("1.0 -0.006136 1200 0.0 15 0.006136 3000\n" f"2.0 -0.006136 1200 0.0 {value} 0.006136 3000\n")
    with pytest.raises(UserError) as caught:
        replay_sensor(read_log(path), model, "x")
    assert str(caught.value) == f"the log's scan at 2 s holds the value {value}; a {model} sends at most {most}"
    path.write_text(f"1.0 -0.006136 1200 0.0 {most} 0.006136 3000\n")
    replay_sensor(read_log(path), model, "x")


def test_replay_refuses_a_log_of_the_other_model(tmp_path: Path) -> None:
    path = tmp_path / "urg.log"
    with path.open("w") as out:
        write_log(out, [urg_scan(0.0, np.zeros(769, dtype=int))], LogHeader("urg", "urg-04lx", "mm"))
    with pytest.raises(UserError, match="recorded from a urg-04lx, not a lms200"):
        replay_sensor(read_log(path), "lms200", "lms")


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--device", "lms200"], "the log was recorded from a urg-04lx, not a lms200"),
        (["--device", "urg-04lx", "--endpoint", "bogus:x"], "endpoint 'bogus:x': expected pty:PATH, tcp:HOST:PORT or rfc2217:HOST:PORT with PORT 0..65535"),
    ],
)
def test_replay_errors_are_one_line(tmp_path: Path, args: list[str], message: str) -> None:
    path = tmp_path / "urg.log"
    with path.open("w") as out:
        write_log(out, [urg_scan(0.0, np.zeros(769, dtype=int))], LogHeader("urg", "urg-04lx", "mm"))
    result = subprocess.run([*CLI, "replay", str(path), *args], capture_output=True, text=True, timeout=60, cwd=tmp_path)
    assert result.returncode == 2
    assert result.stderr.strip() == f"lrf-emulator replay: {message}"
