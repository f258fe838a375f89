"""What a client's reads cost the loop: the event log and a polled scan are encoded once, not per request."""

from __future__ import annotations

import json
from concurrent.futures import Executor, Future

import pytest
from test_twist import Api, run

from emulator.control.events import event_json
from emulator.control.session import EVENTS_SHOWN, plain
from emulator.daemon.scan_cache import ScanCache
from emulator.scene.live import RegionChange
from emulator.sensors import create_sensor


def test_the_event_log_served_is_the_last_events_applied_as_their_json() -> None:
    """GET /api/events serves the JSON text each event got when it was applied (building 10 000 events'
    JSON per request took the loop 34 ms): the last EVENTS_SHOWN events, oldest first, equal to their
    `event_json`, once the kept ones have wrapped round."""

    async def served() -> tuple[list, list]:
        async with Api() as api:
            for index in range(EVENTS_SHOWN + 5):
                api.session.apply(RegionChange(1.0 + 1e-3 * index, "east_room", 1e-4 * (index % 9)))
            async with api.http.get(api.url + "/api/events") as answer:
                assert answer.status == 200 and answer.content_type == "application/json"
                return await answer.json(), [event_json(event) for event in api.session.events]

    log, expected = run(served())
    assert len(log) == EVENTS_SHOWN and log == expected
    assert log[0]["t"] == pytest.approx(1.005) and log[-1]["t"] == pytest.approx(1.0 + 1e-3 * (EVENTS_SHOWN + 4))


class CountingExecutor(Executor):
    """Runs each call at once on the caller's thread, counting them (the feed's serializer, observed)."""

    def __init__(self) -> None:
        self.calls = 0

    def submit(self, function, /, *args, **kwargs) -> Future:
        self.calls += 1
        future: Future = Future()
        future.set_result(function(*args, **kwargs))
        return future


def test_a_scan_polled_many_times_a_period_is_encoded_once_and_again_after_a_change() -> None:
    """GET /api/sensors/{name}/scan encodes each scan once (in the serializer, never on the loop): 20 polls
    within one URG period get one text; the next period, or a live change that replaces the scan, a new one."""

    async def polled() -> tuple[int, list[dict], int, dict, int, dict]:
        async with Api() as api:
            serializer = CountingExecutor()
            api.server.feed._serializer = serializer
            api.daemon.scan_caches["urg"] = ScanCache(create_sensor(api.scene, "urg", api.daemon.world), CountingExecutor())
            api.clock._now = 30.02

            async def get() -> dict:
                async with api.http.get(api.url + "/api/sensors/urg/scan") as answer:
                    assert answer.status == 200 and answer.content_type == "application/json"
                    return await answer.json()

            same = [await get() for _ in range(20)]
            once = serializer.calls
            api.clock._now = 30.12
            later = await get()
            after_period = serializer.calls
            api.session.apply(RegionChange(30.05, "east_room", 0.5))  # from before the scan's instant: it is replaced
            changed = await get()
            return once, same, after_period, later, serializer.calls, changed

    once, same, after_period, later, after_change, changed = run(polled())
    assert once == 1 and all(scan == same[0] for scan in same) and same[0]["time_s"] == pytest.approx(30.0)
    assert after_period == 2 and later["time_s"] == pytest.approx(30.1)
    assert after_change == 3 and changed["time_s"] == pytest.approx(30.1)


def test_the_scene_is_served_as_its_plain_json_made_once() -> None:
    """GET /api/scene: the scene as plain JSON (rescue's takes 8 ms to make), made on the first request and
    kept: the scene of a running daemon never changes."""

    async def served() -> tuple[list, dict]:
        async with Api() as api:
            assert "scene_text" not in vars(api.session)
            bodies = []
            for _ in range(3):
                async with api.http.get(api.url + "/api/scene") as answer:
                    assert answer.status == 200 and answer.content_type == "application/json"
                    bodies.append(await answer.json())
            assert "scene_text" in vars(api.session)
            return bodies, json.loads(json.dumps(plain(api.scene)))

    bodies, expected = run(served())
    assert bodies == [expected] * 3 and expected["name"] == "rescue-live"
