"""The real `lrf-emulator serve` process: ready lines, signals, a URG client over the
pty, several sensors in one process, user errors."""

from __future__ import annotations

import os
import select
import signal
import socket
import subprocess
import time
from pathlib import Path

import pytest
import serial
from support.ports import free_tcp_port

from emulator.bench.serve_process import ServeProcess, parse_ready_line, serve_command
from emulator.errors import UserError
from emulator.scene import load_scene
from emulator.scene.endpoints import plan_endpoints
from protocols.lms2xx import build_telegram

MD_FULL = b"MD0044072501000"  # urg_library: steps 44..725, cluster 1, every scan, unlimited


def scip_checksum(payload: bytes) -> int:
    return (sum(payload) & 0x3F) + 0x30


def read_message(port: serial.Serial, timeout: float = 2.0) -> bytes:
    """One SCIP message: everything up to and including its empty line."""
    port.timeout = timeout
    message = port.read_until(b"\n\n")
    assert message.endswith(b"\n\n"), f"incomplete message: {message!r}"
    return message


def decode_md_scan(message: bytes) -> tuple[int, list[int]]:
    """(timestamp ms, values) of one MD scan message, every checksum verified."""
    lines = message.split(b"\n")[:-2]
    assert lines[0] == MD_FULL and lines[1] == b"99b"
    for line in lines[2:]:
        assert line[-1] == scip_checksum(line[:-1]), f"bad checksum: {line!r}"
    stamp = 0
    for char in lines[2][:-1]:
        stamp = (stamp << 6) | (char - 0x30)
    data = b"".join(line[:-1] for line in lines[3:])
    values = [
        ((data[i] - 0x30) << 12) | ((data[i + 1] - 0x30) << 6) | (data[i + 2] - 0x30) for i in range(0, len(data), 3)
    ]
    return stamp, values


