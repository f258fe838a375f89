"""Live changes held to a rate per thing changed: what a flood of them may cost the daemon.

Every change costs more than its own check: it goes to every worker process,
is held in the live history for a minute of simulated time, and drops the
scans foreseen from its instant; a twist also has its stop searched for on
the loop thread (0.3–1.5 ms on a typical scene, up to 25 ms on the worst a
scene file allows: docs/control.md, "Driving a body by velocity"). Unlimited,
one client sending changes as fast as it can took the loop from every other
client (a WebSocket client sent 18 000 region changes a second, and the URG
beside it got 2 scans in 10 s). So each thing a client can change (a smoke
region, a plume, a live body's pose, its twist, the clock) has a token
bucket: CHANGE_BURST changes at once, refilled at CHANGE_RATE_HZ a second of
wall time (the loop's time, not the simulated clock). A ROS cmd_vel bridge
sends 10–100 twists a second: it always passes, with room for jitter; beyond
the rate a change is refused (HTTP 429, a WebSocket error message naming the
limit) before any work is done, and nothing changes. The limit is per thing,
not per connection, so opening more connections buys no more: what changes
cost stays bounded by the scene's live things × CHANGE_RATE_HZ. Refusing costs
too (40 000 refused WebSocket messages a second took a core): the refusal is
answered when the thing's next token is due, and a WebSocket client's further
messages are not read before then, so a client sending as fast as it can is
paced to about the rate by its own connection's back-pressure, at no cost to
the daemon while it waits. But pacing alone let a killed flooder's backlog,
held in the kernel's socket buffers, go on being applied at the rate for as
long as it took to read (a 5 s flood: 7 s more of changes after its client
was killed). So each WebSocket connection also has a budget of refusals
(REFUSALS_BURST, refilled at REFUSALS_RATE_HZ): a client sending up to about
1.5x the rate never spends it, one sending as fast as it can spends it in
about 4 s and is closed (1008, policy violation), its backlog unread.
Replayed event logs (`--events-in`) are not front-end
commands and are not limited. The values of changes are held to the scene
file's limits (scene/live_limits.py).
"""

from __future__ import annotations

import time
from typing import Callable

from emulator.control.events import ControlError, live_bodies
from emulator.scene.model import Scene

CHANGE_RATE_HZ = 125.0  # sustained changes a second per thing changed: a 100 Hz bridge with 25 % to spare
CHANGE_BURST = 25  # changes one thing may take at once (a bridge that caught up after a stall)
# Refusals one WebSocket connection may draw before it is closed: a flooder paced to the rate is refused
# about CHANGE_RATE_HZ times a second, a client sending 1.5x the rate about half that.
REFUSALS_RATE_HZ = CHANGE_RATE_HZ / 2
REFUSALS_BURST = 250
FLOODING_REASON = f"more than {REFUSALS_BURST} changes refused past the rate; closed"


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


def changeable(scene: Scene) -> dict[tuple[str, str | None], str]:
    """Every (op, name) a client may change in `scene`, with the key its refusal names."""
    things: dict[tuple[str, str | None], str] = {("clock", None): "clock"}
    things.update({("region", region.name): f"smoke.regions[{region.name}]" for region in scene.regions})
    things.update({("plume", plume.name): f"smoke.plumes[{plume.name}]" for plume in scene.plumes})
    for name in live_bodies(scene):
        things.update({("pose", name): f"bodies[{name}].pose", ("twist", name): f"bodies[{name}].twist"})
    return things


class ChangeRate:
    """A token bucket per (op, name) in `things` (`changeable`), on `clock` (seconds, monotonic)."""

    def __init__(
        self, things: dict[tuple[str, str | None], str], clock: Callable[[], float] = time.monotonic,
        rate_hz: float = CHANGE_RATE_HZ, burst: int = CHANGE_BURST,
    ) -> None:
        now = clock()
        self._clock = clock
        self._keys = dict(things)
        self._buckets = {thing: TokenBucket(rate_hz, burst, now) for thing in things}

    def refusal(self, op: object, name: object) -> tuple[ControlError, float] | None:
        """None if `op` on `name` may go now (its token taken), else the 429 naming the limit and the
        seconds until its next token. Anything else passes (an unknown op or name, a body that is not
        live): the change itself then answers 400, 404 or 409, and no bucket is made for it."""
        thing = (op, None if op == "clock" else name)
        bucket = self._buckets.get(thing) if isinstance(op, str) and (name is None or isinstance(name, str)) else None
        if bucket is None or bucket.take(self._clock()):
            return None
        key = self._keys[thing]
        error = ControlError(
            429,
            f"{key}: more than {bucket.rate_hz:g} {op} commands a second{_for_one(op)} (bursts of up to "
            f"{bucket.burst}); refused, nothing changed: send at most {bucket.rate_hz:g} a second",
            key,
        )
        return error, bucket.wait_s()


def _for_one(op: str) -> str:
    return {"region": " for one region", "plume": " for one plume", "pose": " for one body", "twist": " for one body"}.get(op, "")
