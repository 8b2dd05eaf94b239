"""The service's core wiring: create trips, and turn one GPS fix into one advisory.

From a fix to an advisory (:meth:`Engine.on_fix`):

1. **Order**: a fix not newer than the trip's last one is a duplicate or late; it changes nothing and the
   latest advisory is returned, flagged.
2. **Map matching** (``server.gps``): station along the corridor, cross-track offset and distance to the
   route, WGS 84 geodesics via pyproj. Farther than ``off_route_m`` (or a fix less accurate than
   ``max_accuracy_m``): the advice pauses and says so.
3. **Speed**: the fix's speed over ground, else the least-squares slope of the last seconds' stations.
4. **SPaT at the fix's own time**: the trip's plans for the next two lights, from the process's shared SPaT
   (``server.spat``: simulated plans, or the latest state per intersection from a feed, MQTT or a log), turned
   into conservative red windows relative to the fix (``spat_feed.prediction.observe``).
5. **Advice**: ``advisory.advice.advisor.advise(observation, memory, params, tables)``; the trip keeps the new memory.
   When the advisor has no speed advice for want of SPaT, the reason says why: ``no_spat``, ``stale_spat``,
   or ``clock_skew`` (the controller's clock is off ours).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import replace

from pydantic_core import from_json, to_json

from advisory.advice.advisor import advise
from advisory.advice.views import Advice, AdvisorMemory, AdvisorParams
from advisory.advice.wording import published_speed_mps
from advisory.evaluation.track import RED_TOLERANCE_M
from advisory.physics.params import VEHICLE_PRESETS
from spat_feed.road.corridors import Corridor
from spat_feed.transport.scenarios import FeedScenario, Uncertainty, resolve_timing

from server.config import Settings
from server.web.errors import ApiError
from server.gps import Fix, RouteMatcher
from server.queue import QUEUE_MESSAGE, QueueBoard
from server.storage.queue_store import SharedBoard
from server.admission.quotas import Creator, address_quota, key_quotas
from spat_feed.prediction.observe import light_view, observation
from server.admission.ratelimit import TokenBucket
from server.schemas import MS_TIMESTAMP_MIN, GpsFixIn, TripCreate
from server.spat import ScenarioSpat, SharedSpat, SpatHub, TripSpat
from server.storage.store import Limits, RedisTrips, make_store, retry_after  # noqa: F401  (retry_after: re-exported)
from server.trips import Trip
from spat_feed.transport.simulator import shared_scenario

ADVISOR_UNITS = {"metric": "kmh", "imperial": "mph"}
"""A trip's ``units`` -> the advisor's spoken speed unit (``AdvisorParams.units``)."""


SAVE_TRIES = 5
"""A fix is applied at most this many times when other workers keep writing its trip first."""

SERVER_PHRASES = {
    "poor_gps": "GPS signal weak. Advice paused.",
    "no_speed": "Waiting for speed.",
    "no_fix": "No position yet.",
    "clock_skew": "Signal clock out of sync. Drive normally.",
    "queue": QUEUE_MESSAGE,
}
"""Wording for the pauses the service decides itself (the advisor words its own)."""


class Engine:
    """Trips, corridors, SPaT sources and tables, and the per-fix pipeline."""

    def __init__(
        self,
        settings: Settings,
        corridors: dict[str, Corridor],
        tables: dict[str, object] | None = None,
        params: AdvisorParams | None = None,
        spat: SpatHub | None = None,
        clock: Callable[[], float] = time.time,
    ) -> None:
        self.settings = settings
        self.corridors = corridors
        self.matchers = {name: RouteMatcher(c) for name, c in corridors.items()}
        self.tables = tables or {}
        self.params = params or AdvisorParams()
        self.spat = spat if spat is not None else SpatHub(settings, corridors, clock)
        self.clock = clock
        self.limits = Limits(settings)
        self.key_quotas = key_quotas(settings)
        """Each API key's quota, by key id (server.admission.quotas)."""
        self.address_quota = address_quota(settings)
        self.trips = make_store(settings, self.limits, self.trip_from_meta, self._release, clock)
        self._params = {units: replace(self.params, units=ADVISOR_UNITS[units]) for units in ADVISOR_UNITS}
        self._approach: dict[str, float] = {}  # corridor -> how far before its entry a fix is on the route
        self.queue: QueueBoard | None = None
        """Queue-aware advice (server.queue): every trip's fix a probe of its corridor's traffic, on every worker with
        the Redis store (its ``shared`` board synced by the app, server.storage.queue_store); None: off."""
        if settings.queue_aware:
            shared = SharedBoard(self.trips.redis, settings.store_prefix, corridors, settings.queue_sync_s, clock) if isinstance(self.trips, RedisTrips) else None
            self.queue = QueueBoard(arrivals_vph=settings.queue_arrivals_vph, connected_share=settings.queue_connected_share, shared=shared)
        self.on_advice: Callable[[Trip, Advice, str, float], None] | None = None  # metrics hooks
        self.on_ignored_fix: Callable[[str], None] | None = None

    @property
    def on_rate_limited(self) -> Callable[[], None] | None:
        return self.limits.on_rate_limited

    @on_rate_limited.setter
    def on_rate_limited(self, hook: Callable[[], None] | None) -> None:
        self.limits.on_rate_limited = hook

    # -- trips ----------------------------------------------------------------------------------------
    def check_time(self, t_unix_s: float, what: str, future_s: float | None = None) -> None:
        now = self.clock()
        s = self.settings
        ahead_s = s.max_fix_future_s if future_s is None else future_s
        if t_unix_s > now + ahead_s:
            hint = " It looks like milliseconds: divide by 1000, or send it as 'timestamp' (W3C Geolocation, ms)." if t_unix_s >= MS_TIMESTAMP_MIN else ""
            raise ApiError(422, "time_out_of_range", f"{what} = {t_unix_s:.3f} is {t_unix_s - now:.1f} s ahead of server time (limit {ahead_s:g} s); check the device clock.{hint}")
        if t_unix_s < now - s.max_fix_past_s:
            raise ApiError(422, "time_out_of_range", f"{what} = {t_unix_s:.3f} is {now - t_unix_s:.1f} s behind server time (limit {s.max_fix_past_s:g} s)")

    async def create_trip(self, body: TripCreate, client: str = "") -> Trip:
        """A new trip for ``client`` (an API key's id, else ``addr-<address>``: ``server.deps.require_api_key``),
        held to the key's quota (any other client: an address's) and, with ``body.device_id``, the device's."""
        s = self.settings
        quota = self.key_quotas.get(client)
        who = Creator(client, body.device_id or "", quota or self.address_quota, anonymous=quota is None)
        await self.trips.admit(who)
        corridor_name = body.corridor or s.default_corridor
        corridor = self.corridors.get(corridor_name)
        if corridor is None:
            raise ApiError(422, "unknown_corridor", f"unknown corridor {corridor_name!r}; choose from {sorted(self.corridors)}")
        vehicle = body.vehicle or s.default_vehicle
        if vehicle not in VEHICLE_PRESETS:
            raise ApiError(422, "unknown_vehicle", f"unknown vehicle {vehicle!r}; choose from {sorted(VEHICLE_PRESETS)}")
        now = self.clock()
        entry = now if body.entry_unix_s is None else body.entry_unix_s
        if body.entry_unix_s is not None:
            self.check_time(entry, "entry_unix_s", s.max_entry_future_s)
        timing = None  # the lights as they run for everyone: the shared SPaT
        if body.timing is not None:  # a scenario of its own (the corridor's plans by name, a paper preset, or "trip"; never a path from a request)
            try:
                timing = resolve_timing(corridor, body.timing, entry, allow_files=False)
            except KeyError as exc:
                raise ApiError(422, "unknown_timing", str(exc.args[0])) from None
            except ValueError as exc:
                raise ApiError(422, "timing_mismatch", str(exc)) from None
        meta = {"corridor": corridor_name, "timing": timing, "entry_unix_s": float(entry), "uncertainty": [s.spat_early_s, s.spat_late_s, s.spat_confidence_frac],
                "vehicle": vehicle, "created_unix_s": now, "client": client, "device": who.device, "units": body.units or corridor_units(corridor), "observe_spat": None}  # fmt: skip
        trip = await self.trip_from_meta(meta)
        try:
            await self.trips.add(trip, who)
        except ApiError:
            await trip.spat.close()
            raise
        return trip

    async def trip_from_meta(self, meta: dict) -> Trip:
        """A trip from what it was created with (:meth:`Trip.meta`; no ``id``: a new trip with a new token).
        Any worker rebuilds a stored trip's corridor, SPaT view and tables from it."""
        s = self.settings
        corridor = self.corridors[meta["corridor"]]
        timing = meta["timing"]
        spat: TripSpat
        if timing is None:  # the shared SPaT (simulated lights from their plans, the others from the process's store)
            scenario = shared_scenario(corridor, meta["entry_unix_s"])
            spat = SharedSpat(self.spat, scenario)
        else:  # a scenario simulated for this trip alone
            if isinstance(timing, str):
                timing = resolve_timing(corridor, timing, meta["entry_unix_s"], allow_files=False)
            scenario = FeedScenario(corridor, timing, meta["entry_unix_s"], Uncertainty(*meta["uncertainty"]))
            spat = ScenarioSpat(scenario, self.clock)
        observe = meta["observe_spat"]
        vehicle, units = meta["vehicle"], meta["units"]
        return Trip(
            corridor, self.matchers[corridor.name], scenario, spat, vehicle, meta["created_unix_s"],
            TokenBucket(s.rate_per_s, s.rate_burst), s.dropout_s,
            tables=self.tables.get(corridor.name) if vehicle == s.default_vehicle else None,
            client=meta["client"], device=meta.get("device", ""), units=units, params=self._params[units],
            observe_spat=spat.live if observe is None else observe,
            max_speed_mps=s.max_speed_mps, trip_id=meta.get("id"),
        )  # fmt: skip

    @staticmethod
    async def _release(trip: Trip) -> None:
        await trip.spat.close()

    async def end_trip(self, trip: Trip) -> tuple[Trip, tuple]:
        """End ``trip`` (authorized): its score samples, then it is removed (404 if another call ended it first)."""
        samples = await self.trips.samples(trip)
        trip = await self.trips.remove(trip.id)
        await trip.spat.close()
        if self.queue is not None:
            self.queue.forget(trip.corridor.name, trip.id)
        return trip, samples

    async def apply_fix(self, trip_id: str, token: str | None, parse: Callable[[], Fix]) -> dict:
        """Authorize (one token of the trip's bucket), parse the fix (``parse`` raises the 422), apply it, and
        save the trip; with a shared store the fix is applied again on fresh state if another worker wrote
        the trip meanwhile (the bucket's token is taken by the first write only)."""
        return (await self._apply(trip_id, token, parse))[1]

    async def apply_fix_json(self, trip_id: str, token: str | None, parse: Callable[[], Fix]) -> bytes:
        """:meth:`apply_fix`'s advisory as JSON (``pydantic_core.to_json``), the answer of the fix routes: a new advisory
        is encoded once for the answer and the trip's state in a shared store (:meth:`server.trips.Trip.last_json`)."""
        trip, out = await self._apply(trip_id, token, parse)
        return trip.last_json() if out is trip.last else to_json(out)

    async def _apply(self, trip_id: str, token: str | None, parse: Callable[[], Fix]) -> tuple[Trip, dict]:
        store = self.trips
        if not store.shared:
            trip = await store.authorize(trip_id, token, take=True)
            return trip, self.on_fix(trip, parse())
        fix = None
        for attempt in range(SAVE_TRIES):
            async with store.hold(trip_id):
                trip = await store.for_fix(trip_id, token)
                if fix is None:
                    fix = parse()
                out = self.on_fix(trip, fix)
                if await store.save(trip, take=attempt == 0):  # also when the fix changed nothing: the copy was current
                    return trip, out
        raise ApiError(503, "trip_busy", "the trip changed under this fix too often (many workers at once); retry", headers={"Retry-After": "1"})

    # -- fixes ----------------------------------------------------------------------------------------
    def latest(self, trip: Trip, fix_status: str = "none") -> dict:
        """The trip's latest advisory (a 'no position yet' one before the first fix), with ``fix_status``.

        Advisories are plain dicts with the fields of :class:`~server.schemas.AdviceOut` (the documented
        response model; tests validate every kind against it): building and dumping the model costs three
        times as much as ``pydantic_core.to_json`` on the dict, on a path taken once a second per car."""
        if trip.last is None:
            return dict(
                trip_id=trip.id, seq=0, t_unix_s=None, fix_status=fix_status, on_route=False, station_m=None, cross_track_m=None,
                offset_m=None, speed_mps=None, speed_source="none", next_intersection_id=None, distance_to_line_m=None,
                spat_fresh=None, action="none", reason="no_fix", target_speed_mps=None, light_red=None, seconds_to_change_s=None,
                light_intersection_id=None, light_distance_m=None, counts_down_to=None,
                message=SERVER_PHRASES["no_fix"], speak=False, source="service", fix_note=None,
            )  # fmt: skip
        return trip.last if trip.last["fix_status"] == fix_status else {**trip.last, "fix_status": fix_status}

    def approach_of(self, corridor: Corridor) -> float:
        """How far before ``corridor``'s zone entry a fix is on the route: ``approach_m``, or with None
        :func:`approach_m` of the corridor. [m]"""
        if self.settings.approach_m is not None:
            return self.settings.approach_m
        found = self._approach.get(corridor.name)
        if found is None:
            found = self._approach[corridor.name] = approach_m(corridor, self.params, self.settings.speed_limit_mps)
        return found

    def on_fix(self, trip: Trip, fix: Fix) -> dict:
        """Apply one validated fix to ``trip`` and return the advisory (see the module docstring)."""
        self.check_time(fix.t_unix_s, "t_unix_s")
        status = trip.track.order(fix.t_unix_s)
        if status != "ok":
            if self.on_ignored_fix is not None:
                self.on_ignored_fix(status)
            return self.latest(trip, status)
        t0 = time.perf_counter()
        s = self.settings
        m = trip.matcher.match(fix.lat_deg, fix.lon_deg)
        poor = fix.accuracy_m is not None and fix.accuracy_m > s.max_accuracy_m
        before = m.route_m < 0.0 and abs(m.cross_track_m) <= s.off_route_m and -m.route_m <= self.approach_of(trip.corridor)
        on_route = (m.offset_m <= s.off_route_m or before) and not poor
        station = m.route_m if before else m.station_m  # on the approach: negative, the first light that much farther
        if on_route and (why := trip.track.implausible(fix.t_unix_s, m.route_m)) is not None:
            trip.n_rejected += 1
            if self.on_ignored_fix is not None:
                self.on_ignored_fix("implausible")
            return {**self.latest(trip, "implausible"), "fix_note": why}
        point = trip.track.add(fix.t_unix_s, m.route_m if on_route else None, fix.speed_mps)
        speed = point.speed_mps if point is not None else fix.speed_mps
        lights = ()
        spat_fresh = None
        if poor:
            advice, memory = Advice("none", "poor_gps", message=SERVER_PHRASES["poor_gps"]), trip.memory
        elif on_route and speed is None:
            advice, memory = Advice("none", "no_speed", message=SERVER_PHRASES["no_speed"]), trip.memory
        else:
            readings = trip.spat.readings(fix.t_unix_s) if on_route else {}
            if trip.observed is not None and readings:
                trip.observed.add(fix.t_unix_s, readings)
            # (a fix just past a stop line, within what GPS can tell, is still at it: lights_station)
            at_m = lights_station(trip.corridor, station, fix.accuracy_m)
            obs = observation(trip.corridor, at_m, speed or 0.0, fix.t_unix_s, readings,
                              trip.corridor.advisory_limit_mps(max(station, 0.0), s.speed_limit_mps), on_route=on_route)
            held = None
            if self.queue is not None:  # the lights as the car meets them in traffic, or "follow the car in front"
                passed = light_passed(trip.corridor, at_m, speed or 0.0, fix.t_unix_s, readings) if on_route else None
                last = trip.last or {}
                obs, held = self.queue.see(trip.corridor.name, trip.id, fix.t_unix_s, obs, last.get("reason"), passed, trip.params, last.get("target_speed_mps"),
                                           -self.approach_of(trip.corridor))  # fmt: skip
            lights = obs.lights
            spat_fresh = lights[0].fresh if lights else None
            fresh = self.queue is not None and trip.last is not None and self.queue.fresh(trip.last["reason"])  # out of a queue: plan anew
            before = None if fresh else trip.memory
            advice, memory = (held, trip.memory) if held is not None else advise(obs, before, trip.params, trip.tables)
            if self.queue is not None and held is None:  # no plan that gives up a green a normal drive makes
                planned, advice = advice, self.queue.check(obs, advice, trip.params, trip.id, trip.last)
                if advice is not planned:
                    memory = heard(memory, before, advice)
            if advice.action == "none" and advice.reason in ("no_spat", "stale_spat") and lights:
                advice = _spat_reason(advice, trip.spat.status(lights[0].intersection_id))
        trip.memory = memory
        trip.n_fixes += 1
        if on_route and speed is not None and trip.n_trace < s.max_trace_fixes:
            trip.trace_t.append(fix.t_unix_s)
            trip.trace_v.append(speed)
            trip.trace_x.append(m.route_m)
        nxt = lights[0] if lights else None
        # the light the countdown is about (the next one, or the one after it when that one binds), named with it
        named_id = advice.light_id if advice.light_id is not None else (nxt.intersection_id if nxt else None)
        named = next((light for light in lights if light.intersection_id == named_id), None) if advice.light_red is not None else None
        countdown = _finite(advice.seconds_to_change_s) if named is not None else None
        out = dict(
            trip_id=trip.id, seq=trip.n_fixes, t_unix_s=round(fix.t_unix_s, 3), fix_status="ok", on_route=on_route,
            station_m=round(station, 2), cross_track_m=round(m.cross_track_m, 2), offset_m=round(m.offset_m, 2),
            speed_mps=None if speed is None else round(speed, 2),
            speed_source=point.speed_source if point is not None else ("gps" if fix.speed_mps is not None else "none"),
            next_intersection_id=nxt.intersection_id if nxt else None, distance_to_line_m=round(nxt.distance_m, 2) if nxt else None,
            spat_fresh=spat_fresh, action=advice.action, reason=advice.reason,
            target_speed_mps=None if advice.target_speed_mps is None else published_speed_mps(advice.target_speed_mps),  # down: never above the limit
            light_red=advice.light_red if named is not None else None, seconds_to_change_s=countdown,
            light_intersection_id=named.intersection_id if named is not None else None,
            light_distance_m=round(named.distance_m, 2) if named is not None else None,
            counts_down_to=advice.counts_down_to if countdown is not None else None, message=advice.message,
            speak=advice.speak, source=advice.source, fix_note=None,
        )  # fmt: skip
        trip.last = out
        if self.on_advice is not None:
            self.on_advice(trip, advice, "ok" if on_route else ("poor_gps" if poor else "off_route"), time.perf_counter() - t0)
        return out


