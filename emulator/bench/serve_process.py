"""The real `lrf-emulator serve` as a child process, for interop tests and benchmarks.

Measurements and interop checks must see what a driver sees: the installed
daemon, its ptys and sockets, its line pacing. This starts it on the given
endpoints, waits for its `ready SENSOR MODEL URI[ -> /dev/pts/N]` lines
and stops it with SIGTERM, as a service manager would. Its control
API listens on a free loopback port (`control_url`, from its `ready control`
line) unless the arguments say otherwise, so daemons started side by side
never fight over the default port.
"""

from __future__ import annotations

import queue
import signal
import subprocess
import sys
import threading
import time
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from emulator.scene import load_scene


class ServeError(RuntimeError):
    """The daemon did not come up: it exited or printed no `ready` line in time."""


@dataclass(frozen=True)
class ReadyEndpoint:
    """One `ready` line: a sensor served on one endpoint."""

    sensor: str
    model: str
    uri: str
    device: str | None = None  # the pty's /dev/pts/N, for a pty endpoint

    @property
    def path(self) -> str:
        """What a client opens: the pty symlink, or HOST:PORT for TCP."""
        return self.uri.split(":", 1)[1]

    @property
    def address(self) -> tuple[str, int]:
        """(host, port) of a TCP or RFC 2217 endpoint."""
        scheme, host, port = self.uri.split(":")
        if scheme not in ("tcp", "rfc2217"):
            raise ValueError(f"not a TCP endpoint: {self.uri}")
        return host, int(port)


def parse_ready_line(line: str) -> ReadyEndpoint | None:
    """`ready urg urg-04lx pty:/tmp/x -> /dev/pts/3` → ReadyEndpoint; other lines → None."""
    words = line.split()
    if len(words) == 4 and words[0] == "ready":
        return ReadyEndpoint(words[1], words[2], words[3])
    if len(words) == 6 and words[0] == "ready" and words[4] == "->":
        return ReadyEndpoint(words[1], words[2], words[3], words[5])
    return None


def private_endpoints(scene: str | Path, folder: Path) -> list[str]:
    """`SENSOR=pty:FOLDER/SENSOR` for every sensor of the scene: nothing shared with a user's daemon."""
    return [f"{sensor.name}=pty:{folder / sensor.name}" for sensor in load_scene(scene).sensors]


def serve_command() -> list[str]:
    """The installed console script beside this interpreter, else `python -m emulator.cli`."""
    script = Path(sys.executable).with_name("lrf-emulator")
    return [str(script)] if script.exists() else [sys.executable, "-m", "emulator.cli"]


