"""Where the advisor gets SPaT: the common reading interface, the latest-value store, the in-process source.

Every source answers ``reading(intersection_id)`` with a :class:`SpatReading` (the intersection's
latest state, its age and whether it is fresh) and ``fresh(intersection_id)`` with the state only if
it is fresh. :class:`InProcessSpatSource` computes messages from a scenario on demand, so the
advisory service runs with no feed process (the embedded default); :class:`spat_feed.client.SpatClient`
fills a :class:`LatestStore` from a remote feed.

Age rule: ``age = now - min(sender timestamp, arrival time)``, i.e. the larger of the data's own age
and the time since it arrived. Old data replayed by a sender, and data whose feed has gone quiet,
both go stale; a sender clock ahead of ours cannot make data look younger than its arrival.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Protocol

from spat_feed.messages import IntersectionState, SpatMessage, plan_from_movement, to_unix_s
from spat_feed.plans import UncertainPlan
from spat_feed.scenarios import FeedScenario, spat_message_at

Clock = Callable[[], float]
"""Returns Unix seconds. ``time.time`` by default; tests pass their own."""

DEFAULT_STALE_AFTER_S = 2.0


@dataclass(frozen=True, slots=True)
class SpatReading:
    """One intersection's latest state as seen at ``now``: with its age and freshness. [s]"""

    intersection: IntersectionState
    timestamp_unix_s: float
    received_unix_s: float
    age_s: float
    fresh: bool

    def plan(self, signal_group: int) -> UncertainPlan | None:
        """The signal group's plan on the Unix axis (see :func:`spat_feed.messages.plan_from_movement`)."""
        movement = self.intersection.movement(signal_group)
        return None if movement is None else plan_from_movement(movement, self.timestamp_unix_s)


class SpatSource(Protocol):
    """What the advisor needs from any SPaT source."""

    def reading(self, intersection_id: int) -> SpatReading | None: ...

    def fresh(self, intersection_id: int) -> IntersectionState | None: ...

    def readings(self) -> dict[int, SpatReading]: ...


def data_age_s(timestamp_unix_s: float, received_unix_s: float, now_unix_s: float) -> float:
    """Age of a reading: time since the older of its timestamp and its arrival. [s]

    Examples
    --------
    >>> data_age_s(100.0, 100.2, 101.0)
    1.0
    >>> round(data_age_s(105.0, 100.2, 101.0), 3)   # sender clock 5 s fast: age since arrival
    0.8
    """
    return now_unix_s - min(timestamp_unix_s, received_unix_s)


class LatestStore:
    """Latest state per intersection, thread-safe; older or equal timestamps never replace newer ones."""

    def __init__(self, stale_after_s: float = DEFAULT_STALE_AFTER_S, clock: Clock = time.time) -> None:
        if not stale_after_s > 0:
            raise ValueError("stale_after_s must be > 0")
        self.stale_after_s = stale_after_s
        self.clock = clock
        self._lock = threading.Lock()
        self._latest: dict[int, tuple[IntersectionState, float, float]] = {}

    def update(self, items: Iterable[IntersectionState], received_unix_s: float | None = None) -> int:
        """Store each intersection unless we hold a newer one; returns how many were stored."""
        received = self.clock() if received_unix_s is None else received_unix_s
        stored = 0
        with self._lock:
            for ix in items:
                stamp = to_unix_s(ix.timestamp)
                old = self._latest.get(ix.id)
                if old is None or stamp > old[1]:
                    self._latest[ix.id] = (ix, stamp, received)
                    stored += 1
        return stored

    def reading(self, intersection_id: int) -> SpatReading | None:
        with self._lock:
            entry = self._latest.get(intersection_id)
        if entry is None:
            return None
        ix, stamp, received = entry
        age = data_age_s(stamp, received, self.clock())
        return SpatReading(ix, stamp, received, age, age <= self.stale_after_s)

    def fresh(self, intersection_id: int) -> IntersectionState | None:
        r = self.reading(intersection_id)
        return r.intersection if r is not None and r.fresh else None

    def readings(self) -> dict[int, SpatReading]:
        with self._lock:
            ids = list(self._latest)
        return {i: r for i in ids if (r := self.reading(i)) is not None}


class InProcessSpatSource:
    """SPaT computed on demand from a scenario: no feed process, never stale.

    ``clock`` gives the instant of each reading (Unix seconds). Use :meth:`set_scenario` when a new
    trip enters the zone.
    """

    def __init__(self, scenario: FeedScenario, clock: Clock = time.time, n_events: int = 3) -> None:
        self.scenario = scenario
        self.clock = clock
        self.n_events = n_events

    def set_scenario(self, scenario: FeedScenario) -> None:
        self.scenario = scenario

    def message(self) -> SpatMessage:
        """The whole SPaT message at the clock's now."""
        return spat_message_at(self.scenario, self.clock(), self.n_events)

    def reading(self, intersection_id: int) -> SpatReading | None:
        return self.readings().get(intersection_id)

    def fresh(self, intersection_id: int) -> IntersectionState | None:
        r = self.reading(intersection_id)
        return None if r is None else r.intersection

    def readings(self) -> dict[int, SpatReading]:
        msg = self.message()
        now = to_unix_s(msg.timestamp)
        return {ix.id: SpatReading(ix, now, now, 0.0, True) for ix in msg.intersections}
