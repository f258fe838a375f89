"""pty and TCP endpoints against real clients (pyserial on a real pty, real sockets).

The same suite runs on both transports, with a small line-oriented test
device; the pty-only facts (client baud, EIO, symlinks) and the TCP-only
policy (second connection) follow.
"""

from __future__ import annotations

import asyncio
import os
import re
import select
import socket
import threading
import time
from concurrent.futures import Future
from pathlib import Path
from typing import Any, Callable, Iterator

import pytest
import serial

from emulator.daemon.clock import WallClock
from emulator.daemon.service import DeviceSession
from emulator.errors import UserError
from emulator.scene.endpoints import PtyAddress, TcpAddress
from emulator.transport.pty import PtyEndpoint
from emulator.transport.tcp import TcpEndpoint
from protocols.device import Output

STREAM_MESSAGE = re.compile(rb"<(\d{8})\.*>\n")


class LineDevice:
    """A tiny sans-I/O device. Lines: `echo TEXT` → `TEXT\\n`; `burst N` → one N-byte
    output; `stream SIZE PERIOD_MS` → numbered droppable messages of SIZE bytes;
    `stop`. A line starting with `!` is echoed as an interrupting output."""

    def __init__(self, baud: int | None = None) -> None:
        self.lines: list[bytes] = []
        self.lost = 0
        self._baud = baud
        self._buffer = b""
        self._stream: tuple[int, float] | None = None
        self._next_due = 0.0
        self._sequence = 0

    @property
    def baud(self) -> int | None:
        return self._baud

    def receive(self, data: bytes, now: float) -> list[Output]:
        self._buffer += data
        outputs = []
        while b"\n" in self._buffer:
            line, self._buffer = self._buffer.split(b"\n", 1)
            self.lines.append(line)
            outputs += self._command(line, now)
        return outputs

    def _command(self, line: bytes, now: float) -> list[Output]:
        word, _, rest = line.partition(b" ")
        if line.startswith(b"!"):
            return [Output(line + b"\n", baud=self._baud, interrupt=True)]
        if word == b"echo":
            return [Output(rest + b"\n", baud=self._baud)]
        if word == b"burst":
            return [Output(b"x" * int(rest), baud=self._baud)]
        if word == b"stream":
            size, period_ms = (int(field) for field in rest.split())
            self._stream = (size, period_ms / 1000)
            self._next_due = now
            return []
        if word == b"stop":
            self._stream = None
        if word == b"hangup":  # a burst, a hang-up, then a word no client of a hung-up link reads
            return [Output(b"x" * int(rest), baud=self._baud), Output(b"", hang_up=True), Output(b"after\n")]
        return []

    def poll(self, now: float) -> list[Output]:
        outputs = []
        while self._stream is not None and self._next_due <= now:
            size, period = self._stream
            message = b"<%08d" % self._sequence + b"." * (size - 11) + b">\n"
            outputs.append(Output(message, baud=self._baud, droppable=True))
            self._sequence += 1
            self._next_due += period
        return outputs

    def next_deadline(self) -> float | None:
        return self._next_due if self._stream is not None else None

    def connection_lost(self) -> None:
        self.lost += 1
        self._stream = None
        self._buffer = b""


class LoopThread:
    """An asyncio loop on a thread: the endpoints live there, the test drives real clients."""

    def __init__(self) -> None:
        self.loop = asyncio.new_event_loop()
        self._thread = threading.Thread(target=self.loop.run_forever, daemon=True)
        self._thread.start()

    def call(self, function: Callable[..., Any], *args: Any) -> Any:
        result: Future = Future()

        def run() -> None:
            try:
                result.set_result(function(*args))
            except BaseException as error:  # handed to the test thread
                result.set_exception(error)

        self.loop.call_soon_threadsafe(run)
        return result.result(timeout=5)

    def close(self) -> None:
        self.loop.call_soon_threadsafe(self.loop.stop)
        self._thread.join(timeout=5)
        self.loop.close()


@pytest.fixture
def loop_thread() -> Iterator[LoopThread]:
    runner = LoopThread()
    yield runner
    runner.close()


