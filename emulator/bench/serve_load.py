"""A real `serve` streaming N Hokuyos to N real clients: CPU per scan, rate, jitter.

The scene is railway's world (its geometry, smoke and plume) with its sensors
replaced by N Hokuyos of one model side by side (URG-04LX; the UST-10LX row:
8 of them at 40 Hz) (and, for the moonshot row, M LMS200 at 500 kBd), each on
`tcp:127.0.0.1:0`. One client per sensor connects over TCP
and asks for an unlimited MD stream (an LMS200: mode 24, every scan); a single
selector thread in this process reads all sockets and notes when each scan
message ends. Over the measuring window:

- rate: scans received / scans due (10 per second per URG-04LX, 40 per UST-10LX);
- jitter: |Δt − period| between consecutive scans of one sensor, p50 and p99
  over all sensors' periods;
- lateness: each scan's arrival against its slot (the scan's own timestamp,
  with the sensor's least-delayed scan defining the offset); "on time" is
  within ON_TIME_MS of the slot;
- LMS200: telegrams received / due (37.5 per second at 0.5°) and the
  telegram period deviation |Δt − 26.67 ms|, p50 and p99;
- CPU per scan: user + system time of the daemon and its worker processes
  from /proc/PID/stat (the process's own accounting), divided by the scans
  received; "of it loop": the daemon's own process (protocols, transports,
  timers), without its workers.

A SCIP scan's arrival is the kernel's receive stamp of its last packet
(SO_TIMESTAMPNS; on loopback, taken within the daemon's send), so the
figures are the daemon's timing, not this one client process's own
scheduling (`read_late` counts the reads that came a period late, whose
stamp may be the next message's).

rescue's UTM-30LX-EW (`measure_utm_stream`) is served alone under `physical`
and streams ME over TCP; `--epoch` starts simulated time so that the 40 s
window holds the sensor's slowest instant (UTM_SLOWEST_AT_S, from
`bench --section scans`), and each scan's gap to the previous is measured
against the 25 ms period (target: every one within 5 %, 1.25 ms).

The floor rows (`measure_serve_floor`, `measure_utm_floor`) are bare
timerfd-woken senders (`scip_floor`) of the same message sizes, periods and
revolution phases, read by the same client: what the machine itself allows
at the moment, to read the daemon's rows against (as `bench --section cola`
does). The 8 UST-10LX have a second floor, `floor+cpu`: the same senders with
burners (`burner.py`) keeping busy as much CPU as the `physical` row's workers
used, in a worker's bursts: what a design that computes its scans on this
machine could do. The daemon's rows carry its own counters over the window
(SIGUSR1 stats): scans it waited for or sent late, and its timer wake-ups
more than 1, 2, 5 ms late.

Every figure is from one run (no best-of-N); the machine's load average is
reported beside it, as the clients share the machine with the daemon, and so
is the share of CPU time the hypervisor stole over the window (`steal`: on a
virtual machine, a row taken while it was high times the host).
"""

from __future__ import annotations

import fcntl
import math
import os
import selectors
import socket
import struct
import subprocess
import sys
import tempfile
import termios
import time
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Iterator

import numpy as np

from emulator.bench.serve_process import ServeProcess
from emulator.bench.steal import StealMeter, steal_text
from emulator.scene import bundled_scenes, load_scene
from emulator.sensors.hokuyo_models import HOKUYO_MODELS
from protocols.lms2xx import build_telegram
from protocols.scip.encoding import decode_values

URG_MODEL = "urg-04lx"
SCAN_PERIOD_S = 0.1  # the URG-04LX's; other Hokuyos: their model's period
LMS_BAUD = 500_000
LMS_EVERY_SCAN = build_telegram(0x00, b"\x20\x24")  # continuous output of every scan
LMS_PERIOD_S = 2 / 75  # 0.5°: two mirror revolutions per scan; 732 bytes take 14.6 ms at 500 kBd
ON_TIME_MS = 10.0
# Linux socket(7): SO_TIMESTAMPNS stamps each received packet as the kernel queues it on the
# socket (for loopback: within the daemon's send), and recvmsg hands the stamp of the last packet
# read over as SCM_TIMESTAMPNS (a struct timespec, CLOCK_REALTIME). Python names neither.
SO_TIMESTAMPNS = 35
SCM_TIMESTAMPNS = SO_TIMESTAMPNS
_TIMESPEC = struct.Struct("@ll")
_stamp_keeper: socket.socket | None = None


def stamp_received(sock: socket.socket) -> None:
    """Have the kernel stamp `sock`'s received packets (SO_TIMESTAMPNS).

    Linux switches receive stamping on for the whole system lazily (a deferred work item) when a
    first socket asks, and off when the last such socket closes; packets queued meanwhile carry no
    stamp and recvmsg stamps them when read. So the first socket that asks is kept open for the
    process's life: a stream opened after earlier ones closed never starts with read-time stamps."""
    global _stamp_keeper
    if _stamp_keeper is None:
        _stamp_keeper = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        _stamp_keeper.setsockopt(socket.SOL_SOCKET, SO_TIMESTAMPNS, 1)
    sock.setsockopt(socket.SOL_SOCKET, SO_TIMESTAMPNS, 1)
