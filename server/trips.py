"""Open trips, in memory: one car on one corridor, its token, fix history, advisor memory and last advice.

A trip's state only changes in :meth:`server.advising.Engine.on_fix`, after the fix has been validated,
and in one synchronous step on the event loop, so a bad request never leaves a trip half-updated.
Everything a trip records is plain data of bounded size (numbers, strings, lists of floats; the fix trace
capped by ``max_trace_fixes``, observed phases by ``ObservedLights.MAX_RUNS``), so it can be serialised to
a shared store.
"""

from __future__ import annotations

import hmac
import secrets
import time
import uuid
from array import array
from typing import TYPE_CHECKING

from advisory.advice.advisor import AdvisorMemory
from spat_feed.corridors import Corridor
from spat_feed.scenarios import FeedScenario

from spat_feed.plans import phase_class, state_at, state_start_s

from server.errors import ApiError
from server.gps import RouteMatcher, Track
from server.ratelimit import TokenBucket

if TYPE_CHECKING:
    from server.spat import TripSpat


class ObservedLights:
    """What a trip saw of each light on live SPaT, for its score: per intersection id, phase runs
    ``[start_unix_s, end_unix_s, class]`` (class ``red``, ``amber``, ``green`` or ``unknown``, J2735 by meaning).

    Each fix adds the state at its time; a run starts when the SPaT says the state began (``state_start_s``),
    so the boundaries are the controller's, not the fixes'. About two runs per light and cycle.
    """

    MAX_RUNS = 512
    """Runs kept per light (~4 h of 60 s cycles); older ones are dropped."""

    __slots__ = ("runs",)

    def __init__(self) -> None:
        self.runs: dict[int, list[list]] = {}

    def add(self, t_unix_s: float, readings) -> None:
        for ix_id, reading in readings.items():
            plan = reading.plan
            if plan is None or not reading.fresh:
                continue
            cls = phase_class(state_at(plan, t_unix_s)).value
            start = state_start_s(plan, t_unix_s)
            start = t_unix_s if not start > -1e18 else min(start, t_unix_s)
            runs = self.runs.setdefault(ix_id, [])
            if runs and runs[-1][2] == cls and start <= runs[-1][1] + 1e-6:
                runs[-1][1] = t_unix_s
                continue
            if runs:
                runs[-1][1] = max(runs[-1][1], min(start, t_unix_s))
                start = max(start, runs[-1][1])
            runs.append([start, t_unix_s, cls])
            if len(runs) > self.MAX_RUNS:
                del runs[0]


class Trip:
    """One car on one corridor. ``trace_*``: accepted on-route fixes with a speed, for the trip score
    (stations along the route extended beyond its ends)."""

    __slots__ = (
        "id", "token", "corridor", "matcher", "timing", "vehicle", "entry_unix_s", "created_unix_s", "scenario", "spat",
        "track", "memory", "last", "bucket", "trace_t", "trace_v", "trace_x", "n_fixes", "last_seen_s", "tables",
        "client", "units", "params", "observed", "n_rejected",
    )  # fmt: skip

    def __init__(
        self, corridor: Corridor, matcher: RouteMatcher, scenario: FeedScenario, spat: TripSpat, vehicle: str,
        created_unix_s: float, bucket: TokenBucket, dropout_s: float, tables=None, *, client: str = "", units: str = "metric",
        params=None, observe_spat: bool = False, max_speed_mps: float = 50.0,
    ) -> None:  # fmt: skip
        self.id = uuid.uuid4().hex
        self.token = f"{self.id[:8]}.{secrets.token_urlsafe(24)}"
        self.corridor = corridor
        self.matcher = matcher
        self.scenario = scenario
        self.timing = scenario.timing.name
        self.entry_unix_s = scenario.entry_unix_s
        self.spat = spat
        self.vehicle = vehicle
        self.created_unix_s = created_unix_s
        self.bucket = bucket
        self.track = Track(dropout_s, max_speed_mps=max_speed_mps)
        self.memory: AdvisorMemory | None = None
        self.last: dict | None = None  # the latest advisory, fields of server.schemas.AdviceOut
        self.trace_t = array("d")
        self.trace_v = array("d")
        self.trace_x = array("d")
        self.n_fixes = 0
        self.last_seen_s = time.monotonic()
        self.tables = tables
        self.client = client  # who created it (API key id or client address): per-client quotas
        self.units = units  # "metric" or "imperial": the spoken speeds
        self.params = params  # the advisor's settings for this trip (units)
        self.observed = ObservedLights() if observe_spat else None  # live SPaT: what the trip saw, for its score
        self.n_rejected = 0  # fixes rejected as implausible (jumps)


