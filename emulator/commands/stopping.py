"""Stop signals: every command ends cleanly on SIGINT, SIGTERM, SIGHUP or SIGQUIT.

Until `serve`'s loop takes them over (and for every other command) they raise
`Interrupted`, so whatever was made so far (a pty symlink, a half-built
daemon) is undone by the code that made it, and nothing prints a traceback.
"""

from __future__ import annotations

# The C module, imported at once: `signal` builds its enums for a few ms after start-up, a window in
# which a ^C used to land and print a traceback before these handlers were in place.
import _signal

STOP_SIGNALS = (_signal.SIGINT, _signal.SIGTERM, _signal.SIGHUP, _signal.SIGQUIT)


class Interrupted(KeyboardInterrupt):
    """A stop signal arrived; the command exits with status 128 + its number.
    A KeyboardInterrupt, so asyncio lets it through its callbacks as it does ^C."""

    def __init__(self, signum: int) -> None:
        import signal

        super().__init__(signal.Signals(signum).name)
        self.signum = signum


_caught: list[int] = []  # every stop signal that arrived
_raising = False


def hold_stop_signals() -> None:
    """Catch stop signals from now on, holding them until `raise_on_stop_signals` (a
    signal that lands while modules are still being imported must not print a traceback)."""
    for signum in STOP_SIGNALS:
        _signal.signal(signum, _on_stop_signal)


def raise_on_stop_signals() -> None:
    """From now on a stop signal raises `Interrupted` in the main thread; one held so far, at once."""
    global _raising
    hold_stop_signals()
    _raising = True
    if _caught:
        raise Interrupted(_caught[0])


def caught() -> bool:
    """Whether a stop signal has arrived: a library that catches BaseException around its
    imports (trimesh does) can swallow the `Interrupted`, so `serve` asks again."""
    return bool(_caught)


def _on_stop_signal(signum: int, frame: object) -> None:
    _caught.append(signum)
    if _raising:
        raise Interrupted(signum)