def heard(memory: AdvisorMemory, before: AdvisorMemory | None, told: Advice) -> AdvisorMemory:
    """The advisor's ``memory`` after the service answered ``told`` in place of its plan (the queue board's check: a
    pace for the cars behind, "drive normally", the glide to a queue's tail): its plan stays its own (``last``, kept or
    dropped by its rules at the next fix), but what the driver last heard is ``told`` where it was spoken, else what it
    heard ``before`` this fix: so the advisor's plan, when it comes back, is spoken (before, the advisor took its own
    plan as heard, and the driver told "Keep up with the traffic. Hold 40 km/h." never heard the plan again)."""
    return AdvisorMemory(memory.last, told if told.speak else (before.spoken if before is not None else None))


def corridor_units(corridor: Corridor) -> str:
    """The corridor's ``units`` ('metric' or 'imperial'; 'kmh'/'mph' read as those), metric when it has none."""
    units = str(getattr(corridor, "units", None) or "metric").lower()
    return {"kmh": "metric", "km/h": "metric", "mph": "imperial"}.get(units, units if units in ADVISOR_UNITS else "metric")


LINE_HOLD_MAX_M = 10.0
"""A fix at most this far past a stop line (and no farther than its accuracy, at least ``RED_TOLERANCE_M``) is
taken as at the line: the light stays the next one. [m]"""


