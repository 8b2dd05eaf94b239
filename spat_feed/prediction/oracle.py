"""Forecasts that know what really came: an oracle for measuring the decision apart from the prediction.

``ecodrive spat-eval --forecast truth`` and ``--forecast truth-jitter`` (docs/REPLAY.md) replace each light's
forecast by one made from the recorded truth (the change times the hindsight DP sees), so the advisor's kept share
of the hindsight saving splits into what the decision loses when the forecast is right and what the forecast's
error costs on top. Everything else of the service's path stays: the store's reading (its freshness, its age, its
published state), :func:`~spat_feed.prediction.observe.light_view` and the safety rule.

* :func:`exact_reading` (``truth``): the light as if its controller published every coming change exactly (J2735
  ``minEndTime = maxEndTime``): an :class:`~spat_feed.timing.plans.UncertainPlan` of exact windows, which the advisor
  takes as exact timing (its rules, as on a fixed-time plan).
* :func:`jitter_reading` (``truth-jitter``, ``truth-spread``): the published plan as read, with a forecast in place
  of the predictor's: each coming change as :data:`~spat_feed.prediction.predictor.N_SAMPLES` equally likely
  instants ``centre + sigma z``, ``z`` standard normal draws (:func:`jittered_forecasts`). ``truth-jitter``: the
  centre is the truth off by ``sigma e``, ``e`` one more draw, so the forecast is calibrated by construction (the
  truth is as likely at any rank of the instants; its median off by ``0.8 sigma`` on average, as a predictor's of
  that spread is). ``truth-spread``: the centre is the truth (never wrong in its median, only unsure: what the
  spread alone costs the choice). The draws of a change are seeded by the light and the change, the same at every
  second of an approach (a forecast does not jump about from one reading to the next). No change of the published
  phase comes before its ``minEndTime`` (a hard bound: a forecast that put a red's end before it took cars into the
  red on Antwerp's exact windows).

A published red is never shown as green: where the reading still says red at an instant the truth has already
turned green (the truth switches midway between the last red snapshot and the first green one), the red lasts in
the oracle until the next snapshot, the reading that says otherwise (:func:`truth_phases`).
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Sequence
from dataclasses import replace
from functools import lru_cache

import numpy as np

from spat_feed.prediction.observe import PlanReading
from spat_feed.prediction.predictor import N_SAMPLES, ChangeForecast
from spat_feed.timing.plans import (
    AMBER,
    GREEN,
    RED,
    ChangeWindow,
    MovementPhaseState,
    PhaseClass,
    UncertainPlan,
    phase_class,
    published_state,
    published_window,
)

STATE_OF: dict[PhaseClass, MovementPhaseState] = {PhaseClass.RED: RED, PhaseClass.AMBER: AMBER, PhaseClass.GREEN: GREEN}
"""The J2735 state an oracle publishes for each class of the truth (amber counts as green for the rules). [-]"""


def truth_phases(reds_s: Sequence[tuple[float, float]], ambers_s: Sequence[tuple[float, float]], t_unix_s: float, horizon_s: float,
                 published: PhaseClass | None = None, next_reading_unix_s: float = math.inf) -> list[tuple[PhaseClass, float]]:  # fmt: skip
    """The truth's phases from ``t_unix_s``: ``(class, end)`` in order, the first the phase at ``t_unix_s``, the last
    one ending after ``t_unix_s + horizon_s`` (``inf``: it never ends). ``reds_s``, ``ambers_s``: the truth's red
    and amber intervals ``[start, end)`` (sorted, on the same axis); green between them. Where the ``published``
    class is red and the truth is not red at ``t_unix_s`` (the reading lags the truth), a red until
    ``next_reading_unix_s`` comes first. [s]

    Examples
    --------
    >>> truth_phases(((10.0, 40.0), (70.0, 95.0)), ((7.0, 10.0), (67.0, 70.0)), 0.0, 50.0)
    [(<PhaseClass.GREEN: 'green'>, 7.0), (<PhaseClass.AMBER: 'amber'>, 10.0), (<PhaseClass.RED: 'red'>, 40.0), (<PhaseClass.GREEN: 'green'>, 67.0)]
    >>> truth_phases(((10.0, 40.0),), (), 40.2, 20.0, published=PhaseClass.RED, next_reading_unix_s=40.5)
    [(<PhaseClass.RED: 'red'>, 40.5), (<PhaseClass.GREEN: 'green'>, inf)]
    """
    t_end = t_unix_s + horizon_s
    edges: set[float] = set()
    for spans in (reds_s, ambers_s):
        for a, b in spans[max(bisect.bisect_right(spans, (t_unix_s, math.inf)) - 1, 0) :]:  # the span covering now, then on
            edges.update(e for e in (a, b) if t_unix_s < e < math.inf)
            if a > t_end:  # the first one past the horizon: the phase then in progress ends in it or before
                break

    def cls_at(x: float) -> PhaseClass:
        if any(a <= x < b for a, b in _covering(reds_s, x)):
            return PhaseClass.RED
        return PhaseClass.AMBER if any(a <= x < b for a, b in _covering(ambers_s, x)) else PhaseClass.GREEN

    out: list[tuple[PhaseClass, float]] = []
    now = cls_at(t_unix_s)
    if published is PhaseClass.RED and now is not PhaseClass.RED and next_reading_unix_s > t_unix_s:
        out.append((PhaseClass.RED, next_reading_unix_s))
    cls = now
    for e in sorted(edges):
        nxt = cls_at(e)
        if nxt is cls:
            continue
        if not out or e > out[-1][1]:
            out.append((cls, e))
        cls = nxt
        if e > t_end:
            return out
    out.append((cls, math.inf))
    return out


def _covering(spans: Sequence[tuple[float, float]], x: float) -> Sequence[tuple[float, float]]:
    """The span of sorted disjoint ``spans`` that began last at or before ``x`` (as a one-item slice, or empty)."""
    i = bisect.bisect_right(spans, (x, math.inf)) - 1
    return spans[i : i + 1] if i >= 0 else ()


def exact_plan(phases: Sequence[tuple[PhaseClass, float]]) -> UncertainPlan:
    """The phases (:func:`truth_phases`) as a plan published exactly: each change ``minEndTime = maxEndTime``."""
    states = tuple(STATE_OF[c] for c, _ in phases)
    changes = tuple(ChangeWindow.exact(end) for _, end in phases if math.isfinite(end))
    if len(changes) == len(states):  # the last phase ends too: what comes after it is not said
        states += (MovementPhaseState.UNAVAILABLE,)
    return UncertainPlan(states, changes)


@lru_cache(maxsize=4096)
def _draws(seed: tuple[int, ...]) -> tuple[float, np.ndarray]:
    """One change's draws (``seed``: the light and the change): the error of its centre, and :data:`N_SAMPLES`
    standard normal draws about it, sorted. [-]"""
    rng = np.random.default_rng(seed)
    error = float(rng.standard_normal())
    z = np.sort(rng.standard_normal(N_SAMPLES))
    z.setflags(write=False)  # (cached: shared by every second of an approach)
    return error, z


def jittered_forecasts(phases: Sequence[tuple[PhaseClass, float]], t_unix_s: float, sigma_s: float, seed: Sequence[int] = (),
                       centred: bool = False, floor_unix_s: float = -math.inf) -> tuple[ChangeForecast, ...]:  # fmt: skip
    """The changes of ``phases`` (:func:`truth_phases`) as forecasts of spread ``sigma_s``: each change's instants
    ``centre + sigma_s z`` (:func:`_draws`, seeded by ``seed`` and the change's instant to the millisecond), its
    centre the truth off by ``sigma_s e`` (``e`` one more standard normal draw: the truth is as likely at any rank of
    the instants, a calibrated forecast whose median is off by ``0.8 sigma_s`` on average), or, ``centred``, the
    truth itself (what the spread alone costs); none before now, the first none before ``floor_unix_s`` (the published
    phase's ``minEndTime``: a hard bound, as the predictor keeps it), none before the instants of the change before it
    (at each rank: a late change is followed by a late one), sorted; its earliest instant the first of them; a phase
    that never ends (``inf``) is the last. [s]

    Examples
    --------
    >>> f = jittered_forecasts([(PhaseClass.RED, 20.0), (PhaseClass.GREEN, 50.0), (PhaseClass.RED, math.inf)], 0.0, 3.0, (7,), centred=True)
    >>> [(x.ends.value, x.then and x.then.value) for x in f], [round(x.likely_unix_s, 1) for x in f]
    ([('red', 'green'), ('green', 'red'), ('red', None)], [19.9, 50.0, inf])
    """
    out: list[ChangeForecast] = []
    before = np.full(N_SAMPLES, max(t_unix_s, floor_unix_s))
    for k, (cls, end) in enumerate(phases):
        then = phases[k + 1][0] if k + 1 < len(phases) else None
        if math.isfinite(end):
            error, z = _draws((*seed, int(round(end * 1000.0))))
            samples = np.maximum(end + sigma_s * ((0.0 if centred else error) + z), before)
        else:
            samples = np.full(N_SAMPLES, math.inf)
        out.append(ChangeForecast(cls, then, float(samples[0]), samples, "truth-jitter"))
        before = samples
    return tuple(out)


def exact_reading(reading: PlanReading, reds_s, ambers_s, t_unix_s: float, horizon_s: float, next_reading_unix_s: float = math.inf) -> PlanReading:
    """``reading`` (the store's, at ``t_unix_s``) with the truth as its plan, published exactly (module docstring);
    no plan stays no plan (no data is no data). ``reds_s``, ``ambers_s``: the truth (:func:`truth_phases`)."""
    if reading.plan is None:
        return reading
    phases = truth_phases(reds_s, ambers_s, t_unix_s, horizon_s, _published(reading, t_unix_s), next_reading_unix_s)
    return replace(reading, plan=exact_plan(phases), cycle=None, clock_offset_s=0.0, clock_uncertainty_s=0.0)


def jitter_reading(reading: PlanReading, reds_s, ambers_s, t_unix_s: float, horizon_s: float, sigma_s: float, seed: Sequence[int] = (),
                   next_reading_unix_s: float = math.inf, centred: bool = False) -> PlanReading:  # fmt: skip
    """``reading`` (the store's, at ``t_unix_s``) with the truth jittered by ``sigma_s`` as its forecast
    (:func:`jittered_forecasts`, ``centred`` or not; the published plan and its red hold as read); no plan stays no
    plan."""
    if reading.plan is None:
        return reading
    published = _published(reading, t_unix_s)
    phases = truth_phases(reds_s, ambers_s, t_unix_s, horizon_s, published, next_reading_unix_s)
    window = published_window(reading.plan, t_unix_s - reading.age_s) if isinstance(reading.plan, UncertainPlan) else None
    floor = window[0] if window is not None and phases[0][0] is published else -math.inf  # the phase the reading publishes: its minEndTime
    forecasts = jittered_forecasts(phases, t_unix_s, sigma_s, seed, centred, floor)
    return replace(reading, forecasts=forecasts, clock_offset_s=0.0, clock_uncertainty_s=0.0)


def _published(reading: PlanReading, t_unix_s: float) -> PhaseClass:
    """The class the reading publishes now (as of the reading: ``t - age``)."""
    plan, at = reading.plan, t_unix_s - reading.age_s
    if isinstance(plan, UncertainPlan):
        return phase_class(published_state(plan, at))
    from spat_feed.timing.plans import state_at

    return phase_class(state_at(plan, at))
