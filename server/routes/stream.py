"""WebSocket stream: GPS fixes in, advisories out (one advisory per fix), for the trip's lifetime.

Authenticate with ``Authorization: Bearer <trip token>`` or ``?token=<trip token>`` (the handshake is the
one place a token may ride in the URL: browsers cannot set headers there). A refused connection is
accepted, told why (``{"error": ..., "status": 401|403|404|429}``) and closed with code 4000 + HTTP
status. A bad message gets an error object and the stream goes on; nothing about the trip changes. Every
message keeps the trip alive (``last_seen``). At most ``ws_max_per_trip`` streams per trip are open at once (a
newer one replaces the oldest, which is told why and closed with 4409: ``server.storage.streams``) and
``ws_max_per_client`` per client address (4429 beyond). A fix that comes while the worker sheds load
(``server.admission.overload``) gets ``{"error": "overloaded", "status": 503, ...}`` and is dropped; the stream goes on.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
from collections.abc import Callable

from fastapi import APIRouter, WebSocket, WebSocketDisconnect
from starlette.websockets import WebSocketState
from pydantic import ValidationError

from server.advising import Engine, parse_fix
from server.config import Settings
from server.gps import Fix
from server.admission.overload import RETRY_AFTER_S, Shedder
from server.deps import EngineDep, MetricsDep, SettingsDep, TripId, bearer_token, client_address
from server.web.errors import ApiError, clean_errors, validation_summary
from server.storage.streams import StreamCounts, StreamHandle

router = APIRouter(prefix="/v1/trips", tags=["stream"])


def _parse(text: str) -> Fix:
    try:
        return parse_fix(text)
    except ValidationError as exc:
        errors = clean_errors(exc.errors())
        kind = "malformed_json" if any(e["type"] == "json_invalid" for e in errors) else "validation_error"
        raise ApiError(422, kind, validation_summary(errors), detail=errors) from None


def _error(exc: ApiError) -> str:
    return json.dumps({**exc.body(), "status": exc.status})


def _replaced(ws: WebSocket, per_trip: int) -> Callable[[], None]:
    """What a stream does when a newer one of its trip replaces it (``server.storage.streams``): say why, close 4409."""
    tasks: set[asyncio.Task] = set()

    async def close() -> None:
        exc = ApiError(409, "stream_replaced", f"a newer stream of this trip replaced this one (at most {per_trip} per trip)")
        with contextlib.suppress(WebSocketDisconnect, RuntimeError, OSError):  # the stream may be closing already
            if ws.application_state == WebSocketState.CONNECTED:
                await ws.send_text(_error(exc))
                await ws.close(code=4409, reason=exc.error)

    def on_replaced() -> None:
        task = asyncio.get_running_loop().create_task(close())
        tasks.add(task)
        task.add_done_callback(tasks.discard)

    return on_replaced


@router.websocket("/{trip_id}/stream")
async def stream(ws: WebSocket, trip_id: TripId, engine: EngineDep, metrics: MetricsDep, settings: SettingsDep) -> None:
    counts: StreamCounts = ws.app.state.streams  # or server.storage.streams.RedisStreams
    client = client_address(ws)
    token = bearer_token(ws, allow_query=True)
    try:  # the slot is taken before the handshake completes: a client whose handshake is done holds it
        trip = await engine.trips.authorize(trip_id, token)
        handle = await counts.open(trip.id, client, settings.ws_max_per_trip, settings.ws_max_per_client, _replaced(ws, settings.ws_max_per_trip))
    except ApiError as exc:
        await ws.accept()
        await ws.send_text(_error(exc))
        await ws.close(code=4000 + exc.status, reason=exc.error)
        return
    metrics.ws_open.inc()
    try:
        await ws.accept()
        if handle.replaced:  # replaced before its handshake was done
            handle.on_replaced()
        # The messages are served by a task of its own, which this one awaits: a fix wakes the stream twice (its
        # message, then Redis's reply), and each wake-up of a task resumes every frame it is suspended in, here the
        # ~20 calls of uvicorn, Starlette, FastAPI and the middlewares above this route (issue 30).
        await asyncio.ensure_future(_serve(ws, trip_id, token, engine, settings, handle))
    except WebSocketDisconnect:
        pass
    except RuntimeError:  # sending on a stream closed meanwhile as replaced (starlette: "once a close message has been sent")
        if not handle.replaced:
            raise
    finally:
        await counts.close(handle)
        metrics.ws_open.dec()


async def _serve(ws: WebSocket, trip_id: str, token: str | None, engine: Engine, settings: Settings, handle: StreamHandle) -> None:
    """The stream's messages, each fix answered with its advisory or an error object, until the phone or the trip goes."""
    limit = settings.ws_max_message_bytes
    shedder: Shedder = ws.app.state.shedder
    while True:
        message = await ws.receive()
        if message["type"] == "websocket.disconnect" or handle.replaced:
            break
        text = message.get("text")
        if text is None:
            data = message.get("bytes") or b""
            size = len(data)
            text = data.decode("utf-8", errors="replace") if size <= limit else ""
        else:  # the limit is in bytes, as uvicorn's ws_max_size (a character is 1 to 4 of them)
            size = len(text) if len(text) * 4 <= limit else len(text.encode("utf-8", "surrogatepass"))
        try:
            if size > limit:
                await engine.trips.authorize(trip_id, token)  # the message keeps the trip alive all the same
                raise ApiError(413, "payload_too_large", f"message of {size} bytes, larger than {limit}")
            if (reason := shedder.refusal()) is not None:  # overloaded (server.admission.overload): this fix is dropped, the stream goes on
                raise ApiError(503, "overloaded", shedder.error_body(reason)["message"], headers={"Retry-After": str(RETRY_AFTER_S)})
            shedder.in_flight += 1
            try:
                out = await engine.apply_fix_json(trip_id, token, lambda: _parse(text))
            finally:
                shedder.in_flight -= 1
            await ws.send_text(out.decode())
        except ApiError as exc:
            await ws.send_text(_error(exc))
            if exc.status == 404:
                await ws.close(code=4404, reason="trip ended")
                break