class Served:
    def __init__(self, device: LineDevice, endpoint: PtyEndpoint | TcpEndpoint, target: str) -> None:
        self.device, self.endpoint, self.target = device, endpoint, target


def serve(loop_thread: LoopThread, device: LineDevice, kind: str, tmp_path: Path, name: str = "tty0") -> Served:
    """Serve `device` on a fresh pty (`target` = symlink path) or TCP port (`target` = port)."""

    def open_endpoint() -> Served:
        session = DeviceSession(device, WallClock(), loop_thread.loop)
        if kind == "pty":
            endpoint: PtyEndpoint | TcpEndpoint = PtyEndpoint(PtyAddress(str(tmp_path / name)), session)
            endpoint.open(loop_thread.loop)
            target = str(tmp_path / name)
        else:
            endpoint = TcpEndpoint(TcpAddress("127.0.0.1", 0), session)
            target = str(endpoint.open(loop_thread.loop).port)
        session.endpoint = endpoint
        session.start()
        return Served(device, endpoint, target)

    return loop_thread.call(open_endpoint)


class Client:
    """A blocking client: pyserial on the pty, a plain socket on TCP."""

    def __init__(self, kind: str, target: str, baud: int = 9600, receive_buffer: int | None = None) -> None:
        self.kind = kind
        if kind == "pty":
            self._port = serial.Serial(target, baudrate=baud, timeout=0.05)
        else:
            self._socket = socket.socket()
            if receive_buffer:
                self._socket.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, receive_buffer)
            self._socket.connect(("127.0.0.1", int(target)))
            self._socket.settimeout(0.05)

    def write(self, data: bytes) -> None:
        if self.kind == "pty":
            self._port.write(data)
        else:
            self._socket.sendall(data)

    def read_some(self, limit: int = 65536) -> bytes:
        """Up to `limit` bytes that arrive within 50 ms (b"" if none; EOFError at end of stream)."""
        if self.kind == "pty":
            return self._port.read(limit)
        try:
            data = self._socket.recv(limit)
        except socket.timeout:
            return b""
        if not data:
            raise EOFError
        return data

    def read_exactly(self, count: int, timeout: float = 5.0) -> bytes:
        data = bytearray()
        deadline = time.monotonic() + timeout
        while len(data) < count and time.monotonic() < deadline:
            data += self.read_some(count - len(data))
        return bytes(data)

    def read_for(self, seconds: float) -> bytes:
        data = bytearray()
        deadline = time.monotonic() + seconds
        while time.monotonic() < deadline:
            data += self.read_some()
        return bytes(data)

    def read_until_quiet(self, quiet_s: float = 0.3, timeout: float = 10.0) -> bytes:
        data = bytearray()
        deadline = time.monotonic() + timeout
        last = time.monotonic()
        while time.monotonic() - last < quiet_s and time.monotonic() < deadline:
            chunk = self.read_some()
            if chunk:
                data += chunk
                last = time.monotonic()
        return bytes(data)

    def set_baud(self, baud: int) -> None:
        self._port.baudrate = baud

    def close(self) -> None:
        if self.kind == "pty":
            self._port.close()
        else:
            self._socket.close()


def wait_for(condition: Callable[[], bool], timeout: float = 2.0) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if condition():
            return True
        time.sleep(0.005)
    return condition()


TRANSPORTS = ["pty", "tcp"]


@pytest.mark.parametrize("kind", TRANSPORTS)
def test_echo_round_trip(loop_thread: LoopThread, tmp_path: Path, kind: str) -> None:
    served = serve(loop_thread, LineDevice(), kind, tmp_path)
    client = Client(kind, served.target)
    client.write(b"echo hello\n")
    assert client.read_exactly(6, timeout=2) == b"hello\n"
    client.close()


