"""Dependencies as ``Annotated`` aliases; they work for HTTP routes and WebSockets (``HTTPConnection``).

All are ``async def``: they never block, and a sync dependency would cost a thread-pool hop per request.
"""

from __future__ import annotations

import hmac
from typing import Annotated

from fastapi import Depends, Path
from starlette.requests import HTTPConnection

from server.advising import Engine
from server.audio import Speech
from server.config import Settings
from server.errors import ApiError
from server.metrics import Metrics
from server.trips import Trip


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


def bearer_token(conn: HTTPConnection) -> str | None:
    """The bearer token from ``Authorization``, else (WebSocket clients that cannot set headers) ``?token=``."""
    auth = conn.headers.get("authorization")
    if auth:
        scheme, _, value = auth.partition(" ")
        if scheme.lower() == "bearer" and value.strip():
            return value.strip()
        return None
    return conn.query_params.get("token") or None


async def get_trip(conn: HTTPConnection, trip_id: TripId) -> Trip:
    """The trip named in the path, if the request carries its token (404 / 401 / 403 otherwise)."""
    return conn.app.state.engine.trips.authorize(trip_id, bearer_token(conn))


TripDep = Annotated[Trip, Depends(get_trip)]


async def require_api_key(conn: HTTPConnection) -> None:
    """Creating trips needs one of ``ECO_API_KEYS`` as bearer token, when keys are configured."""
    keys = conn.app.state.settings.api_keys
    if not keys:
        return
    token = bearer_token(conn)
    if token is None:
        raise ApiError(401, "unauthorized", "creating a trip needs an API key: 'Authorization: Bearer <key>'", headers={"WWW-Authenticate": "Bearer"})
    if not any(hmac.compare_digest(token.encode(), key.encode()) for key in keys):
        raise ApiError(403, "forbidden", "this API key is not accepted")


ApiKeyDep = Annotated[None, Depends(require_api_key)]
