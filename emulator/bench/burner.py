"""A process that keeps a share of one core busy in bursts, as a daemon's scan workers do.

The floor rows (bare timerfd senders) show what the machine's timer, scheduler and sockets
allow with nothing else running. A daemon also computes its scans on the same cores: 8
UST-10LX under `physical` keep a worker busy for about 0.6 of a core, in bursts of a batch of
scans. Run beside the bare senders, this burner gives the floor under the same CPU demand
(`serve_load.measure_serve_floor(..., burn_cores=...)`), so a daemon row can be read against
what any design that computes its scans on this machine could do: if the daemon matches that
floor, what is left is the machine's; if not, its own loop.

`python -m emulator.bench.burner SHARE [BURST_MS]`: busy for BURST_MS, then idle so that the
busy share of wall time is SHARE (0 < SHARE ≤ 1), until terminated.
"""

from __future__ import annotations

import sys
import time

BURST_MS = 16.0  # a worker's batch: 8 scans of ~2 ms


def idle_after(burst_s: float, share: float) -> float:
    """The pause after a burst of `burst_s` that makes the busy share of wall time `share`."""
    if not 0.0 < share <= 1.0:
        raise ValueError(f"the busy share must lie in (0, 1], not {share}")
    return burst_s * (1.0 - share) / share


def burn(share: float, burst_ms: float = BURST_MS, until: float = float("inf")) -> int:
    """Alternate busy bursts and pauses until `until` (monotonic s); returns the bursts made."""
    burst_s = burst_ms / 1000.0
    pause_s = idle_after(burst_s, share)
    bursts = 0
    while time.monotonic() < until:
        end = time.monotonic() + burst_s
        while time.monotonic() < end:
            pass
        bursts += 1
        if pause_s > 0:
            time.sleep(pause_s)
    return bursts


def main(argv: list[str]) -> None:
    share = float(argv[0])
    burst_ms = float(argv[1]) if len(argv) > 1 else BURST_MS
    try:
        burn(share, burst_ms)
    except KeyboardInterrupt:
        pass


if __name__ == "__main__":
    main(sys.argv[1:])
