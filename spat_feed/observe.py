"""From a matched GPS fix and SPaT plans to the advisor's :class:`~advisory.advice.advisor.Observation`.

Pure: the bridge between ``spat_feed`` (plans on the Unix time axis) and ``advisory`` (lights ahead, times
relative to the fix). No clock, no I/O.

Conversion of one light (:func:`light_view`):

* ``distance_m`` = stop-line station - car station; only lights ahead (distance > 0), nearest first, two at most.
* ``red_windows_s``: the plan's red intervals relative to the fix time, **conservative**: a red begins at the
  earliest instant its change window allows (``min_end_s`` of the change into red) and ends at the latest
  (``max_end_s`` of the change out of red). Unknown states (``unavailable``, ``dark``) count as red, so a
  speed is never advised that reaches a line after the plan's horizon. Windows are kept up to ``horizon_s``.
* ``fresh``: the reading's flag; a light whose state is unknown *now* is reported as not fresh (no data).
* ``confidence_frac``: the lowest confidence of the change windows that bound a red window within the horizon
  (1 for a fixed-time plan).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

from advisory.advice.advisor import LightView, Observation
from spat_feed.corridors import Corridor, IntersectionSpec
from spat_feed.plans import (
    STOP_STATES,
    UNKNOWN_STATES,
    FixedTimePlan,
    MovementPhaseState,
    Plan,
    UncertainPlan,
    possible_states_at,
    uncertain_from_fixed,
)

HORIZON_S = 150.0
"""Red windows are reported this far ahead of the fix. [s]"""

BLOCKING_STATES = STOP_STATES | UNKNOWN_STATES
"""States a car must not plan to cross in: red, and anything the plan does not know."""


@dataclass(frozen=True, slots=True)
class PlanReading:
    """One light's plan (Unix axis) as read from a SPaT source, with the reading's freshness. ``plan`` None: no data."""

    plan: Plan | None
    fresh: bool = True
    age_s: float = 0.0


def as_uncertain(plan: Plan, t_unix_s: float, horizon_s: float = HORIZON_S) -> UncertainPlan:
    """An :class:`UncertainPlan` covering at least ``[t - cycle, t + horizon]``; fixed plans become exact windows."""
    if isinstance(plan, UncertainPlan):
        return plan
    assert isinstance(plan, FixedTimePlan)
    return uncertain_from_fixed(plan, t_unix_s - plan.cycle_s, t_unix_s + horizon_s + plan.cycle_s)


def red_windows_s(plan: Plan, t_unix_s: float, horizon_s: float = HORIZON_S) -> tuple[tuple[float, float], ...]:
    """Conservative blocking intervals ``(start, end)`` relative to ``t_unix_s``; ``start <= 0`` means now. [s]

    Windows that ended by ``t_unix_s`` or begin after ``t + horizon_s`` are left out; a start before now is
    written as 0; an end may be ``inf`` (no change known).

    Examples
    --------
    >>> red_windows_s(FixedTimePlan(30, 30, offset_s=1000.0), 1010.0, horizon_s=100.0)
    ((0.0, 20.0), (50.0, 80.0))
    """
    if isinstance(plan, FixedTimePlan):
        return _fixed_red_windows_s(plan, t_unix_s, horizon_s)
    up = plan
    out: list[list[float]] = []
    for i, state in enumerate(up.states):
        if state not in BLOCKING_STATES:
            continue
        start = up.changes[i - 1].min_end_s if i > 0 else -math.inf
        end = up.changes[i].max_end_s if i < len(up.changes) else math.inf
        start_rel, end_rel = start - t_unix_s, end - t_unix_s
        if end_rel <= 0.0 or start_rel >= horizon_s:
            continue
        start_rel = max(start_rel, 0.0)
        if out and start_rel <= out[-1][1]:  # touching or overlapping: one window
            out[-1][1] = max(out[-1][1], end_rel)
        else:
            out.append([start_rel, end_rel])
    return tuple((float(s), float(e)) for s, e in out)


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
    """True when the plan cannot say the state at ``t_unix_s`` (possibly unavailable or dark)."""
    if isinstance(plan, FixedTimePlan):
        return False
    return bool(possible_states_at(plan, t_unix_s) & UNKNOWN_STATES)


def light_view(
    intersection: IntersectionSpec, reading: PlanReading | None, station_m: float, t_unix_s: float, horizon_s: float = HORIZON_S
) -> LightView:
    """The advisor's view of one light ahead at the fix time (see the module docstring)."""
    distance_m = float(intersection.stop_line_m - station_m)
    if reading is None or reading.plan is None or unknown_now(reading.plan, t_unix_s):
        return LightView(intersection.id, distance_m, fresh=False)
    return LightView(
        intersection.id,
        distance_m,
        fresh=bool(reading.fresh),
        confidence_frac=confidence_frac(reading.plan, t_unix_s, horizon_s),
        red_windows_s=red_windows_s(reading.plan, t_unix_s, horizon_s),
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
        light_view(ix, readings.get(ix.id), station_m, t_unix_s, horizon_s) for ix in intersections_ahead(corridor, station_m, n_lights)
    )
    return Observation(speed_mps=speed_mps, speed_limit_mps=speed_limit_mps, lights=tuple(lights), position_m=station_m, on_route=True)
