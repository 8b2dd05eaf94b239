"""Where the advisor gets SPaT: the latest-value store with its time rules, and the in-process source.

Real controllers publish SPaT per intersection. :class:`SpatStore` keeps the latest state of every
(intersection, signal group) it is offered, from any source (the simulator, a recorded-log player, an MQTT
subscriber, a remote feed), and answers readers with that state, its age and a status. Every trip on a
corridor reads the same entries: the SPaT work per message does not grow with the number of trips.

J2735 movements update independently, and controllers publish partial messages (Antwerp's K648 on 2019-05-01:
1,384 of 13,275 messages carry 9 of its 10 signal groups, 150 one): a message updates the groups it carries, a
group it omits keeps its latest state, aging from the message that carried it. Each group has its own timestamp,
age and status (:meth:`SpatStore.plan`, :meth:`SpatStore.plan_reading`, ``status(id, group)``); the intersection's
(:meth:`SpatStore.reading`, ``status(id)``) are its latest message's.

Time rules (:class:`TimeRules`), judged on the controller's own timestamp:

* **rejected** (counted per reason, never stored), judged per signal group: a message is stored for the groups it
  has newer news of (one older than the latest message too), else rejected as ``duplicate`` (the timestamp of
  some group's state held) or ``out_of_order`` (older than every group's state held); ``malformed`` (not our
  schema), ``too_large`` (over ``MAX_SPAT_BYTES``, dropped before parsing), ``clock_ahead`` (dated more than
  ``clock_tolerance_s`` after its arrival: it would look fresher than it is), ``implausible`` (a signal group green
  while the state held of it, from the same controller, guaranteed a red then: a red that ends more than
  ``PLAUSIBLE_SLACK_S`` before the ``minEndTime`` it was published with; what a forged "green" on a red shows, since
  a controller never ends a phase before its published minimum), ``unknown_intersection`` (a store told which
  intersections to keep, ``only=``), ``wrong_topic`` (an MQTT payload about another intersection than its topic's:
  the broker's ACL lets a controller write its own topic only).
* **age** = now - the older of timestamp and arrival, per group; older than ``stale_after_s`` (default 2 s):
  ``stale``, the group alone when the others of its intersection are heard.
* **clock offset** = arrival - timestamp, its floor (the smallest over ``skew_window_s``, which strips the
  network delay), the offset readings correct by. A controller clock off ours by more than ``clock_tolerance_s``,
  its windows would put advice seconds into a red: ``clock_skew`` (one clock per intersection: every group), never
  served as fresh, as soon as every offset of the last ``skew_detect_s`` is beyond it (a clock behind; within 5 s
  of the step, whatever the long window still holds) or a message was dated that far ahead (``clock_ahead``).
  Until then, and within the tolerance, readings carry ``clock_uncertainty_s`` = the largest offset of the last
  ``skew_detect_s`` minus the one corrected by: every red window widened by it both ways, so a clock that has just
  moved never shifts a window into a red.

Statuses: ``ok``, ``stale``, ``clock_skew``, ``no_spat`` (never heard). Only ``ok`` is fresh.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import Counter, deque
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from typing import Protocol

from spat_feed.timing.messages import IntersectionState, SpatMessage, plan_from_movement, to_unix_s
from spat_feed.prediction.history import IntersectionHistory
from spat_feed.prediction.observe import PlanReading
from spat_feed.timing.plans import PhaseClass, UncertainPlan, phase_class, possible_states_at, state_at
from spat_feed.transport.scenarios import FeedScenario, spat_message_at

Clock = Callable[[], float]
"""Returns Unix seconds. ``time.time`` by default; tests pass their own."""

DEFAULT_STALE_AFTER_S = 2.0
MAX_SPAT_BYTES = 256 * 1024
"""The largest SPaT text any source hands the parser (an MQTT payload, a feed's WebSocket message or HTTP body, a
log line); larger ones are dropped unparsed, rejected ``too_large``. Our JSON of K648's largest recorded state (10
signal groups) is 1.75 KB, ~175 B a movement: a J2735 intersection at its maximum of 255 movements is ~45 KB, and a
whole J2735 SpatMessage (at most 32 intersections) of K648-sized ones ~56 KB. [bytes]"""
REJECT_REASONS = ("malformed", "too_large", "duplicate", "out_of_order", "clock_ahead", "implausible", "wrong_topic", "unknown_intersection")
PLAUSIBLE_SLACK_S = 0.5
"""How far before the minEndTime its controller published a red may turn green (timestamps rounded to 0.1 s). [s]"""
STATUSES = ("ok", "stale", "clock_skew", "no_spat")

log = logging.getLogger("spat_feed.transport.store")


@dataclass(frozen=True, slots=True)
class TimeRules:
    """When SPaT is fresh. [s]"""

    stale_after_s: float = DEFAULT_STALE_AFTER_S
    clock_tolerance_s: float = 1.0
    skew_window_s: float = 30.0
    skew_detect_s: float = 4.0  # a steady offset beyond the tolerance for this long is clock_skew (flagged within 5 s)

    def __post_init__(self) -> None:
        if not (self.stale_after_s > 0 and self.clock_tolerance_s > 0 and self.skew_window_s > 0 and 0 < self.skew_detect_s <= self.skew_window_s):
            raise ValueError(f"time rules must be > 0: {self}")


@dataclass(frozen=True, slots=True)
class SpatReading:
    """One intersection's latest state as seen at ``now``: its age, status and the controller's clock offset. [s]

    From :meth:`SpatStore.plan`: a signal group's, the message that carried its latest state, that state's age.
    """

    intersection: IntersectionState
    timestamp_unix_s: float
    received_unix_s: float
    age_s: float
    fresh: bool
    status: str = "ok"
    clock_offset_s: float = 0.0
    clock_uncertainty_s: float = 0.0  # how far the offset may be off (a clock that has just moved; network jitter)

    def plan(self, signal_group: int) -> UncertainPlan | None:
        """The signal group's plan on the Unix axis (see :func:`spat_feed.timing.messages.plan_from_movement`)."""
        movement = self.intersection.movement(signal_group)
        return None if movement is None else plan_from_movement(movement, self.timestamp_unix_s)


