"""Twist commands held to a rate per live body: what a flood of them may cost the daemon.

Finding where a twist stops costs the loop thread 0.3–1.5 ms on a typical
scene and up to 25 ms on the worst a scene file allows (docs/control.md,
"Driving a body by velocity"). Unlimited, one client sending them as fast as
it can would hold the loop every other client's scans and answers need.
Each live body therefore has a token bucket: TWIST_BURST commands at once,
refilled at TWIST_RATE_HZ a second of wall time (the loop's time, not the
simulated clock). A ROS cmd_vel bridge sends 10–100 a second: it always
passes, with room for jitter; beyond the rate the command is refused (HTTP
429, a WebSocket error message naming the limit) before any work is done,
and nothing changes. The limit is per body, not per connection, so opening
more connections buys no more: the twists' cost stays bounded by the scene's
live bodies × TWIST_RATE_HZ. Refusing costs too (40 000 refused WebSocket
messages a second took a core): the refusal is answered when the body's next
token is due, and a WebSocket client's further messages are not read before
then, so a client sending as fast as it can is paced to about the rate by its
own connection's back-pressure, at no cost to the daemon while it waits. Replayed event logs (`--events-in`) are not
front-end commands and are not limited. The other live changes cost
microseconds each and are not limited; their values are held to the scene
file's limits (scene/live_limits.py).
"""

from __future__ import annotations

import time
from typing import Callable, Iterable

from emulator.control.events import ControlError

TWIST_RATE_HZ = 125.0  # sustained twist commands a second per live body: a 100 Hz bridge with 25 % to spare
TWIST_BURST = 25  # commands one body may take at once (a bridge that caught up after a stall)


class TokenBucket:
    """`burst` tokens at most, refilled at `rate_hz` a second; each command takes one."""

    def __init__(self, rate_hz: float, burst: int, now: float) -> None:
        self.rate_hz = rate_hz
        self.burst = burst
        self._tokens = float(burst)
        self._last = now

    def take(self, now: float) -> bool:
        """Whether a command at `now` may go (it takes a token); a clock that went back adds nothing."""
        self._tokens = min(self.burst, self._tokens + max(now - self._last, 0.0) * self.rate_hz)
        self._last = max(self._last, now)
        if self._tokens < 1.0:
            return False
        self._tokens -= 1.0
        return True

    def wait_s(self) -> float:
        """Seconds from the last `take` until a token is back."""
        return max(1.0 - self._tokens, 0.0) / self.rate_hz


class TwistRate:
    """A token bucket per name in `bodies` (the scene's live bodies), on `clock` (seconds, monotonic)."""

    def __init__(
        self, bodies: Iterable[str], clock: Callable[[], float] = time.monotonic,
        rate_hz: float = TWIST_RATE_HZ, burst: int = TWIST_BURST,
    ) -> None:
        now = clock()
        self._clock = clock
        self._buckets = {name: TokenBucket(rate_hz, burst, now) for name in bodies}

    def refusal(self, name: object) -> tuple[ControlError, float] | None:
        """None if body `name` may take a twist now (its token taken), else the 429 naming the limit and
        the seconds until its next token. A name that is not a live body passes: the change itself then
        answers 404 or 409, and no bucket is made for it."""
        bucket = self._buckets.get(name) if isinstance(name, str) else None
        if bucket is None or bucket.take(self._clock()):
            return None
        error = ControlError(
            429,
            f"bodies[{name}].twist: more than {bucket.rate_hz:g} twist commands a second for one body "
            f"(bursts of up to {bucket.burst}); refused, nothing changed: send at most {bucket.rate_hz:g} a second",
            f"bodies[{name}].twist",
        )
        return error, bucket.wait_s()
