"""The control API's HTTP and WebSocket server (docs/control.md), on the daemon's asyncio loop.

Every answer is JSON. Client mistakes get a 4xx with `{"error", "key"}` in
the scene loader's words (404 unknown name or path, 400 a refused value or
body, 405 a method the path does not take, 409 a change the resource does
not allow, 413 a body over 64 KiB, 401 a missing or wrong token, 429 changes
to one thing faster than control/change_rate.py allows). Bodies are
read within 64 KiB, WebSocket messages too; each WebSocket client has a
bounded queue of outgoing messages, and a client that stops reading is
dropped when it fills, so it neither grows the daemon's memory nor delays
its scans.
"""

from __future__ import annotations

import asyncio
import hmac
import ipaddress
import json
import logging
import struct
import time
from socket import SO_LINGER, SO_SNDBUF, SOL_SOCKET
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import Any, Awaitable, Callable

from aiohttp import WSCloseCode, WSMsgType, web

from emulator.control.events import ControlError, event_json
from emulator.control.scan_feed import ScanFeed
from emulator.control.session import LiveSession
from emulator.control.change_rate import FLOODING_REASON, REFUSALS_BURST, REFUSALS_RATE_HZ, ChangeRate, TokenBucket, changeable
from emulator.errors import UserError
from emulator.scene.live import ClockChange, LiveEvent