class SpatSource(Protocol):
    """What the advisor needs from any SPaT source."""

    def reading(self, intersection_id: int) -> SpatReading | None: ...

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


@dataclass
class IntersectionStats:
    """Counters of one intersection since the store started."""

    messages: int = 0
    rejected: Counter = field(default_factory=Counter)
    stale_since_unix_s: float | None = None  # set while stale (for the one WARNING per outage)
    implausible_unix_s: float | None = None  # arrival of the last message rejected as implausible


class _Entry:
    """One intersection: its latest message, each signal group's latest state (its plan parsed once, the
    timestamp and arrival of the message that carried it), its clock offsets, and what its signal groups have been
    seen to do (:class:`~spat_feed.prediction.history.IntersectionHistory`)."""

    __slots__ = ("state", "stamp", "received", "heard_unix_s", "groups", "offsets", "recent_low", "recent_high", "offset",
                 "uncertainty", "skewed", "ahead_unix_s", "ahead_offset", "history")

    def __init__(self) -> None:
        self.state: IntersectionState | None = None  # the latest message (the newest timestamp)
        self.stamp = self.received = float("-inf")
        self.heard_unix_s = float("-inf")  # arrival of the last message stored (for some group)
        self.groups: dict[int, _Group] = {}  # signal group -> its latest state
        self.offsets: deque[tuple[float, float]] = deque()  # (arrival, arrival - timestamp), offsets increasing
        self.recent_low: deque[tuple[float, float]] = deque()  # the same over skew_detect_s
        self.recent_high: deque[tuple[float, float]] = deque()  # offsets decreasing, over skew_detect_s
        self.offset = self.uncertainty = 0.0  # the offset readings are corrected by, how far it may be off [s]
        self.skewed = False  # every offset of the last skew_detect_s beyond the tolerance
        self.ahead_unix_s = float("-inf")  # arrival of the last message rejected as clock_ahead
        self.ahead_offset = 0.0  # its arrival - timestamp (< -clock_tolerance_s)
        self.history = IntersectionHistory()


class _Group:
    """A signal group's latest state: the stamp and arrival of the message that carried it, its plan, the message, and
    the queue its movement published (``MovementState.queue_length_m``, read once per message) [m]."""

    __slots__ = ("stamp", "received", "plan", "state", "queue_m")

    def __init__(self, stamp: float, received: float, plan: UncertainPlan, state: IntersectionState, queue_m: float | None = None) -> None:
        self.stamp, self.received, self.plan, self.state, self.queue_m = stamp, received, plan, state, queue_m