WARM_UP_S = 3.0
FIRST_SCAN_TIMEOUT_S = 120.0
CLOCK_TICKS = os.sysconf("SC_CLK_TCK")


def md_unlimited(hokuyo: str) -> bytes:
    """An unlimited MD stream of the model's measured steps AMIN..AMAX."""
    model = HOKUYO_MODELS[hokuyo]
    return b"MD%04d%04d01000\n" % (model.first_valid_step, model.last_valid_step)




# The dense-plume fleet: railway's plume (8 puffs a second, each living 10 s, density 0.05) with puffs of
# 0.4 m instead of 0.35, and the URGs 1.5 m ahead of the robot, inside the haze and 1.1 m before the
# burning debris, so every scan crosses the plume: 40 URG-04LX on two workers, under `physical`.
DENSE_PLUME_FLEET = 40
DENSE_PLUME_WORKERS = 2
DENSE_PLUME_SIZE = 0.4
DENSE_PLUME_SENSOR_X = 1.5


def fleet_scene_text(count: int, lms_count: int = 0, hokuyo: str = URG_MODEL, *, dense_plume: bool = False) -> str:
    """railway's world with `count` Hokuyos of model `hokuyo` (URG-04LX: urg00, urg01, ...; others named
    by `sensor_name`) side by side, and `lms_count` LMS200 (lms00, ...) at 500 kBd, each on a free TCP port.
    `dense_plume`: the plume's puffs DENSE_PLUME_SIZE and the Hokuyos inside the haze (DENSE_PLUME_SENSOR_X)."""
    railway = next(bundled for bundled in bundled_scenes() if bundled.name == "railway")
    text = Path(railway.path).read_text()
    world = text[: text.index("[[sensors]]")]
    x = 0.25
    if dense_plume:
        plume = world.index("[[smoke.plumes]]")
        size = world.index("size = 0.35", plume)
        world = world[:size] + f"size = {DENSE_PLUME_SIZE}" + world[size + len("size = 0.35"):]
        x = DENSE_PLUME_SENSOR_X
    sensors = []
    for index in range(count):
        y = -0.6 + 1.2 * index / max(1, count - 1)
        sensors.append(
            f'[[sensors]]\nname = "{sensor_name(hokuyo, index)}"\nmodel = "{hokuyo}"\n'
            f'position = [{x}, {y:.4f}, 0.3]\nendpoints = ["tcp:127.0.0.1:0"]\n'
        )
    for index in range(lms_count):
        y = -0.6 + 1.2 * index / max(1, lms_count - 1)
        sensors.append(
            f'[[sensors]]\nname = "{lms_name(index)}"\nmodel = "lms200"\nbaud = {LMS_BAUD}\n'
            f'position = [0.0, {y:.4f}, 0.4]\nendpoints = ["tcp:127.0.0.1:0"]\n'
        )
    return world + "\n".join(sensors)


def urg_name(index: int) -> str:
    return f"urg{index:02d}"


def sensor_name(hokuyo: str, index: int) -> str:
    """urg00, ... for URG-04LX; ust-10lx-00, ... for the others."""
    return urg_name(index) if hokuyo == URG_MODEL else f"{hokuyo}-{index:02d}"


def lms_name(index: int) -> str:
    return f"lms{index:02d}"


def cpu_seconds(pid: int, children: bool = True) -> float:
    """User + system CPU of process `pid` and (unless told not to) of its live child processes (the scan workers)."""
    total = 0.0
    for process in [pid, *(child_pids(pid) if children else [])]:
        try:
            fields = Path(f"/proc/{process}/stat").read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue  # a worker that exited meanwhile
        total += (int(fields[11]) + int(fields[12])) / CLOCK_TICKS  # utime, stime (fields 14, 15)
    return total


def child_pids(pid: int) -> list[int]:
    children = []
    for task in Path(f"/proc/{pid}/task").iterdir():
        try:
            children += [int(child) for child in (task / "children").read_text().split()]
        except OSError:
            continue
    return children


