"""A scene file's limits applied to live changes that depend on what came before: particles and body speed.

Most limits hold for a value alone (a density, a position) and are checked as
the scene loader checks them. Two depend on the changes before:

- The particle budget. A scene file's plumes may have at most MAX_PARTICLES_ALIVE particles alive at
once (Σ rate × lifetime, scene/loader.py). A live change of a plume's rate
must keep to the same budget, and the particles born at an earlier, higher
rate stay alive for their lifetime: from instant T on, plume p can have at
most lifetime_p × (the highest rate in force at any time in
[T − lifetime_p, ∞)) particles alive. `ParticleBudget` keeps each plume's
rate changes and sums that bound over the plumes, so a change is refused if
the bound it leaves could exceed the budget at any instant after it.
- A live body's speed: from its pose before (the last live pose, else its
  scene pose at 0 s) to a new pose at a later instant it moves at most
  MAX_BODY_SPEED_M_S, as between two keyframe rows; a pose at the same
  instant as the last one is a jump, as two rows at one time are.

`LiveLimits` holds both for one scene; the control API asks it before a
change is applied and tells it each change applied (the event log's too).
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass, field

from emulator.scene.loader import MAX_BODY_SPEED_M_S, MAX_PARTICLES_ALIVE, particle_budget_words
from emulator.scene.model import Plume, Scene, Vec3


@dataclass
class _Rates:
    """One plume's rate from each instant on, ascending: the scene's rate from -inf."""

    lifetime: float
    times: list[float] = field(default_factory=list)
    rates: list[float] = field(default_factory=list)

    def with_change(self, time_s: float, rate: float) -> tuple[list[float], list[float]]:
        """The rates if `rate` held from `time_s` on (a change replaces the ones stamped after it)."""
        keep = bisect.bisect_right(self.times, time_s)
        return [*self.times[:keep], time_s], [*self.rates[:keep], rate]

    def peak_alive(self, time_s: float, times: list[float], rates: list[float]) -> float:
        """lifetime × the highest rate in force from `time_s − lifetime` on."""
        first = max(bisect.bisect_right(times, time_s - self.lifetime) - 1, 0)
        return self.lifetime * max(rates[first:])


    def prune(self, horizon_s: float) -> None:
        """Forget the rates no change at or after `horizon_s` looks at (those superseded `lifetime` before it)."""
        count = bisect.bisect_right(self.times, horizon_s - self.lifetime) - 1
        if count > 0 and 2 * count >= len(self.times):
            del self.times[:count], self.rates[:count]


class ParticleBudget:
    """Each plume's rate history, and the particles alive at once it allows from an instant on."""

    def __init__(self, plumes: tuple[Plume, ...]) -> None:
        self._plumes = {plume.name: _Rates(plume.lifetime, [float("-inf")], [plume.rate]) for plume in plumes}

    def alive_after(self, name: str, time_s: float, rate: float) -> float:
        """The most particles alive at once from `time_s` on if plume `name`'s rate became `rate` then."""
        total = 0.0
        for plume_name, rates in self._plumes.items():
            times, values = rates.with_change(time_s, rate) if plume_name == name else (rates.times, rates.rates)
            total += rates.peak_alive(time_s, times, values)
        return total

    def refusal(self, name: str, time_s: float, rate: float) -> str | None:
        """Why the budget refuses plume `name`'s rate `rate` from `time_s` on (None: it fits)."""
        alive = self.alive_after(name, time_s, rate)
        if alive <= MAX_PARTICLES_ALIVE:
            return None
        return (
            f"rate {rate:.6g}/s would make up to {alive:.6g} plume particles alive at once "
            f"(Σ rate × lifetime, counting those born at earlier rates); {particle_budget_words()}"
        )

    def add(self, name: str, time_s: float, rate: float) -> None:
        """Plume `name` emits at `rate` from `time_s` on."""
        rates = self._plumes[name]
        rates.times, rates.rates = rates.with_change(time_s, rate)


    def prune(self, horizon_s: float) -> None:
        """Forget what no change stamped at or after `horizon_s` is checked against."""
        for rates in self._plumes.values():
            rates.prune(horizon_s)


class LiveLimits:
    """The scene's particle budget and body speed, for one session's live changes in order."""

    def __init__(self, scene: Scene) -> None:
        self.particles = ParticleBudget(scene.plumes)
        self._poses: dict[str, tuple[float, Vec3]] = {body.name: (0.0, body.pose.position) for body in scene.bodies}

    def speed_refusal(self, name: str, time_s: float, position: Vec3) -> str | None:
        """Why body `name` may not stand at `position` from `time_s` on (None: it may)."""
        last_time, last_position = self._poses[name]
        if time_s <= last_time:
            return None
        distance = math.dist(last_position, position)
        speed = distance / (time_s - last_time)
        if speed <= MAX_BODY_SPEED_M_S:
            return None
        return (
            f"moving {distance:.6g} m in {time_s - last_time:.6g} s is {speed:.6g} m/s; "
            f"a body may move at most {MAX_BODY_SPEED_M_S:g} m/s"
        )

    def add_pose(self, name: str, time_s: float, position: Vec3) -> None:
        self._poses[name] = (time_s, position)