@pytest.mark.parametrize("kind", TRANSPORTS)
def test_a_hang_up_drops_a_tcp_client_after_what_came_before_and_a_pty_keeps_its_client(
    loop_thread: LoopThread, tmp_path: Path, kind: str
) -> None:
    """A device that hangs up (a rebooting unit): a TCP client gets everything sent before it, then the
    end of the stream, and the session is told once; a pty cannot drop its client, which reads on."""
    device = LineDevice()
    served = serve(loop_thread, device, kind, tmp_path)
    client = Client(kind, served.target)
    client.write(b"hangup 200000\n")  # more than the socket takes at once: the hang-up waits for the rest
    assert client.read_exactly(200000, timeout=5) == b"x" * 200000
    if kind == "tcp":
        with pytest.raises(EOFError):
            client.read_for(2.0)
        assert wait_for(lambda: device.lost == 1 and not served.endpoint.connected)
        again = Client(kind, served.target)  # the endpoint takes the next client
        again.write(b"echo back\n")
        assert again.read_exactly(5, timeout=2) == b"back\n"
        again.close()
    else:
        assert client.read_exactly(6, timeout=2) == b"after\n"
        assert device.lost == 0 and served.endpoint.connected
    client.close()


@pytest.mark.parametrize("kind", TRANSPORTS)
@pytest.mark.parametrize("baud", [9600, 38400, 500000])
def test_output_is_paced_at_its_baud(loop_thread: LoopThread, tmp_path: Path, kind: str, baud: int) -> None:
    """Half a second of line time, measured at the client: within 10 %."""
    size = baud // 10 // 2
    served = serve(loop_thread, LineDevice(baud), kind, tmp_path)
    client = Client(kind, served.target, baud=baud)
    started = time.monotonic()
    client.write(b"burst %d\n" % size)
    received = client.read_exactly(size, timeout=3)
    elapsed = time.monotonic() - started
    assert received == b"x" * size
    assert 0.45 <= elapsed <= 0.55, f"{size} bytes at {baud} took {elapsed:.3f} s, expected 0.5 s"
    client.close()


@pytest.mark.parametrize("kind", TRANSPORTS)
def test_a_client_that_stops_reading_loses_whole_scans_and_stalls_nobody(
    loop_thread: LoopThread, tmp_path: Path, kind: str
) -> None:
    streaming = serve(loop_thread, LineDevice(), kind, tmp_path, "tty0")
    other = serve(loop_thread, LineDevice(), kind, tmp_path, "tty1")
    client = Client(kind, streaming.target, receive_buffer=4096)
    client.write(b"stream 2137 2\n")  # a URG MD scan every 2 ms, ~1 MB/s unread
    other_client = Client(kind, other.target)
    latencies = []
    for _ in range(20):  # the other endpoint answers promptly all along
        started = time.monotonic()
        other_client.write(b"echo ping\n")
        assert other_client.read_exactly(5, timeout=1) == b"ping\n"
        latencies.append(time.monotonic() - started)
        time.sleep(0.05)
    link = streaming.endpoint.link
    assert link is not None and link.outbox.dropped > 0
    assert link.outbox.pending_bytes <= link.outbox.limit_bytes
    client.write(b"stop\n")
    received = client.read_until_quiet()
    messages = STREAM_MESSAGE.findall(received)
    assert b"".join(b"<" + m + b"." * (2137 - 11) + b">\n" for m in messages) == received, "torn message"
    sequence = [int(m) for m in messages]
    assert sequence == sorted(set(sequence)) and sequence[-1] - sequence[0] + 1 > len(sequence)
    assert max(latencies) < 0.05, f"other endpoint stalled: {max(latencies) * 1000:.1f} ms"
    client.close()
    other_client.close()


@pytest.mark.parametrize("kind", TRANSPORTS)
def test_an_interrupting_output_overtakes_a_slow_one(loop_thread: LoopThread, tmp_path: Path, kind: str) -> None:
    served = serve(loop_thread, LineDevice(9600), kind, tmp_path)
    client = Client(kind, served.target, baud=9600)
    client.write(b"burst 2000\n")  # 2.08 s of line time
    head = client.read_for(0.2)
    started = time.monotonic()
    client.write(b"!now\n")
    rest = client.read_until_quiet(quiet_s=0.2, timeout=3)
    assert rest.endswith(b"!now\n")
    assert time.monotonic() - started < 0.6
    assert set(head + rest[: -len(b"!now\n")]) == {ord("x")}
    assert len(head + rest) < 400
    client.close()