@dataclass
class _Stream:
    """One client's MD stream: when each scan message was sent and its timestamp.

    "Sent" is the kernel's receive stamp of the message's last packet (SO_TIMESTAMPNS), taken as the
    daemon's send puts it on the loopback: the figures are the daemon's, not this client's own
    scheduling (one process reading 320 messages a second on a busy 2-core machine is often
    late by milliseconds). Once a message's length is known, reads stop at its end, so a stamp is
    never that of a later message read in the same call. A message read while the next one's bytes
    were already queued (this client more than a period late on that stream) may carry the later
    one's stamp (the kernel merges queued packets, keeping the newest stamp): such reads are counted
    (`read_late`), and they can only make the daemon look later than it was."""

    sock: socket.socket
    buffer: bytes = b""
    echoed: bool = False
    message_bytes: int | None = None  # a scan message's length, known from the first one
    read_late: int = 0  # messages read with the next one already queued behind them
    arrivals: list[float] = field(default_factory=list)
    stamps: list[int] = field(default_factory=list)

    def __post_init__(self) -> None:
        stamp_received(self.sock)

    def receive(self, realtime_to_monotonic: float) -> None:
        wanted = self.message_bytes - len(self.buffer) if self.message_bytes and self.echoed else 65536
        data, ancillary, _, _ = self.sock.recvmsg(max(wanted, 1), socket.CMSG_SPACE(_TIMESPEC.size))
        if not data:
            raise RuntimeError("the daemon closed a stream")
        received = time.monotonic()
        for level, kind, payload in ancillary:
            if level == socket.SOL_SOCKET and kind == SCM_TIMESTAMPNS and len(payload) >= _TIMESPEC.size:
                seconds, nanoseconds = _TIMESPEC.unpack_from(payload)
                received = seconds + nanoseconds * 1e-9 - realtime_to_monotonic
        if self.echoed and self.message_bytes and len(self.buffer) + len(data) == self.message_bytes:
            self.read_late += _queued_bytes(self.sock) > 0
        self.feed(data, received)

    def feed(self, data: bytes, now: float) -> None:
        self.buffer += data
        while (end := self.buffer.find(b"\n\n")) >= 0:
            message, self.buffer = self.buffer[:end], self.buffer[end + 2 :]
            if not self.echoed:
                self.echoed = True
                continue
            self.message_bytes = self.message_bytes or len(message) + 2
            self.arrivals.append(now)
            self.stamps.append(int(decode_values(message.split(b"\n", 3)[2][:4], 4)[0]))

    def forget(self) -> None:
        self.arrivals.clear()
        self.stamps.clear()
        self.read_late = 0


def _queued_bytes(sock: socket.socket) -> int:
    """Bytes received and not yet read (FIONREAD)."""
    return int.from_bytes(fcntl.ioctl(sock.fileno(), termios.FIONREAD, bytes(4)), sys.byteorder, signed=True)


@dataclass
class _LmsStream:
    """One client's LMS200 stream (mode 24: every scan): when each B0 telegram's last byte arrived.
    Framed by STX, address and length only (no CRC: the bench measures timing, the interop tests
    check the bytes), so the client's own cost stays small beside the daemon's."""

    sock: socket.socket
    buffer: bytearray = field(default_factory=bytearray)
    arrivals: list[float] = field(default_factory=list)

    def receive(self, realtime_to_monotonic: float) -> None:
        data = self.sock.recv(65536)
        if not data:
            raise RuntimeError("the daemon closed a stream")
        self.feed(data, time.monotonic())

    def feed(self, data: bytes, now: float) -> None:
        self.buffer += data
        while self.buffer:
            if self.buffer[0] != 0x02:  # the ACK, or bytes before the first telegram
                start = self.buffer.find(b"\x02\x80")
                del self.buffer[: start if start >= 0 else len(self.buffer)]
                continue
            if len(self.buffer) < 5:
                return
            total = 4 + int.from_bytes(self.buffer[2:4], "little") + 2
            if len(self.buffer) < total:
                return
            if self.buffer[4] == 0xB0:
                self.arrivals.append(now)
            del self.buffer[:total]

    def forget(self) -> None:
        self.arrivals.clear()


def measure_serve(
    count: int, duration_s: float, workers: int | None = None, model: str = "physical", lms_count: int = 0,
    hokuyo: str = URG_MODEL, dense_plume: bool = False,
) -> dict:
    """Start `serve` with `count` Hokuyos of model `hokuyo` (and `lms_count` LMS200 at 500 kBd) under
    preset `model`, stream them all to as many clients, measure `duration_s` (`dense_plume`: the
    Hokuyos inside railway's plume, `fleet_scene_text`)."""
    with tempfile.TemporaryDirectory(prefix="lrf-bench-serve-") as folder:
        scene = Path(folder) / f"{hokuyo}-x{count}-lms-x{lms_count}.toml"
        scene.write_text(fleet_scene_text(count, lms_count, hokuyo, dense_plume=dense_plume))
        names = [sensor_name(hokuyo, index) for index in range(count)] + [lms_name(index) for index in range(lms_count)]
        endpoints = [f"{name}=tcp:127.0.0.1:0" for name in names]
        extra = ["--model", model, *(["--workers", str(workers)] if workers is not None else [])]
        with ServeProcess(scene, endpoints, extra_args=extra, timeout_s=300.0) as daemon:
            counters: list[dict[str, int]] = []
            steal = StealMeter()
            streams = _stream_all(daemon, count, lms_count, duration_s, hokuyo=hokuyo,
                                  on_window=lambda: (counters.append(daemon.stats()), steal.mark()))
            load = os.getloadavg()
    period_s = HOKUYO_MODELS[hokuyo].period_s
    return {"model": model, "hokuyo": hokuyo, "dense_plume": dense_plume,
            **_figures(count, lms_count, duration_s, workers, streams, load, period_s), **daemon_counters(*counters),
            "steal": steal.share}


