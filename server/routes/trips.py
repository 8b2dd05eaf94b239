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

from server.advising import Engine, parse_fix
from server.web.bodies import JsonBodyRoute
from server.gps import Fix
from server.deps import ApiKeyDep, EngineDep, MetricsDep, TripDep, TripId, TripToEndDep, bearer_token
from server.schemas import AdviceOut, ErrorOut, GpsFixIn, TripCreate, TripCreated, TripLinks, TripOut, TripScoreOut
from server.trips import Trip
from server.score import trip_score

router = APIRouter(prefix="/v1/trips", tags=["trips"], route_class=JsonBodyRoute)  # bodies parsed strictly (server.web.bodies)

ERRORS = {code: {"model": ErrorOut} for code in (401, 403, 404, 422, 429)}


def _trip_out(trip: Trip, engine: Engine) -> dict:
    base = f"/v1/trips/{trip.id}"
    return dict(
        trip_id=trip.id,
        corridor=trip.corridor.name,
        timing=trip.timing,
        vehicle=trip.vehicle,
        units=trip.units,
        entry_unix_s=round(trip.entry_unix_s, 3),
        created_unix_s=round(trip.created_unix_s, 3),
        idle_ttl_s=engine.settings.trip_idle_ttl_s,
        n_fixes=trip.n_fixes,
        links=TripLinks(trip=base, fixes=f"{base}/fixes", advice=f"{base}/advice", stream=f"{base}/stream", audio=f"{base}/advice.wav", spat=f"{base}/spat", end=f"{base}/end"),
    )


@router.post("", response_model=TripCreated, status_code=201, responses={401: {"model": ErrorOut}, 403: {"model": ErrorOut}, 422: {"model": ErrorOut}, 429: {"model": ErrorOut}, 503: {"model": ErrorOut}})
async def create_trip(body: TripCreate, engine: EngineDep, metrics: MetricsDep, client: ApiKeyDep, response: Response) -> TripCreated:
    """Start a trip: a car on a corridor. Returns its id and a bearer token valid for this trip only
    (`Location` gives the trip's URL).

    With the simulated SPaT feed, the lights' timing is relative to the trip's **creation** instant (or
    `entry_unix_s`): the car is taken to enter the zone (station 0) then.
    """
    trip = await engine.create_trip(body, client)
    metrics.trips_created.inc()
    response.headers["Location"] = f"/v1/trips/{trip.id}"
    return TripCreated(**_trip_out(trip, engine), token=trip.token)


@router.get("/{trip_id}", response_model=TripOut, responses=ERRORS)
async def get_trip(trip: TripDep, engine: EngineDep) -> TripOut:
    """The trip: its corridor, timing, vehicle, units, entry and fixes so far."""
    return TripOut(**_trip_out(trip, engine))


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

    Duplicate, older and implausible fixes (a jump along the route no car makes) are ignored: `fix_status`
    says so and the latest advisory is returned.
    \f
    The hot path (a :class:`DirectRoute`): the token is checked first (401 / 403 / 404, as for every trip
    route, then the rate limit, 429), then the body is validated by pydantic straight from the raw bytes (422
    with the same error shape as FastAPI's), then the fix goes inline on the event loop (well under a
    millisecond of pure computation, cheaper than a thread hop) and the trip is saved to its store.
    """
    engine: Engine = request.app.state.engine
    body = await _body(request)

    def parse() -> Fix:
        try:
            return parse_fix(body)
        except ValidationError as exc:
            raise RequestValidationError([{**e, "loc": ("body", *e["loc"])} for e in exc.errors(include_url=False)]) from None

    return _JsonResponse(await engine.apply_fix_json(trip_id, bearer_token(request), parse))


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


class _JsonResponse(Response):
    """A 200 with a JSON body, its headers as ``Response(body, media_type="application/json")`` makes them
    (content-length, content-type), without ``Response.__init__``'s general header building: an advisory per fix."""

    media_type = "application/json"

    def __init__(self, body: bytes) -> None:
        self.status_code = 200
        self.background = None
        self.body = body
        self.raw_headers = [(b"content-length", str(len(body)).encode()), (b"content-type", b"application/json")]


def _json(out: dict) -> Response:
    return _JsonResponse(to_json(out))


@router.get("/{trip_id}/advice", response_model=AdviceOut, responses=ERRORS)
async def get_advice(trip: TripDep, engine: EngineDep) -> Response:
    """The latest advisory (for polling clients)."""
    return _json(engine.latest(trip))


@router.get("/{trip_id}/spat", responses=ERRORS)
async def get_spat(trip: TripDep, engine: EngineDep) -> dict:
    """The trip's current SPaT message (J2735-aligned JSON, see docs/SPAT.md)."""
    return trip.spat.message()


@router.post("/{trip_id}/end", response_model=TripScoreOut, responses=ERRORS)
async def end_trip(trip: TripToEndDep, engine: EngineDep, metrics: MetricsDep) -> TripScoreOut:
    """End the trip (its token stops working) and score it: energy, wear and cost, against the regular driver."""
    trip, samples = await engine.end_trip(trip)
    metrics.trips_closed.labels("ended").inc()
    return await run_in_threadpool(score_of, trip, samples, engine.settings.speed_limit_mps)


def score_of(trip: Trip, samples: tuple[np.ndarray, np.ndarray, np.ndarray], speed_limit_mps: float) -> TripScoreOut:
    """The ended trip's score (``server.score.trip_score``) from what it recorded: ``samples`` = (t, v, x)."""
    t, v, x = samples
    notes = []
    if trip.n_rejected:
        notes.append(f"{trip.n_rejected} fix(es) ignored as implausible jumps")
    if trip.track.reanchors:
        notes.append(f"the track was re-anchored {trip.track.reanchors} time(s) after consistent jumps: the comparison is indicative")
    observed = None if trip.observed is None else trip.observed.runs
    return trip_score(trip.id, trip.scenario, trip.vehicle, t, v, x, speed_limit_mps, observed=observed, notes=notes)