class TripStore:
    """Trips by id and by token. Tokens are random; comparing them is constant-time."""

    def __init__(self, max_trips: int, max_per_client: int = 0) -> None:
        self.max_trips = max_trips
        self.max_per_client = max_per_client
        self._trips: dict[str, Trip] = {}
        self._by_token: dict[str, str] = {}
        self._per_client: dict[str, int] = {}

    def __len__(self) -> int:
        return len(self._trips)

    def add(self, trip: Trip) -> None:
        self.check_capacity(trip.client)
        self._trips[trip.id] = trip
        self._by_token[trip.token] = trip.id
        self._per_client[trip.client] = self._per_client.get(trip.client, 0) + 1

    def open_for(self, client: str) -> int:
        return self._per_client.get(client, 0)

    def check_capacity(self, client: str | None = None) -> None:
        if client is not None and self.max_per_client and self._per_client.get(client, 0) >= self.max_per_client:
            raise ApiError(429, "too_many_trips_for_client", f"this client already holds its maximum of {self.max_per_client} open trips; end one (POST /v1/trips/{{id}}/end) or wait for idle ones to expire",
                           headers={"Retry-After": "60"})  # fmt: skip
        if len(self._trips) >= self.max_trips:
            raise ApiError(503, "too_many_trips", f"the service holds its maximum of {self.max_trips} open trips; end one or retry later",
                           headers={"Retry-After": "30"})  # fmt: skip

    @staticmethod
    def touch(trip: Trip) -> None:
        """The trip is in use (a request or a WebSocket message): it is not idle."""
        trip.last_seen_s = time.monotonic()

    def get(self, trip_id: str) -> Trip:
        trip = self._trips.get(trip_id)
        if trip is None:
            raise ApiError(404, "unknown_trip", f"no open trip {trip_id!r} (never created, ended or expired)")
        return trip

    def authorize(self, trip_id: str, token: str | None) -> Trip:
        """The trip if ``token`` is its token: 404 unknown trip, 401 no/invalid token, 403 another trip's token."""
        trip = self.get(trip_id)
        if not token:
            raise ApiError(401, "unauthorized", "missing bearer token: send 'Authorization: Bearer <trip token>'",
                           headers={"WWW-Authenticate": "Bearer"})  # fmt: skip
        if hmac.compare_digest(token.encode(), trip.token.encode()):
            trip.last_seen_s = time.monotonic()
            return trip
        if self._by_token.get(token) is not None:
            raise ApiError(403, "forbidden", "this token belongs to another trip")
        raise ApiError(401, "unauthorized", "invalid bearer token for this trip", headers={"WWW-Authenticate": "Bearer"})

    def is_open(self, trip: Trip) -> bool:
        return self._trips.get(trip.id) is trip

    def pop(self, trip_id: str) -> Trip:
        trip = self.get(trip_id)
        del self._trips[trip_id]
        self._by_token.pop(trip.token, None)
        left = self._per_client.get(trip.client, 1) - 1
        if left > 0:
            self._per_client[trip.client] = left
        else:
            self._per_client.pop(trip.client, None)
        return trip

    def idle(self, ttl_s: float, now_s: float | None = None) -> list[str]:
        now = time.monotonic() if now_s is None else now_s
        return [tid for tid, trip in self._trips.items() if now - trip.last_seen_s > ttl_s]

    def all(self) -> list[Trip]:
        return list(self._trips.values())
