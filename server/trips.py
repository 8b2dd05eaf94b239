"""Open trips, in memory: one car on one corridor, its token, fix history, advisor memory and last advice.

A trip's state only changes in :meth:`server.advising.Engine.on_fix`, after the fix has been validated,
and in one synchronous step on the event loop, so a bad request never leaves a trip half-updated.
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

from server.errors import ApiError
from server.gps import RouteMatcher, Track
from server.ratelimit import TokenBucket

if TYPE_CHECKING:
    from server.spat import TripSpat


class Trip:
    """One car on one corridor. ``trace_*``: accepted on-route fixes with a speed, for the trip score."""

    __slots__ = (
        "id", "token", "corridor", "matcher", "timing", "vehicle", "entry_unix_s", "created_unix_s", "scenario", "spat",
        "track", "memory", "last", "bucket", "trace_t", "trace_v", "trace_x", "n_fixes", "last_seen_s", "tables",
    )  # fmt: skip

    def __init__(
        self, corridor: Corridor, matcher: RouteMatcher, scenario: FeedScenario, spat: TripSpat, vehicle: str,
        created_unix_s: float, bucket: TokenBucket, dropout_s: float, tables=None,
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
        self.track = Track(dropout_s)
        self.memory: AdvisorMemory | None = None
        self.last: dict | None = None  # the latest advisory, fields of server.schemas.AdviceOut
        self.trace_t = array("d")
        self.trace_v = array("d")
        self.trace_x = array("d")
        self.n_fixes = 0
        self.last_seen_s = time.monotonic()
        self.tables = tables


class TripStore:
    """Trips by id and by token. Tokens are random; comparing them is constant-time."""

    def __init__(self, max_trips: int) -> None:
        self.max_trips = max_trips
        self._trips: dict[str, Trip] = {}
        self._by_token: dict[str, str] = {}

    def __len__(self) -> int:
        return len(self._trips)

    def add(self, trip: Trip) -> None:
        self.check_capacity()
        self._trips[trip.id] = trip
        self._by_token[trip.token] = trip.id

    def check_capacity(self) -> None:
        if len(self._trips) >= self.max_trips:
            raise ApiError(503, "too_many_trips", f"the service holds its maximum of {self.max_trips} open trips; end one or retry later",
                           headers={"Retry-After": "30"})  # fmt: skip

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
        return trip

    def idle(self, ttl_s: float, now_s: float | None = None) -> list[str]:
        now = time.monotonic() if now_s is None else now_s
        return [tid for tid, trip in self._trips.items() if now - trip.last_seen_s > ttl_s]

    def all(self) -> list[Trip]:
        return list(self._trips.values())
