"""A trip: one car on one corridor, its token, fix history, advisor memory and last advice.

A trip's state only changes in :meth:`server.advising.Engine.on_fix`, after the fix has been validated,
and in one synchronous step on the event loop, so a bad request never leaves a trip half-updated.
Everything a trip records is plain data of bounded size (numbers, strings, lists of floats; the fix trace
capped by ``max_trace_fixes``, observed phases by ``ObservedLights.MAX_RUNS``), so a shared store
(``server.storage.store``) holds it as three parts: :meth:`Trip.meta` (written once: what the trip was created
with, from which any worker rebuilds its corridor, SPaT view and tables), :meth:`Trip.state` (rewritten
per fix: track, advisor memory, last advice, counters) and the score samples (appended per fix).
"""

from __future__ import annotations

import hashlib
import secrets
import time
import uuid
from array import array
from typing import TYPE_CHECKING

from pydantic_core import to_json

from advisory.advice.views import Advice, AdvisorMemory
from spat_feed.road.corridors import Corridor
from spat_feed.transport.scenarios import FeedScenario

from spat_feed.timing.plans import phase_class, state_at, state_start_s

from server.gps import RouteMatcher, Track
from server.admission.ratelimit import TokenBucket

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
    (stations along the route extended beyond its ends); with a shared store only those not yet written
    there (``trace_base`` counts the written ones)."""

    __slots__ = (
        "id", "token", "token_hash", "corridor", "matcher", "timing", "vehicle", "entry_unix_s", "created_unix_s", "scenario", "spat",
        "track", "memory", "_last", "_last_json", "bucket", "trace_t", "trace_v", "trace_x", "trace_base", "n_fixes", "last_seen_s", "tables",
        "client", "device", "units", "params", "observed", "n_rejected", "version",
    )  # fmt: skip

    def __init__(
        self, corridor: Corridor, matcher: RouteMatcher, scenario: FeedScenario, spat: TripSpat, vehicle: str,
        created_unix_s: float, bucket: TokenBucket, dropout_s: float, tables=None, *, client: str = "", device: str = "", units: str = "metric",
        params=None, observe_spat: bool = False, max_speed_mps: float = 50.0, trip_id: str | None = None,
    ) -> None:  # fmt: skip
        self.id = trip_id or uuid.uuid4().hex
        self.token: str | None = None  # the bearer token, known only to the worker that created the trip (or has checked it since)
        self.token_hash = b""  # what the stores keep (token_hash(token))
        if trip_id is None:
            self.token = f"{self.id[:8]}.{secrets.token_urlsafe(24)}"
            self.token_hash = token_hash(self.token)
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
        self.last = None  # the latest advisory, fields of server.schemas.AdviceOut
        self.trace_t = array("d")
        self.trace_v = array("d")
        self.trace_x = array("d")
        self.trace_base = 0
        self.n_fixes = 0
        self.last_seen_s = time.monotonic()
        self.tables = tables
        self.client = client  # who created it (API key id or client address): per-client quotas
        self.device = device  # the device id it was created with ("": none): per-device limits (server.admission.quotas)
        self.units = units  # "metric" or "imperial": the spoken speeds
        self.params = params  # the advisor's settings for this trip (units)
        self.observed = ObservedLights() if observe_spat else None  # live SPaT: what the trip saw, for its score
        self.n_rejected = 0  # fixes rejected as implausible (jumps)
        self.version = 0  # a shared store's version of the state this object holds

    @property
    def last(self) -> dict | None:
        """The latest advisory (a plain dict with the fields of ``server.schemas.AdviceOut``); set, never changed in place."""
        return self._last

    @last.setter
    def last(self, advisory: dict | None) -> None:
        self._last = advisory
        self._last_json = None

    def last_json(self) -> bytes:
        """:attr:`last` as JSON (``pydantic_core.to_json``), made once per advisory: the fix's answer and the state a
        shared store writes (:meth:`state_json`) hold the same bytes."""
        data = self._last_json
        if data is None:
            data = self._last_json = to_json(self._last)
        return data

    @property
    def n_trace(self) -> int:
        """Score samples recorded so far (written to a store or pending)."""
        return self.trace_base + len(self.trace_t)

    def meta(self) -> dict:
        """What the trip was created with (never changes): enough for any worker to rebuild it."""
        u = self.scenario.uncertainty
        return {"id": self.id, "corridor": self.corridor.name, "timing": None if self.spat.shared else self.timing, "entry_unix_s": self.entry_unix_s,
                "uncertainty": [u.early_s, u.late_s, u.confidence_frac], "vehicle": self.vehicle, "created_unix_s": self.created_unix_s,
                "client": self.client, "device": self.device, "units": self.units, "observe_spat": self.observed is not None}  # fmt: skip

    def state(self) -> dict:
        """What a fix changes, of bounded size (the score samples apart): plain data and the advisor's memory as its
        frozen ``Advice`` dataclasses, which ``pydantic_core.to_json`` writes as the dicts of their fields (no dict
        built per fix); :meth:`restore` reads the JSON back."""
        m = self.memory
        return {
            "track": self.track.state(),
            "memory": None if m is None else [m.last, m.spoken],  # Advice dataclasses: JSON of their fields, as Advice.as_dict
            "last": self.last, "n_fixes": self.n_fixes, "n_rejected": self.n_rejected, "n_trace": self.n_trace,
            "observed": None if self.observed is None else [[ix, runs] for ix, runs in self.observed.runs.items()],
        }  # fmt: skip

    def state_json(self) -> bytes:
        """``to_json(self.state())``, what a shared store writes per fix; the latest advisory's JSON in it is kept as
        :meth:`last_json` (the fix's answer: the same bytes, not encoded again). One encoding and a slice: cheaper on a
        worker that wakes cold for each fix than the parts encoded apart and joined (measured: ``profile_worker.py``)."""
        data = to_json(self.state())
        if self._last is not None and self._last_json is None:  # (keys in state()'s order: "last" follows "memory", "n_fixes" follows it)
            start = data.index(b',"last":') + 8
            self._last_json = data[start : data.index(b',"n_fixes":', start)]
        return data

    def restore(self, state: dict) -> None:
        """Take :meth:`state` (of this trip, from a store) as this object's own; pending samples are dropped."""
        self.track.restore(state["track"])
        m = state["memory"]
        self.memory = None if m is None else AdvisorMemory(*(None if a is None else Advice(**a) for a in m))
        self.last, self.n_fixes, self.n_rejected = state["last"], state["n_fixes"], state["n_rejected"]
        self.trace_base = state["n_trace"]
        del self.trace_t[:], self.trace_v[:], self.trace_x[:]
        if state["observed"] is not None and self.observed is not None:
            self.observed.runs = {int(ix): runs for ix, runs in state["observed"]}


def token_hash(token: str) -> bytes:
    """What a store keeps of a trip token: its SHA-256 (a leaked store gives no working token)."""
    return hashlib.sha256(token.encode()).digest()
