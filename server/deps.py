"""Dependencies as ``Annotated`` aliases; they work for HTTP routes and WebSockets (``HTTPConnection``).

All are ``async def``: they never block, and a sync dependency would cost a thread-pool hop per request.
Tokens come from headers only (``Authorization: Bearer``, or ``X-API-Key`` for an API key); the WebSocket
handshake alone may carry the trip token as ``?token=`` (browsers cannot set headers there).
"""

from __future__ import annotations

import hmac
from typing import Annotated

from fastapi import Depends, Path
from starlette.requests import HTTPConnection

from server.advising import Engine
from server.audio import Speech
from server.config import Settings
from server.web.errors import ApiError
from server.web.metrics import Metrics
from server.admission.quotas import ANONYMOUS_PREFIX, anonymous_allowed, key_id
from server.trips import Trip

API_KEY_HEADER = "x-api-key"


async def get_engine(conn: HTTPConnection) -> Engine:
    return conn.app.state.engine


async def get_settings(conn: HTTPConnection) -> Settings:
    return conn.app.state.settings


async def get_metrics(conn: HTTPConnection) -> Metrics:
    return conn.app.state.metrics


async def get_speech(conn: HTTPConnection) -> Speech:
    return conn.app.state.speech


EngineDep = Annotated[Engine, Depends(get_engine)]
SettingsDep = Annotated[Settings, Depends(get_settings)]
MetricsDep = Annotated[Metrics, Depends(get_metrics)]
SpeechDep = Annotated[Speech, Depends(get_speech)]
TripId = Annotated[str, Path(min_length=1, max_length=64, description="trip id from POST /v1/trips")]


def bearer_token(conn: HTTPConnection, *, allow_query: bool = False) -> str | None:
    """The bearer token from ``Authorization``; with ``allow_query`` (the WebSocket handshake) also ``?token=``.

    A REST request carrying ``?token=`` is refused (401) rather than ignored, so the client learns why: a
    token in a URL lands in proxies' and servers' logs."""
    auth = conn.headers.get("authorization")
    if auth:
        scheme, _, value = auth.partition(" ")
        if scheme.lower() == "bearer" and value.strip():
            return value.strip()
        return None
    if b"token" in conn.scope.get("query_string", b"") and "token" in conn.query_params:
        if allow_query:
            return conn.query_params.get("token") or None
        raise ApiError(401, "token_in_query", "send the token in the 'Authorization: Bearer <token>' header; ?token= is accepted only on the WebSocket handshake",
                       headers={"WWW-Authenticate": "Bearer"})  # fmt: skip
    return None


async def get_trip(conn: HTTPConnection, trip_id: TripId) -> Trip:
    """The trip named in the path, if the request carries its token (404 / 401 / 403 otherwise), and one token
    of the trip's request bucket (429 when empty)."""
    return await conn.app.state.engine.trips.authorize(trip_id, bearer_token(conn), take=True)


async def get_trip_to_end(conn: HTTPConnection, trip_id: TripId) -> Trip:
    """As :func:`get_trip`, outside the rate limit: a phone can always end its trip."""
    return await conn.app.state.engine.trips.authorize(trip_id, bearer_token(conn))


TripDep = Annotated[Trip, Depends(get_trip)]
TripToEndDep = Annotated[Trip, Depends(get_trip_to_end)]


def api_key_of(conn: HTTPConnection) -> str | None:
    """The API key a request carries: ``X-API-Key``, else ``Authorization: Bearer``."""
    return conn.headers.get(API_KEY_HEADER) or bearer_token(conn)


def check_api_key(conn: HTTPConnection, what: str) -> str | None:
    """None when no keys are configured; else the matching key's id (``key-<8 hex of its SHA-256>``), or 401/403."""
    keys = conn.app.state.settings.api_keys
    if not keys:
        return None
    token = api_key_of(conn)
    if token is None:
        raise ApiError(401, "unauthorized", f"{what} needs an API key: 'X-API-Key: <key>' or 'Authorization: Bearer <key>'", headers={"WWW-Authenticate": "Bearer"})
    for key in keys:
        if hmac.compare_digest(token.encode(), key.encode()):
            return key_id(key)
    raise ApiError(403, "forbidden", "this API key is not accepted")


def client_address(conn: HTTPConnection) -> str:
    return conn.client.host if conn.client else "unknown"


async def require_api_key(conn: HTTPConnection) -> str:
    """Creating trips needs one of ``ECO_API_KEYS`` when keys are configured, unless ``ECO_ANONYMOUS_TRIPS``
    allows trips without one (a key sent must still be valid). Returns the client the trip is counted against
    for quotas (``server.admission.quotas``): the key's id, else the client's address (``addr-<address>``)."""
    settings = conn.app.state.settings
    if not (anonymous_allowed(settings) and api_key_of(conn) is None):
        if kid := check_api_key(conn, "creating a trip"):
            return kid
    return ANONYMOUS_PREFIX + client_address(conn)


ApiKeyDep = Annotated[str, Depends(require_api_key)]


async def metrics_access(conn: HTTPConnection) -> None:
    """``/metrics`` needs an API key when ``ECO_METRICS_ACCESS=api_key`` (the default) and keys are set."""
    if conn.app.state.settings.metrics_access == "api_key":
        check_api_key(conn, "reading metrics")


MetricsAccessDep = Annotated[None, Depends(metrics_access)]