def run_serve(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    """`serve` with its control API and view off, so a daemon already on their default ports
    (a user's, another test's) cannot change which error a test sees."""
    return subprocess.run(
        [*serve_command(), "serve", *args, "--control", "off", "--view", "off"],
        cwd=cwd, capture_output=True, text=True, timeout=60,
    )


def test_ready_lines_then_sigterm_exits_0_and_removes_symlinks(tmp_path: Path) -> None:
    urg_link, lms_link = tmp_path / "ttyURG0", tmp_path / "ttyLMS0"
    daemon = ServeProcess(
        "railway", [f"urg=pty:{urg_link}", "urg=tcp:127.0.0.1:0", f"lms=pty:{lms_link}"], cwd=tmp_path
    )
    assert [(r.sensor, r.model, r.uri.split(":")[0]) for r in daemon.ready] == [
        ("urg", "urg-04lx", "pty"),
        ("urg", "urg-04lx", "tcp"),
        ("lms", "lms200", "pty"),
    ]
    assert daemon.endpoint("urg", "pty").device == os.readlink(urg_link)
    assert daemon.endpoint("lms", "pty").device == os.readlink(lms_link)
    host, port = daemon.endpoint("urg", "tcp").address
    assert host == "127.0.0.1" and port > 0
    assert daemon.stop() == 0
    assert not os.path.lexists(urg_link) and not os.path.lexists(lms_link)
    assert "Traceback" not in daemon.stderr


def test_sigint_exits_0_too(tmp_path: Path) -> None:
    daemon = ServeProcess("railway", [f"urg=pty:{tmp_path / 'u'}", f"lms=pty:{tmp_path / 'l'}"])
    daemon.process.send_signal(signal.SIGINT)
    assert daemon.process.wait(10) == 0
    assert not os.path.lexists(tmp_path / "u")


def test_urg_library_open_sequence_over_the_pty(tmp_path: Path) -> None:
    link = tmp_path / "ttyURG0"
    with ServeProcess("railway", [f"urg=pty:{link}", f"lms=pty:{tmp_path / 'l'}"]) as _daemon:
        port = serial.Serial(str(link), baudrate=115200, timeout=1)
        port.write(b"\n")
        port.write(b"QT\n")
        assert read_message(port) == b"QT\n00P\n\n"
        for command in (b"PP", b"VV", b"II"):
            port.write(command + b"\n")
            assert read_message(port).startswith(command + b"\n00P\n")
        port.write(MD_FULL + b"\n")
        assert read_message(port) == MD_FULL + b"\n00P\n\n"
        scans = [decode_md_scan(read_message(port)) for _ in range(4)]
        assert all(len(values) == 682 for _, values in scans)
        stamps = [stamp for stamp, _ in scans]
        assert all(95 <= later - earlier <= 105 for earlier, later in zip(stamps, stamps[1:]))
        port.write(b"QT\n")
        tail = port.read_until(b"QT\n00P\n\n")
        assert tail.endswith(b"QT\n00P\n\n")
        port.timeout = 0.3
        assert port.read(100000) == b"", "still streaming after QT"
        port.close()


def test_speed_scales_the_scan_period(tmp_path: Path) -> None:
    with ServeProcess(
        "railway", ["urg=tcp:127.0.0.1:0", f"lms=pty:{tmp_path / 'l'}"], extra_args=["--speed", "2"]
    ) as daemon:
        with socket.create_connection(daemon.endpoint("urg", "tcp").address, timeout=2) as client:
            client.sendall(MD_FULL + b"\n")
            buffer, arrivals, stamps = b"", [], []
            while len(arrivals) < 12:
                buffer += client.recv(65536)
                while b"\n\n" in buffer:
                    message, buffer = buffer.split(b"\n\n", 1)
                    if b"\n99b\n" in message + b"\n":
                        arrivals.append(time.monotonic())
                        stamps.append(decode_md_scan(message + b"\n\n")[0])
    wall_period = (arrivals[-1] - arrivals[1]) / (len(arrivals) - 2)
    assert 0.045 <= wall_period <= 0.055
    assert all(later - earlier == 100 for earlier, later in zip(stamps[1:], stamps[2:]))


def test_a_streaming_lms_at_9600_does_not_stall_the_urg(tmp_path: Path) -> None:
    lms_link = tmp_path / "ttyLMS0"
    with ServeProcess("railway", ["urg=tcp:127.0.0.1:0", f"lms=pty:{lms_link}"]) as daemon:
        lms = serial.Serial(str(lms_link), baudrate=9600, timeout=0.5)
        lms.write(build_telegram(0x00, bytes([0x20, 0x24])))  # continuous output of every scan
        assert lms.read(1) == b"\x06"
        with socket.create_connection(daemon.endpoint("urg", "tcp").address, timeout=2) as urg:
            urg.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            started = time.monotonic()
            latencies = []
            while time.monotonic() - started < 2.0:
                sent = time.perf_counter()
                urg.sendall(b"VV\n")
                reply = b""
                while not reply.endswith(b"\n\n"):
                    reply += urg.recv(4096)
                latencies.append(time.perf_counter() - sent)
                time.sleep(0.02)
        lms.timeout = 0
        streamed = lms.read(100000)
        lms.timeout = 2.0
        streamed += lms.read(1920)  # what the line carries in the next 2 s
        elapsed = time.monotonic() - started
        lms.close()
    # a stall behind the LMS line would be a whole telegram: 0.76 s at 9600; the URG
    # itself answers at its next 100 ms command cycle (real timing), so allow that
    assert max(latencies) < 0.15, f"URG reply took {max(latencies) * 1000:.1f} ms while the LMS streamed"
    assert b"\x02\x80" in streamed  # B0 telegrams from the LMS (STX, address 0x80)
    bytes_per_s = (len(streamed) + 1) / elapsed
    assert 0.85 * 960 <= bytes_per_s <= 1.1 * 960, f"LMS line carried {bytes_per_s:.0f} B/s at 9600"


@pytest.mark.parametrize(
    ("arguments", "expected"),
    [
        (["railway", "--endpoint", "nosuch=tcp:127.0.0.1:0"], "no sensor named 'nosuch'"),
        (["railway", "--endpoint", "urg=udp:127.0.0.1:1"], "expected pty:PATH, tcp:HOST:PORT or rfc2217:HOST:PORT"),
        (["railway", "--endpoint", "urg=tcp:127.0.0.1:99999"], "PORT 0..65535"),
        (["railway", "--endpoint", "urg"], "expected SENSOR=URI"),
        (["no-such-scene"], "no-such-scene"),
        (["railway", "--speed", "0"], "--speed must be >= 0.001 and <= 1000, got 0"),
        (["railway", "--worker-nice", "20"], "--worker-nice must be 0..19, got 20"),
        (["railway", "--worker-nice", "-1"], "--worker-nice must be 0..19, got -1"),
    ],
)
def test_user_errors_are_one_line_and_exit_2(tmp_path: Path, arguments: list[str], expected: str) -> None:
    result = run_serve(*arguments, cwd=tmp_path)
    assert result.returncode == 2
    assert result.stderr.count("\n") == 1 and expected in result.stderr, result.stderr
    assert result.stdout == ""


def test_port_in_use_is_a_user_error_with_no_ready_line_and_leaves_no_symlink(tmp_path: Path) -> None:
    """The pty is bound first, the taken port second: neither is announced."""
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen(1)
        port = taken.getsockname()[1]
        result = run_serve(
            "railway", "--endpoint", f"urg=pty:{tmp_path / 'u'}", "--endpoint", f"lms=tcp:127.0.0.1:{port}",
            cwd=tmp_path,
        )
    assert result.returncode == 2
    assert result.stderr == f"lrf-emulator serve: --endpoint lms: tcp:127.0.0.1:{port}: Address already in use\n"
    assert result.stdout == ""
    assert not os.path.lexists(tmp_path / "u")


def test_every_taken_port_and_path_is_reported_at_once(tmp_path: Path) -> None:
    """Two endpoint ports, a pty path, the control API's and the view's port all taken:
    one line each, exit 2, nothing announced and nothing left behind."""
    (tmp_path / "ttyLMS0").write_text("a user's file\n")
    sockets = [socket.socket() for _ in range(4)]
    try:
        for taken in sockets:
            taken.bind(("127.0.0.1", 0))
            taken.listen(1)
        urg, lms, control, view = (taken.getsockname()[1] for taken in sockets)
        result = subprocess.run(
            [*serve_command(), "serve", "railway", "--endpoint", f"urg=tcp:127.0.0.1:{urg}",
             "--endpoint", "urg=pty:ttyURG0", "--endpoint", "lms=pty:ttyLMS0", "--endpoint", f"lms=tcp:127.0.0.1:{lms}",
             "--control", f"127.0.0.1:{control}", "--view", f"127.0.0.1:{view}"],
            cwd=tmp_path, capture_output=True, text=True, timeout=60,
        )
    finally:
        for taken in sockets:
            taken.close()
    assert result.returncode == 2 and result.stdout == ""
    lines = result.stderr.splitlines()
    assert len(lines) == 5, result.stderr
    assert all(line.startswith("lrf-emulator serve: ") for line in lines)
    assert f"--endpoint urg: tcp:127.0.0.1:{urg}: Address already in use" in lines[0]
    assert "--endpoint lms: pty:ttyLMS0:" in lines[1] and "already exists" in lines[1]
    assert f"--endpoint lms: tcp:127.0.0.1:{lms}: Address already in use" in lines[2]
    assert f"--control 127.0.0.1:{control}: cannot listen" in lines[3]
    assert f"--view 127.0.0.1:{view}:" in lines[4]
    assert sorted(path.name for path in tmp_path.iterdir()) == ["ttyLMS0"]  # the pty made for urg is gone again
    assert (tmp_path / "ttyLMS0").read_text() == "a user's file\n"


def test_a_taken_port_from_the_scene_file_is_named_by_file_table_and_key(tmp_path: Path) -> None:
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen(1)
        port = taken.getsockname()[1]
        scene = tmp_path / "two.toml"
        scene.write_text(
            '[[sensors]]\nname = "urg"\nmodel = "urg-04lx"\nendpoints = ["tcp:127.0.0.1:0"]\n'
            f'[[sensors]]\nname = "lms"\nmodel = "lms200"\nendpoints = ["pty:l", "tcp:127.0.0.1:{port}"]\n'
        )
        result = run_serve(str(scene), cwd=tmp_path)
    assert result.returncode == 2
    assert result.stderr == (
        f"lrf-emulator serve: two.toml: sensors[1].endpoints[1]: tcp:127.0.0.1:{port}: Address already in use\n"
    )
    assert result.stdout == ""
    assert not os.path.lexists(tmp_path / "l")


def test_tcp_port_0_in_a_scene_file_means_what_it_means_on_endpoint(tmp_path: Path) -> None:
    """A free port chosen by the system and named on the ready line, from the scene
    file as from `--endpoint urg=tcp:127.0.0.1:0`."""
    scene = tmp_path / "zero.toml"
    scene.write_text('[[sensors]]\nname = "urg"\nmodel = "urg-04lx"\nendpoints = ["tcp:127.0.0.1:0"]\n')
    for extra in ([], ["--endpoint", "urg=tcp:127.0.0.1:0"]):
        process = subprocess.Popen(
            [*serve_command(), "serve", str(scene), *extra, "--control", "off"], cwd=tmp_path, stdout=subprocess.PIPE, text=True
        )
        try:
            ready = parse_ready_line(process.stdout.readline())
            assert ready is not None and ready.sensor == "urg"
            host, port = ready.address
            assert host == "127.0.0.1" and port > 0
            with socket.create_connection((host, port), timeout=5) as client:
                client.sendall(b"VV\n")
                assert client.recv(4) == b"VV\n0"
        finally:
            process.terminate()
            process.wait(10)


def test_an_override_onto_a_wildcard_of_a_port_another_sensor_keeps_is_refused_before_serving(tmp_path: Path) -> None:
    """railway's urg keeps tcp:127.0.0.1:10940; 0.0.0.0 on that port could not be bound beside it."""
    result = run_serve("railway", "--endpoint", "lms=tcp:0.0.0.0:10940", cwd=tmp_path)
    assert result.returncode == 2
    assert result.stderr == (
        "lrf-emulator serve: --endpoint: endpoint tcp:0.0.0.0:10940 of sensor 'lms' already used by sensor 'urg'"
        " as tcp:127.0.0.1:10940\n"
    )
    assert result.stdout == ""
    assert not os.path.lexists(tmp_path / "ttyURG0")


@pytest.mark.parametrize(
    ("overrides", "expected"),
    [
        ({"urg": ["pty:ttyLMS0"]}, "endpoint pty:ttyLMS0 of sensor 'lms' already used by sensor 'urg'"),
        ({"lms": ["tcp:[::]:10940"]},
         "endpoint tcp:[::]:10940 of sensor 'lms' already used by sensor 'urg' as tcp:127.0.0.1:10940"),
        ({"lms": ["tcp:localhost:10940"]},
         "endpoint tcp:localhost:10940 of sensor 'lms' already used by sensor 'urg' as tcp:127.0.0.1:10940"),
        ({"urg": ["tcp:*:7", "tcp:127.0.0.9:7"]},
         "endpoint tcp:127.0.0.9:7 of sensor 'urg' already used by sensor 'urg' as tcp:*:7"),
        ({"urg": ["pty:u", "tcp:0.0.0.0:10941"], "lms": ["tcp:0.0.0.0:10941"]},
         "endpoint tcp:0.0.0.0:10941 of sensor 'lms' already used by sensor 'urg'"),
    ],
)
def test_clashing_overrides_are_one_user_error(overrides: dict[str, list[str]], expected: str) -> None:
    with pytest.raises(UserError) as raised:
        plan_endpoints(load_scene("railway"), overrides)
    assert str(raised.value) == f"--endpoint: {expected}"


def test_overrides_on_distinct_hosts_or_fresh_ports_are_accepted() -> None:
    plan_endpoints(
        load_scene("railway"),
        {
            "urg": ["tcp:127.0.0.2:10940", "tcp:0.0.0.0:0", "tcp:127.0.0.1:0"],
            "lms": ["tcp:[::1]:10940", "tcp:0.0.0.0:0"],
        },
    )


SCENE_WITH_ENDPOINTS = """\
[scene]
name = "endpoints"

[[objects]]
name = "wall"
box = {{ size = [0.2, 4.0, 2.0] }}
position = [2.0, 0.0, 1.0]

[[sensors]]
name = "urg"
model = "urg-04lx"
position = [0.0, 0.0, 0.3]
endpoints = ["pty:ttyA", "tcp:127.0.0.1:{port}"]
"""


def test_scene_endpoints_are_served_with_pty_paths_relative_to_the_cwd(tmp_path: Path) -> None:
    port = free_tcp_port()
    scene = tmp_path / "endpoints.toml"
    scene.write_text(SCENE_WITH_ENDPOINTS.format(port=port))
    workdir = tmp_path / "work"
    workdir.mkdir()
    process = subprocess.Popen(
        [*serve_command(), "serve", str(scene), "--control", "off"], cwd=workdir, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )
    try:
        assert select.select([process.stdout], [], [], 30)[0], "no ready line in 30 s"
        lines = [process.stdout.readline(), process.stdout.readline()]  # printed together, once all are bound
        slave = os.readlink(workdir / "ttyA")
        assert lines == [f"ready urg urg-04lx pty:ttyA -> {slave}\n", f"ready urg urg-04lx tcp:127.0.0.1:{port}\n"]
        with socket.create_connection(("127.0.0.1", port), timeout=2) as client:
            client.sendall(b"QT\n")
            assert client.recv(100) == b"QT\n00P\n\n"
    finally:
        process.send_signal(signal.SIGTERM)
        assert process.wait(10) == 0
    assert not os.path.lexists(workdir / "ttyA")
