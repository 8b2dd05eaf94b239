r"""Signal plans as pure schedules: fixed-time and uncertain (actuated), evaluated at any instant.

A *plan* describes one signal group (one movement's light) on its own time axis, in seconds. The axis is
the caller's: seconds since a car entered the control zone (as in :mod:`advisory.signals`) or Unix
seconds (as in the feed). Nothing here reads a clock; every function takes the instant ``t_s``.

Two kinds of plan:

``FixedTimePlan``
    Red, green and an optional amber repeat every ``cycle_s``; a red begins at ``offset_s``. The
    paper's lights are fixed-time plans without amber.
``UncertainPlan``
    A finite sequence of states whose changes are each known only as a window
    ``[min_end_s, max_end_s]`` with a ``likely_s`` and a confidence, as in the J2735
    ``TimeChangeDetails`` of an actuated controller [1]_.

Both answer the same questions through module-level functions: :func:`state_at`,
:func:`possible_states_at`, :func:`seconds_to_next_green`, :func:`seconds_to_next_red` and
:func:`next_changes`. Intervals are half-open: a light that turns green at ``t`` is green at ``t``
(the paper's eco-driver crosses at that very instant) and was red just before.

References
----------
.. [1] SAE International, "V2X Communications Message Set Dictionary," SAE J2735_202309, 2023
   (DF_TimeChangeDetails, DE_MovementPhaseState, DE_TimeIntervalConfidence).
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Iterable
from dataclasses import dataclass
from enum import Enum
from typing import NamedTuple

from advisory.signals import FixedTimeSignal


class MovementPhaseState(str, Enum):
    """J2735 DE_MovementPhaseState, with J2735's own spellings as values."""

    UNAVAILABLE = "unavailable"
    DARK = "dark"
    STOP_THEN_PROCEED = "stop-Then-Proceed"  # flashing red
    STOP_AND_REMAIN = "stop-And-Remain"  # red
    PRE_MOVEMENT = "pre-Movement"  # red + amber (not used in the USA)
    PERMISSIVE_MOVEMENT_ALLOWED = "permissive-Movement-Allowed"  # permissive green
    PROTECTED_MOVEMENT_ALLOWED = "protected-Movement-Allowed"  # protected green
    PERMISSIVE_CLEARANCE = "permissive-clearance"  # permissive amber
    PROTECTED_CLEARANCE = "protected-clearance"  # protected amber
    CAUTION_CONFLICTING_TRAFFIC = "caution-Conflicting-Traffic"  # flashing amber


class PhaseClass(str, Enum):
    """What a J2735 movement phase means for a car approaching the stop line."""

    RED = "red"  # must stop at the line (also red + amber, and flashing red: stop, then proceed)
    AMBER = "amber"  # clearance: enter only if unable to stop safely (also flashing amber: caution)
    GREEN = "green"  # may enter (permissive or protected)
    UNKNOWN = "unknown"  # no information: the light is unavailable or dark; never a basis for speed advice


PHASE_CLASS: dict[MovementPhaseState, PhaseClass] = {
    MovementPhaseState.UNAVAILABLE: PhaseClass.UNKNOWN,  # 0
    MovementPhaseState.DARK: PhaseClass.UNKNOWN,  # 1: signal off
    MovementPhaseState.STOP_THEN_PROCEED: PhaseClass.RED,  # 2: flashing red, a stop sign
    MovementPhaseState.STOP_AND_REMAIN: PhaseClass.RED,  # 3
    MovementPhaseState.PRE_MOVEMENT: PhaseClass.RED,  # 4: red + amber before green (Europe); still no entry
    MovementPhaseState.PERMISSIVE_MOVEMENT_ALLOWED: PhaseClass.GREEN,  # 5
    MovementPhaseState.PROTECTED_MOVEMENT_ALLOWED: PhaseClass.GREEN,  # 6
    MovementPhaseState.PERMISSIVE_CLEARANCE: PhaseClass.AMBER,  # 7
    MovementPhaseState.PROTECTED_CLEARANCE: PhaseClass.AMBER,  # 8
    MovementPhaseState.CAUTION_CONFLICTING_TRAFFIC: PhaseClass.AMBER,  # 9: flashing amber
}
"""Every J2735 MovementPhaseState by its meaning (SAE J2735 DE_MovementPhaseState; docs/SPAT.md table)."""

