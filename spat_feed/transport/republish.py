"""SPaT republished with our predictions: every movement's J2735 ``likelyTime`` and ``confidence``.

What the feed (its ``/spat/intersections``, its stream, MQTT, its recording) and the service (a trip's SPaT) send
on is the controller's state with, for each movement whose controller did not state them, the predicted end of its
current phase (:func:`spat_feed.prediction.predictor.forecast`, from what the intersection's groups have been seen
to do, :class:`~spat_feed.prediction.history.IntersectionHistory`, fed with every state):

* ``likelyTime``: the forecast's median (``ChangeForecast.likely_unix_s``), held inside the published
  ``[minEndTime, maxEndTime]`` (J2735 puts the likely time between the two; ``maxEndTime`` is soft and a later
  median is stated as ``maxEndTime``); left out where nothing bounds the change (no forecast, or an unbounded
  median), and so is ``confidence`` then;
* ``confidence``: J2735 TimeIntervalConfidence, which J2735 ties to ``likelyTime`` alone: the index of the largest
  ``CONFIDENCE_FRAC`` level not above the probability that the change comes within :data:`TOLERANCE_S` of the
  stated ``likelyTime`` (index 0 reads "21 % or less"). That probability is the forecast's own
  (``ChangeForecast.within_frac``) **as this intersection's past statements bore it out** (:class:`Calibration`):
  the forecast's share alone is overconfident (2019-05-01, whole day: stated 73-88 %, 29-49 % came within 2 s), and
  J2735 asks for the statistical confidence, so the share is a measured one.

Never touched: the state, ``startTime``, ``minEndTime``, ``maxEndTime``, ``nextTime``, and a ``likelyTime`` or
``confidence`` the controller stated itself (where it stated a ``likelyTime`` only, the added confidence is that of
its ``likelyTime``). Phases after the current one are filled where the controller published them and the forecast
chains to the same phase class (their confidence is never borne out here: index 0).

The fields added are marked: the event gets a J2735 regional extension (``regionId``
:data:`~spat_feed.timing.messages.PREDICTED_REGION_ID`, ``regExtValue`` ``{"predicted": [...],
"confidenceWithinS": 2.0}``). Other consumers read the standard fields; ours
(:func:`~spat_feed.timing.messages.plan_from_movement`) reads marked fields as absent, so a receiver of the
republished feed makes the very plan of the controller's own message (a window's confidence is only ever the
controller's: a predicted 21 % never silences the advisor). Republishing is idempotent: marked fields are dropped
and predicted again.

Pure: no clock; the instant is the state's own timestamp.
"""

from __future__ import annotations

import bisect
import math
import threading
from collections.abc import Callable

from spat_feed.prediction.history import CycleStats, IntersectionHistory
from spat_feed.prediction.predictor import ChangeForecast, forecast
from spat_feed.timing.messages import (
    PREDICTED_REGION_ID,
    IntersectionState,
    MovementEvent,
    MovementState,
    RegionalExtension,
    confidence_index,
    from_unix_s,
    plan_from_movement,
    predicted_fields,
    to_unix_s,
)
from spat_feed.timing.plans import PhaseClass, UncertainPlan, phase_class

TOLERANCE_S = 2.0
"""``confidence`` is the probability that the change comes within this of ``likelyTime`` (J2735 calls it the
statistical confidence of the predicted time and names no interval). 2 s: a recorded controller is read once a
second, so a change is dated up to 1 s late (a tighter interval would score the sampling, not the prediction), and
it is the resolution a driver's countdown needs (28 m at 50 km/h). [s]"""

MAX_GAP_S = 2.0
"""A change seen after a gap longer than this in the group's states bears out no statement (when it came is not
known; as ``ecodrive predict-eval``). [s]"""

WILSON_Z = 1.645
"""The stated probability is the one-sided 95 % lower bound (Wilson score) of the share borne out. [-]"""

HORIZON_BINS_S = (5.0, 15.0, 45.0)
"""How far ahead the likely time is splits the calibration bins here: a change a minute ahead is told less well than
one due in seconds, whatever the forecast's own spread. [s]"""

MAX_STATEMENTS = 1200
"""Statements kept per phase in progress (20 min of a state a second; a forecast looks 3 min ahead at most). [-]"""

KEEP_CHANGES = 200
"""A calibration bin's counts are halved when it has seen this many changes: it follows the controller's hours. [-]"""