def approach_m(corridor: Corridor, params: AdvisorParams, default_limit_mps: float) -> float:
    """How far before the zone entry the service must advise a car so that the first light can be met without
    hard braking: a car at the entry's limit ``v`` hears the advice, reacts (``reaction_s``), is told to prepare
    (``stop_lead_s``) and stops at ``comfort_decel_mps2``: ``v (reaction_s + stop_lead_s) + v² / (2 comfort_decel)``
    before the first stop line, less the part of it inside the zone. 0 where the zone holds it all.

    Without it the paper's corridor (first light 100 m after the entry, 55 mph) was advised from 27 m before the entry
    (map matching's ``off_route_m``): 5 s before the line, where a red needs 3.7 m/s² from any driver at the limit
    (SUMO, docs/history/TRAFFIC.md). [m]

    Examples
    --------
    >>> from spat_feed.road.corridors import load_corridor
    >>> round(approach_m(load_corridor("paper_s400"), AdvisorParams(), 13.4), 1), approach_m(load_corridor("oakland_7th_westbound"), AdvisorParams(), 13.4)
    (175.3, 0.0)
    """
    if not corridor.intersections:
        return 0.0
    v = corridor.advisory_limit_mps(0.0, default_limit_mps)
    need = v * (params.reaction_s + params.stop_lead_s) + v * v / (2.0 * params.comfort_decel_mps2)
    return float(max(need - corridor.intersections[0].stop_line_m, 0.0))