def test_pty_input_at_the_wrong_baud_is_dropped(loop_thread: LoopThread, tmp_path: Path) -> None:
    device = LineDevice(38400)
    served = serve(loop_thread, device, "pty", tmp_path)
    client = Client("pty", served.target, baud=9600)
    client.write(b"echo wrong rate\n")
    assert client.read_for(0.3) == b""
    client.set_baud(38400)
    client.write(b"echo right rate\n")
    assert client.read_exactly(11, timeout=2) == b"right rate\n"
    assert device.lines == [b"echo right rate"]
    client.close()


def test_pty_client_leaving_resets_the_session_once_and_the_next_starts_clean(
    loop_thread: LoopThread, tmp_path: Path
) -> None:
    device = LineDevice()
    served = serve(loop_thread, device, "pty", tmp_path)
    first = Client("pty", served.target)
    first.write(b"stream 500 5\n")
    assert first.read_exactly(2000, timeout=2)
    time.sleep(0.1)  # stops reading: 10 messages wait in the pty when it closes
    first.close()
    assert wait_for(lambda: device.lost == 1)
    # a plain open: pyserial would flush the input itself and hide stale bytes
    second = os.open(served.target, os.O_RDWR | os.O_NOCTTY)
    assert wait_for(lambda: served.endpoint.connected)
    os.write(second, b"echo clean\n")
    assert select.select([second], [], [], 2)[0]
    assert os.read(second, 65536) == b"clean\n", "stale bytes from the last client"
    os.close(second)
    assert wait_for(lambda: device.lost == 2)
    time.sleep(0.1)
    assert device.lost == 2


def test_a_pty_client_opening_as_the_last_one_leaves_keeps_what_it_writes(
    loop_thread: LoopThread, tmp_path: Path
) -> None:
    """A driver restarted at once (killed mid-stream, then started again) opens the pty and writes its
    first command while the daemon is still handling the old client's departure: the stale scans for
    the old client are discarded, the new client's command is not (it was, 1 run in ~100 under load,
    and MRPT's CHokuyoURG then got no reply to its first QT)."""
    device = LineDevice()
    served = serve(loop_thread, device, "pty", tmp_path)
    first = Client("pty", served.target)
    first.write(b"stream 500 5\n")
    assert first.read_exactly(2000, timeout=2)
    time.sleep(0.1)  # stops reading: messages wait in the pty when it closes
    endpoint = served.endpoint
    disconnect = endpoint._disconnect
    second: list[int] = []

    def the_next_client_arrives_meanwhile() -> None:
        if not second:  # the moment the old client's departure is handled
            second.append(os.open(served.target, os.O_RDWR | os.O_NOCTTY))
            os.write(second[0], b"echo first command\n")
        disconnect()

    endpoint._disconnect = the_next_client_arrives_meanwhile  # type: ignore[method-assign]
    first.close()
    assert wait_for(lambda: device.lost == 1)
    assert wait_for(lambda: b"echo first command" in device.lines), device.lines[-3:]
    assert select.select([second[0]], [], [], 2)[0]
    assert os.read(second[0], 65536) == b"first command\n", "stale bytes from the last client"
    os.close(second[0])


def test_pty_symlink_is_created_and_removed_on_close(loop_thread: LoopThread, tmp_path: Path) -> None:
    link = tmp_path / "tty0"
    served = serve(loop_thread, LineDevice(), "pty", tmp_path)
    slave = os.readlink(link)
    assert slave == served.endpoint.slave_name and slave.startswith("/dev/pts/")
    loop_thread.call(served.endpoint.close)
    assert not os.path.lexists(link)


