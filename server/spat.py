"""Where each trip's SPaT comes from: the in-process simulation (default) or a remote feed.

Both give, for a fix time, one :class:`~spat_feed.observe.PlanReading` per intersection, and the current
SPaT message for ``GET .../spat``. For the simulation the trip's scenario (corridor, timing, zone entry)
gives the plans directly (``FeedScenario.plans_at``), the same plans that ``InProcessSpatSource`` turns
into messages. For a remote feed one :class:`spat_feed.client.SpatClient` per scenario subscribes to
``/spat/stream`` with the trip's scenario as query parameters; trips with the same scenario share it.
"""

from __future__ import annotations

import time
from typing import Any, Protocol

from spat_feed.client import SpatClient
from spat_feed.messages import SpatMessage, from_unix_s
from spat_feed.plans import Plan
from spat_feed.scenarios import FeedScenario
from spat_feed.source import Clock, InProcessSpatSource

from spat_feed.observe import PlanReading


class TripSpat(Protocol):
    def readings(self, t_unix_s: float) -> dict[int, PlanReading]: ...

    def message(self) -> dict[str, Any]: ...

    async def close(self) -> None: ...


class SimulatedSpat:
    """The trip's scenario computed in process: always fresh."""

    __slots__ = ("scenario", "_fixed", "_clock")

    def __init__(self, scenario: FeedScenario, clock: Clock = time.time) -> None:
        self.scenario = scenario
        self._clock = clock
        self._fixed: dict[int, PlanReading] | None = None
        if scenario.uncertainty.is_fixed:  # fixed plans do not depend on the instant: compute them once
            self._fixed = self._from_plans(scenario.fixed_plans())

    def _from_plans(self, plans: dict[tuple[int, int], Plan]) -> dict[int, PlanReading]:
        return {ix.id: PlanReading(plans.get((ix.id, ix.signal_groups[0].id))) for ix in self.scenario.corridor.intersections}  # live light: no data

    def readings(self, t_unix_s: float) -> dict[int, PlanReading]:
        if self._fixed is not None:
            return self._fixed
        return self._from_plans(self.scenario.plans_at(t_unix_s))

    def message(self) -> dict[str, Any]:
        msg = InProcessSpatSource(self.scenario, self._clock).message()
        return msg.model_dump(mode="json", by_alias=True, exclude_none=True)

    async def close(self) -> None:
        return None


def feed_params(scenario: FeedScenario) -> dict[str, Any]:
    """The feed's query parameters for a scenario (``/spat/stream?corridor=...&timing=...``)."""
    u = scenario.uncertainty
    params: dict[str, Any] = {"corridor": scenario.corridor.name, "timing": scenario.timing.name, "entry_unix_s": scenario.entry_unix_s}
    if not u.is_fixed:
        params.update(early_s=u.early_s, late_s=u.late_s, confidence=u.confidence_frac)
    return params


class RemoteSpat:
    """A trip's view of a shared :class:`SpatClient`; plans are parsed once per received state."""

    __slots__ = ("feed", "key", "client", "scenario", "_cache")

    def __init__(self, feed: RemoteFeed, key: tuple, client: SpatClient, scenario: FeedScenario) -> None:
        self.feed, self.key, self.client, self.scenario = feed, key, client, scenario
        self._cache: dict[int, tuple[object, Plan | None]] = {}

    def readings(self, t_unix_s: float) -> dict[int, PlanReading]:
        out: dict[int, PlanReading] = {}
        for ix in self.scenario.corridor.intersections:
            reading = self.client.reading(ix.id)
            if reading is None:
                out[ix.id] = PlanReading(None, fresh=False, age_s=float("inf"))
                continue
            cached = self._cache.get(ix.id)
            if cached is None or cached[0] is not reading.intersection:
                cached = (reading.intersection, reading.plan(ix.signal_groups[0].id))
                self._cache[ix.id] = cached
            out[ix.id] = PlanReading(cached[1], fresh=reading.fresh, age_s=reading.age_s)
        return out

    def message(self) -> dict[str, Any]:
        readings = self.client.readings()
        items = [readings[i].intersection for i in sorted(readings)]
        stamp = from_unix_s(time.time())
        msg = SpatMessage(timestamp=stamp, name=f"{self.scenario.corridor.name} {self.scenario.timing.name}", intersections=items)
        out = msg.model_dump(mode="json", by_alias=True, exclude_none=True)
        out["fresh"] = {str(i): r.fresh for i, r in readings.items()}
        return out

    async def close(self) -> None:
        await self.feed.release(self.key)


class RemoteFeed:
    """Shared SPaT clients of a remote feed, one per scenario, reference-counted."""

    def __init__(self, base_url: str, stale_after_s: float) -> None:
        self.base_url = base_url
        self.stale_after_s = stale_after_s
        self._clients: dict[tuple, tuple[SpatClient, int]] = {}

    async def subscribe(self, scenario: FeedScenario) -> RemoteSpat:
        key = scenario.key
        entry = self._clients.get(key)
        if entry is None:
            client = SpatClient(self.base_url, feed_params(scenario), stale_after_s=self.stale_after_s, backoff_max_s=2.0)
            await client.start()
            entry = (client, 0)
        self._clients[key] = (entry[0], entry[1] + 1)
        return RemoteSpat(self, key, entry[0], scenario)

    async def release(self, key: tuple) -> None:
        entry = self._clients.get(key)
        if entry is None:
            return
        client, count = entry
        if count <= 1:
            del self._clients[key]
            await client.stop()
        else:
            self._clients[key] = (client, count - 1)

    @property
    def connected(self) -> int:
        return sum(1 for client, _ in self._clients.values() if client.connected)

    async def close(self) -> None:
        for client, _ in list(self._clients.values()):
            await client.stop()
        self._clients.clear()