def light_passed(corridor: Corridor, station_m: float | None, speed_mps: float, t_unix_s: float, readings: dict):
    """The light whose stop line the car passed last (its view: distance negative), where it has a reading: the cars
    behind still have to cross it (queue-aware advice prices them, :func:`advisory.advice.behind.cut_behind`); None
    before the first line or where nothing is read."""
    if station_m is None:
        return None
    ix = next((ix for ix in reversed(corridor.intersections) if ix.stop_line_m <= station_m), None)
    return light_view(ix, readings[ix.id], station_m, t_unix_s, speed_mps=speed_mps) if ix is not None and ix.id in readings else None


def lights_station(corridor: Corridor, station_m: float | None, accuracy_m: float | None) -> float | None:
    """The station the lights ahead are read from: ``station_m``, unless it lies past a stop line by less than the
    fix can tell (its accuracy, at least ``RED_TOLERANCE_M`` = 3 m, at most ``LINE_HOLD_MAX_M``): then just before that
    line. A car waiting at a red whose position jitters 0.4 m past the line has not passed the light (it was: the
    next light bound for one fix, the lamp turned green and "Red in 23 seconds. Drive normally." was spoken, issue 29);
    a moving car is that far past in well under a second. The advisory's ``station_m`` stays the fix's own."""
    if station_m is None:
        return None
    margin = min(max(RED_TOLERANCE_M, accuracy_m or 0.0), LINE_HOLD_MAX_M)
    for ix in corridor.intersections:
        if ix.stop_line_m <= station_m < ix.stop_line_m + margin:
            return ix.stop_line_m - 0.01
    return station_m


