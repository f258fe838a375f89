"""Live history is bounded (scene/live.py `LiveState.prune`): a long session holds a bounded number of
events, and every instant at or after the horizon evaluates bit for bit as with the whole history."""

from __future__ import annotations

import os
import pickle
import signal

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from emulator.control.events import ControlError
from emulator.control.session import LiveSession
from emulator.daemon.clock import ManualClock
from emulator.daemon.service import PRUNE_STEP_S, Daemon
from emulator.scene import load_scene
from emulator.scene.drive import Twist
from emulator.daemon.workers import WorkerPool
from emulator.optics import World
from emulator.scene.live import (LIVE_KEEP_S, LiveState, PlumeChange, PoseChange, RegionChange, TwistChange,
                                 emission_segments, event_record, live_horizon)
from emulator.scene.model import Pose
from emulator.scene.plumes import particles_at
from emulator.sensors import create_sensor

SCENE = load_scene("rescue-live")  # a live robot, a door on keyframes, plume "smoulder" (lifetime 15 s), two regions
PLUME = SCENE.plumes[0]


def _event(kind: int, time_s: float, value: float):
    if kind == 0:
        return RegionChange(time_s, "east_room", round(0.001 + 0.05 * value, 6))
    if kind == 1:
        return PlumeChange(time_s, "smoulder", rate=1.0 + 4.0 * value, wind=(value - 0.5, 0.0, 0.0))
    if kind == 2:
        return PlumeChange(time_s, "smoulder", emitting=value > 0.5)
    if kind == 3:
        return PoseChange(time_s, "robot", Pose((2.0 + value, 1.5, 0.0), (0.0, 0.0, 360.0 * value)))
    # resolved already (until given): no solids needed, the pruned and the whole state move alike
    return TwistChange(time_s, "robot", Twist(0.3 * value, 0.0, value - 0.5), until_s=time_s + 0.5)


def _assert_same_at(pruned: LiveState, whole: LiveState, times: np.ndarray) -> None:
    for time_s in times:
        assert pruned.region_density(0, time_s) == whole.region_density(0, time_s)
        assert pruned.plume_state("smoulder", time_s) == whole.plume_state("smoulder", time_s)
        assert pruned.body_twist("robot", time_s) == whole.body_twist("robot", time_s)
        a = particles_at(PLUME, SCENE.seed, 0, time_s, pruned.plume_segments(0))
        b = particles_at(PLUME, SCENE.seed, 0, time_s, whole.plume_segments(0))
        np.testing.assert_array_equal(a.index, b.index)
        np.testing.assert_array_equal(a.centers, b.centers)
        np.testing.assert_array_equal(a.half_sizes, b.half_sizes)
    a, b = pruned.bodies.frames("robot", times), whole.bodies.frames("robot", times)
    np.testing.assert_array_equal(a.positions, b.positions)
    np.testing.assert_array_equal(a.rotations, b.rotations)


@settings(max_examples=60, deadline=None)
@given(
    st.lists(st.tuples(st.integers(0, 4), st.floats(0.0, 3.0), st.floats(0.0, 1.0)), min_size=1, max_size=120),
    st.floats(0.5, 20.0),
)
def test_scans_after_the_horizon_are_bit_identical_to_the_whole_history(steps, keep_s) -> None:
    pruned, whole = LiveState(SCENE), LiveState(SCENE)
    time_s, applied = 0.0, []
    for kind, gap_s, value in steps:
        time_s = round(time_s + gap_s, 6)
        event = _event(kind, time_s, value)
        pruned.apply(event)
        whole.apply(event)
        pruned.prune(time_s - keep_s)
        # appended changes recompute only the last parts: the same segments as from every change
        applied.append(event)
        changes = [step for step in applied if isinstance(step, PlumeChange)]
        assert whole.plume_segments(0) == (emission_segments(PLUME, changes) if changes else None)
    horizon = time_s - keep_s
    assert pruned.horizon == horizon
    times = np.unique(np.concatenate([[horizon, time_s, time_s + 20.0], np.linspace(horizon, time_s + 20.0, 17)]))
    _assert_same_at(pruned, whole, times)
    # a restarted worker starts from the pruned state, through a pipe (pickled)
    restored = LiveState(SCENE)
    restored.restore(pickle.loads(pickle.dumps(pruned.export())))
    assert restored.generation == whole.generation
    _assert_same_at(restored, whole, times)
    # what the whole history held at the horizon, the pruned one holds too: later changes agree as well
    for state in (pruned, whole, restored):
        state.apply(_event(1, round(time_s + 0.25, 6), 0.3))
        state.apply(_event(4, round(time_s + 0.5, 6), 0.9))
    _assert_same_at(pruned, whole, times)
    _assert_same_at(restored, whole, times)


