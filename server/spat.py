"""Where the service's SPaT comes from: one shared, per-intersection source for all trips.

:class:`SpatHub` (one per process) holds a :class:`~spat_feed.transport.store.SpatStore`: the latest state of every
(intersection, signal group), filled by whichever sources the settings name, all at once if need be:

* the **simulator**, in process (``ECO_SPAT_SIMULATE``, on by default without a remote feed): a light with a
  fixed-time plan (the corridor's plan file, else the paper's ``15_15`` anchored on the epoch,
  :func:`spat_feed.transport.simulator.shared_scenario`) is read from its plan directly: exact, always fresh, and
  fit for the DP lookup tables; nothing to do per tick;
* a **remote feed** (``ECO_SPAT_FEED_URL``): one WebSocket to its ``/spat/intersections/stream``;
* an **MQTT broker** (``ECO_SPAT_MQTT_URL``): one subscription per intersection the corridors need;
* a **recorded log** played in process (``ECO_SPAT_LOG``, ``ECO_SPAT_LOG_SPEEDUP``, ``ECO_SPAT_LOG_LOOP``).

A trip reads its lights from the hub (:class:`SharedSpat`): no per-trip connection, no per-trip work per
message. A trip's SPaT message re-serves each live intersection's latest state with every movement's predicted
``likelyTime`` and ``confidence`` (:mod:`spat_feed.transport.republish`). A trip created with an explicit
``timing`` (the paper's scenarios, for research and demos) is simulated for itself (:class:`ScenarioSpat`), as
before.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from typing import Any, Protocol

from spat_feed.transport.client import SpatClient
from spat_feed.road.corridors import Corridor
from spat_feed.timing.messages import SpatMessage, from_unix_s
from spat_feed.transport.mqtt import MqttSubscriber
from spat_feed.prediction.observe import PlanReading
from spat_feed.transport.player import JsonlRecorder, LogPlayer, read_spat_log
from spat_feed.timing.plans import Plan
from spat_feed.transport.pump import SpatPump, run_every
from spat_feed.transport.republish import Republisher
from spat_feed.transport.scenarios import FeedScenario, spat_message_at
from spat_feed.transport.simulator import shared_scenario
from spat_feed.transport.store import Clock, InProcessSpatSource, SpatStore, TimeRules

from server.config import Settings

log = logging.getLogger("server.spat")
IMPLAUSIBLE_ALERT_S = 60.0  # /health degraded this long after an implausible (rejected) SPaT message


class TripSpat(Protocol):
    shared: bool  # the process's shared SPaT (True) or a scenario of the trip's own
    live: bool  # some light comes from a source (its score then uses the phases the trip observed)

    def readings(self, t_unix_s: float) -> dict[int, PlanReading]: ...

    def status(self, intersection_id: int) -> str: ...

    def message(self) -> dict[str, Any]: ...

    async def close(self) -> None: ...


class SpatHub:
    """The process's SPaT: the store, its sources and their health (see the module docstring)."""

    def __init__(self, settings: Settings, corridors: dict[str, Corridor], clock: Clock = time.time) -> None:
        self.settings = settings
        self.clock = clock
        self.simulate = settings.spat_simulated
        self.store = SpatStore(TimeRules(settings.spat_stale_after_s, settings.spat_clock_tolerance_s), clock)
        self.needed = tuple(sorted(_live_ids(corridors.values(), self.simulate)))
        """Intersections whose SPaT comes from the store (not simulated here)."""
        self.client = (
            SpatClient(settings.spat_feed_url.rstrip("/") + "/spat/intersections/stream", store=self.store, stale_after_s=settings.spat_stale_after_s, clock=clock, backoff_max_s=2.0)
            if settings.spat_feed_url
            else None
        )
        self.mqtt = MqttSubscriber(settings.spat_mqtt_url, self.store, self.needed or None) if settings.spat_mqtt_url else None
        self.player = LogPlayer(read_spat_log(settings.spat_log, lambda where: self.store.reject("too_large", None, where)), clock(), settings.spat_log_speedup, settings.spat_log_loop) if settings.spat_log else None
        self.recorder = JsonlRecorder(settings.spat_record) if settings.spat_record else None
        if self.recorder is not None:
            self.store.observers.append(self.recorder)
        self.republisher = Republisher()
        """Every accepted state with its movements' predicted likelyTime and confidence: what a trip's SPaT re-serves."""
        self.store.observers.append(self.republisher)
        self._tasks: list[asyncio.Task] = []
        self.statuses: dict[int, str] = {}

    @property
    def description(self) -> str:
        parts = ["in-process simulation"] if self.simulate else []
        if self.client is not None:
            parts.append(f"remote {self.settings.spat_feed_url}")
        if self.mqtt is not None:
            parts.append(f"mqtt {self.mqtt.target.host}:{self.mqtt.target.port}/{self.mqtt.target.prefix}")
        if self.player is not None:
            parts.append(f"log {self.settings.spat_log}")
        return " + ".join(parts) or "none"

    async def start(self) -> None:
        if self.client is not None:
            await self.client.start()
        if self.mqtt is not None:
            self.mqtt.start()
        if self.player is not None:
            pump = SpatPump(self.player.due, [self.store.offer], self.settings.spat_rate_hz, self.clock)
            self._tasks.append(asyncio.create_task(pump.run(), name="spat log player"))
        self._tasks.append(asyncio.create_task(run_every(1.0, self.sweep, "SPaT sweep"), name="spat sweep"))

    def sweep(self) -> None:
        """Once a second: every needed intersection's status (one WARNING per outage, in the store)."""
        self.statuses = self.store.sweep(self.needed)

    async def stop(self) -> None:
        for task in self._tasks:
            task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await task
        self._tasks.clear()
        if self.client is not None:
            await self.client.stop()
        if self.mqtt is not None:
            await asyncio.to_thread(self.mqtt.stop)
        if self.recorder is not None:
            self.recorder.close()

    def sources(self) -> list[dict[str, Any]]:
        """Each source: kind, whether it is connected (or playing), its counters."""
        out: list[dict[str, Any]] = []
        if self.simulate:
            out.append({"kind": "simulator", "connected": True})
        if self.client is not None:
            out.append({"kind": "feed", "url": self.settings.spat_feed_url, "connected": self.client.connected, "reconnects": max(0, self.client.stats.connects - 1)})
        if self.mqtt is not None:
            t = self.mqtt.target
            out.append({"kind": "mqtt", "url": f"{'mqtts' if t.tls else 'mqtt'}://{t.host}:{t.port}/{t.prefix}", "connected": self.mqtt.connected.is_set(), "reconnects": max(0, self.mqtt.connects - 1)})
        if self.player is not None:
            out.append({"kind": "log", "file": str(self.settings.spat_log), "connected": not self.player.done, "passes": self.player.passes})
        return out

    def health(self) -> dict[str, Any]:
        """Sources and every needed intersection's freshness and rejections; ``degraded`` when one is not ``ok``, a source
        is down or an intersection sent an ``implausible`` message in the last ``IMPLAUSIBLE_ALERT_S``."""
        sources = self.sources()
        intersections, now, suspect = [], self.store.clock(), False
        for ident in self.needed:
            r, st = self.store.reading(ident), self.store.stats.get(ident)
            item = {"id": ident, "status": self.store.status(ident), "age_s": None if r is None else round(r.age_s, 3),
                    "clock_offset_s": None if r is None else round(r.clock_offset_s, 3), "rejected": dict(st.rejected) if st else {}}
            if st is not None and st.implausible_unix_s is not None and now - st.implausible_unix_s < IMPLAUSIBLE_ALERT_S:
                item["implausible_s_ago"] = round(now - st.implausible_unix_s, 1)  # a controller contradicted itself: forged?
                suspect = True
            intersections.append(item)
        ok = all(s["connected"] for s in sources) and all(i["status"] == "ok" for i in intersections) and not suspect
        return {"status": "ok" if ok else "degraded", "source": self.description, "sources": sources, "intersections": intersections}