def _spat_reason(advice: Advice, status: str) -> Advice:
    """The advisor's "no SPaT" advice with the reason the shared SPaT gives (never, ahead or behind, skewed)."""
    reason = {"no_spat": "no_spat", "stale": "stale_spat", "clock_skew": "clock_skew"}.get(status, advice.reason)
    if reason == advice.reason:
        return advice
    return replace(advice, reason=reason, message=SERVER_PHRASES.get(reason) or advice.message)


def _finite(x: float | None) -> float | None:
    """Seconds rounded to 0.1, None when unknown or infinite."""
    return None if x is None or not math.isfinite(x) else round(float(x), 1)


def fix_from_schema(body) -> Fix:
    return Fix(body.time_unix_s, body.lat_deg, body.lon_deg, body.speed_mps, body.heading_deg, body.accuracy_m)


PLAIN_FIX_RANGES = {
    "t_unix_s": (-1.7976931348623157e308, MS_TIMESTAMP_MIN), "lat_deg": (-90.0, 90.0), "lon_deg": (-180.0, 180.0), "speed_mps": (0.0, 70.0),
    "heading_deg": (0.0, 360.0), "accuracy_m": (0.0, 100_000.0), "altitude_m": (-1000.0, 10_000.0), "altitude_accuracy_m": (0.0, 100_000.0),
}  # fmt: skip
"""A plain fix's fields and their ranges, both ends allowed, as :class:`~server.schemas.GpsFixIn` validates them (its
``ge`` / ``le``; ``t_unix_s``: finite, below ``MS_TIMESTAMP_MIN``, which GpsFixIn refuses as milliseconds)."""
_EXACT_INT = 2**53  # a JSON integer below this in size is exactly a float, as GpsFixIn (strict) takes it


