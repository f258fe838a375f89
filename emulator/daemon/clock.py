"""Simulated time. The daemon runs a `WallClock`; tests inject a `ManualClock`."""

from __future__ import annotations

import math
import time
from typing import Callable

MIN_SPEED = 1e-3  # simulated seconds per wall second: slower is a pause in all but name (pause for that)
MAX_SPEED = 1000.0  # beyond this scans could not keep up anyway


class WallClock:
    """Simulated seconds advance at `speed` × wall seconds, unless paused.

    Speed and pause can change while the daemon runs (the control API's
    `PATCH /api/clock`): simulated time is continuous at the change, it only
    runs at another rate from then on. A paused clock's `wall_delay` is
    infinite: nothing simulated comes due until it resumes.
    """

    def __init__(self, speed: float = 1.0, start_s: float = 0.0, wall: Callable[[], float] = time.monotonic) -> None:
        _check_speed(speed)
        self._wall = wall
        self.speed = speed
        self.paused = False
        self._origin = wall()
        self._start_s = start_s

    @classmethod
    def from_epoch(cls, epoch_s: float, speed: float = 1.0) -> WallClock:
        """Simulated time = (UNIX time − `epoch_s`) × speed: daemons given one epoch (on
        hosts whose clocks agree) share simulated time without talking to each other.
        Read once here; the clock then runs on the monotonic clock, immune to wall-clock steps."""
        elapsed = time.time() - epoch_s
        if elapsed < 0:
            raise ValueError(f"the epoch {epoch_s} is {-elapsed:.3f} s in the future")
        return cls(speed, start_s=elapsed * speed)

    def now(self) -> float:
        if self.paused:
            return self._start_s
        return self._start_s + (self._wall() - self._origin) * self.speed

    def wall_delay(self, sim_seconds: float) -> float:
        """Wall seconds until `sim_seconds` of simulated time have passed (inf while paused)."""
        if self.paused:
            return math.inf
        return max(0.0, sim_seconds / self.speed)

    def set(self, *, speed: float | None = None, paused: bool | None = None) -> None:
        """Change speed and/or pause from now on; simulated time is continuous at the change."""
        if speed is not None:
            _check_speed(speed)
        self._start_s, self._origin = self.now(), self._wall()
        if speed is not None:
            self.speed = speed
        if paused is not None:
            self.paused = paused


def _check_speed(speed: float) -> None:
    if not (math.isfinite(speed) and MIN_SPEED <= speed <= MAX_SPEED):
        raise ValueError(f"speed must be >= {MIN_SPEED:g} and <= {MAX_SPEED:g}, got {speed}")


class ManualClock:
    """A clock that moves only when told to."""

    def __init__(self, start_s: float = 0.0) -> None:
        self._now = start_s
        self.speed = 1.0
        self.paused = False

    def now(self) -> float:
        return self._now

    def advance(self, seconds: float) -> None:
        self._now += seconds

    def wall_delay(self, sim_seconds: float) -> float:
        return math.inf if self.paused else max(0.0, sim_seconds)

    def set(self, *, speed: float | None = None, paused: bool | None = None) -> None:
        if speed is not None:
            _check_speed(speed)
            self.speed = speed
        if paused is not None:
            self.paused = paused