# The daemon's own counters over a window (SIGUSR1 stats; service.Daemon.stats): scans a device had to wait for
# (`scan_waits`), scans sent late or skipped (the workers behind), its loop's timer wake-ups and those more
# than 1, 2, 5 ms late.
DAEMON_COUNTERS = ("scan_waits", "late", "skipped", "wakes", "late_1ms", "late_2ms", "late_5ms")


def daemon_counters(*counters: dict[str, int]) -> dict[str, int]:
    """The change of DAEMON_COUNTERS between the first and the last of `counters` (none: {})."""
    if len(counters) < 2:
        return {}
    return {f"daemon_{key}": counters[-1][key] - counters[0][key] for key in DAEMON_COUNTERS if key in counters[0]}


class FloorProcess:
    """`scip_floor` as a child process: bare SCIP senders, one per spec, `endpoint(name).address` as a
    ServeProcess's (so the same clients read them) and `pid` (its CPU, as a daemon's)."""

    def __init__(self, specs: list[str]) -> None:
        self.process = subprocess.Popen([sys.executable, "-m", "emulator.bench.scip_floor", *specs],
                                        stdout=subprocess.PIPE, text=True)
        self.pid = self.process.pid
        self._ports: dict[str, int] = {}
        for _ in specs:
            _, name, port = self.process.stdout.readline().split()  # type: ignore[union-attr]
            self._ports[name] = int(port)

    def endpoint(self, name: str) -> _FloorEndpoint:
        return _FloorEndpoint(("127.0.0.1", self._ports[name]))

    def __enter__(self) -> FloorProcess:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.process.terminate()
        self.process.wait(10)


@dataclass(frozen=True)
class _FloorEndpoint:
    address: tuple[str, int]


def worker_cores(row: dict) -> float:
    """The cores a daemon row's workers used: all of its CPU less its own process's."""
    scans = row["scans_received"] + row.get("lms_scans_received", 0)
    return max(0.0, (row["cpu_ms_per_scan"] - row["daemon_cpu_ms_per_scan"]) * scans / 1000.0 / row["duration_s"])


def floor_spec(name: str, hokuyo: str, phase_ms: int, chars: int = 3) -> str:
    """A `scip_floor` stream of model `hokuyo`'s period, its measured steps at `chars` a step (MD: 3, ME: 6)."""
    model = HOKUYO_MODELS[hokuyo]
    steps = model.last_valid_step - model.first_valid_step + 1
    return f"{name}:{model.period_s * 1000:g}:{phase_ms}:{steps}:{chars}"