def test_instants_and_changes_before_the_horizon_are_refused() -> None:
    state = LiveState(SCENE)
    for i in range(400):
        state.apply(_event(4, 1.0 + i * 0.1, 0.7))
    state.prune(30.0)
    with pytest.raises(ValueError, match="horizon"):
        state.bodies.frames("robot", np.array([29.9, 31.0]))
    with pytest.raises(ValueError, match="horizon"):
        state.apply(RegionChange(29.0, "east_room", 0.02))
    with pytest.raises(ValueError, match="horizon"):
        state.plume_state("smoulder", 10.0)
    state.bodies.frames("robot", np.array([30.0, 31.0]))  # at and after it: answered


def _daemon() -> tuple[ManualClock, Daemon, LiveSession]:
    clock = ManualClock()
    daemon = Daemon(SCENE, clock=clock, workers=0)
    return clock, daemon, LiveSession(daemon)


def test_a_100_hz_twist_stream_for_100_000_commands_holds_a_bounded_history() -> None:
    clock, daemon, session = _daemon()
    window = int((LIVE_KEEP_S + PRUNE_STEP_S) * 100)  # twists within the horizon (moved on a second at a time)
    try:
        for i in range(100_000):
            clock._now = i * 0.01
            session.apply(TwistChange(round(i * 0.01 + 1e-6, 6), "robot", Twist(0.0, 0.0, 0.4 if i % 2 else -0.4),
                                      until_s=round(i * 0.01 + 0.5, 6)))
        held = daemon.live.held()
        assert held <= 2 * window + 2, held  # cut once half is droppable: at most twice the window
        assert len(daemon.live.bodies.live_events("robot").times) == held
        assert len(session.events) <= 10_000 and session.applied == 100_000
        now = clock.now()
        assert live_horizon(now) - PRUNE_STEP_S <= daemon.live.horizon <= live_horizon(now)
        daemon.live.body_pose("robot", now)  # now is still answered
    finally:
        session.close()
        daemon.close()


def test_20_000_plume_and_region_changes_hold_a_bounded_history() -> None:
    clock, daemon, session = _daemon()
    spacing_s = 0.5
    try:
        for i in range(20_000):
            clock._now = i * spacing_s
            at = round(i * spacing_s + 1e-6, 6)
            session.apply(PlumeChange(at, "smoulder", rate=2.0 + i % 3, wind=(0.1 * (i % 5), 0.0, 0.0)) if i % 2
                          else RegionChange(at, "corridor_haze", 0.01 + 0.001 * (i % 7)))
        # a plume keeps its changes of the last LIVE_KEEP_S + lifetime seconds, a region those of LIVE_KEEP_S
        bound = 2 * ((LIVE_KEEP_S + PRUNE_STEP_S + PLUME.lifetime) + LIVE_KEEP_S + PRUNE_STEP_S) / spacing_s + 4
        assert daemon.live.held() <= bound, daemon.live.held()
        assert len(daemon.live.plume_segments(0)) <= 2 * (LIVE_KEEP_S + 2 * PLUME.lifetime) / spacing_s
        assert sum(len(rates.times) for rates in session.limits.particles._plumes.values()) <= bound
    finally:
        session.close()
        daemon.close()


def test_a_change_before_the_horizon_is_a_409() -> None:
    clock, daemon, session = _daemon()
    try:
        for i in range(200):
            clock._now = i * 1.0
            session.apply(RegionChange(i + 1e-6, "east_room", 0.02))
        with pytest.raises(ControlError) as refused:
            session.apply(TwistChange(1.0, "robot", Twist(0.1, 0.0, 0.0)))
        assert refused.value.status == 409 and "horizon" in str(refused.value)
    finally:
        session.close()
        daemon.close()


def test_a_restarted_worker_starts_from_the_pruned_state_and_scans_as_the_whole_history() -> None:
    """With `live_state`, the pool keeps no event: a restarted worker gets the daemon's pruned state."""
    whole_world = World(SCENE)
    whole = create_sensor(SCENE, "urg", world=whole_world)
    main = LiveState(SCENE)  # the daemon's record of the live changes
    pool = WorkerPool(SCENE, ["urg"], on_restart=lambda line: None, live_state=main.export)
    pool.start()

    def apply(event) -> list:
        event = main.apply(event)
        whole_world.apply(event)
        main.prune(event.time_s - 3.0)
        return pool.apply([{**event_record(event), "gen": main.generation}, {"op": "prune", "t": main.horizon}])

    try:
        for i in range(200):
            at = round(0.5 + 0.1 * i, 6)
            apply(TwistChange(at, "robot", Twist(0.2, 0.0, 0.3 if i % 20 < 10 else -0.3)) if i % 3
                  else RegionChange(at, "corridor_haze", 0.02 + 0.01 * (i % 4)))
        assert pool._events == []  # nothing kept for replays: the state is
        assert main.held() < 200 / 2
        os.kill(pool.pids[0], signal.SIGKILL)
        for future in apply(TwistChange(21.0, "robot", Twist(0.1, 0.0, 0.0))):
            future.result(timeout=120)
        for time_s in (main.horizon + 0.5, 20.5, 21.3):  # a scan also looks a revolution back
            scan = pool.executor().submit(pool.sensor("urg").scan, time_s).result(timeout=120)
            np.testing.assert_array_equal(scan.values, whole.scan(time_s).values)
    finally:
        pool.close()