MAX_BODY_BYTES = 64 * 1024
POSE_STREAM_HZ = 20.0  # `{"type": "poses"}` messages a second while a live body moves
# `{"type": "state"}` messages a second at most: a 125 Hz twist stream would otherwise cost the loop a
# state (~1 ms) per twist; the changes in between share one message, which carries the latest state.
STATE_MESSAGE_HZ = 20.0
CLIENT_QUEUE_MESSAGES = 32  # outgoing messages a WebSocket client may fall behind by before it is dropped
# The kernel's send buffer of a WebSocket client: what a client that stops reading can hold
# besides its queue (loopback autotuning would let it grow to megabytes).
CLIENT_SEND_BUFFER_BYTES = 256 * 1024
# What stopping the daemon waits for its WebSocket clients' close handshakes and for the requests under
# way; then they are reset. A client that never answers (or has a backlog of messages queued before its
# close) must not hold the daemon's exit.
CLOSE_TIMEOUT_S = 1.0
DEFAULT_ADDRESS = "127.0.0.1:8765"

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class ControlAddress:
    host: str
    port: int

    @property
    def url(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"http://{host}:{self.port}"

    @property
    def loopback(self) -> bool:
        if self.host == "localhost":
            return True
        try:
            return ipaddress.ip_address(self.host).is_loopback
        except ValueError:
            return False


def parse_control_address(text: str) -> ControlAddress | None:
    """`HOST:PORT` (IPv6 as `[::1]:PORT`; port 0 picks a free one) → address; `off` → None."""
    if text == "off":
        return None
    host, sep, port = text.rpartition(":")
    host = host[1:-1] if host.startswith("[") and host.endswith("]") else host
    if not sep or not host or not port.isdigit() or not 0 <= int(port) <= 65535:
        raise UserError(f"--control {text!r}: expected HOST:PORT (PORT 0..65535) or off")
    return ControlAddress(host, int(port))


def check_exposure(address: ControlAddress | None, token: str | None) -> None:
    """A control API beyond loopback changes the world for anyone who reaches it: it needs a token."""
    if token is not None and not token.strip():
        raise UserError("--control-token: expected a token, got an empty one (leave the option out for none on loopback)")
    if address is not None and not address.loopback and not token:
        raise UserError(
            f"--control {address.host}:{address.port} is not a loopback address: give --control-token TOKEN "
            "(clients then send Authorization: Bearer TOKEN)"
        )


class ControlServer:
    """The API of one daemon's `LiveSession`, listening on `address`."""

    def __init__(
        self, session: LiveSession, address: ControlAddress, token: str | None = None,
        rate_clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.session = session
        self.changes = ChangeRate(changeable(session.scene), rate_clock)  # per thing changed: control/change_rate.py
        self._rate_clock = rate_clock
        self.address = address
        self._token = token
        self._serializer = ThreadPoolExecutor(max_workers=1, thread_name_prefix="control-json")
        self._clock_changed = asyncio.Event()
        self.feed = ScanFeed(session.daemon, self._serializer, self._clock_changed)
        self._clients: set[_Client] = set()
        self._state_pending = False
        self._state_sent_at = -float("inf")  # the loop's time of the last state message
        self._runner: web.AppRunner | None = None
        self._unlisten = session.listen(self._changed)
        self._pose_stream: asyncio.Task | None = None

    async def start(self) -> ControlAddress:
        """Listen; the address actually bound (a port 0 resolved). UserError if it cannot."""
        app = web.Application(client_max_size=MAX_BODY_BYTES, middlewares=[self._errors_as_json, self._authorize])
        app.router.add_get("/api/scene", self._scene)
        app.router.add_get("/api/state", self._state)
        app.router.add_get("/api/events", self._events)
        app.router.add_put("/api/bodies/{name}/pose", self._change_handler("pose"))
        app.router.add_put("/api/bodies/{name}/twist", self._change_handler("twist"))
        app.router.add_patch("/api/smoke/regions/{name}", self._change_handler("region"))
        app.router.add_patch("/api/smoke/plumes/{name}", self._change_handler("plume"))
        app.router.add_patch("/api/clock", self._change_handler("clock"))
        app.router.add_get("/api/sensors/{name}/scan", self._scan)
        app.router.add_get("/api/ws", self._websocket)
        self._runner = web.AppRunner(app, access_log=None, handle_signals=False, shutdown_timeout=CLOSE_TIMEOUT_S)
        await self._runner.setup()
        site = web.TCPSite(self._runner, self.address.host, self.address.port, reuse_address=True)
        try:
            await site.start()
        except OSError as error:
            await self._runner.cleanup()
            raise UserError(
                f"--control {self.address.host}:{self.address.port}: cannot listen: {error.strerror or error} "
                "(choose another with --control HOST:PORT, or --control off)"
            ) from None
        sockets = site._server.sockets if site._server is not None else []  # type: ignore[union-attr]
        port = sockets[0].getsockname()[1] if sockets else self.address.port
        self.address = ControlAddress(self.address.host, port)
        live = self.session.daemon.live
        if live is not None and live.bodies.live_names:
            self._pose_stream = asyncio.get_running_loop().create_task(self._stream_poses())
        return self.address

    async def close(self) -> None:
        self._unlisten()
        if self._pose_stream is not None:
            self._pose_stream.cancel()
        self.feed.close()
        clients = list(self._clients)
        if clients:
            await asyncio.wait([asyncio.ensure_future(client.close()) for client in clients], timeout=CLOSE_TIMEOUT_S)
        for client in clients:
            client.reset()
        if self._runner is not None:
            await self._runner.cleanup()
        self._serializer.shutdown(wait=False, cancel_futures=True)

    # ----------------------------------------------------------------------- middlewares

    @web.middleware
    async def _errors_as_json(self, request: web.Request, handler: Callable[[web.Request], Awaitable]) -> web.StreamResponse:
        """aiohttp's own refusals (no route, wrong method, body too large) and ours, as JSON."""
        try:
            return await handler(request)
        except ControlError as error:
            return web.json_response(error.json(), status=error.status)
        except web.HTTPException as error:
            if error.status < 400:
                raise
            message = {404: "no such resource", 405: f"method {request.method} not allowed on {request.path}",
                       413: f"body over {MAX_BODY_BYTES} bytes"}.get(error.status, error.reason)
            headers = {"Allow": error.headers["Allow"]} if "Allow" in error.headers else None
            return web.json_response({"error": message, "key": ""}, status=error.status, headers=headers)

    @web.middleware
    async def _authorize(self, request: web.Request, handler: Callable[[web.Request], Awaitable]) -> web.StreamResponse:
        if self._token is not None:
            given = request.headers.get("Authorization", "")
            if not hmac.compare_digest(given.encode(), f"Bearer {self._token}".encode()):
                raise ControlError(401, "missing or wrong token: send Authorization: Bearer TOKEN", "Authorization")
        return await handler(request)

    # ----------------------------------------------------------------------- resources

    async def _scene(self, request: web.Request) -> web.Response:
        return web.Response(text=self.session.scene_text, content_type="application/json")

    async def _state(self, request: web.Request) -> web.Response:
        return web.json_response(self.session.state())

    async def _events(self, request: web.Request) -> web.Response:
        return web.Response(text=self.session.event_log_text(), content_type="application/json")

    def _change_handler(self, op: str) -> Callable[[web.Request], Awaitable[web.Response]]:
        async def handle(request: web.Request) -> web.Response:
            if (refused := self.changes.refusal(op, request.match_info.get("name"))) is not None:
                error, wait_s = refused  # before the body is even read; answered when the next token is due
                await asyncio.sleep(wait_s)
                raise error
            body = await _json_body(request)
            event = self.session.request(op, request.match_info.get("name"), body)
            return web.json_response({"applied": event_json(event), "state": self.session.state()})

        return handle

    async def _scan(self, request: web.Request) -> web.Response:
        name = request.match_info["name"]
        self._check_sensor(name)
        return web.Response(text=await self.feed.latest(name), content_type="application/json")

    def _check_sensor(self, name: str) -> None:
        """404 for a name the scene lacks, 409 for a sensor of the scene this daemon does not serve."""
        shown = json.dumps(name)[:60]
        if self.feed.spec(name) is None:
            known = ", ".join(spec.name for spec in self.session.scene.sensors)
            raise ControlError(404, f"no sensor named {shown} (known: {known})", f"sensors[{name[:60]}]")
        if not self.feed.serves(name):
            raise ControlError(409, f"sensor {shown} is not served by this daemon (see --sensors)", f"sensors[{name}]")

    async def _websocket(self, request: web.Request) -> web.WebSocketResponse:
        socket = web.WebSocketResponse(max_msg_size=MAX_BODY_BYTES, heartbeat=None)
        await socket.prepare(request)
        connection = request.transport.get_extra_info("socket") if request.transport is not None else None
        if connection is not None:
            connection.setsockopt(SOL_SOCKET, SO_SNDBUF, CLIENT_SEND_BUFFER_BYTES)
        client = _Client(socket, request.transport, self._drop, TokenBucket(REFUSALS_RATE_HZ, REFUSALS_BURST, self._rate_clock()))
        self._clients.add(client)
        client.offer(self._state_message())
        try:
            async for message in socket:
                if message.type != WSMsgType.TEXT:
                    client.offer(_error_message(ControlError(400, "expected a text message holding a JSON object")))
                    continue
                if (pause_s := self._on_message(client, message.data)) > 0:
                    if not client.refusals.take(self._rate_clock()):
                        log.info("control: a WebSocket client kept sending changes past the rate; closed")
                        await client.close_flooding()
                        break
                    await asyncio.sleep(pause_s)  # this client's next message waits for the next token
        finally:
            self._drop(client)
            client.stop_writing()
        return socket

    def _on_message(self, client: _Client, text: str) -> float:
        """A subscription or a change; a refused one is answered with an error message, the socket stays.
        The seconds to wait before reading the client's next message (a change over the rate: until the
        thing's next token)."""
        try:
            data = _parse_json(text)
            if not isinstance(data, dict):
                raise ControlError(400, "expected a JSON object with \"op\" or \"subscribe\"")
            if "subscribe" in data:
                self._subscribe(client, data)
                return 0.0
            body = dict(data)
            op, name = body.pop("op", None), body.pop("name", None)
            if (refused := self.changes.refusal(op, name)) is not None:
                client.offer(_error_message(refused[0]))
                return refused[1]
            self.session.request(op, name, body)
        except ControlError as error:
            client.offer(_error_message(error))
        return 0.0

    def _subscribe(self, client: _Client, data: dict) -> None:
        names = data["subscribe"]
        if set(data) != {"subscribe"}:
            raise ControlError(400, "subscribe: expected {\"subscribe\": [sensor names]} alone", "subscribe")
        if not isinstance(names, list) or not all(isinstance(name, str) for name in names):
            raise ControlError(400, "subscribe: expected a list of sensor names", "subscribe")
        names = list(dict.fromkeys(names))  # a 64 KiB message may name one sensor 6000 times: each is checked once
        for name in names:
            self._check_sensor(name)
        self.feed.unsubscribe(client.offer)
        for name in names:
            self.feed.subscribe(name, client.offer)

    def _drop(self, client: _Client) -> None:
        self.feed.unsubscribe(client.offer)
        self._clients.discard(client)

    # ----------------------------------------------------------------------- state on every change

    def _changed(self, event: LiveEvent) -> None:
        if isinstance(event, ClockChange):
            self._clock_changed.set()
        if not self._state_pending and self._clients:  # changes until the message is sent share it
            self._state_pending = True
            loop = asyncio.get_running_loop()
            loop.call_at(max(loop.time(), self._state_sent_at + 1.0 / STATE_MESSAGE_HZ), self._send_state)

    def _send_state(self) -> None:
        self._state_pending = False
        self._state_sent_at = asyncio.get_running_loop().time()
        message = self._state_message()
        for client in list(self._clients):
            client.offer(message)

    def _state_message(self) -> str:
        return json.dumps({"type": "state", **self.session.state()})

    async def _stream_poses(self) -> None:
        """While a live body moves by a twist, its pose to every client POSE_STREAM_HZ times a second
        (and once more when it has stopped), as `{"type": "poses", "time_s", "bodies": {name: pose}}`."""
        moved = False
        while True:
            await asyncio.sleep(1.0 / POSE_STREAM_HZ)
            if not self._clients:
                continue
            poses = self.session.live_poses()
            moving = any(any(pose["twist"].values()) for pose in poses["bodies"].values())
            if moving or moved:
                message = json.dumps({"type": "poses", **poses})
                for client in list(self._clients):
                    client.offer(message)
            moved = moving


class _Client:
    """One WebSocket client: outgoing messages through a bounded queue, written by its own task."""

    def __init__(
        self, socket: web.WebSocketResponse, transport: asyncio.BaseTransport | None, on_drop: Callable[[_Client], None],
        refusals: TokenBucket,
    ) -> None:
        self.refusals = refusals  # what this connection may be refused before it is closed (control/change_rate.py)
        self._socket = socket
        self._transport = transport
        self._on_drop = on_drop
        self._queue: asyncio.Queue[str] = asyncio.Queue(CLIENT_QUEUE_MESSAGES)
        self._writer = asyncio.get_running_loop().create_task(self._write())
        self.dropped = False

    def offer(self, message: str) -> None:
        if self.dropped:
            return
        try:
            self._queue.put_nowait(message)
        except asyncio.QueueFull:
            log.info("control: a WebSocket client stopped reading; dropped")
            self.dropped = True
            self._on_drop(self)
            self.reset()

    def stop_writing(self) -> None:
        """Its writer ended (the connection is over): a task left waiting on the queue would be
        destroyed pending when the loop collects it, with a warning on the daemon's stderr."""
        self._writer.cancel()

    def reset(self) -> None:
        """The connection reset at once, discarding what the kernel still holds for it either way."""
        self._writer.cancel()
        if self._transport is not None and not self._transport.is_closing():
            connection = self._transport.get_extra_info("socket")
            if connection is not None:
                connection.setsockopt(SOL_SOCKET, SO_LINGER, struct.pack("ii", 1, 0))
            self._transport.abort()

    async def _write(self) -> None:
        try:
            while True:
                await self._socket.send_str(await self._queue.get())
        except (ConnectionError, RuntimeError, asyncio.CancelledError):
            pass

    async def close(self) -> None:
        self._writer.cancel()
        await self._socket.close()

    async def close_flooding(self) -> None:
        """Closed with 1008 and the reason, then reset: a flooder's backlog is never read, and one that
        does not answer the close within CLOSE_TIMEOUT_S cannot hold the connection open."""
        self._writer.cancel()
        try:
            await asyncio.wait_for(self._socket.close(code=WSCloseCode.POLICY_VIOLATION, message=FLOODING_REASON.encode()), CLOSE_TIMEOUT_S)
        except (asyncio.TimeoutError, ConnectionError, RuntimeError):
            pass
        self.reset()


async def _json_body(request: web.Request) -> Any:
    raw = await request.read()  # at most client_max_size, else 413
    if not raw.strip():
        return {}
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError:
        raise ControlError(400, "body: not UTF-8 text") from None
    return _parse_json(text)


def _parse_json(text: str) -> Any:
    try:
        return json.loads(text)
    except (ValueError, RecursionError):
        raise ControlError(400, "body: not valid JSON") from None


def _error_message(error: ControlError) -> str:
    return json.dumps({"type": "error", "status": error.status, **error.json()})
