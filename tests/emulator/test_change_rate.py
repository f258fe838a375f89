"""Live changes held to a rate per thing changed (control/change_rate.py): a token bucket on an injected
clock, refusing with a 429 (HTTP) or an error message (WebSocket) that names the limit, before any work."""

from __future__ import annotations

import json

import pytest
from aiohttp import WSCloseCode, WSMsgType
from test_twist import Api, run

from emulator.control.change_rate import (
    CHANGE_BURST, CHANGE_RATE_HZ, FLOODING_REASON, REFUSALS_BURST, ChangeRate, TokenBucket, changeable,
)
from emulator.scene import load_scene


class Tick:
    """A wall clock the test moves."""

    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


def test_a_bucket_takes_its_burst_then_its_rate_and_a_clock_going_back_adds_nothing() -> None:
    bucket = TokenBucket(rate_hz=100.0, burst=5, now=0.0)
    assert [bucket.take(0.0) for _ in range(7)] == [True] * 5 + [False] * 2
    assert bucket.take(0.005) is False  # half a token
    assert bucket.take(0.010) is True and bucket.take(0.010) is False
    assert bucket.take(-50.0) is False  # back in time: no refill
    assert [bucket.take(10.0) for _ in range(6)] == [True] * 5 + [False]  # a long pause refills to the burst only
    taken = sum(bucket.take(10.0 + k / 1000) for k in range(1, 1001))  # 1 kHz for 1 s: the rate gets through
    assert taken == 100


def test_a_100_hz_bridge_with_jitter_always_passes_and_200_hz_is_held_to_the_rate() -> None:
    clock = Tick()
    limit = ChangeRate({("twist", "robot"): "bodies[robot].twist"}, clock)
    jitter = [0.004, 0.016, 0.0, 0.02, 0.01] * 400  # 100 Hz on average, in pairs and gaps, for 20 s
    for gap in jitter:
        clock.now += gap
        assert limit.refusal("twist", "robot") is None
    refused = 0
    for _ in range(4000):  # then 200 Hz for 20 s
        clock.now += 0.005
        if (refusal := limit.refusal("twist", "robot")) is not None:
            refused += 1
            error, wait_s = refusal
            assert error.status == 429 and error.key == "bodies[robot].twist"
            assert f"more than {CHANGE_RATE_HZ:g} twist commands a second" in error.message
            assert 0.0 < wait_s <= 1.0 / CHANGE_RATE_HZ
    assert 4000 - refused == pytest.approx(20 * CHANGE_RATE_HZ + CHANGE_BURST, abs=2)


def test_a_refusal_says_when_the_next_token_is_due() -> None:
    clock = Tick()
    limit = ChangeRate({("twist", "robot"): "bodies[robot].twist"}, clock, rate_hz=100.0, burst=1)
    assert limit.refusal("twist", "robot") is None
    clock.now += 0.004
    _, wait_s = limit.refusal("twist", "robot")
    assert wait_s == pytest.approx(0.006)
    clock.now += wait_s
    assert limit.refusal("twist", "robot") is None


def test_names_that_are_not_live_things_pass_and_make_no_bucket() -> None:
    clock = Tick()
    limit = ChangeRate(changeable(load_scene("rescue-live")), clock)
    things = dict(limit._buckets)
    for k in range(10_000):
        assert limit.refusal("twist", f"nobody{k}") is None  # the change answers 404 itself
        assert limit.refusal("twist", None) is None
        assert limit.refusal("region", ["east_room"]) is None  # the change answers 400
        assert limit.refusal(["region"], "east_room") is None
        assert limit.refusal("pose", "east_door") is None  # not a live body: the change answers 409
    assert limit._buckets == things


def test_every_live_thing_has_its_own_bucket_named_in_its_refusal() -> None:
    """Each region, plume, live body's pose and twist, and the clock: a burst, then refusals naming it;
    one thing's flood leaves the others their whole burst."""
    clock = Tick()
    scene = load_scene("rescue-live")
    things = changeable(scene)
    assert set(things) == {
        ("clock", None), ("region", "east_room"), ("region", "corridor_haze"), ("plume", "smoulder"),
        ("pose", "robot"), ("twist", "robot"),
    }
    limit = ChangeRate(things, clock)
    for (op, name), key in things.items():
        asked = name if op != "clock" else None
        assert [limit.refusal(op, asked) is None for _ in range(CHANGE_BURST)] == [True] * CHANGE_BURST
        error, wait_s = limit.refusal(op, asked)
        assert error.status == 429 and error.key == key and error.message.startswith(f"{key}: more than 125 {op} commands")
        assert 0.0 < wait_s <= 1.0 / CHANGE_RATE_HZ