class SpatStore:
    """Latest SPaT per (intersection, signal group) from any source; thread-safe; see the module docstring.

    Parameters
    ----------
    rules : TimeRules
        Stale age, clock tolerance, skew window.
    clock : callable
        Unix seconds (arrival times and ages); ``time.time`` by default.
    only : iterable of int, optional
        Keep these intersections only; others are rejected as ``unknown_intersection``.
    """

    def __init__(self, rules: TimeRules | None = None, clock: Clock = time.time, only: Iterable[int] | None = None, *, stale_after_s: float | None = None) -> None:
        self.rules = rules or TimeRules(stale_after_s if stale_after_s is not None else DEFAULT_STALE_AFTER_S)
        self.clock = clock
        self.only = None if only is None else frozenset(only)
        self.stats: dict[int, IntersectionStats] = {}
        self.rejected: Counter = Counter()  # by reason, all intersections (malformed texts have none)
        self.observers: list[Callable[[IntersectionState], None]] = []  # called with every accepted state
        self._lock = threading.Lock()
        self._entries: dict[int, _Entry] = {}
        self._amber_s: dict[tuple[int, int], float] = {}  # (intersection, group) -> the amber its source declared [s]

    @property
    def stale_after_s(self) -> float:
        return self.rules.stale_after_s

    # writing ------------------------------------------------------------------------------------

    def reject(self, reason: str, intersection_id: int | None = None, detail: str = "") -> str:
        """Count a rejected message (``malformed`` ones come from parsers); returns ``reason``."""
        self.rejected[reason] += 1
        if intersection_id is not None:
            self.stats.setdefault(intersection_id, IntersectionStats()).rejected[reason] += 1
        log.debug("rejected SPaT (%s) %s %s", reason, intersection_id, detail)
        return reason

    def offer(self, state: IntersectionState, received_unix_s: float | None = None) -> str:
        """Store one intersection's state unless a time rule rejects it; returns ``"ok"`` or the reason."""
        received = self.clock() if received_unix_s is None else received_unix_s
        ident = state.id
        if self.only is not None and ident not in self.only:
            return self.reject("unknown_intersection", None, str(ident))
        stamp = to_unix_s(state.timestamp)
        with self._lock:
            entry = self._entries.get(ident)
            if entry is None:
                entry = self._entries[ident] = _Entry()
            if stamp > received + self.rules.clock_tolerance_s:
                entry.ahead_unix_s, entry.ahead_offset = received, received - stamp
                verdict = "clock_ahead"
            else:
                groups, plans, queues, seen, implausible = entry.groups, {}, {}, False, False
                for movement in state.states:
                    g = movement.signal_group
                    if g in plans:
                        continue  # a group's first movement, as IntersectionState.movement finds it
                    held = groups.get(g)
                    if held is not None and held.stamp >= stamp:
                        seen = seen or held.stamp == stamp
                        continue  # this group's state held is as new or newer
                    # parsed once per message: the plan the history records (its minEndTime too: held, resumed) is the
                    # one readings get
                    plans[g] = plan_from_movement(movement, stamp)
                    queues[g] = movement.queue_length_m()
                    if held is not None and _contradicts(held.plan, plans[g], stamp):
                        implausible = True
                        break
                if implausible:
                    verdict = "implausible"
                elif not plans:
                    verdict = "duplicate" if seen else "out_of_order"  # news held of some group, or older than all
                else:
                    verdict = "ok"
                    for g, plan in plans.items():
                        held = groups.get(g)
                        if held is None:
                            groups[g] = _Group(stamp, received, plan, state, queues[g])
                        else:
                            held.stamp, held.received, held.plan, held.state, held.queue_m = stamp, received, plan, state, queues[g]
                    if stamp > entry.stamp:
                        entry.state, entry.stamp, entry.received = state, stamp, received
                    entry.history.record(stamp, plans)  # each group's phases (its own readings), the links between groups
            if verdict == "ok":
                entry.heard_unix_s = received
                self._clock_offset(entry, received, received - stamp)
        if verdict != "ok":
            if verdict == "implausible":
                self.stats.setdefault(ident, IntersectionStats()).implausible_unix_s = received
                log.warning("implausible SPaT of intersection %d (a red ended before its minEndTime): rejected", ident)
            return self.reject(verdict, ident)
        self.stats.setdefault(ident, IntersectionStats()).messages += 1
        for observer in self.observers:
            observer(state)
        return "ok"

    def declare_amber(self, intersection_id: int, signal_group: int, amber_s: float | None) -> None:
        """A source that knows the amber a signal group shows before its reds says so (SUMO's program,
        :meth:`~spat_feed.transport.sumo.SumoSpatSource.amber_s`): its readings then carry it
        (``PlanReading.amber_s``; 0: no amber, the advisor keeps a margin before such a red); None withdraws it. J2735
        SPaT carries no such field: for a group no source declared, readings say None (unknown: some amber). The store
        never infers it from the phases it saw (recorded controllers go from green to red where their amber is not
        published)."""
        if amber_s is not None and not amber_s >= 0.0:
            raise ValueError(f"amber_s must be >= 0 or None, got {amber_s}")
        with self._lock:
            if amber_s is None:
                self._amber_s.pop((intersection_id, signal_group), None)
            else:
                self._amber_s[(intersection_id, signal_group)] = float(amber_s)

    def offer_many(self, states: Iterable[IntersectionState], received_unix_s: float | None = None) -> int:
        """Offer each state; returns how many were stored."""
        return sum(self.offer(s, received_unix_s) == "ok" for s in states)

    def _clock_offset(self, entry: _Entry, received: float, offset: float) -> None:
        """Update the intersection's clock offset with one accepted message's (monotonic deques: heads are the floors
        of ``skew_window_s`` and ``skew_detect_s``, the top of the latter)."""
        rules = self.rules
        for dq, horizon, sign in ((entry.offsets, rules.skew_window_s, 1.0), (entry.recent_low, rules.skew_detect_s, 1.0),
                                  (entry.recent_high, rules.skew_detect_s, -1.0)):  # fmt: skip
            while dq and sign * dq[-1][1] >= sign * offset:
                dq.pop()
            dq.append((received, offset))
            while dq[0][0] < received - horizon:
                dq.popleft()
        floor, recent, top = entry.offsets[0][1], entry.recent_low[0][1], entry.recent_high[0][1]
        entry.skewed = recent > rules.clock_tolerance_s or floor < -rules.clock_tolerance_s
        entry.offset = recent if recent > rules.clock_tolerance_s else floor
        entry.uncertainty = max(0.0, top - entry.offset)

    # reading ------------------------------------------------------------------------------------

    def _status(self, entry: _Entry, stamp: float, received: float, now: float) -> tuple[float, str, float]:
        """(age, status, clock offset) of a state of ``entry`` stamped ``stamp``, arrived at ``received``."""
        age = data_age_s(stamp, received, now)
        if entry.ahead_unix_s > entry.heard_unix_s:
            return age, "clock_skew", entry.ahead_offset
        offset = entry.offset
        if entry.skewed:
            return age, "clock_skew", offset
        return age, ("ok" if age <= self.rules.stale_after_s else "stale"), offset

    def reading(self, intersection_id: int) -> SpatReading | None:
        """The intersection's latest message with its age and status, its ``intersection`` holding every signal group
        not stale (a group the message omits: its latest state); ``None`` if never heard."""
        with self._lock:
            entry = self._entries.get(intersection_id)
            if entry is None or entry.state is None:
                return None
            now = self.clock()
            age, status, offset = self._status(entry, entry.stamp, entry.received, now)
            state = entry.state
            if any(g.state is not state for g in entry.groups.values()):  # a group the latest message omits
                carried = {m.signal_group for m in state.states}
                held = [g.state.movement(k) for k, g in entry.groups.items()
                        if k not in carried and data_age_s(g.stamp, g.received, now) <= self.rules.stale_after_s]  # fmt: skip
                if held:
                    state = state.model_copy(update={"states": [*state.states, *held]})
            return SpatReading(state, entry.stamp, entry.received, age, status == "ok", status, offset, entry.uncertainty)

    def _plan(self, entry: _Entry | None, signal_group: int) -> tuple[UncertainPlan | None, SpatReading | None]:
        if entry is None or entry.state is None:
            return None, None
        held, now = entry.groups.get(signal_group), self.clock()
        if held is None:  # a group the intersection never published: no plan, the intersection's reading
            age, status, offset = self._status(entry, entry.stamp, entry.received, now)
            return None, SpatReading(entry.state, entry.stamp, entry.received, age, status == "ok", status, offset, entry.uncertainty)
        age, status, offset = self._status(entry, held.stamp, held.received, now)
        return held.plan, SpatReading(held.state, held.stamp, held.received, age, status == "ok", status, offset, entry.uncertainty)

    def plan(self, intersection_id: int, signal_group: int) -> tuple[UncertainPlan | None, SpatReading | None]:
        """The signal group's latest plan (parsed once) and its reading: the message that carried it, its age and
        status (``None`` plan and the intersection's reading for a group never published; ``None, None``: never heard)."""
        with self._lock:
            return self._plan(self._entries.get(intersection_id), signal_group)

    def plan_reading(self, intersection_id: int, signal_group: int) -> PlanReading:
        """What the advisor's observation needs of one light (:class:`~spat_feed.prediction.observe.PlanReading`): the plan,
        freshness and age (the group's own), what the group has been seen to do (bounds the phases after the published
        one), and the controller's clock offset (within the tolerance; beyond it the reading is not fresh anyway) with
        how far it may be off (red windows widened by it), and the amber its source declared (:meth:`declare_amber`)."""
        with self._lock:
            entry = self._entries.get(intersection_id)
            plan, reading = self._plan(entry, signal_group)
            if reading is None:
                return PlanReading(None, fresh=False, age_s=float("inf"))
            cycle = entry.history.stats(signal_group)
            held = entry.groups.get(signal_group)
            amber_s = self._amber_s.get((intersection_id, signal_group))
        return PlanReading(plan, fresh=reading.fresh, age_s=reading.age_s, cycle=cycle, clock_offset_s=-reading.clock_offset_s,
                           clock_uncertainty_s=reading.clock_uncertainty_s, queue_m=None if held is None else held.queue_m, amber_s=amber_s)

    def fresh(self, intersection_id: int) -> IntersectionState | None:
        r = self.reading(intersection_id)
        return r.intersection if r is not None and r.fresh else None

    def readings(self) -> dict[int, SpatReading]:
        with self._lock:
            ids = list(self._entries)
        return {i: r for i in ids if (r := self.reading(i)) is not None}

    def status(self, intersection_id: int, signal_group: int | None = None) -> str:
        """``ok``, ``stale``, ``clock_skew`` (also when every message so far came from a clock ahead) or ``no_spat``:
        of the intersection's latest message, or of ``signal_group``'s latest state (``no_spat``: never published)."""
        with self._lock:
            entry = self._entries.get(intersection_id)
            if entry is None:
                return "no_spat"
            if entry.state is None:
                return "clock_skew" if entry.ahead_unix_s > entry.heard_unix_s else "no_spat"
            held = entry if signal_group is None else entry.groups.get(signal_group)
            if held is None:
                return "no_spat"
            return self._status(entry, held.stamp, held.received, self.clock())[1]

    def sweep(self, expected: Iterable[int] = ()) -> dict[int, str]:
        """Status of every intersection held (and of ``expected`` ones); logs one WARNING when one goes
        out of ``ok`` and one INFO when it is back. Call it about once a second."""
        now = self.clock()
        with self._lock:
            ids = set(self._entries)
        out = {i: self.status(i) for i in sorted(ids.union(expected))}
        for i, status in out.items():
            st = self.stats.setdefault(i, IntersectionStats())
            if status != "ok" and st.stale_since_unix_s is None:
                st.stale_since_unix_s = now
                log.warning("SPaT of intersection %d: %s (no fresh data since %.1f s)", i, status, self._age(i, now))
            elif status == "ok" and st.stale_since_unix_s is not None:
                log.info("SPaT of intersection %d fresh again after %.1f s", i, now - st.stale_since_unix_s)
                st.stale_since_unix_s = None
        return out

    def _age(self, intersection_id: int, now: float) -> float:
        r = self.reading(intersection_id)
        return float("inf") if r is None else r.age_s


def _contradicts(held: UncertainPlan, new: UncertainPlan, stamp: float) -> bool:
    """``new`` shows green at ``stamp`` where ``held`` (the controller's previous word) could only be red then and for
    ``PLAUSIBLE_SLACK_S`` after (a held green about to end is no contradiction: it is still green at ``stamp``)."""
    if phase_class(state_at(new, stamp)) is not PhaseClass.GREEN:
        return False
    return all(phase_class(s) is PhaseClass.RED for t in (stamp, stamp + PLAUSIBLE_SLACK_S) for s in possible_states_at(held, t))


LatestStore = SpatStore
"""The earlier name of :class:`SpatStore`."""


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