def _live_ids(corridors, simulate: bool) -> set[int]:
    """Intersections read from the store: every one without simulation, else those with no fixed plan."""
    out: set[int] = set()
    for corridor in corridors:
        plans = shared_scenario(corridor, 0.0).fixed_plans() if simulate else {}
        out.update(ix.id for ix in corridor.intersections if not simulate or (ix.id, ix.signal_groups[0].id) not in plans)
    return out


class SharedSpat:
    """A trip's view of the hub: simulated lights from their fixed plans, the others from the store."""

    __slots__ = ("hub", "scenario", "_fixed", "_live")
    shared = True  # rebuilt from the corridor and entry alone (server.trips.Trip.meta: timing None)

    def __init__(self, hub: SpatHub, scenario: FeedScenario) -> None:
        self.hub = hub
        self.scenario = scenario
        plans = scenario.fixed_plans() if hub.simulate else {}
        self._fixed: dict[int, PlanReading] = {}
        self._live: list[tuple[int, int]] = []
        for ix in scenario.corridor.intersections:
            sg = ix.signal_groups[0].id
            if (ix.id, sg) in plans:
                self._fixed[ix.id] = PlanReading.of_plan(plans[(ix.id, sg)])
            else:
                self._live.append((ix.id, sg))

    @property
    def live(self) -> bool:
        """True when some light's SPaT comes from the store (its score then uses the observed phases)."""
        return bool(self._live)

    def readings(self, t_unix_s: float) -> dict[int, PlanReading]:
        if not self._live:
            return self._fixed
        out = dict(self._fixed)
        for ident, sg in self._live:
            out[ident] = self.hub.store.plan_reading(ident, sg)
        return out

    def status(self, intersection_id: int) -> str:
        return "ok" if intersection_id in self._fixed else self.hub.store.status(intersection_id)

    def message(self) -> dict[str, Any]:
        now = self.hub.clock()
        items = spat_message_at(self.scenario, now).intersections if self._fixed else []
        items = [ix for ix in items if ix.id in self._fixed]
        fresh = {str(i): True for i in self._fixed}
        for ident, _ in self._live:
            r = self.hub.store.reading(ident)
            fresh[str(ident)] = bool(r and r.fresh)
            if r is not None:
                items.append(self.hub.republisher.republished(r.intersection))
        msg = SpatMessage(timestamp=from_unix_s(now), name=f"{self.scenario.corridor.name} shared", intersections=items[:32])
        out = msg.model_dump(mode="json", by_alias=True, exclude_none=True)
        out["fresh"] = fresh
        return out

    async def close(self) -> None:
        return None