def _plain_fix(data: str | bytes) -> Fix | None:
    """The fix in ``data`` when it is a plain one: one JSON object of :data:`PLAIN_FIX_RANGES`' fields, each once, each a
    number in its range (or null where optional), ``t_unix_s``, ``lat_deg`` and ``lon_deg`` given. Exactly what
    GpsFixIn accepts of such bodies, with the same numbers (the same JSON parser, jiter), but no model built; None for
    anything else (aliases, ``timestamp``, a wrong type, a value out of range, malformed JSON), for GpsFixIn to judge."""
    try:
        body = from_json(data)
    except ValueError:
        return None
    if type(body) is not dict or data.count(b":" if type(data) is bytes else ":") != len(body):  # (a name twice: GpsFixIn's)
        return None
    values = {}
    for name, value in body.items():
        bounds = PLAIN_FIX_RANGES.get(name)
        if bounds is None:
            return None
        if type(value) is int and -_EXACT_INT < value < _EXACT_INT:
            value = float(value)
        elif type(value) is not float:  # (bool, str, null, list, object: GpsFixIn's, or null left out as its default)
            if value is None and name not in ("t_unix_s", "lat_deg", "lon_deg"):
                continue
            return None
        if not bounds[0] <= value <= bounds[1]:  # (nan and inf too)
            return None
        values[name] = value
    t = values.get("t_unix_s")
    if t is None or t == MS_TIMESTAMP_MIN or "lat_deg" not in values or "lon_deg" not in values:
        return None
    return Fix(t, values["lat_deg"], values["lon_deg"], values.get("speed_mps"), values.get("heading_deg"), values.get("accuracy_m"))


def parse_fix(data: str | bytes) -> Fix:
    """The fix in the JSON ``data``, or :class:`pydantic.ValidationError` (GpsFixIn's errors). A plain fix, what phones
    send once a second (:func:`_plain_fix`), is read without building the model; anything else goes through GpsFixIn."""
    return _plain_fix(data) or fix_from_schema(GpsFixIn.model_validate_json(data))
