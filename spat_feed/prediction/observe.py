"""From a matched GPS fix and SPaT plans to the advisor's :class:`~advisory.advice.views.Observation`.

Pure: the bridge between ``spat_feed`` (plans on the Unix time axis) and ``advisory`` (lights ahead, times
relative to the fix). No clock, no I/O. What each signal group has been seen to do, which bounds the phases after the
published ones, is learnt in :mod:`spat_feed.prediction.history`; the phase ends forecast from it in
:mod:`spat_feed.prediction.predictor`.

Conversion of one light (:func:`light_view`):

* ``distance_m`` = stop-line station - car station; only lights ahead (distance > 0), nearest first, two at most.
* ``red_windows_s``: the plan's red intervals relative to the fix time, **conservative**: a red begins at the
  earliest instant its change window allows (``min_end_s`` of the change into red) and ends at the latest
  (``max_end_s`` of the change out of red). Unknown states (``unavailable``, ``dark``) count as red, so a
  speed is never advised that reaches a line after the plan's horizon. Windows are kept up to ``horizon_s``.
* ``fresh``: the reading's flag; a light whose published state is unknown is reported as not fresh (no data),
  unless the group's history reads its unknown phases as a passable phase published as ``unavailable``
  (:func:`_unknown_as`): its amber (between green and red, no longer than :data:`CLEARANCE_MAX_S`) or its go phase
  (between reds, longer than an amber: a red ends into a movement). Such a phase passes as an amber or a green
  does, and when it is the current one the cycle goes on from it as the history says. A
  phase past its ``minEndTime`` is still the published one (it may end any moment: a possible red, not no data).
* ``unknown_windows_s``: the phases within those windows whose state nothing reads (an ``unavailable`` between
  greens, say), as each change is likely, where they end: blocking for every plan, but not a red (no stop is asked
  for them, the driver's display shows none). The open tail past the plan and the history is not among them: a red
  whose end is unknown stays a red.
* ``confidence_frac``: the lowest confidence of the change windows that bound a red window within the horizon
  (1 for a fixed-time plan).
* **After the published phases** (an actuated controller publishes the current phase only): what the signal
  group has been seen to do (:class:`~spat_feed.prediction.history.PhaseHistory`, passed as ``PlanReading.cycle``)
  bounds the phases that follow, so a red is no longer endless. Each change is a triple (earliest, likely, late): the
  current phase ends no earlier than ``minEndTime`` (hard), likely at the median of the forecast of
  :mod:`spat_feed.prediction.predictor` (a linked change of another group, a held ``minEndTime`` running again, the
  controller's cycle or the durations seen, whichever applies) but no later than the published ``maxEndTime``,
  late at its :data:`~spat_feed.prediction.history.LATE_QUANTILE` (soft; it replaces ``maxEndTime``, which on the
  Antwerp controller was now 9 s early, now 2 minutes late; without a history ``maxEndTime`` is the late bound); the next phases end at the
  shortest durations seen after the earliest, and at the forecast chained over their durations (median, late).
  ``red_windows_s`` spans earliest start to late
  end; ``likely_red_windows_s`` the likely ones (the countdown; "stop" only when a stop is likely);
  ``late_red_windows_s`` latest start to late end (never slowed for a red that may not have begun on arrival;
  what a driver's display may rely on). The first two contain every red that ``minEndTime`` guarantees.
* **The safety rule** (:func:`red_hold_s`): a light whose latest reading is red (or amber) stays red in all three
  for as long as a plan could otherwise cross it before the car, told at the next reading, could still stop.
* **Clock**: a reading may carry the feed clock's estimated offset (subtracted) and its uncertainty (every
  ``red_windows_s`` widened by it on both sides, a red that ended less than that long ago included), so a few
  seconds of skew never put the advice into a red.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from numba import njit

from advisory.advice.views import AdvisorParams, LightView, Observation, Timings
from spat_feed.prediction.history import LATE_QUANTILE, CycleStats, _quantile
from spat_feed.prediction.predictor import EXACT_S, ChangeForecast, class_model, current_end, ends_after, sample_quantile
from spat_feed.road.corridors import Corridor, IntersectionSpec
from spat_feed.timing.plans import (
    STOP_STATES,
    UNKNOWN_STATES,
    FixedTimePlan,
    PhaseClass,
    Plan,
    UncertainPlan,
    phase_class,
    published_index,
    published_state,
    uncertain_from_fixed,
)

HORIZON_S = 150.0
"""Red windows are reported this far ahead of the fix. [s]"""


BLOCKING_CLASSES = frozenset({PhaseClass.RED, PhaseClass.UNKNOWN})


@dataclass(frozen=True, slots=True)
class PlanReading:
    """One light's plan (Unix axis) as read from a SPaT source, with the reading's freshness. ``plan`` None: no data.

    ``cycle``: what the signal group has been seen to do (:meth:`~spat_feed.prediction.history.PhaseHistory.stats`), to bound the phases after
    the published ones. ``clock_offset_s``: the feed clock minus ours, as estimated (subtracted from the plan's
    instants); ``clock_uncertainty_s``: how far that estimate may be off (red windows widened by it). [s]
    ``amber_s``: the amber the light really shows before each red, where the source knows it: None (unknown) is
    taken as some amber, as traffic law requires, whether the feed publishes it or not; 0: none, a green may turn
    red at once (:func:`no_amber`). [s]
    ``queue_m``: the queue standing back from the stop line that the controller's detectors published with the
    reading (J2735 ``queueLength``, :meth:`~spat_feed.timing.messages.MovementState.queue_length_m`); None: not said. [m]
    ``forecasts``: the light's coming changes as forecast apart from the plan and its history, the first the end of
    the phase now (an oracle's: :mod:`spat_feed.prediction.oracle`, ``spat-eval --forecast truth-jitter``), in place
    of the predictor's (:func:`forecast_phases`); the published plan still holds its red (:func:`red_hold_s`).
    None: the predictor's.
    """

    plan: Plan | None
    fresh: bool = True
    age_s: float = 0.0
    cycle: CycleStats | None = None
    clock_offset_s: float = 0.0
    clock_uncertainty_s: float = 0.0
    amber_s: float | None = None
    queue_m: float | None = None
    forecasts: tuple[ChangeForecast, ...] | None = None

    @classmethod
    def of_plan(cls, plan: Plan | None) -> PlanReading:
        """A plan the service knows in advance (a plan file, the simulator's corridor plans), with the amber it says:
        a fixed-time plan's ``amber_s`` (0: its greens turn red at once); unknown (None) for any other plan."""
        return cls(plan, amber_s=plan.amber_s if isinstance(plan, FixedTimePlan) else None)


def as_uncertain(plan: Plan, t_unix_s: float, horizon_s: float = HORIZON_S) -> UncertainPlan:
    """An :class:`UncertainPlan` covering at least ``[t - cycle, t + horizon]``; fixed plans become exact windows."""
    if isinstance(plan, UncertainPlan):
        return plan
    assert isinstance(plan, FixedTimePlan)
    return uncertain_from_fixed(plan, t_unix_s - plan.cycle_s, t_unix_s + horizon_s + plan.cycle_s)


def red_windows_s(plan: Plan, t_unix_s: float, horizon_s: float = HORIZON_S, cycle: CycleStats | None = None) -> tuple[tuple[float, float], ...]:
    """Conservative blocking intervals ``(start, end)`` relative to ``t_unix_s``; ``start <= 0`` means now. [s]

    Windows that ended by ``t_unix_s`` or begin after ``t + horizon_s`` are left out; a start before now is
    written as 0; an end may be ``inf`` (no change known). ``cycle`` bounds the phases after the published ones.

    Examples
    --------
    >>> red_windows_s(FixedTimePlan(30, 30, offset_s=1000.0), 1010.0, horizon_s=100.0)
    ((0.0, 20.0), (50.0, 80.0))
    """
    if isinstance(plan, FixedTimePlan):
        return _fixed_red_windows_s(plan, t_unix_s, horizon_s)
    return _windows(predicted_phases(plan, t_unix_s, horizon_s, cycle), t_unix_s, horizon_s, 0, 2)


Bound = tuple
"""A change's (earliest, likely, late) instant on the plan's axis, and where the predictor says, a fourth item: its
:data:`N_SCENARIOS` quantiles (:func:`_levels`, an array). [s]"""

N_SCENARIOS = 20
"""Equally likely timings of a light the advisor weighs its plans on (``LightView.scenario_red_windows_s``): every
change at the same quantile ``(k + 1/2) / N`` of its forecast (comonotone: a late red ends late). [-]"""

SCENARIO_LEVELS = tuple((k + 0.5) / N_SCENARIOS for k in range(N_SCENARIOS))


@lru_cache(maxsize=512)
def _level_ranks(n: int) -> np.ndarray:
    """Where :data:`SCENARIO_LEVELS`' quantiles lie in ``n`` sorted samples (:func:`sample_quantile`'s ranks)."""
    ranks = np.array([sample_quantile(range(n), q) for q in SCENARIO_LEVELS], dtype=np.int64)
    ranks.setflags(write=False)  # (cached: shared by every call)
    return ranks


def _levels(samples: np.ndarray, floor_s: float) -> np.ndarray:
    """The forecast's quantiles at :data:`SCENARIO_LEVELS` (sorted ``samples``), none before ``floor_s``: shape
    ``(N_SCENARIOS,)``. [s]"""
    return np.maximum(samples[_level_ranks(len(samples))], floor_s)


def _pick(bound: Bound, which) -> float:
    """One instant of a change: ``which`` an index (0 earliest, 1 likely, 2 late) or a quantile level in (0, 1): the
    forecast's where it has one, else read off the (earliest, likely, latest) window, a published one, as piecewise
    uniform (half the chance on each side of its likely time; uniform over the window where the likely time is its
    earliest, which says nothing of where in it)."""
    if isinstance(which, int):
        return bound[which]
    if len(bound) > 3:
        return bound[3][SCENARIO_LEVELS.index(which)]
    lo, mid, hi = bound[:3]
    if not math.isfinite(lo) or hi - lo < EXACT_S:
        return mid  # exact, or before anything is known
    if mid - lo < EXACT_S and math.isfinite(hi):
        # a likely time at the earliest (a controller's likely time that has passed is published as "now"): no news
        # about where in the window, which is read as uniform (not half the chance at its first instant)
        return lo + (hi - lo) * which
    if which <= 0.5:
        return lo + (mid - lo) * which / 0.5
    return mid + (hi - mid) * (which - 0.5) / 0.5 if math.isfinite(hi) else hi


def predicted_phases(plan: UncertainPlan, t_unix_s: float, horizon_s: float, cycle: CycleStats | None) -> list[tuple[PhaseClass, Bound, Bound]]:
    """(class, start, end) of each phase of the plan, each bound an (earliest, likely, late) triple on the plan's axis;
    the open tail (a last "unavailable") bounded by ``cycle`` where the history can (module docstring)."""
    inf = math.inf
    out: list[tuple[PhaseClass, Bound, Bound]] = []
    start: Bound = (-inf, -inf, -inf)
    for i, state in enumerate(plan.states):
        if i < len(plan.changes):
            c = plan.changes[i]
            end: Bound = (c.min_end_s, c.likely_s, c.max_end_s)
        else:
            end = (inf, inf, inf)
        out.append((phase_class(state), start, end))
        start = end
    if cycle is None or out[-1][0] is not PhaseClass.UNKNOWN:
        return out
    if len(out) == 1:  # unknown now (no window), in a group whose unknown phases are its amber or go phase: as its history says
        if not _passable_now(cycle):
            return out
        return _continued(PhaseClass.UNKNOWN, cycle.since_unix_s, (-inf,) * 3, t_unix_s, t_unix_s, horizon_s, cycle, current=True) or out
    # the plan ends in "unavailable": its last known phase ends when such phases end, then the cycle goes on. A
    # group's amber or go phase now that has run longer than any seen ends in its published window; a red stays
    # unbounded (its window's middle as the likely end slowed cars that the regular driver beat: docs/ADVISOR.md 1a)
    cls, begun, published = out[-2]
    since = begun[1] if math.isfinite(begun[1]) else (cycle.since_unix_s if cycle.current is cls else None)
    current = cycle.current is cls and len(out) - 2 <= published_index(plan, t_unix_s)  # the phase in progress, not a later one
    rest = _continued(cls, since, begun, t_unix_s, max(t_unix_s, published[0]), horizon_s, cycle, published, current)
    return out if rest is None else out[:-2] + rest


def forecast_phases(forecasts: Sequence[ChangeForecast], t_unix_s: float) -> list[tuple[PhaseClass, Bound, Bound]]:
    """(class, start, end) of each phase that ``forecasts`` end (the first the phase now), as :func:`predicted_phases`
    gives them: each end (earliest, likely, late, its :data:`N_SCENARIOS` levels) read off the forecast's samples as
    :func:`_continued` reads the predictor's (likely its median, late its :data:`LATE_QUANTILE`, none before now or
    its earliest), then the unknown (a red) past the last change."""
    inf = math.inf
    out: list[tuple[PhaseClass, Bound, Bound]] = []
    start: Bound = (-inf, -inf, -inf)
    for f in forecasts:
        s, floor = f.samples_unix_s, max(t_unix_s, f.earliest_unix_s)
        likely = max(sample_quantile(s, 0.5), floor)
        end: Bound = (floor, likely, max(sample_quantile(s, LATE_QUANTILE), likely), _levels(s, floor))
        out.append((f.ends, start, end))
        start = end
    if math.isfinite(start[0]):
        out.append((PhaseClass.UNKNOWN, start, (inf, inf, inf)))
    return out


CLEARANCE_MAX_S = 6.0
"""The longest amber (yellow change interval) of real signals: 3-6 s (MUTCD 4D.26; Belgian urban signals 3 s). An
unknown phase between green and red that lasts no longer is that group's amber, published as "unavailable". [s]"""


def _unknown_as(cycle: CycleStats | None) -> PhaseClass:
    """What the group's unknown phases are, read by what the group does (J2735 ``unavailable`` says nothing):

    * AMBER: they come between green and red and last no longer than an amber (:data:`CLEARANCE_MAX_S`): its
      clearance interval published as "unavailable" (2019-05-01 does so);
    * GREEN: they come between reds and usually last longer than an amber: its go phase (green, then its amber)
      published as "unavailable" (2019-05-17 does so for every group). A stop-And-Remain ends into a movement
      (J2735's phase sequence); the group publishes its reds, so the next red is the change out of the unknown
      phase, bounded by the published window and the durations seen like any other;
    * UNKNOWN: anything else (an unknown between greens, a group too young to tell): never a basis for advice.
    """
    if cycle is None or cycle.following.get(PhaseClass.UNKNOWN) is not PhaseClass.RED or not (d := cycle.durations(PhaseClass.UNKNOWN)):
        return PhaseClass.UNKNOWN
    if cycle.following.get(PhaseClass.GREEN) is PhaseClass.UNKNOWN and _quantile(d, LATE_QUANTILE) <= CLEARANCE_MAX_S:
        return PhaseClass.AMBER
    if cycle.following.get(PhaseClass.RED) is PhaseClass.UNKNOWN and _quantile(d, 0.5) > CLEARANCE_MAX_S:
        return PhaseClass.GREEN
    return PhaseClass.UNKNOWN


def _passable_now(cycle: CycleStats | None) -> bool:
    """In such a passable unknown phase now (:func:`_unknown_as`): the light is fresh, the cycle goes on from it."""
    return cycle is not None and cycle.current is PhaseClass.UNKNOWN and cycle.since_unix_s is not None and _unknown_as(cycle) is not PhaseClass.UNKNOWN


def _continued(cls: PhaseClass, since_unix_s: float | None, begun: Bound, now_s: float, after_s: float, horizon_s: float, cycle: CycleStats,
               published: Bound | None = None, current: bool = False) -> list | None:  # fmt: skip
    """The phase of class ``cls`` that began at ``since_unix_s`` (``begun``: its start bounds), ending no earlier
    than ``after_s``, when such phases have ended (given how long it has run at ``now_s``; one that would have ended
    before ``after_s``, its minEndTime, ends then; likely no later than its ``published``
    maxEndTime), else, for an amber or go phase read from "unavailable", in its ``published`` window (when finite),
    then the classes that followed it for ``horizon_s``, then the unknown; None when neither says."""
    inf = math.inf
    max_end = published[2] if published is not None else inf
    min_end = published[0] if published is not None else -inf
    got = current_end(cycle, cls, since_unix_s, now_s, min_end, max_end, current)
    if got is None or (got[1] == "window" and cls is not PhaseClass.UNKNOWN):  # no history: the published window stands
        return None
    samples = np.sort(got[0])
    if got[1] == "published":  # an exact end: the samples are when the class changes after it (:func:`current_end`)
        max_end = inf
    # the likely end is the forecast's median, but no later than the controller's own maxEndTime; the late end its
    # LATE_QUANTILE (maxEndTime is soft: 6-12 % of phases outlast it, some by minutes)
    likely, late = max(min(sample_quantile(samples, 0.5), max_end), after_s), max(sample_quantile(samples, LATE_QUANTILE), after_s)
    start: Bound = (after_s, likely, max(late, likely), _levels(samples, after_s))
    unknown_as = _unknown_as(cycle)  # the group's amber or go phase published as "unavailable"
    out: list[tuple[PhaseClass, Bound, Bound]] = [(unknown_as if cls is PhaseClass.UNKNOWN else cls, begun, start)]
    for cls, shortest, median, late, levels in _chain(cycle, cls, samples, horizon_s):
        if not start[0] < after_s + horizon_s:
            break
        end = (start[0] + shortest, min(max(median, start[1] + shortest), late), late, np.maximum(levels, start[3] + shortest))
        out.append((unknown_as if cls is PhaseClass.UNKNOWN else cls, start, end))
        start = end
    out.append((PhaseClass.UNKNOWN, start, (inf, inf, inf)))
    return out


CHAIN_MARGIN_S = 1.0
""":func:`_chain` goes this far past the horizon (the caller stops at it, adding the shortest durations to its own
instant: rounding apart, the same phases). [s]"""

CHAINS_KEPT = 64
"""Chains a snapshot keeps (:func:`_chain`; then it starts afresh). [-]"""


def _chain(cycle: CycleStats, cls: PhaseClass, samples: np.ndarray, horizon_s: float) -> tuple[tuple[PhaseClass, float, float, float, np.ndarray], ...]:
    """The phases that follow a phase of class ``cls`` ending at ``samples`` (sorted), as the history ``cycle`` says,
    while their shortest durations add up to less than the horizon (:func:`_chain_steps`): each one's class, shortest
    duration, the median and :data:`LATE_QUANTILE` of its end (:func:`~spat_feed.prediction.predictor.ends_after`)
    and its :func:`_levels`.

    What :func:`_continued` chains after the phase in progress; kept in the snapshot (``CycleStats.chains``, by class,
    samples and horizon): between two changes of a group's history the end of its phase in progress is often the same
    set of samples from reading to reading (on the bench's observations the chain was kept in 1 of 4 views of 2019-05-17
    and 2 of 3 of US 1136), every car at the light reads the same, and the forecast after it depends on nothing else. [s]"""
    key = (cls, samples.tobytes(), horizon_s)
    kept = cycle.chains.get(key)
    if kept is not None:
        return kept
    out = []
    for cls, shortest_s, model in _chain_steps(cycle, cls, horizon_s):
        samples = ends_after(samples, model, cycle)
        levels = samples[_level_ranks(len(samples))]
        levels.setflags(write=False)  # (kept: shared by every view)
        out.append((cls, shortest_s, sample_quantile(samples, 0.5), sample_quantile(samples, LATE_QUANTILE), levels))
    if len(cycle.chains) >= CHAINS_KEPT:
        cycle.chains.clear()
    cycle.chains[key] = kept = tuple(out)
    return kept


def _chain_steps(cycle: CycleStats, cls: PhaseClass, horizon_s: float) -> tuple[tuple[PhaseClass, float, tuple], ...]:
    """The classes that follow a phase of class ``cls`` in the history ``cycle`` while their shortest durations add up
    to less than the horizon (and :data:`CHAIN_MARGIN_S`), each with its shortest duration and its model
    (:func:`~spat_feed.prediction.predictor.class_model`): what :func:`_chain` adds, step by step, to the samples of
    the phase in progress. The history's alone: made once per snapshot (``CycleStats.chain_steps``). [s]"""
    key = (cls, horizon_s)
    steps = cycle.chain_steps.get(key)
    if steps is None:
        out, total_s = [], 0.0
        while total_s < horizon_s + CHAIN_MARGIN_S:
            nxt = cycle.following.get(cls)
            model = class_model(cycle, nxt) if nxt is not None else None
            if model is None:
                break
            cls = nxt
            out.append((cls, cycle.durations(cls)[0], model))
            total_s += out[-1][1]
        cycle.chain_steps[key] = steps = tuple(out)
    return steps


def _windows(phases, t_unix_s: float, horizon_s: float, lo, hi, classes=BLOCKING_CLASSES) -> tuple[tuple[float, float], ...]:
    """Phases of ``classes`` as windows from their start's ``lo`` bound to their end's ``hi`` bound (:func:`_pick`),
    relative, merged."""
    return _merged(((_pick(start, lo) - t_unix_s, _pick(end, hi) - t_unix_s) for cls, start, end in phases if cls in classes), horizon_s)


def _merged(spans, horizon_s: float) -> tuple[tuple[float, float], ...]:
    """Relative ``(start, end)`` spans in order as windows: those within ``(0, horizon_s)``, clipped at now, the
    touching or overlapping ones merged. [s]"""
    out: list[list[float]] = []
    for start_rel, end_rel in spans:
        if end_rel <= 0.0 or start_rel >= horizon_s:
            continue
        start_rel = max(start_rel, 0.0)
        if out and start_rel <= out[-1][1]:  # touching or overlapping: one window
            out[-1][1] = max(out[-1][1], end_rel)
        else:
            out.append([start_rel, end_rel])
    return tuple((float(a), float(b)) for a, b in out)


def _view_windows(phases, t_unix_s: float, horizon_s: float, widen_s: float, hold_s: float, red_now: bool) -> list:
    """The three views' windows (``red_windows_s``: each red from its start's earliest to its end's latest instant;
    ``likely``: both at their likely instants; ``late``: both at their latest), each ``_windows(phases, t, horizon, lo,
    hi)`` moved ``widen_s`` earlier and :func:`_widened` by it, then the published red held (``hold_s``, ``red_now``:
    :func:`_timing_windows`), made at once (:func:`_made_windows`). [s]"""
    blocking = [(start, end) for cls, start, end in phases if cls in BLOCKING_CLASSES]
    starts = np.array([[start[0], start[1], start[2]] for start, _ in blocking], dtype=float).reshape(-1, 3).T - t_unix_s
    ends = np.array([[end[2], end[1], end[2]] for _, end in blocking], dtype=float).reshape(-1, 3).T - t_unix_s
    return _made_windows(starts, ends, horizon_s, widen_s, hold_s, red_now)[0]


def _scenario_windows(phases, t_unix_s: float, horizon_s: float, widen_s: float = 0.0, hold_s: float = 0.0, red_now: bool = False) -> Timings:
    """The blocking phases' windows in each equally likely timing: ``_windows(phases, t, horizon, q, q)`` for each
    ``q`` of :data:`SCENARIO_LEVELS`, then moved ``widen_s`` earlier and :func:`_widened` by it, then the published red
    held (``hold_s``, ``red_now``), as the other views (:func:`_view_windows`); the instants of all of them read at once
    (:func:`_level_picks`), the windows made at once (:func:`_made_windows`) and handed to the advisor packed
    (:class:`~advisory.advice.views.Timings`)."""
    blocking = [(start, end) for cls, start, end in phases if cls in BLOCKING_CLASSES]
    if blocking:
        starts = np.array([_level_picks(start) for start, _ in blocking]).T - t_unix_s
        ends = np.array([_level_picks(end) for _, end in blocking]).T - t_unix_s
    else:
        starts = ends = np.empty((N_SCENARIOS, 0))
    rows, packed = _made_windows(starts, ends, horizon_s, widen_s, hold_s, red_now)
    timings = Timings(rows)
    timings.array_s = packed
    return timings


def _made_windows(starts: np.ndarray, ends: np.ndarray, horizon_s: float, widen_s: float, hold_s: float, red_now: bool) -> tuple[list, np.ndarray]:
    """The windows of each row of spans (``starts``, ``ends``: (rows, spans), relative, in order) as tuples, and packed
    (rows, k, 2), padded with +inf (:func:`_timing_windows`). [s]"""
    out = np.empty((starts.shape[0], starts.shape[1] + 1, 2))
    counts = np.empty(starts.shape[0], dtype=np.int64)
    _timing_windows(starts, ends, horizon_s, widen_s, hold_s, red_now, out, counts)
    k = int(counts.max())
    return [tuple(map(tuple, row[:c])) for row, c in zip(out[:, :k].tolist(), counts.tolist())], out[:, :k]


@njit(cache=True, inline="always")
def _put(out, i, c, a, b):
    """The window ``(a, b)`` after the ``c`` windows made in row ``i`` of ``out``: clipped at now, one with the last
    where it touches or overlaps it (:func:`_merged`); the row's count after it. [s]"""
    if a < 0.0:
        a = 0.0
    if c > 0 and a <= out[i, c - 1, 1]:
        if b > out[i, c - 1, 1]:
            out[i, c - 1, 1] = b
        return c
    out[i, c, 0], out[i, c, 1] = a, b
    return c + 1


@njit(cache=True, error_model="numpy")
def _timing_windows(starts, ends, horizon_s, widen_s, hold_s, red_now, out, counts):
    """Each row's windows (row ``i`` of ``starts`` / ``ends``: relative spans in order) as :func:`_merged` makes them,
    then :func:`_widened` after moving them ``widen_s`` earlier (where ``widen_s > 0``), then held: where ``hold_s >
    0`` (:func:`red_hold_s`), the first red (the published one, ``red_now``, or the one after a published amber, which
    begins before ``hold_s``) lasts at least ``hold_s`` from now, a red now that the windows lost is put back, and the
    windows it then runs into are merged with it. The same operations in the same order as those functions (bit for
    bit; ``tests/server/test_observe.py`` holds the plain reading of the hold): into ``out[i, :counts[i]]``
    (capacity spans + 1), the rest +inf. [s]"""
    n, m = starts.shape
    for i in range(n):
        c = 0
        for j in range(m):  # _merged
            if not (ends[i, j] <= 0.0 or starts[i, j] >= horizon_s):
                c = _put(out, i, c, starts[i, j], ends[i, j])
        if widen_s > 0.0:  # _widened((a - u, b - u) ...)
            w = 0
            for j in range(c):
                w = _put(out, i, w, (out[i, j, 0] - widen_s) - widen_s, (out[i, j, 1] - widen_s) + widen_s)
            c = w
        if hold_s > 0.0 and (red_now or (c > 0 and 0.0 < out[i, 0, 0] < hold_s)):  # the red held
            if c > 0 and out[i, 0, 0] < hold_s and (red_now or out[i, 0, 0] > 0.0):
                if hold_s > out[i, 0, 1]:
                    out[i, 0, 1] = hold_s
            elif red_now:
                for j in range(c, 0, -1):
                    out[i, j, 0], out[i, j, 1] = out[i, j - 1, 0], out[i, j - 1, 1]
                out[i, 0, 0], out[i, 0, 1] = 0.0, hold_s
                c += 1
            while c > 1 and out[i, 1, 0] <= out[i, 0, 1]:
                if out[i, 1, 1] > out[i, 0, 1]:
                    out[i, 0, 1] = out[i, 1, 1]
                for j in range(1, c - 1):
                    out[i, j, 0], out[i, j, 1] = out[i, j + 1, 0], out[i, j + 1, 1]
                c -= 1
        out[i, c:] = np.inf
        counts[i] = c


def _level_picks(bound: Bound) -> np.ndarray:
    """A change's instants at :data:`SCENARIO_LEVELS` (:func:`_pick`): the forecast's, or read off its window. [s]"""
    return bound[3] if len(bound) > 3 else _window_picks(bound[:3])


@lru_cache(maxsize=1024)
def _window_picks(bound: Bound) -> np.ndarray:
    """:func:`_level_picks` of a bound with no forecast (a published window: the same from reading to reading)."""
    picks = np.array([_pick(bound, q) for q in SCENARIO_LEVELS], dtype=float)
    picks.setflags(write=False)  # (cached: shared by every call)
    return picks


def _fixed_red_windows_s(plan: FixedTimePlan, t_unix_s: float, horizon_s: float) -> tuple[tuple[float, float], ...]:
    """Fast path for a fixed plan (exact windows): reds ``[offset + k cycle, + red_s)``; amber counts as green."""
    cycle = plan.cycle_s
    k = math.floor((t_unix_s - plan.offset_s) / cycle)
    out = []
    while True:
        start = plan.offset_s + k * cycle - t_unix_s
        if start >= horizon_s:
            break
        end = start + plan.red_s
        if end > 0.0:
            out.append((max(float(start), 0.0), float(end)))
        k += 1
    return tuple(out)


def confidence_frac(plan: Plan, t_unix_s: float, horizon_s: float = HORIZON_S) -> float:
    """Lowest confidence of the changes into or out of red whose window overlaps ``[t, t + horizon]``. [-]"""
    if isinstance(plan, FixedTimePlan):
        return 1.0
    lowest = 1.0
    for i, change in enumerate(plan.changes):
        if change.max_end_s < t_unix_s or change.min_end_s > t_unix_s + horizon_s:
            continue
        if plan.states[i] in STOP_STATES or plan.states[i + 1] in STOP_STATES:
            lowest = min(lowest, change.confidence_frac)
    return lowest


def unknown_now(plan: Plan, t_unix_s: float) -> bool:
    """True when the plan cannot say the state at ``t_unix_s``: the published state (:func:`~spat_feed.timing.plans.published_state`) is
    unavailable or dark. A phase past its ``minEndTime``, which may turn unavailable any moment, is not unknown."""
    if isinstance(plan, FixedTimePlan):
        return False
    return published_state(plan, t_unix_s) in UNKNOWN_STATES


def _widened(windows: tuple[tuple[float, float], ...], widen_s: float) -> tuple[tuple[float, float], ...]:
    """Windows widened by ``widen_s`` on both sides (clipped at now), overlapping ones merged."""
    if widen_s <= 0.0:
        return windows
    out: list[list[float]] = []
    for a, b in windows:
        a, b = max(a - widen_s, 0.0), b + widen_s
        if out and a <= out[-1][1]:
            out[-1][1] = max(out[-1][1], b)
        else:
            out.append([a, b])
    return tuple((a, b) for a, b in out)


READING_PERIOD_S = 1.0
"""A published red lasts at least until the next reading could say otherwise (SPaT comes at 1-10 Hz). [s]"""



def red_hold_s(plan: UncertainPlan, t_reading_unix_s: float, speed_mps: float, params: AdvisorParams = AdvisorParams()) -> float:
    """How long from now a light whose latest reading is red (or amber, a red to come) stays red in every view: **the
    safety rule**. No prediction, countdown or clock correction ends such a red before the next reading could say
    otherwise (:data:`READING_PERIOD_S`), and no plan reaches the line before the car, told of the red at that
    reading, could still stop at the advisor's firm braking: the crossing (at least ``green_margin_s`` after a red's
    end, the advisor's own rule) is at least ``READING_PERIOD_S + reaction_s + v / (2 firm_decel_mps2)`` away, the
    time the car takes at its speed to its point of no return and one reading more. A plan never crosses a published
    red on a guess. 0 where the red's end is exact (:data:`EXACT_S`) or the light is not red. [s]"""
    i = published_index(plan, t_reading_unix_s)
    cls = phase_class(plan.states[i])
    k = i if cls is PhaseClass.RED else i + 1 if cls is PhaseClass.AMBER else None  # the change out of the red
    if k is None or (k < len(plan.changes) and plan.changes[k].max_end_s - plan.changes[k].min_end_s < EXACT_S):
        return 0.0
    no_return_s = params.reaction_s + max(speed_mps, 0.0) / (2.0 * params.firm_decel_mps2)
    return READING_PERIOD_S + max(0.0, no_return_s - params.green_margin_s)


def no_amber(phases: list[tuple[PhaseClass, Bound, Bound]]) -> list[tuple[PhaseClass, Bound, Bound]]:
    """The phases of a light that shows no amber before its reds (``PlanReading.amber_s`` = 0), each red that a go
    phase ends into beginning at its earliest in every view: the safety rule for a green whose end is uncertain.

    A driver is warned of a red by its amber: a car past the point where it can stop clears the line in it, and
    one before that point stops (the driver's eye, with or without advice). A green that turns red at once warns
    nobody, so a plan that reaches the line inside the window where its red may begin, on the likely time, meets
    the red at speed when it comes early: a car is too close to stop as soon as it is within its stopping distance
    (seed 3 of the randomized runs: "Drive normally" into a window open 0.5 s after entry, the change published
    exactly 4 s before the line at 24.6 m/s, 2.1 s into the red). So where no amber comes, no view puts such a red
    later than its earliest start (``minEndTime``, widened for the clock like any red): no plan reaches the line
    after a green may have ended, and the driver's display, which shows the late views, shows the possible red
    (the eye cannot). A red after an amber, or whose start is exact, is left as it is."""
    out = []
    for n, (cls, start, end) in enumerate(phases):
        if cls is PhaseClass.RED and n > 0 and phases[n - 1][0] is PhaseClass.GREEN and start[2] - start[0] >= EXACT_S:
            start = (start[0], start[0], start[0])
        out.append((cls, start, end))
    return out


def light_view(
    intersection: IntersectionSpec, reading: PlanReading | None, station_m: float, t_unix_s: float, horizon_s: float = HORIZON_S,
    speed_mps: float = 0.0,
) -> LightView:
    """The advisor's view of one light ahead at the fix time (see the module docstring); ``speed_mps``: the car's, for
    how long a published red holds (:func:`red_hold_s`)."""
    distance_m = float(intersection.stop_line_m - station_m)
    if reading is None or reading.plan is None:
        return LightView(intersection.id, distance_m, fresh=False, age_s=float(reading.age_s) if reading is not None else math.inf)
    plan, t_feed = reading.plan, t_unix_s + reading.clock_offset_s  # our instant on the feed's clock
    # a clock that may be off by u: any red may begin u earlier and end u later (the likely ones too: skew is no
    # chance), a red that ended less than u ago by the feed's clock included: the windows are taken from u before now
    u = reading.clock_uncertainty_s
    scenarios: Timings | None = None
    # how long a published red holds in every view (the safety rule), fresh or not: the latest reading
    hold = red_hold_s(plan, t_feed - reading.age_s, speed_mps) if not isinstance(plan, FixedTimePlan) else 0.0
    red_now = hold > 0.0 and phase_class(published_state(plan, t_feed - reading.age_s)) is PhaseClass.RED
    if isinstance(plan, FixedTimePlan):
        windows = likely = late = red_windows_s(plan, t_feed - u, horizon_s + u)
        if u > 0.0:
            windows = likely = late = _widened(tuple((a - u, b - u) for a, b in windows), u)
        unknown = ()
    else:
        given = reading.forecasts is not None
        phases = forecast_phases(reading.forecasts, t_feed) if given else predicted_phases(plan, t_feed, horizon_s, reading.cycle)
        if reading.amber_s == 0.0:
            phases = no_amber(phases)
        read_at = t_unix_s - reading.age_s
        if unknown_now(plan, read_at) and u > 0.0 and phase_class(published_state(plan, read_at - u)) in (PhaseClass.GREEN, PhaseClass.AMBER):
            # a go phase that ended into the unknown past the last published event, by a clock that may be u off: it may
            # not have ended yet, and the red after it may come (with no amber, unseen): not "no data" (a skewed clock
            # 2.8 s behind said so 7 m before the line, "Drive normally.", and the car rolled into the red); the
            # windows, widened by u, carry that red. (A red that ended so is left to the eye: the light is green.)
            read_at -= u
        if not given and unknown_now(plan, read_at) and (not _passable_now(reading.cycle) or all(c is PhaseClass.UNKNOWN for c, _, _ in phases)):
            return LightView(intersection.id, distance_m, fresh=False, age_s=float(reading.age_s))  # nothing reads it: no data
        # (widened by the clock, a published red held: where the windows then differ, so did they before)
        windows, likely, late = _view_windows(phases, t_feed - u, horizon_s + u, u, hold, red_now)
        if likely != windows:  # uncertain: the equally likely timings too, widened and held as the others
            # (the reds: the amber before each, published or not, is the advisor's to weigh, ``LightView.amber_s``)
            scenarios = _scenario_windows(phases, t_feed - u, horizon_s + u, u, hold, red_now)
        # the unknown phases that end (between known ones; the open tail past the plan and the history stays a red)
        unknown = tuple(w for w in _windows(phases, t_feed, horizon_s, 1, 1, {PhaseClass.UNKNOWN}) if math.isfinite(w[1]))
    return LightView(
        intersection.id,
        distance_m,
        fresh=bool(reading.fresh),
        confidence_frac=confidence_frac(plan, t_feed, horizon_s),
        red_windows_s=windows,
        likely_red_windows_s=None if likely == windows else likely,
        late_red_windows_s=None if late == windows else late,
        age_s=float(reading.age_s),
        unknown_windows_s=unknown,
        scenario_red_windows_s=scenarios if likely != windows else None,
        queue_m=reading.queue_m if reading.fresh else None,
        amber_s=reading.amber_s,
    )


def intersections_ahead(corridor: Corridor, station_m: float, n: int = 2) -> tuple[IntersectionSpec, ...]:
    """The next ``n`` intersections whose stop line is ahead of ``station_m`` (distance > 0), nearest first."""
    return tuple(ix for ix in corridor.intersections if ix.stop_line_m > station_m)[:n]


def observation(
    corridor: Corridor,
    station_m: float | None,
    speed_mps: float,
    t_unix_s: float,
    readings: Mapping[int, PlanReading],
    speed_limit_mps: float,
    *,
    on_route: bool = True,
    n_lights: int = 2,
    horizon_s: float = HORIZON_S,
) -> Observation:
    """The advisor's input for a fix at ``t_unix_s``: ``readings`` maps intersection id to its plan reading."""
    if not on_route or station_m is None:
        # off the route with every light behind (the route's end is clamped to its last station): a normal exit
        exit_ = station_m is not None and not intersections_ahead(corridor, station_m, 1)
        return Observation(speed_mps=speed_mps, speed_limit_mps=speed_limit_mps, lights=(), position_m=station_m, on_route=False, zone_exit=exit_)
    lights: Sequence[LightView] = tuple(
        light_view(ix, readings.get(ix.id), station_m, t_unix_s, horizon_s, speed_mps) for ix in intersections_ahead(corridor, station_m, n_lights)
    )
    return Observation(speed_mps=speed_mps, speed_limit_mps=speed_limit_mps, lights=tuple(lights), position_m=station_m, on_route=True)