class Calibration:
    """How often the forecasts of one intersection came true: per bin (the forecast's method, the J2735 index of its
    own probability, the horizon: :func:`_bin`), the statements made, those whose change came within
    :data:`TOLERANCE_S` of the likely time, and the changes they were about (the statements of one change are not
    independent: a phase is forecast at every state). :meth:`frac` is the share borne out, as a lower bound over the
    changes seen (0 with none)."""

    __slots__ = ("bins",)

    def __init__(self) -> None:
        self.bins: dict[tuple, list[float]] = {}  # bin -> [statements, within, changes]

    def frac(self, key: tuple) -> float:
        """The probability to state for a forecast of bin ``key``. [-]"""
        b = self.bins.get(key)
        if b is None or b[2] <= 0:
            return 0.0
        p, n, z2 = b[1] / b[0], b[2], WILSON_Z**2
        return max(0.0, (p + z2 / (2 * n) - WILSON_Z * math.sqrt(p * (1 - p) / n + z2 / (4 * n * n))) / (1 + z2 / n))

    def add(self, statements: list[tuple[tuple, float]], change_unix_s: float) -> None:
        """The change that ``statements`` (bin, likely instant) were about came at ``change_unix_s``."""
        seen = set()
        for key, likely in statements:
            b = self.bins.get(key)
            if b is None:
                b = self.bins[key] = [0.0, 0.0, 0.0]
            b[0] += 1.0
            b[1] += abs(change_unix_s - likely) <= TOLERANCE_S
            if key not in seen:
                seen.add(key)
                b[2] += 1.0
                if b[2] >= KEEP_CHANGES:
                    b[:] = [x / 2.0 for x in b]


def _bin(fc: ChangeForecast, likely_unix_s: float, t_unix_s: float) -> tuple[str, int, int]:
    """A statement's calibration bin: the forecast's method, the J2735 index of its own probability, how far
    ahead (:data:`HORIZON_BINS_S`)."""
    return fc.method, confidence_index(fc.within_frac(likely_unix_s, TOLERANCE_S)), bisect.bisect(HORIZON_BINS_S, likely_unix_s - t_unix_s)


def _own(event: MovementEvent) -> MovementEvent:
    """``event`` as the controller published it: fields and the extension of an earlier republisher removed."""
    if not event.regional:
        return event
    predicted = predicted_fields(event)
    others = [x for x in event.regional if x.region_id != PREDICTED_REGION_ID] or None
    timing = event.timing
    if timing is not None and predicted:
        timing = timing.model_copy(update={k: None for k, f in (("likely_time", "likelyTime"), ("confidence", "confidence")) if f in predicted})
    return event.model_copy(update={"timing": timing, "regional": others})


def _stated(event: MovementEvent) -> bool:
    """Whether the controller stated all there is to state of this event (no timing, or likelyTime and confidence)."""
    t = event.timing
    return t is None or (t.likely_time is not None and t.confidence is not None and not predicted_fields(event))


def _likely(event: MovementEvent, fc: ChangeForecast):
    """The likely time to state (a datetime: the controller's, else the forecast's median inside the published
    window), or None when nothing bounds the change."""
    timing = event.timing
    if timing.likely_time is not None:
        return timing.likely_time
    x = fc.likely_unix_s
    if not math.isfinite(x):
        return None
    if x <= to_unix_s(timing.min_end_time):
        return timing.min_end_time
    if timing.max_end_time is not None and x >= to_unix_s(timing.max_end_time):
        return timing.max_end_time
    return from_unix_s(x)


def _predicted(event: MovementEvent, likely, confidence_frac: float) -> MovementEvent:
    """``event`` (the controller's own) with the likelyTime and confidence it lacks, marked."""
    timing, added, update = event.timing, [], {}
    if timing.likely_time is None:
        update["likely_time"] = likely
        added.append("likelyTime")
    if timing.confidence is None:
        update["confidence"] = confidence_index(confidence_frac)
        added.append("confidence")
    if not added:
        return event
    mark = RegionalExtension(region_id=PREDICTED_REGION_ID, reg_ext_value={"predicted": added, "confidenceWithinS": TOLERANCE_S})
    return event.model_copy(update={"timing": timing.model_copy(update=update), "regional": [*(event.regional or ()), mark]})


Statement = Callable[[int, ChangeForecast, float], float]
"""``(k, forecast, likely instant) -> probability`` for the ``k``-th coming change of a movement."""