J2735_STATE_NUMBERS: tuple[MovementPhaseState, ...] = tuple(MovementPhaseState)
"""The states in J2735's enumeration order: ``J2735_STATE_NUMBERS[3]`` is stop-And-Remain."""


def phase_class(state: MovementPhaseState) -> PhaseClass:
    """The meaning of a J2735 phase state for an approaching car.

    Examples
    --------
    >>> phase_class(MovementPhaseState.PERMISSIVE_MOVEMENT_ALLOWED).value, phase_class(J2735_STATE_NUMBERS[0]).value
    ('green', 'unknown')
    """
    return PHASE_CLASS[state]


def _states_of(cls: PhaseClass) -> frozenset[MovementPhaseState]:
    return frozenset(s for s, c in PHASE_CLASS.items() if c is cls)


RED = MovementPhaseState.STOP_AND_REMAIN
GREEN = MovementPhaseState.PROTECTED_MOVEMENT_ALLOWED
AMBER = MovementPhaseState.PROTECTED_CLEARANCE

GO_STATES = _states_of(PhaseClass.GREEN)
"""States in which a car may enter the intersection: the 'green' of :func:`seconds_to_next_green`."""

STOP_STATES = _states_of(PhaseClass.RED)
"""States in which a car must stop at the line: the 'red' of :func:`seconds_to_next_red`."""

UNKNOWN_STATES = _states_of(PhaseClass.UNKNOWN)
"""States that say nothing about the light: unavailable and dark."""


@dataclass(frozen=True, slots=True)
class FixedTimePlan:
    """A fixed-time light: red, then green, then amber, repeating every ``cycle_s``.

    ``offset_s`` is one instant at which a red begins (the paper's x or y when the axis is "seconds
    since entering the zone"); the plan repeats in both directions of time. Durations in [s].
    """

    red_s: float = 30.0
    green_s: float = 30.0
    amber_s: float = 0.0
    offset_s: float = 0.0

    def __post_init__(self) -> None:
        for name in ("red_s", "green_s", "amber_s", "offset_s"):
            object.__setattr__(self, name, float(getattr(self, name)))
        if not (self.red_s > 0 and self.green_s > 0 and self.amber_s >= 0):
            raise ValueError(f"need red_s > 0, green_s > 0, amber_s >= 0; got {self}")
        if not math.isfinite(self.offset_s):
            raise ValueError("offset_s must be finite")

    @property
    def cycle_s(self) -> float:
        """Cycle length, red + green + amber. [s]"""
        return self.red_s + self.green_s + self.amber_s

    def shifted(self, dt_s: float) -> FixedTimePlan:
        """The same plan on an axis whose origin is ``dt_s`` later (``offset_s - dt_s``)."""
        return FixedTimePlan(self.red_s, self.green_s, self.amber_s, self.offset_s - dt_s)


@dataclass(frozen=True, slots=True)
class ChangeWindow:
    """When one state ends and the next begins: J2735 TimeChangeDetails on the plan's axis.

    ``min_end_s <= likely_s <= max_end_s``; ``max_end_s`` may be ``math.inf`` (no upper bound known).
    ``confidence_frac`` is the probability that the change happens inside the window [-].
    """

    min_end_s: float
    likely_s: float
    max_end_s: float
    confidence_frac: float = 1.0

    def __post_init__(self) -> None:
        if not (math.isfinite(self.min_end_s) and math.isfinite(self.likely_s)):
            raise ValueError("min_end_s and likely_s must be finite")
        if not self.min_end_s <= self.likely_s <= self.max_end_s:
            raise ValueError(f"need min_end_s <= likely_s <= max_end_s, got {self}")
        if not 0.0 <= self.confidence_frac <= 1.0:
            raise ValueError(f"confidence_frac must be in [0, 1], got {self.confidence_frac}")

    @classmethod
    def exact(cls, t_s: float) -> ChangeWindow:
        """A change known to the instant (a fixed-time light)."""
        return cls(t_s, t_s, t_s, 1.0)


