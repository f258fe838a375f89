"""The URG-04LX's real-unit timing on the wire, against the real `serve`: replies
at the 100 ms command cycle, fresh GD scans, RS stamps, settings that outlive a
connection, and `timing = "fast"` (docs/scip.md, "Time")."""

from __future__ import annotations

import socket
import time

import pytest

from emulator.bench.serve_process import ServeProcess
from protocols.scip.encoding import decode_values

SCENE = """
[[sensors]]
name = "real"
model = "urg-04lx"
endpoints = ["tcp:127.0.0.1:0"]

[[sensors]]
name = "fast"
model = "urg-04lx"
timing = "fast"
boot_protocol = "scip1"
endpoints = ["tcp:127.0.0.1:0"]
"""


@pytest.fixture(scope="module")
def daemon(tmp_path_factory: pytest.TempPathFactory):
    folder = tmp_path_factory.mktemp("urg-timing")
    scene = folder / "urgs.toml"
    scene.write_text(SCENE)
    with ServeProcess(scene, ["real=tcp:127.0.0.1:0", "fast=tcp:127.0.0.1:0"]) as process:
        yield process


class Client:
    def __init__(self, daemon: ServeProcess, sensor: str) -> None:
        self.socket = socket.create_connection(daemon.endpoint(sensor, "tcp").address, timeout=3)
        self.socket.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self.buffer = b""

    def ask(self, command: bytes) -> tuple[bytes, float]:
        """One command, its whole reply, and the seconds it took."""
        sent = time.perf_counter()
        self.socket.sendall(command + b"\n")
        while b"\n\n" not in self.buffer:
            chunk = self.socket.recv(65536)
            assert chunk, f"connection closed waiting for the reply to {command!r}"
            self.buffer += chunk
        reply, _, self.buffer = self.buffer.partition(b"\n\n")
        return reply + b"\n\n", time.perf_counter() - sent

    def close(self) -> None:
        self.socket.close()


def stamp_of(reply: bytes) -> int:
    return int(decode_values(reply.split(b"\n")[2][:4], 4)[0])


def test_a_command_sent_just_after_a_reply_waits_for_the_next_cycle(daemon):
    """Commands are handled once per 100 ms revolution: one sent right after a
    reply (just after a cycle point) is answered at the next one."""
    client = Client(daemon, "real")
    try:
        client.ask(b"VV")
        latencies = [client.ask(b"VV")[1] for _ in range(5)]
    finally:
        client.close()
    assert min(latencies) >= 0.08, f"answered before the next cycle: {latencies}"
    assert max(latencies) < 0.3, f"a reply took more than a cycle and a half: {latencies}"


def test_back_to_back_gds_return_distinct_scans_measured_after_each_command(daemon):
    client = Client(daemon, "real")
    try:
        client.ask(b"BM")
        replies = [client.ask(b"GD0044072501") for _ in range(5)]
    finally:
        client.close()
    stamps = [stamp_of(reply) for reply, _ in replies]
    steps = [later - earlier for earlier, later in zip(stamps, stamps[1:])]
    assert all(step > 0 and step % 100 == 0 for step in steps), stamps  # a new revolution each time
    assert min(steps) == 100, stamps  # asked again at once: the very next revolution
    assert all(latency >= 0.09 for _, latency in replies), "a GD must wait for its revolution"


def test_rs_restarts_the_stamps_from_a_small_positive_value(daemon):
    client = Client(daemon, "real")
    try:
        client.ask(b"BM")
        client.ask(b"GD0044072501")
        assert client.ask(b"RS")[0] == b"RS\n00P\n\n"
        client.ask(b"BM")
        stamp = stamp_of(client.ask(b"GD0044072501")[0])
    finally:
        client.close()
    assert 0 < stamp <= 300


def test_fast_timing_answers_at_once(daemon):
    client = Client(daemon, "fast")
    try:
        client.ask(b"SCIP2.0")
        latencies = [client.ask(b"VV")[1] for _ in range(5)]
    finally:
        client.close()
    assert max(latencies) < 0.05, latencies


def test_settings_outlive_the_connection(daemon):
    """urg_c, hokuyo-python-lib and BreezyLidar switch a SCIP 1.1 unit to 2.0 once
    and expect 2.0 on their next open; speed and bit rate stay as set too."""
    client = Client(daemon, "fast")
    try:
        client.ask(b"SCIP2.0")  # 1.1 at power-on; 2.0 already if an earlier test switched it
        client.ask(b"CR00")
        assert client.ask(b"CR05")[0] == b"CR05\n00P\n\n"
        client.ask(b"MD0044072501000")  # left streaming
    finally:
        client.close()
    client = Client(daemon, "fast")
    try:
        time.sleep(0.25)
        client.socket.setblocking(False)
        with pytest.raises(BlockingIOError):
            client.socket.recv(1)  # the stream stopped with the old connection
        client.socket.setblocking(True)
        reply, _ = client.ask(b"II")
        assert b"SCSP:Changed(570[rpm])" in reply
        assert client.ask(b"VV")[0].startswith(b"VV\n00P\n")  # still SCIP 2.0
        assert client.ask(b"CR00")[0] == b"CR00\n00P\n\n"
    finally:
        client.close()