def predicted_movement(
    movement: MovementState, t_unix_s: float, cycle: CycleStats | None, frac: Statement, plan: UncertainPlan | None = None
) -> MovementState:
    """``movement`` with the predicted likelyTime and confidence of each event that lacks them (module docstring).

    ``t_unix_s``: the intersection's timestamp; ``cycle``: the group's
    :class:`~spat_feed.prediction.history.CycleStats`; ``frac``: the probability to state for a forecast (a
    :class:`Calibration`'s); ``plan``: :func:`plan_from_movement` of it, if already made.
    """
    events = [_own(e) for e in movement.state_time_speed]
    if all(_stated(e) for e in events):
        unchanged = all(a is b for a, b in zip(events, movement.state_time_speed))
        return movement if unchanged else movement.model_copy(update={"state_time_speed": events})
    plan = plan if plan is not None else plan_from_movement(movement, t_unix_s)
    first = sum(1 for c in plan.changes if c.max_end_s <= t_unix_s)  # the published phase, as forecast() finds it
    for k, fc in enumerate(forecast(plan, t_unix_s, cycle)):
        j = first + k
        if j >= len(plan.changes) or phase_class(events[j].event_state) is not fc.ends:
            break
        if _stated(events[j]) or (likely := _likely(events[j], fc)) is None:
            continue
        events[j] = _predicted(events[j], likely, frac(k, fc, to_unix_s(likely)))
    return movement.model_copy(update={"state_time_speed": events})


class _Ix:
    """One intersection: its history, its calibration, and per group the phase in progress and what was stated
    of its end."""

    __slots__ = ("history", "calibration", "phases", "last_unix_s")

    def __init__(self) -> None:
        self.history = IntersectionHistory()
        self.calibration = Calibration()
        self.phases: dict[int, tuple[PhaseClass, float, list]] = {}  # group -> (class, last seen, statements)
        self.last_unix_s = -math.inf


class Republisher:
    """Adds the predictions to each state it is handed (``republisher(state)``, module docstring), learning each
    intersection from those states: its groups (:class:`~spat_feed.prediction.history.IntersectionHistory`, as a
    store does) and how its forecasts came true (:class:`Calibration`). Thread-safe. ``latest``: the last state
    returned per intersection."""

    def __init__(self) -> None:
        self._ix: dict[int, _Ix] = {}
        self.latest: dict[int, IntersectionState] = {}
        self._seen: dict[int, IntersectionState] = {}  # the state each of ``latest`` was made from
        self._lock = threading.Lock()

    def __call__(self, state: IntersectionState) -> IntersectionState:
        if all(_stated(e) for m in state.states for e in m.state_time_speed):
            return state  # a controller that states everything (the simulator): as it is, nothing to learn
        with self._lock:
            out = self._republished(state)
            self.latest[state.id], self._seen[state.id] = out, state
            return out

    def republished(self, state: IntersectionState) -> IntersectionState:
        """``state`` as this republisher last returned it (a store's observer has seen it), else with the
        predictions from what is known now (learning nothing: an older state)."""
        with self._lock:
            out = self.latest.get(state.id)
            seen = self._seen.get(state.id)
        return out if seen is state and out is not None else self(state)

    def calibration(self, intersection_id: int) -> Calibration | None:
        ix = self._ix.get(intersection_id)
        return None if ix is None else ix.calibration

    def _republished(self, state: IntersectionState) -> IntersectionState:
        t = to_unix_s(state.timestamp)
        ix = self._ix.get(state.id)
        if ix is None:
            ix = self._ix[state.id] = _Ix()
        plans: dict[int, UncertainPlan] = {}
        first: dict[int, MovementState] = {}
        for m in state.states:  # a group's plan is its first movement's, as the store and IntersectionState.movement take it
            if m.signal_group not in first:
                first[m.signal_group] = m
                plans[m.signal_group] = plan_from_movement(m, t)
        learn = t > ix.last_unix_s  # a repeat or an older state teaches nothing (predicted from what is known)
        if learn:
            ix.last_unix_s = t
            ix.history.record(t, plans)
        for g, plan in plans.items() if learn else ():  # the phase ends seen bear out (or not) what was stated of them
            cls = phase_class(plan.states[sum(1 for c in plan.changes if c.max_end_s <= t)])
            seen = ix.phases.get(g)
            if seen is not None and (seen[0] is not cls or t - seen[1] > MAX_GAP_S):
                if seen[0] is not cls and t - seen[1] <= MAX_GAP_S and seen[2]:
                    ix.calibration.add(seen[2], t)
                seen = None
            ix.phases[g] = (cls, t, [] if seen is None else seen[2])
        movements = []
        for m in state.states:
            g = m.signal_group
            statements = ix.phases[g][2] if learn and first[g] is m else []

            def frac(k: int, fc: ChangeForecast, likely: float, statements=statements) -> float:
                if k > 0:
                    return 0.0  # a later phase's end: never borne out here
                key = _bin(fc, likely, t)
                statements.append((key, likely))
                if len(statements) > MAX_STATEMENTS:  # a phase that never ends: its oldest statements go
                    del statements[: MAX_STATEMENTS // 2]
                return ix.calibration.frac(key)

            movements.append(predicted_movement(m, t, ix.history.stats(g), frac, plans[g] if first[g] is m else None))
        return state.model_copy(update={"states": movements})