@dataclass(frozen=True, slots=True)
class UncertainPlan:
    """States ``states[0..n]`` separated by ``n`` change windows, in time order.

    ``states[i]`` ends, and ``states[i + 1]`` begins, somewhere in ``changes[i]``. Windows may touch
    but not overlap (``changes[i].max_end_s <= changes[i + 1].min_end_s``), so at any instant at most
    one change is in doubt. ``states[0]`` holds before the first window and ``states[-1]`` after the
    last one; use ``UNAVAILABLE`` as the last state when nothing is known beyond the horizon.
    """

    states: tuple[MovementPhaseState, ...]
    changes: tuple[ChangeWindow, ...]

    def __post_init__(self) -> None:
        if len(self.states) != len(self.changes) + 1:
            raise ValueError(f"need len(states) == len(changes) + 1, got {len(self.states)} and {len(self.changes)}")
        for a, b in zip(self.changes, self.changes[1:]):
            if a.max_end_s > b.min_end_s:
                raise ValueError(f"change windows overlap: {a} then {b}")

    # Sorted bounds for bisection; cheap to rebuild, plans are short.
    def _bounds(self, attr: str) -> list[float]:
        return [getattr(c, attr) for c in self.changes]


Plan = FixedTimePlan | UncertainPlan


class Change(NamedTuple):
    """One future change of state on the plan's axis: the state it leads to and its window. [s]"""

    state: MovementPhaseState
    min_s: float
    likely_s: float
    max_s: float
    confidence_frac: float


class TimeToChange(NamedTuple):
    """Seconds from now until a state begins: earliest, likely and latest (``math.inf``: unbounded). [s]

    All three are 0 when the state certainly holds now; ``min_s`` is 0 when it possibly holds now.
    ``confidence_frac`` is the confidence of the window that ``likely_s`` comes from (1 for fixed plans).
    """

    min_s: float
    likely_s: float
    max_s: float
    confidence_frac: float


# --------------------------------------------------------------------------------------------------
# Fixed-time plans


def fixed_phase_s(plan: FixedTimePlan, t_s: float) -> float:
    """Seconds since the last red began, in ``[0, cycle_s)``. [s]

    Examples
    --------
    >>> fixed_phase_s(FixedTimePlan(30, 30, offset_s=-15), 0.0)
    15.0
    """
    return float(math.fmod(t_s - plan.offset_s, plan.cycle_s)) % plan.cycle_s


def _fixed_sequence(plan: FixedTimePlan) -> list[tuple[MovementPhaseState, float]]:
    """(state, duration) of one cycle, starting with red; amber left out when zero."""
    seq = [(RED, plan.red_s), (GREEN, plan.green_s)]
    if plan.amber_s > 0:
        seq.append((AMBER, plan.amber_s))
    return seq


def _fixed_changes(plan: FixedTimePlan, t_s: float) -> Iterable[tuple[float, MovementPhaseState]]:
    """Endless (instant, new state) pairs, from the red that begins the cycle before the one containing ``t_s``.

    Instants are ``offset_s + (k cycle_s + within_s)``, one rounding each, so they do not drift; every
    fixed-plan answer is read off these instants, so the answers agree with each other to the bit.
    """
    k = math.floor((t_s - plan.offset_s) / plan.cycle_s) - 1
    seq = _fixed_sequence(plan)
    while True:
        within_s = 0.0
        for state, dur_s in seq:
            yield plan.offset_s + (k * plan.cycle_s + within_s), state
            within_s += dur_s
        k += 1


