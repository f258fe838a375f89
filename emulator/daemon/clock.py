"""Simulated time. The daemon runs a `WallClock`; tests inject a `ManualClock`."""

from __future__ import annotations

import time


class WallClock:
    """Simulated seconds = wall seconds since start × speed."""

    def __init__(self, speed: float = 1.0, start_s: float = 0.0) -> None:
        if speed <= 0:
            raise ValueError(f"speed must be > 0, got {speed}")
        self.speed = speed
        self._origin = time.monotonic()
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
        return self._start_s + (time.monotonic() - self._origin) * self.speed

    def wall_delay(self, sim_seconds: float) -> float:
        """Wall seconds until `sim_seconds` of simulated time have passed."""
        return max(0.0, sim_seconds / self.speed)


class ManualClock:
    """A clock that moves only when told to."""

    def __init__(self, start_s: float = 0.0) -> None:
        self._now = start_s
        self.speed = 1.0

    def now(self) -> float:
        return self._now

    def advance(self, seconds: float) -> None:
        self._now += seconds

    def wall_delay(self, sim_seconds: float) -> float:
        return max(0.0, sim_seconds)