@pytest.mark.parametrize("existing", ["dangling link", "link to a file", "file"])
def test_anything_already_at_the_pty_path_is_a_user_error_and_is_kept(
    loop_thread: LoopThread, tmp_path: Path, existing: str
) -> None:
    """Only a link to a vanished /dev/pts/N is a dead daemon's: nothing else is replaced."""
    path = tmp_path / "tty0"
    target = tmp_path / "precious"
    target.write_text("not a device")
    if existing == "dangling link":
        path.symlink_to("/dev/pts/does-not-exist")
    elif existing == "link to a file":
        path.symlink_to(target)
    else:
        path.write_text("not a device")
    with pytest.raises(UserError, match="already exists"):
        serve(loop_thread, LineDevice(), "pty", tmp_path)
    assert os.path.lexists(path) and target.read_text() == "not a device"
    if path.is_symlink():
        assert os.readlink(path) in ("/dev/pts/does-not-exist", str(target))


def test_tcp_second_connection_is_refused_while_the_first_is_served(loop_thread: LoopThread, tmp_path: Path) -> None:
    device = LineDevice()
    served = serve(loop_thread, device, "tcp", tmp_path)
    first = Client("tcp", served.target)
    first.write(b"echo one\n")
    assert first.read_exactly(4) == b"one\n"
    second = Client("tcp", served.target)
    with pytest.raises(EOFError):
        second.read_for(1.0)
    first.write(b"echo still\n")
    assert first.read_exactly(6) == b"still\n"
    assert served.endpoint.refused == 1
    first.write(b"stream 500 5\n")
    first.close()
    assert wait_for(lambda: device.lost == 1)
    third = Client("tcp", served.target)
    third.write(b"echo three\n")
    assert third.read_exactly(6) == b"three\n"
    third.close()
    second.close()


class CostlyDevice(LineDevice):
    """Input that costs 20 µs of CPU a byte (an LMS200's reader checking a CRC at every STX of a flood)."""

    def __init__(self) -> None:
        super().__init__()
        self.calls: list[tuple[int, float]] = []  # (bytes, CPU seconds) of each receive

    def receive(self, data: bytes, now: float) -> list[Output]:
        started = time.thread_time()
        while time.thread_time() < started + 20e-6 * len(data):
            pass
        self.calls.append((len(data), time.thread_time() - started))
        return super().receive(data, now)


@pytest.mark.parametrize("kind", TRANSPORTS)
def test_input_that_costs_much_per_byte_is_fed_in_smaller_slices(loop_thread: LoopThread, tmp_path: Path, kind: str) -> None:
    """512-byte slices of it held the loop 10 ms each; they shrink until one costs about a millisecond."""
    device = CostlyDevice()
    served = serve(loop_thread, device, kind, tmp_path)
    client = Client(kind, served.target, baud=115200)
    try:
        client.write(b"x" * 3000)
        assert wait_for(lambda: sum(size for size, _ in device.calls) == 3000, timeout=20.0), device.calls
    finally:
        client.close()
        loop_thread.call(served.endpoint.close)
    assert device.calls[0][0] == 512  # the first slice is a whole one
    assert max(cpu for _, cpu in device.calls[5:]) < 0.003, device.calls
    assert max(size for size, _ in device.calls[5:]) <= 64, device.calls


def test_a_client_gone_with_its_input_unread_leaves_the_port_to_the_next(loop_thread: LoopThread, tmp_path: Path) -> None:
    """Slow input beyond one read, then the client closes: worked off at its share of the loop it would
    take minutes, and the port refused every new client meanwhile (the kernel still held the bytes, so the
    daemon took the client for alive). A client that has finished sending gives way to a new one."""
    device = CostlyDevice()
    served = serve(loop_thread, device, "tcp", tmp_path)
    first = socket.create_connection(("127.0.0.1", int(served.target)))
    first.settimeout(5.0)
    first.sendall(b"x" * 100_000)  # past one read (64 KiB): the rest waits in the daemon's kernel, the FIN after it
    assert wait_for(lambda: len(device.calls) > 0)
    first.close()
    second = Client("tcp", served.target)
    try:
        second.write(b"echo next\n")
        assert second.read_exactly(5) == b"next\n"
        assert served.endpoint.refused == 0
    finally:
        second.close()
        loop_thread.call(served.endpoint.close)