def _fixed_current(plan: FixedTimePlan, t_s: float) -> tuple[float, MovementPhaseState]:
    """(instant it began, state) of the change in force at ``t_s``."""
    current = None
    for when_s, state in _fixed_changes(plan, t_s):
        if when_s > t_s:
            return current
        current = (when_s, state)
    raise AssertionError("unreachable")  # pragma: no cover


# --------------------------------------------------------------------------------------------------
# Uncertain plans


def _uncertain_indices(plan: UncertainPlan, t_s: float) -> tuple[int, int, int]:
    """(lo, likely, hi): lowest possible, likely and highest possible state index at ``t_s``."""
    lo = bisect.bisect_right(plan._bounds("max_end_s"), t_s)
    likely = bisect.bisect_right(plan._bounds("likely_s"), t_s)
    hi = bisect.bisect_right(plan._bounds("min_end_s"), t_s)
    return lo, likely, hi


def uncertain_from_fixed(
    plan: FixedTimePlan,
    t0_s: float,
    t1_s: float,
    *,
    early_s: float = 0.0,
    late_s: float = 0.0,
    confidence_frac: float = 1.0,
) -> UncertainPlan:
    """An actuated-looking plan around a fixed one: every change in ``(t0_s, t1_s]`` becomes a window.

    The window of a change at ``t`` is ``[t - early_s, t + late_s]`` with ``likely_s = t``; windows
    are cut where they would overlap a neighbour. Before the first and after the last change the
    states are those of the fixed plan; after ``t1_s`` the plan says ``UNAVAILABLE``.

    Examples
    --------
    >>> p = uncertain_from_fixed(FixedTimePlan(30, 30), 0.0, 60.0, early_s=2, late_s=5)
    >>> [s.value for s in p.states], [(c.min_end_s, c.max_end_s) for c in p.changes]
    (['stop-And-Remain', 'protected-Movement-Allowed', 'stop-And-Remain', 'unavailable'], [(28.0, 35.0), (58.0, 60.0), (60.0, 60.0)])
    """
    if early_s < 0 or late_s < 0 or t1_s <= t0_s:
        raise ValueError("need early_s >= 0, late_s >= 0 and t1_s > t0_s")
    states = [state_at(plan, t0_s)]
    instants = []
    for when_s, new_state in _fixed_changes(plan, t0_s):
        if when_s <= t0_s:
            continue
        if when_s > t1_s:
            break
        states.append(new_state)
        instants.append(when_s)
    states.append(MovementPhaseState.UNAVAILABLE)
    instants.append(t1_s)
    changes = []
    for i, when_s in enumerate(instants):
        last = i == len(instants) - 1
        lo_s = when_s if last else max(when_s - early_s, changes[-1].max_end_s if changes else -math.inf)
        hi_s = when_s if last else min(when_s + late_s, instants[i + 1])
        lo_s = min(lo_s, when_s)
        conf = 1.0 if last or (early_s == 0 and late_s == 0) else confidence_frac
        changes.append(ChangeWindow(lo_s, when_s, hi_s, conf))
    return UncertainPlan(tuple(states), tuple(changes))


def published_state(plan: UncertainPlan, t_s: float) -> MovementPhaseState:
    """The state the plan says holds unless a change has surely come (the lowest possible index at ``t_s``).
    A phase past its ``minEndTime`` is still this state: it may end any moment, it is not unknown."""
    return plan.states[published_index(plan, t_s)]


def published_index(plan: UncertainPlan, t_s: float) -> int:
    """The lowest index the plan's state can have at ``t_s``: changes that have surely come."""
    return sum(1 for c in plan.changes if c.max_end_s <= t_s)


