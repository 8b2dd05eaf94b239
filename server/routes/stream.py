"""WebSocket stream: GPS fixes in, advisories out (one advisory per fix), for the trip's lifetime.

Authenticate with ``Authorization: Bearer <trip token>`` or ``?token=<trip token>`` (the handshake is the
one place a token may ride in the URL: browsers cannot set headers there). A refused connection is
accepted, told why (``{"error": ..., "status": 401|403|404|429}``) and closed with code 4000 + HTTP
status. A bad message gets an error object and the stream goes on; nothing about the trip changes. Every
message keeps the trip alive (``last_seen``). At most ``ws_max_per_trip`` streams per trip and
``ws_max_per_client`` per client address are open at once (4429 beyond). A fix that comes while the worker
sheds load (``server.overload``) gets ``{"error": "overloaded", "status": 503, ...}`` and is dropped; the stream goes on.
"""

from __future__ import annotations

import json

from fastapi import APIRouter, WebSocket, WebSocketDisconnect
from pydantic import ValidationError
from pydantic_core import to_json

from server.advising import fix_from_schema
from server.gps import Fix
from server.overload import RETRY_AFTER_S, Shedder
from server.deps import EngineDep, MetricsDep, SettingsDep, TripId, bearer_token, client_address
from server.errors import ApiError, clean_errors, validation_summary
from server.schemas import GpsFixIn

router = APIRouter(prefix="/v1/trips", tags=["stream"])


class StreamCounts:
    """Open streams per trip and per client address in this process (bounded: entries leave at zero); with
    a shared trip store, ``server.store.RedisStreams`` counts them across workers (same calls)."""

    def __init__(self) -> None:
        self.by_trip: dict[str, int] = {}
        self.by_client: dict[str, int] = {}

    async def open(self, trip_id: str, client: str, per_trip: int, per_client: int) -> tuple[str, str]:
        if self.by_trip.get(trip_id, 0) >= per_trip:
            raise ApiError(429, "too_many_streams", f"this trip already has {per_trip} open stream(s); close one first")
        if per_client and self.by_client.get(client, 0) >= per_client:
            raise ApiError(429, "too_many_streams", f"this client address already has {per_client} open streams")
        self.by_trip[trip_id] = self.by_trip.get(trip_id, 0) + 1
        self.by_client[client] = self.by_client.get(client, 0) + 1
        return trip_id, client

    async def renew(self, handle: tuple[str, str]) -> None:
        return None

    async def close(self, handle: tuple[str, str]) -> None:
        trip_id, client = handle
        for table, key in ((self.by_trip, trip_id), (self.by_client, client)):
            left = table.get(key, 1) - 1
            if left > 0:
                table[key] = left
            else:
                table.pop(key, None)


def _parse(text: str) -> Fix:
    try:
        return fix_from_schema(GpsFixIn.model_validate_json(text))
    except ValidationError as exc:
        errors = clean_errors(exc.errors())
        kind = "malformed_json" if any(e["type"] == "json_invalid" for e in errors) else "validation_error"
        raise ApiError(422, kind, validation_summary(errors), detail=errors) from None


def _error(exc: ApiError) -> str:
    return json.dumps({**exc.body(), "status": exc.status})


@router.websocket("/{trip_id}/stream")
async def stream(ws: WebSocket, trip_id: TripId, engine: EngineDep, metrics: MetricsDep, settings: SettingsDep) -> None:
    counts: StreamCounts = ws.app.state.streams  # or server.store.RedisStreams
    client = client_address(ws)
    token = bearer_token(ws, allow_query=True)
    try:  # the slot is taken before the handshake completes: a client whose handshake is done holds it
        trip = await engine.trips.authorize(trip_id, token)
        handle = await counts.open(trip.id, client, settings.ws_max_per_trip, settings.ws_max_per_client)
    except ApiError as exc:
        await ws.accept()
        await ws.send_text(_error(exc))
        await ws.close(code=4000 + exc.status, reason=exc.error)
        return
    metrics.ws_open.inc()
    limit = settings.ws_max_message_bytes
    shedder: Shedder = ws.app.state.shedder
    try:
        await ws.accept()
        while True:
            message = await ws.receive()
            if message["type"] == "websocket.disconnect":
                break
            text = message.get("text")
            if text is None:
                data = message.get("bytes") or b""
                size = len(data)
                text = data.decode("utf-8", errors="replace") if size <= limit else ""
            else:  # the limit is in bytes, as uvicorn's ws_max_size (a character is 1 to 4 of them)
                size = len(text) if len(text) * 4 <= limit else len(text.encode("utf-8", "surrogatepass"))
            try:
                await counts.renew(handle)
                if size > limit:
                    await engine.trips.authorize(trip_id, token)  # the message keeps the trip alive all the same
                    raise ApiError(413, "payload_too_large", f"message of {size} bytes, larger than {limit}")
                if (reason := shedder.refusal()) is not None:  # overloaded (server.overload): this fix is dropped, the stream goes on
                    raise ApiError(503, "overloaded", shedder.error_body(reason)["message"], headers={"Retry-After": str(RETRY_AFTER_S)})
                shedder.in_flight += 1
                try:
                    out = await engine.apply_fix(trip_id, token, lambda: _parse(text))
                finally:
                    shedder.in_flight -= 1
                await ws.send_text(to_json(out).decode())
            except ApiError as exc:
                await ws.send_text(_error(exc))
                if exc.status == 404:
                    await ws.close(code=4404, reason="trip ended")
                    break
    except WebSocketDisconnect:
        pass
    finally:
        await counts.close(handle)
        metrics.ws_open.dec()