def test_the_api_refuses_a_flood_per_body_over_http_and_websocket_and_changes_nothing() -> None:
    clock = Tick()

    async def flood() -> tuple[list[int], dict, list[dict], int, int]:
        async with Api(rate_clock=clock) as api:
            api.clock._now = 1.0
            statuses, refusal = [], {}
            for _ in range(CHANGE_BURST + 10):  # all at one wall instant
                status, answer = await api.call("PUT", "/api/bodies/robot/twist", {"vx": 0.2})
                statuses.append(status)
                if status == 429:
                    refusal = answer
            applied = len(api.session.events)
            async with api.http.ws_connect(api.url + "/api/ws") as ws:
                assert json.loads((await ws.receive(timeout=5)).data)["type"] == "state"
                await ws.send_json({"op": "twist", "name": "robot", "vx": 0.2})
                errors = [json.loads((await ws.receive(timeout=5)).data)]
                clock.now += 0.1  # 12.5 tokens back
                for _ in range(12):
                    await ws.send_json({"op": "twist", "name": "robot", "vx": 0.2})
                await ws.send_json({"op": "twist", "name": "robot", "vx": 0.2})
                while len(errors) < 2:
                    message = json.loads((await ws.receive(timeout=5)).data)
                    if message["type"] == "error":
                        errors.append(message)
            return statuses, refusal, errors, applied, len(api.session.events)

    statuses, refusal, errors, applied, after = run(flood())
    assert statuses == [200] * CHANGE_BURST + [429] * 10
    assert refusal["key"] == "bodies[robot].twist" and "refused, nothing changed" in refusal["error"]
    assert applied == CHANGE_BURST  # the refused ones are not in the log
    assert [error["status"] for error in errors] == [429, 429] and errors[0]["key"] == "bodies[robot].twist"
    assert after == CHANGE_BURST + 12  # the 12 the refill allowed, not the 13th



async def _send_and_settle(api: Api, ws, messages: list) -> int:
    """Send one change and wait until the daemon has applied it or answered it with an error: the test's
    clock then stands where the daemon read it. How many errors came back (0 or 1)."""
    before = len(api.session.events)
    await ws.send_json({"op": "region", "name": "east_room", "density": 0.5})
    while len(api.session.events) == before:
        try:
            message = await ws.receive(timeout=0.001)
        except TimeoutError:
            continue
        messages.append(message)
        if message.type != WSMsgType.TEXT or json.loads(message.data)["type"] == "error":
            return 1
    return 0


def test_a_websocket_client_refused_past_its_budget_is_closed_unread_and_one_at_1_4x_the_rate_is_not() -> None:
    """A flooder (every change at one wall instant) is closed with 1008 once REFUSALS_BURST changes have been
    refused: what it sent after is never applied. A client at 1.4x the rate for 10 s is refused about 500
    times, twice the burst, and stays: the refill (REFUSALS_RATE_HZ) outpaces its refusals."""
    clock = Tick()

    async def flood() -> tuple[list, int]:
        async with Api(rate_clock=clock) as api:
            async with api.http.ws_connect(api.url + "/api/ws") as ws:
                assert json.loads((await ws.receive(timeout=5)).data)["type"] == "state"
                for _ in range(CHANGE_BURST + REFUSALS_BURST + 50):
                    await ws.send_json({"op": "region", "name": "east_room", "density": 0.5})
                messages = []
                while (message := await ws.receive(timeout=10)).type == WSMsgType.TEXT:
                    messages.append(json.loads(message.data))
                return [*messages, message], len(api.session.events)

    async def steady() -> tuple[int, int, bool]:
        async with Api(rate_clock=clock) as api:
            async with api.http.ws_connect(api.url + "/api/ws") as ws:
                messages: list = []
                refused = 0
                for _ in range(1750):
                    clock.now += 1.0 / (1.4 * CHANGE_RATE_HZ)
                    refused += await _send_and_settle(api, ws, messages)
                return refused, len(api.session.events), all(message.type == WSMsgType.TEXT for message in messages)

    messages, applied = run(flood())
    errors = [message for message in messages[:-1] if message["type"] == "error"]
    assert messages[-1].type == WSMsgType.CLOSE and messages[-1].data == WSCloseCode.POLICY_VIOLATION, messages[-1]
    assert messages[-1].extra == FLOODING_REASON
    assert applied == CHANGE_BURST  # none of the 50 after the close
    assert len(errors) <= REFUSALS_BURST + 1 and all(error["status"] == 429 for error in errors)
    refused, applied, stayed = run(steady())
    assert stayed, "the connection was closed"
    assert 2 * REFUSALS_BURST - 50 <= refused <= 2 * REFUSALS_BURST + 50, refused
    assert refused + applied == 1750
