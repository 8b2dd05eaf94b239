"""Trips over REST: create, send fixes and get advice, poll the latest advice, current SPaT, end and score."""

from __future__ import annotations

import numpy as np
from fastapi import APIRouter, Request, Response
from fastapi.routing import APIRoute
from starlette.requests import ClientDisconnect
from fastapi.exceptions import RequestValidationError
from pydantic import ValidationError
from pydantic_core import to_json
from fastapi.concurrency import run_in_threadpool

from server.advising import Engine, fix_from_schema
from server.deps import ApiKeyDep, EngineDep, MetricsDep, TripDep, TripId, bearer_token
from server.schemas import AdviceOut, ErrorOut, GpsFixIn, TripCreate, TripCreated, TripLinks, TripScoreOut
from server.score import trip_score

router = APIRouter(prefix="/v1/trips", tags=["trips"])

ERRORS = {code: {"model": ErrorOut} for code in (401, 403, 404, 422, 429)}


@router.post("", response_model=TripCreated, status_code=201, responses={401: {"model": ErrorOut}, 403: {"model": ErrorOut}, 422: {"model": ErrorOut}, 429: {"model": ErrorOut}, 503: {"model": ErrorOut}})
async def create_trip(body: TripCreate, engine: EngineDep, metrics: MetricsDep, _: ApiKeyDep) -> TripCreated:
    """Start a trip: a car on a corridor. Returns its id and a bearer token valid for this trip only.

    With the simulated SPaT feed, the lights' timing is relative to the trip's **creation** instant (or
    ``entry_unix_s``): the car is taken to enter the zone (station 0) then.
    """
    trip = await engine.create_trip(body)
    metrics.trips_created.inc()
    base = f"/v1/trips/{trip.id}"
    return TripCreated(
        trip_id=trip.id,
        token=trip.token,
        corridor=trip.corridor.name,
        timing=trip.timing,
        vehicle=trip.vehicle,
        entry_unix_s=trip.entry_unix_s,
        created_unix_s=trip.created_unix_s,
        idle_ttl_s=engine.settings.trip_idle_ttl_s,
        links=TripLinks(fixes=f"{base}/fixes", advice=f"{base}/advice", stream=f"{base}/stream", audio=f"{base}/advice.wav", spat=f"{base}/spat", end=f"{base}/end"),
    )


_FIX_BODY = {"required": True, "content": {"application/json": {"schema": GpsFixIn.model_json_schema()}}}


class DirectRoute(APIRoute):
    """A route for the hot path: its endpoint is called as ``endpoint(request, **path_params)`` and returns a
    ``Response``. FastAPI still documents it (parameters, body via ``openapi_extra``, responses), but skips
    its per-request dependency solving, body pre-reading and response-model serialisation
    (FastAPI's documented extension point: a custom ``APIRoute.get_route_handler``)."""

    def get_route_handler(self):
        endpoint = self.endpoint

        async def handler(request: Request) -> Response:
            return await endpoint(request=request, **request.path_params)

        return handler


async def post_fix(trip_id: TripId, request: Request) -> Response:
    """Send one GPS fix; get the advisory computed at the fix's time.

    Duplicate or older fixes are ignored (``fix_status``), the latest advisory is returned. This is the hot
    path (a :class:`DirectRoute`): the token is checked first (401 / 403 / 404, as for every trip route),
    then the body is validated by pydantic straight from the raw bytes (422 with the same error shape as
    FastAPI's), then the fix goes inline on the event loop (well under a millisecond of pure computation,
    cheaper than a thread hop).
    """
    engine: Engine = request.app.state.engine
    trip = engine.trips.authorize(trip_id, bearer_token(request))
    try:
        fix = GpsFixIn.model_validate_json(await _body(request))
    except ValidationError as exc:
        raise RequestValidationError([{**e, "loc": ("body", *e["loc"])} for e in exc.errors(include_url=False)]) from None
    engine.rate_limit(trip)
    return _json(engine.on_fix(trip, fix_from_schema(fix)))


async def _body(request: Request) -> bytes:
    """The body read straight from ASGI ``receive`` (a few us less than ``Request.body``'s async generator)."""
    chunks = []
    while True:
        message = await request.receive()
        if message["type"] == "http.disconnect":
            raise ClientDisconnect()
        chunks.append(message.get("body", b""))
        if not message.get("more_body", False):
            return b"".join(chunks)


router.add_api_route("/{trip_id}/fixes", post_fix, methods=["POST"], response_model=AdviceOut, responses=ERRORS,
                     openapi_extra={"requestBody": _FIX_BODY}, route_class_override=DirectRoute)  # fmt: skip


def _json(out: dict) -> Response:
    return Response(to_json(out), media_type="application/json")


@router.get("/{trip_id}/advice", response_model=AdviceOut, responses=ERRORS)
async def get_advice(trip: TripDep, engine: EngineDep) -> Response:
    """The latest advisory (for polling clients)."""
    engine.rate_limit(trip)
    return _json(engine.latest(trip))


@router.get("/{trip_id}/spat", responses=ERRORS)
async def get_spat(trip: TripDep, engine: EngineDep) -> dict:
    """The trip's current SPaT message (J2735-aligned JSON, see docs/SPAT.md)."""
    engine.rate_limit(trip)
    return trip.spat.message()


@router.post("/{trip_id}/end", response_model=TripScoreOut, responses=ERRORS)
async def end_trip(trip: TripDep, engine: EngineDep, metrics: MetricsDep) -> TripScoreOut:
    """End the trip (its token stops working) and score it: energy, wear and cost, against the regular driver."""
    trip = await engine.end_trip(trip.id)
    metrics.trips_closed.labels("ended").inc()
    t, v, x = (np.frombuffer(a, dtype=np.float64).copy() for a in (trip.trace_t, trip.trace_v, trip.trace_x))
    return await run_in_threadpool(trip_score, trip.id, trip.scenario, trip.vehicle, t, v, x, engine.settings.speed_limit_mps)