def measure_serve_floor(count: int, duration_s: float, hokuyo: str = URG_MODEL, burn_cores: float = 0.0) -> dict:
    """The floor under `measure_serve(count, …, hokuyo=hokuyo)`: bare timerfd senders (`scip_floor`) of
    the same MD message sizes, period and revolution phases (the i-th of n turns i × period / n behind
    the first, as `revolution_phase_ms`), read by the same client. `burn_cores` > 0: beside them, burners
    (`burner.py`) keep that much CPU busy in a worker's bursts: the floor under the daemon's scan work."""
    model = HOKUYO_MODELS[hokuyo]
    period_ms = int(round(model.period_s * 1000))
    specs = [floor_spec(sensor_name(hokuyo, index), hokuyo, index * period_ms // count) for index in range(count)]
    steal = StealMeter()
    with FloorProcess(specs) as floor, burners(burn_cores):
        streams = _stream_all(floor, count, 0, duration_s, hokuyo=hokuyo, on_window=steal.mark)  # type: ignore[arg-type]
        load = os.getloadavg()
    return {"model": "floor+cpu" if burn_cores > 0 else "floor", "hokuyo": hokuyo,
            **_figures(count, 0, duration_s, 0, streams, load, model.period_s), "steal": steal.share, "burn_cores": burn_cores}


@contextmanager
def burners(cores: float) -> Iterator[list[subprocess.Popen]]:
    """Burner processes (`burner.py`) busy for `cores` of CPU together (at most one core each), until exit."""
    shares = [1.0] * int(cores) + ([cores - int(cores)] if cores - int(cores) > 1e-3 else [])
    processes = [subprocess.Popen([sys.executable, "-m", "emulator.bench.burner", f"{share:.4f}"]) for share in shares]
    try:
        yield processes
    finally:
        for process in processes:
            process.terminate()
        for process in processes:
            process.wait(10)


def _stream_all(
    daemon: ServeProcess | FloorProcess, count: int, lms_count: int, duration_s: float, on_window: Callable[[], None] | None = None,
    hokuyo: str = URG_MODEL,
) -> tuple[list[_Stream], list[_LmsStream], tuple[float, float]]:
    """Stream from every sensor; `on_window` is called as the measuring window opens and closes."""
    selector = selectors.DefaultSelector()
    streams: list[_Stream] = []
    lms_streams: list[_LmsStream] = []
    for index in range(count):
        sock = socket.create_connection(daemon.endpoint(sensor_name(hokuyo, index)).address, timeout=5)
        sock.sendall(md_unlimited(hokuyo))
        streams.append(_Stream(sock))
    for index in range(lms_count):
        sock = socket.create_connection(daemon.endpoint(lms_name(index)).address, timeout=5)
        sock.sendall(LMS_EVERY_SCAN)
        lms_streams.append(_LmsStream(sock))
    everyone: list[_Stream | _LmsStream] = [*streams, *lms_streams]
    for stream in everyone:
        stream.sock.setblocking(False)
        selector.register(stream.sock, selectors.EVENT_READ, stream)
    realtime_to_monotonic = time.time() - time.monotonic()  # the kernel stamps packets on CLOCK_REALTIME
    measure_from = measure_to = math.inf  # WARM_UP_S after every stream's first scan (a worker's first may take seconds)
    give_up = time.monotonic() + FIRST_SCAN_TIMEOUT_S
    cpu_before = loop_before = None
    try:
        while (now := time.monotonic()) < measure_to:
            if measure_from == math.inf and all(stream.arrivals for stream in everyone):
                measure_from, measure_to = now + WARM_UP_S, now + WARM_UP_S + duration_s
            elif measure_from == math.inf and now > give_up:
                raise RuntimeError(f"a stream sent no scan within {FIRST_SCAN_TIMEOUT_S:g} s")
            if cpu_before is None and now >= measure_from:
                cpu_before, loop_before = cpu_seconds(daemon.pid), cpu_seconds(daemon.pid, children=False)
                if on_window is not None:
                    on_window()
                for stream in everyone:  # the window starts here: forget the warm-up
                    stream.forget()
            for key, _ in selector.select(timeout=0.05):
                key.data.receive(realtime_to_monotonic)
        cpu = cpu_seconds(daemon.pid) - (cpu_before or 0.0), cpu_seconds(daemon.pid, children=False) - (loop_before or 0.0)
        if on_window is not None:
            on_window()
    finally:
        for stream in everyone:
            selector.unregister(stream.sock)
            stream.sock.close()
        selector.close()
    return streams, lms_streams, cpu


def _figures(
    count: int, lms_count: int, duration_s: float, workers: int | None,
    measured: tuple[list[_Stream], list[_LmsStream], tuple[float, float]], load: tuple, period_s: float = SCAN_PERIOD_S,
) -> dict:
    streams, lms_streams, (cpu, daemon_cpu) = measured
    received = sum(len(stream.arrivals) for stream in streams)
    lms_received = sum(len(stream.arrivals) for stream in lms_streams)
    due = count * duration_s / period_s
    periods, lateness = [], []
    for stream in streams:
        if len(stream.arrivals) < 2:
            continue
        arrivals, stamps = np.asarray(stream.arrivals), np.asarray(stream.stamps, dtype=float) / 1000.0
        periods.append(np.diff(arrivals))
        offset = arrivals - stamps
        lateness.append((offset - offset.min()) * 1000.0)
    jitter = np.abs(np.concatenate(periods) - period_s) * 1000.0 if periods else np.array([np.nan])
    late = np.concatenate(lateness) if lateness else np.array([np.nan])
    scans = received + lms_received
    row = {
        "sensors": count,
        "workers": workers if workers is not None else "default",
        "duration_s": duration_s,
        "scans_received": received,
        "rate": received / due if due else float("nan"),
        "on_time": float(np.mean(late <= ON_TIME_MS)) * min(1.0, received / due) if due else float("nan"),
        "jitter_p50_ms": float(np.percentile(jitter, 50)),
        "jitter_p99_ms": float(np.percentile(jitter, 99)),
        "lateness_p99_ms": float(np.percentile(late, 99)),
        "lateness_max_ms": float(np.max(late)),
        "read_late": sum(stream.read_late for stream in streams),
        "cpu_ms_per_scan": cpu / scans * 1000.0 if scans else float("nan"),
        "daemon_cpu_ms_per_scan": daemon_cpu / scans * 1000.0 if scans else float("nan"),
        "cpu_cores": cpu / duration_s,
        "load_average": [round(value, 2) for value in load],
    }
    if lms_count:
        deviations = [
            np.abs(np.diff(stream.arrivals) - LMS_PERIOD_S) * 1000.0 for stream in lms_streams if len(stream.arrivals) > 1
        ]
        deviation = np.concatenate(deviations) if deviations else np.array([np.nan])
        row |= {
            "lms_sensors": lms_count,
            "lms_scans_received": lms_received,
            "lms_rate": lms_received / (lms_count * duration_s / LMS_PERIOD_S),
            "lms_period_deviation_p50_ms": float(np.percentile(deviation, 50)),
            "lms_period_deviation_p99_ms": float(np.percentile(deviation, 99)),
        }
    return row


def table_lines(rows: list[dict]) -> list[str]:
    lines = [
        "serve: a real daemon streaming N Hokuyos (railway's world) to N TCP clients (floor: bare timerfd senders of the"
        " same message sizes, periods and phases); one run each, no best-of;"
        f" on time = within {ON_TIME_MS:g} ms of its slot; CPU = daemon + workers (/proc/PID/stat)",
        f"  {'model':<11} {'N':>3} {'sensor':<14} {'workers':>7} {'rate':>7} {'on time':>8} {'jitter p50':>10} {'p99 ms':>7}"
        f" {'late p99':>8} {'max ms':>7} {'CPU ms/scan':>11} {'of it loop':>10} {'cores':>6}  load avg",
    ]
    for row in rows:
        sensor = row.get("hokuyo", URG_MODEL) + ("+plume" if row.get("dense_plume") else "")
        lines.append(
            f"  {row['model']:<11} {row['sensors']:>3} {sensor:<14} {row['workers']!s:>7} {row['rate']:>7.1%} {row['on_time']:>8.2%}"
            f" {row['jitter_p50_ms']:>10.2f} {row['jitter_p99_ms']:>7.2f} {row['lateness_p99_ms']:>8.2f}"
            f" {row['lateness_max_ms']:>7.1f} {row['cpu_ms_per_scan']:>11.2f} {row['daemon_cpu_ms_per_scan']:>10.2f}"
            f" {row['cpu_cores']:>6.2f}"
            f"  {' '.join(f'{value:g}' for value in row['load_average'])}, {steal_text(row.get('steal', math.nan))}"
        )
        if "daemon_wakes" in row:
            lines.append(f"  {'':<11} the daemon: {_counter_text(row)}")
        if row.get("lms_sensors"):
            lines.append(
                f"  {'':<11} + {row['lms_sensors']} LMS200 at {LMS_BAUD // 1000} kBd: rate {row['lms_rate']:.1%},"
                f" telegram period deviation p50 {row['lms_period_deviation_p50_ms']:.2f} /"
                f" p99 {row['lms_period_deviation_p99_ms']:.2f} ms (CPU per scan above counts both kinds)"
            )
    return lines


MOONSHOT = (100, 20, "formsma2011")  # URG-04LX, LMS200 at 500 kBd, preset: the fleet-sized row


UST_ROW = (8, "ust-10lx")  # one daemon, eight UST-10LX at 40 Hz: every scan on time, jitter p99 <= 1 ms
UST_PRESETS = ("formsma2011", "physical")

# rescue's UTM-30LX-EW streaming ME under `physical`: every scan's gap to the previous within 5 % of its
# 25 ms period, over a window holding the sensor's slowest instant (`bench --section scans`: rescue, utm,
# physical, "at s"; docs/performance.md has the run).
UTM_SCENE, UTM_SENSOR, UTM_PRESET = "rescue", "utm", "physical"
UTM_SLOWEST_AT_S = 59.0
UTM_WINDOW_S = 40.0
UTM_TOLERANCE = 0.05
UTM_START_UP_S = 30.0  # allowance for the daemon's start before the warm-up (its worker builds rescue's world and compiles the echo walks: 24 s at load 5)


def me_unlimited(hokuyo: str) -> bytes:
    """An unlimited ME stream (range + intensity) of the model's measured steps AMIN..AMAX."""
    return b"ME" + md_unlimited(hokuyo)[2:]


def measure_utm_stream(
    duration_s: float = UTM_WINDOW_S, slowest_at_s: float = UTM_SLOWEST_AT_S, model: str = UTM_PRESET
) -> dict:
    """Serve rescue's UTM-30LX-EW alone under `model` with simulated time started (`--epoch`) so that the
    measuring window of `duration_s` is centred on `slowest_at_s`; stream ME over TCP and measure each
    scan's gap to the previous against the 25 ms period (kernel receive stamps, as the fleet rows)."""
    scene_path = Path(next(bundled for bundled in bundled_scenes() if bundled.name == UTM_SCENE).path)
    hokuyo = next(spec.model for spec in load_scene(scene_path).sensors if spec.name == UTM_SENSOR)
    period_s = HOKUYO_MODELS[hokuyo].period_s
    window_from_s = max(0.0, slowest_at_s - duration_s / 2)
    epoch = time.time() - max(0.0, window_from_s - WARM_UP_S - UTM_START_UP_S)
    extra = ["--model", model, "--sensors", UTM_SENSOR, "--epoch", f"{epoch:.6f}"]
    with ServeProcess(scene_path, [f"{UTM_SENSOR}=tcp:127.0.0.1:0"], extra_args=extra, timeout_s=300.0) as daemon:
        counters: list[dict[str, int]] = []
        steal = StealMeter()
        # the window opens WARM_UP_S after the first scan, and not before its simulated start
        scans, measure_from, read_late = _stream_one(
            daemon.endpoint(UTM_SENSOR).address, me_unlimited(hokuyo), duration_s,
            lambda now: now + max(WARM_UP_S, window_from_s - (time.time() - epoch)),
            on_window=lambda: (counters.append(daemon.stats()), steal.mark()),
        )
        load = os.getloadavg()
    realtime_to_monotonic = time.time() - time.monotonic()
    window_sim = (measure_from + realtime_to_monotonic - epoch, measure_from + duration_s + realtime_to_monotonic - epoch)
    return {
        "scene": UTM_SCENE,
        "hokuyo": hokuyo,
        "model": model,
        "duration_s": duration_s,
        "window_sim_s": [round(window_sim[0], 1), round(window_sim[1], 1)],
        "slowest_at_s": slowest_at_s,
        **_gap_figures(scans, duration_s, period_s),
        "read_late": read_late,
        **daemon_counters(*counters),
        "load_average": [round(value, 2) for value in load],
        "steal": steal.share,
    }


def measure_utm_floor(duration_s: float = UTM_WINDOW_S) -> dict:
    """The UTM row's floor: a bare timerfd sender (`scip_floor`) of the same ME message size and period,
    read by the same client for `duration_s` after WARM_UP_S."""
    scene_path = Path(next(bundled for bundled in bundled_scenes() if bundled.name == UTM_SCENE).path)
    hokuyo = next(spec.model for spec in load_scene(scene_path).sensors if spec.name == UTM_SENSOR)
    model = HOKUYO_MODELS[hokuyo]
    steal = StealMeter()
    with FloorProcess([floor_spec(UTM_SENSOR, hokuyo, 0, chars=6)]) as floor:
        scans, _, read_late = _stream_one(
            floor.endpoint(UTM_SENSOR).address, me_unlimited(hokuyo), duration_s, lambda now: now + WARM_UP_S,
            on_window=steal.mark,
        )
        load = os.getloadavg()
    return {"hokuyo": hokuyo, "duration_s": duration_s, **_gap_figures(scans, duration_s, model.period_s),
            "read_late": read_late,
            "load_average": [round(value, 2) for value in load], "steal": steal.share}


def _stream_one(
    address: tuple[str, int], command: bytes, duration_s: float, window_from: Callable[[float], float],
    on_window: Callable[[], None] | None = None,
) -> tuple[list[tuple[float, int]], float, int]:
    """One stream asked with `command`: its scans (arrival, time stamp in ms) from `window_from(now at its
    first scan)` for `duration_s` (kernel receive stamps, as the fleet rows), that start (monotonic s) and
    the reads made a period late; `on_window` is called as the window opens and as it closes."""
    sock = socket.create_connection(address, timeout=5)
    stream = _Stream(sock)
    sock.sendall(command)
    sock.setblocking(False)
    selector = selectors.DefaultSelector()
    selector.register(sock, selectors.EVENT_READ, stream)
    realtime_to_monotonic = time.time() - time.monotonic()
    measure_from, opened = math.inf, False
    give_up = time.monotonic() + FIRST_SCAN_TIMEOUT_S
    try:
        while (now := time.monotonic()) < measure_from + duration_s:
            if measure_from == math.inf and stream.arrivals:
                measure_from = window_from(now)
            elif measure_from == math.inf and now > give_up:
                raise RuntimeError(f"no scan within {FIRST_SCAN_TIMEOUT_S:g} s")
            if not opened and measure_from <= now:
                opened = True
                stream.forget()  # the window starts here: forget the warm-up
                if on_window is not None:
                    on_window()
            for _ in selector.select(timeout=0.05):
                stream.receive(realtime_to_monotonic)
        if on_window is not None:
            on_window()
    finally:
        selector.close()
        sock.close()
    kept = [(arrival, stamp) for arrival, stamp in zip(stream.arrivals, stream.stamps) if arrival >= measure_from]
    return kept, measure_from, stream.read_late


def _gap_figures(scans: list[tuple[float, int]], duration_s: float, period_s: float) -> dict:
    """Each scan's gap to the previous against the period: the share within UTM_TOLERANCE, deviation
    percentiles; and each scan's lateness against its own time stamp (the least delayed one defining
    the offset, as the fleet rows)."""
    arrivals = [arrival for arrival, _ in scans]
    gaps = np.diff(arrivals) if len(arrivals) > 1 else np.array([np.nan])
    deviation = np.abs(gaps - period_s) / period_s
    offset = np.array([arrival - stamp / 1000.0 for arrival, stamp in scans]) if scans else np.array([np.nan])
    lateness = (offset - offset.min()) * 1000.0
    return {
        "scans_received": len(arrivals),
        "rate": len(arrivals) / (duration_s / period_s),
        "within_5pct": float(np.mean(deviation <= UTM_TOLERANCE)),
        "gap_deviation_p50_ms": float(np.percentile(deviation, 50)) * period_s * 1000.0,
        "gap_deviation_p99_ms": float(np.percentile(deviation, 99)) * period_s * 1000.0,
        "gap_deviation_max_ms": float(np.max(deviation)) * period_s * 1000.0,
        "lateness_p99_ms": float(np.percentile(lateness, 99)),
    }


def utm_lines(row: dict, floor: dict | None = None) -> list[str]:
    def gaps(row: dict) -> str:
        return (f"rate {row['rate']:.1%}, gaps within {UTM_TOLERANCE:.0%} of the period {row['within_5pct']:.2%},"
                f" deviation p50 {row['gap_deviation_p50_ms']:.2f} / p99 {row['gap_deviation_p99_ms']:.2f}"
                f" / max {row['gap_deviation_max_ms']:.2f} ms, lateness p99 {row['lateness_p99_ms']:.2f} ms"
                f"  load {' '.join(f'{value:g}' for value in row['load_average'])}, {steal_text(row.get('steal', math.nan))}")

    lines = [
        f"serve: {row['scene']}'s {row['hokuyo']} alone under {row['model']}, ME over TCP, {row['duration_s']:g} s over simulated"
        f" {row['window_sim_s'][0]:g}..{row['window_sim_s'][1]:g} s (its slowest instant: {row['slowest_at_s']:g} s): {gaps(row)}",
    ]
    if "daemon_wakes" in row:
        lines.append(f"  the daemon: {_counter_text(row)}")
    if floor is not None:
        lines.append(f"  its floor (a bare timerfd sender of the same ME message, {floor['duration_s']:g} s): {gaps(floor)}")
    return lines


def _counter_text(row: dict) -> str:
    wakes = row["daemon_wakes"]
    late = " ".join(f">{ms}ms {row[f'daemon_late_{ms}ms']}" for ms in (1, 2, 5))
    return (f"scans waited for {row['daemon_scan_waits']}, sent late {row['daemon_late']}, skipped {row['daemon_skipped']};"
            f" timer wake-ups {wakes}, late {late}")


def bench_section(quick: bool) -> tuple[dict, list[str]]:
    """`lrf-emulator bench --section serve`: N = 1, 10, 40 URGs under `physical`, 8 UST-10LX (40 Hz) under
    `formsma2011` and under `physical` and their floor, then the moonshot (100 URGs + 20 LMS200 under `formsma2011`;
    not in a quick run: its start-up alone takes ~10 s), the dense-plume fleet (40 URGs inside railway's plume,
    two workers), rescue's UTM-30LX-EW streaming ME under `physical` over its slowest instant (40 s; quick: 10 s)
    and its floor, then the capacity curve (`capacity.py`). Quick: 5 s each, else 30 s."""
    duration = 5.0 if quick else 30.0
    rows = [measure_serve(count, duration) for count in (1, 10, 40)]
    count, hokuyo = UST_ROW
    rows += [measure_serve(count, duration, model=preset, hokuyo=hokuyo) for preset in UST_PRESETS]
    rows.append(measure_serve_floor(count, duration, hokuyo=hokuyo))
    # the floor again with the CPU the `physical` row's workers used, kept busy beside the senders
    rows.append(measure_serve_floor(count, duration, hokuyo=hokuyo, burn_cores=worker_cores(rows[-2])))
    if not quick:
        urgs, lms, model = MOONSHOT
        rows.append(measure_serve(urgs, duration, model=model, lms_count=lms))
    # the dense-plume fleet (URGs inside railway's plume, two workers): whether it fits on 2 cores
    rows.append(measure_serve(DENSE_PLUME_FLEET, duration, workers=DENSE_PLUME_WORKERS, dense_plume=True))
    from emulator.bench.capacity import bench_curves  # the fleet past what its worker computes

    utm = measure_utm_stream(duration_s=10.0 if quick else UTM_WINDOW_S)
    utm_floor = measure_utm_floor(duration_s=10.0 if quick else UTM_WINDOW_S)
    curves, curve_lines = bench_curves(quick)
    return ({"serve": rows, "utm_stream": utm, "utm_floor": utm_floor, **curves},
            [*table_lines(rows), *utm_lines(utm, utm_floor), *curve_lines])