class ServeProcess:
    """`lrf-emulator serve SCENE --endpoint SENSOR=URI ...`, running until `stop()`.

    `endpoints` are `SENSOR=URI` strings; the constructor returns once each
    sensor named there has printed one ready line per URI given for it, and
    raises ServeError (with the daemon's stderr) if it exits or stays silent
    for `timeout_s`. Sensors not named keep the scene's own endpoints.
    The browser view is off unless `extra_args` ask for it (`--view`), so
    daemons started side by side do not compete for its port. `services`
    holds the `ready NAME URL` lines (view, foxglove, control) seen so far;
    `service(NAME)` waits for one.
    """

    def __init__(
        self,
        scene: str | Path,
        endpoints: Sequence[str],
        *,
        extra_args: Sequence[str] = (),
        timeout_s: float = 30.0,
        cwd: str | Path | None = None,
    ) -> None:
        self.args = [*serve_command(), "serve", str(scene)]
        for endpoint in endpoints:
            self.args += ["--endpoint", endpoint]
        self.args += list(extra_args)
        if "--control" not in self.args:
            self.args += ["--control", "127.0.0.1:0"]
        wants_control = self.args[self.args.index("--control") + 1] != "off"
        if "--view" not in self.args:
            self.args += ["--view", "off"]
        self.ready: list[ReadyEndpoint] = []
        self.services: dict[str, str] = {}
        self.control_url: str | None = None
        self._stdout_lines: queue.Queue[str | None] = queue.Queue()
        self._stderr_chunks: list[str] = []
        self.process = subprocess.Popen(
            self.args, cwd=cwd, stdin=subprocess.DEVNULL,
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, bufsize=1,
        )
        self._readers = [
            threading.Thread(target=self._pump_stdout, daemon=True),
            threading.Thread(target=self._pump_stderr, daemon=True),
        ]
        for reader in self._readers:
            reader.start()
        try:
            expected = Counter(endpoint.split("=", 1)[0] for endpoint in endpoints)
            self._wait_ready(expected, timeout_s, wants_control)
        except BaseException:
            self.stop()
            raise

    @property
    def pid(self) -> int:
        return self.process.pid

    @property
    def stderr(self) -> str:
        return "".join(self._stderr_chunks)

    def service(self, name: str, timeout_s: float = 30.0) -> str:
        """The URL of the `ready NAME URL` line (view, foxglove, control), waiting for it."""
        deadline = time.monotonic() + timeout_s
        while name not in self.services:
            try:
                line = self._stdout_lines.get(timeout=max(deadline - time.monotonic(), 0.0))
            except queue.Empty:
                raise ServeError(f"no `ready {name}` line after {timeout_s} s\n{self.stderr}") from None
            if line is None:
                raise ServeError(f"serve exited before `ready {name}`\n{self.stderr}")
            self._note(line)
        return self.services[name]

    def _note(self, line: str) -> None:
        words = line.split()
        if len(words) == 3 and words[0] == "ready":
            self.services[words[1]] = words[2]
            if words[1] == "control":
                self.control_url = words[2]
        ready = parse_ready_line(line)
        if ready is not None:
            self.ready.append(ready)

    def endpoint(self, sensor: str, scheme: str | None = None) -> ReadyEndpoint:
        """The ready endpoint of `sensor` (of the given scheme: "pty" or "tcp")."""
        for ready in self.ready:
            if ready.sensor == sensor and (scheme is None or ready.uri.startswith(scheme + ":")):
                return ready
        raise KeyError(f"{sensor} ({scheme or 'any'}) not among {self.ready}")

    def stats(self, timeout_s: float = 10.0) -> dict[str, int]:
        """The daemon's counters now: SIGUSR1, then its next `stats k=v ...` line on stderr."""
        seen = sum(chunk.startswith("stats ") for chunk in self._stderr_chunks)
        self.process.send_signal(signal.SIGUSR1)
        deadline = time.monotonic() + timeout_s
        while True:
            lines = [chunk for chunk in self._stderr_chunks if chunk.startswith("stats ")]
            if len(lines) > seen:
                return {key: int(value) for key, value in (field.split("=") for field in lines[-1].split()[1:])}
            if time.monotonic() > deadline or self.process.poll() is not None:
                raise ServeError(f"no stats line after SIGUSR1\n{self.stderr}")
            time.sleep(0.005)

    def stop(self, timeout_s: float = 10.0) -> int:
        """SIGTERM, then wait: the daemon's exit status (SIGKILL and ServeError if it hangs)."""
        if self.process.poll() is None:
            self.process.send_signal(signal.SIGTERM)
            try:
                self.process.wait(timeout_s)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()
                raise ServeError(f"serve ignored SIGTERM for {timeout_s} s; killed") from None
        for reader in self._readers:
            reader.join(timeout_s)
        return self.process.returncode

    def __enter__(self) -> ServeProcess:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.stop()

    def _pump_stdout(self) -> None:
        assert self.process.stdout is not None
        for line in self.process.stdout:
            self._stdout_lines.put(line)
        self._stdout_lines.put(None)

    def _pump_stderr(self) -> None:
        assert self.process.stderr is not None
        for line in self.process.stderr:
            self._stderr_chunks.append(line)

    def _wait_ready(self, expected: Counter[str], timeout_s: float, control: bool) -> None:
        deadline = time.monotonic() + timeout_s
        while expected - Counter(ready.sensor for ready in self.ready) or (control and self.control_url is None):
            remaining = deadline - time.monotonic()
            try:
                line = self._stdout_lines.get(timeout=max(remaining, 0.0))
            except queue.Empty:
                missing = expected - Counter(ready.sensor for ready in self.ready)
                raise ServeError(
                    f"not ready after {timeout_s} s: {dict(missing)}: "
                    f"{' '.join(self.args)}\n{self.stderr}"
                ) from None
            if line is None:
                self.process.wait()
                raise ServeError(
                    f"serve exited with status {self.process.returncode} before it was ready: "
                    f"{' '.join(self.args)}\n{self.stderr}"
                )
            self._note(line)