def published_window(plan: UncertainPlan, t_s: float) -> tuple[float, float] | None:
    """The ``(minEndTime, maxEndTime)`` of the published phase (:func:`published_state`; ``inf`` for an unknown
    ``maxEndTime``), None when it has none."""
    i = published_index(plan, t_s)
    return (plan.changes[i].min_end_s, plan.changes[i].max_end_s) if i < len(plan.changes) else None


# --------------------------------------------------------------------------------------------------
# Questions every plan answers


def state_at(plan: Plan, t_s: float) -> MovementPhaseState:
    """The state at ``t_s``; for an uncertain plan, the likely one (changes at their ``likely_s``).

    Examples
    --------
    >>> state_at(FixedTimePlan(30, 30, offset_s=15), 0.0).value   # the paper's light with x = 15 s
    'protected-Movement-Allowed'
    """
    if isinstance(plan, FixedTimePlan):
        return _fixed_current(plan, t_s)[1]
    return plan.states[_uncertain_indices(plan, t_s)[1]]


def possible_states_at(plan: Plan, t_s: float) -> frozenset[MovementPhaseState]:
    """Every state the light may be in at ``t_s``: one for a fixed plan, two inside a change window."""
    if isinstance(plan, FixedTimePlan):
        return frozenset({state_at(plan, t_s)})
    lo, _, hi = _uncertain_indices(plan, t_s)
    return frozenset(plan.states[lo : hi + 1])


def state_start_s(plan: Plan, t_s: float) -> float:
    """When the (likely) state at ``t_s`` began; ``-math.inf`` if before an uncertain plan's first change. [s]"""
    if isinstance(plan, FixedTimePlan):
        return _fixed_current(plan, t_s)[0]
    idx = _uncertain_indices(plan, t_s)[1]
    return plan.changes[idx - 1].likely_s if idx > 0 else -math.inf


def next_changes(plan: Plan, t_s: float, k: int) -> list[Change]:
    """The next ``k`` changes after ``t_s`` (fewer if an uncertain plan runs out), in time order.

    For an uncertain plan a change still counts while ``t_s`` is inside its window and it is likely
    still to come (``likely_s > t_s``). The window is reported as given; callers that publish it clip
    ``min_s`` to now.

    Examples
    --------
    >>> [(c.state.value, c.likely_s) for c in next_changes(FixedTimePlan(30, 30, 5, offset_s=0), 10.0, 3)]
    [('protected-Movement-Allowed', 30.0), ('protected-clearance', 60.0), ('stop-And-Remain', 65.0)]
    """
    if k <= 0:
        return []
    out: list[Change] = []
    if isinstance(plan, FixedTimePlan):
        for when_s, new_state in _fixed_changes(plan, t_s):
            if when_s > t_s:
                out.append(Change(new_state, when_s, when_s, when_s, 1.0))
                if len(out) == k:
                    return out
    idx = _uncertain_indices(plan, t_s)[1]
    for i in range(idx, min(idx + k, len(plan.changes))):
        c = plan.changes[i]
        out.append(Change(plan.states[i + 1], c.min_end_s, c.likely_s, c.max_end_s, c.confidence_frac))
    return out


def _uncertain_time_to(plan: UncertainPlan, t_s: float, wanted: frozenset) -> TimeToChange | None:
    lo, likely, hi = _uncertain_indices(plan, t_s)
    states, changes = plan.states, plan.changes

    def first_after(i: int) -> int | None:
        return next((j for j in range(i + 1, len(states)) if states[j] in wanted), None)

    if any(s in wanted for s in states[lo : hi + 1]):
        min_s = 0.0
    else:
        j = first_after(hi)
        if j is None:
            return None
        min_s = changes[j - 1].min_end_s - t_s
    if states[likely] in wanted:
        likely_s, conf = 0.0, 1.0
    else:
        j = first_after(likely)
        if j is None:
            return None
        likely_s, conf = changes[j - 1].likely_s - t_s, changes[j - 1].confidence_frac
    if lo == hi and states[lo] in wanted:
        max_s = 0.0
    else:
        j = first_after(lo)
        max_s = math.inf if j is None else changes[j - 1].max_end_s - t_s
    return TimeToChange(max(min_s, 0.0), max(likely_s, 0.0), max(max_s, 0.0), conf)