class ScenarioSpat:
    """A trip with its own ``timing`` (a paper scenario), simulated for it alone: always fresh."""

    __slots__ = ("scenario", "_fixed", "_clock")
    shared = False
    live = False  # never observed: the scenario's plans are the truth of its score

    def __init__(self, scenario: FeedScenario, clock: Clock = time.time) -> None:
        self.scenario = scenario
        self._clock = clock
        self._fixed: dict[int, PlanReading] | None = None
        if scenario.uncertainty.is_fixed:  # fixed plans do not depend on the instant: compute them once
            self._fixed = self._from_plans(scenario.fixed_plans())

    def _from_plans(self, plans: dict[tuple[int, int], Plan]) -> dict[int, PlanReading]:
        return {ix.id: PlanReading.of_plan(plans.get((ix.id, ix.signal_groups[0].id))) for ix in self.scenario.corridor.intersections}  # live light: no data

    def readings(self, t_unix_s: float) -> dict[int, PlanReading]:
        if self._fixed is not None:
            return self._fixed
        return self._from_plans(self.scenario.plans_at(t_unix_s))

    def status(self, intersection_id: int) -> str:
        return "ok"

    def message(self) -> dict[str, Any]:
        msg = InProcessSpatSource(self.scenario, self._clock).message()
        return msg.model_dump(mode="json", by_alias=True, exclude_none=True)

    async def close(self) -> None:
        return None


SimulatedSpat = ScenarioSpat
"""The earlier name of :class:`ScenarioSpat`."""