def _time_to(plan: Plan, t_s: float, wanted: frozenset) -> TimeToChange | None:
    if isinstance(plan, UncertainPlan):
        return _uncertain_time_to(plan, t_s, wanted)
    if state_at(plan, t_s) in wanted:
        return TimeToChange(0.0, 0.0, 0.0, 1.0)
    for when_s, new_state in _fixed_changes(plan, t_s):
        if when_s > t_s and new_state in wanted:
            return TimeToChange(when_s - t_s, when_s - t_s, when_s - t_s, 1.0)
    raise AssertionError("unreachable: a fixed plan always turns green and red")  # pragma: no cover


def seconds_to_next_green(plan: Plan, t_s: float) -> TimeToChange | None:
    r"""Seconds from ``t_s`` until the light shows green (a state in ``GO_STATES``); 0 if green now.

    Parameters
    ----------
    plan : FixedTimePlan or UncertainPlan
        The light's plan, on the same time axis as ``t_s``.
    t_s : float
        The instant asked about. [s]

    Returns
    -------
    TimeToChange or None
        ``(min_s, likely_s, max_s, confidence_frac)`` [s, s, s, -]; equal for a fixed plan. ``None``
        when an uncertain plan shows no green before its horizon.

    Notes
    -----
    For an uncertain plan with possible state indices ``lo..hi`` and likely index ``m`` at ``t``:
    ``min`` is 0 if green is possible now, else the earliest onset of the first green after ``hi``;
    ``likely`` is 0 if state ``m`` is green, else the likely onset of the first green after ``m``;
    ``max`` is 0 only if green is certain now, else the latest onset of the first green after ``lo``.

    Examples
    --------
    >>> seconds_to_next_green(FixedTimePlan(30, 30, offset_s=0.0), 10.0)   # the paper's [0, y]
    TimeToChange(min_s=20.0, likely_s=20.0, max_s=20.0, confidence_frac=1.0)
    """
    return _time_to(plan, t_s, GO_STATES)


def seconds_to_next_red(plan: Plan, t_s: float) -> TimeToChange | None:
    """Seconds from ``t_s`` until the light shows red (a state in ``STOP_STATES``); 0 if red now.

    Same conventions as :func:`seconds_to_next_green`. With amber, the red comes after the amber.

    Examples
    --------
    >>> seconds_to_next_red(FixedTimePlan(30, 27, 3, offset_s=0.0), 40.0).likely_s
    20.0
    """
    return _time_to(plan, t_s, STOP_STATES)


def to_fixed_time_signal(plan: FixedTimePlan, position_m: float, t0_s: float = 0.0) -> FixedTimeSignal:
    """The advisor's :class:`advisory.signals.FixedTimeSignal` for this plan, on an axis starting at ``t0_s``.

    ``t0_s`` is the instant (on the plan's axis) the car entered the zone, so the returned light's
    ``red_start_s`` is the paper's x or y. Amber counts as green: the paper's model has no amber and a
    car may legally enter on amber.

    Examples
    --------
    >>> to_fixed_time_signal(FixedTimePlan(30, 30, offset_s=1_000_015.0), 100.0, t0_s=1_000_000.0)
    FixedTimeSignal(position_m=100.0, red_start_s=15.0, red_s=30.0, green_s=30.0)
    """
    shifted = plan.shifted(t0_s)
    # Keep red_start_s near 0 (the paper's x, y lie in [-30, 30]), to keep float error small.
    red_start_s = shifted.offset_s - round(shifted.offset_s / plan.cycle_s) * plan.cycle_s
    return FixedTimeSignal(float(position_m), float(red_start_s), float(plan.red_s), float(plan.green_s + plan.amber_s))
