"""From a matched GPS fix and SPaT plans to the advisor's :class:`~advisory.advice.views.Observation`.

Pure: the bridge between ``spat_feed`` (plans on the Unix time axis) and ``advisory`` (lights ahead, times
relative to the fix). No clock, no I/O.

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
  group has been seen to do (:class:`PhaseHistory`, passed as ``PlanReading.cycle``) bounds the phases that
  follow, so a red is no longer endless. Each change is a triple (earliest, likely, late): the current phase ends
  no earlier than ``minEndTime`` (hard), likely at the median of the forecast of
  :mod:`spat_feed.prediction.predictor` (a linked change of another group, a held ``minEndTime`` running again, the
  controller's cycle or the durations seen, whichever applies) but no later than the published ``maxEndTime``,
  late at its :data:`LATE_QUANTILE` (soft; it replaces ``maxEndTime``, which on the Antwerp controller was now
  9 s early, now 2 minutes late; without a history ``maxEndTime`` is the late bound); the next phases end at the
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

import bisect
import math
from collections import deque
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from functools import lru_cache

import numpy as np
from numba import njit

from advisory.advice.views import AdvisorParams, LightView, Observation, Timings
from spat_feed.prediction.predictor import (
    EXACT_S,
    ChangeForecast,
    SCORE_AHEAD_S,
    current_end,
    cycle_period_s,
    durations_given_stage,
    durations_given_state,
    ends_given_window,
    next_end,
    period_fit_s,
    sample_quantile,
    scored_errors_s,
)
from spat_feed.road.corridors import Corridor, IntersectionSpec
from spat_feed.timing.plans import (
    STOP_STATES,
    UNKNOWN_STATES,
    FixedTimePlan,
    MovementPhaseState,
    PhaseClass,
    Plan,
    UncertainPlan,
    phase_class,
    uncertain_from_fixed,
)

HORIZON_S = 150.0
"""Red windows are reported this far ahead of the fix. [s]"""

BLOCKING_STATES = STOP_STATES | UNKNOWN_STATES
"""States a car must not plan to cross in: red, and anything the plan does not know."""


LATE_QUANTILE = 0.9
"""A phase counts as "late" past this quantile of the durations seen: the soft end of a window, like maxEndTime
(which real phases outlast 6-12 % of the time). [-]"""

MIN_PHASES_SEEN = 3
"""Durations of a phase class needed before they bound anything. [-]"""

HOLD_STEP_S = 0.5
"""A published ``minEndTime`` that moves later by at least this between two readings of one phase is held (the
controller extends the phase); one that then stays put again has resumed. [s]"""

MIN_RESUMED_SEEN = 20
"""Readings of resumed phases (with how long after their ``minEndTime`` they ended) needed before they say when
one ends. [-]"""

RESUMED_KEEP = 300
"""The readings of resumed phases kept per class (and the exact ends, :meth:`PhaseHistory.exact_lags_s`). [-]"""

EXACT_NEAREST = 20
"""Past exact ends, the nearest in how far ahead they were first published, whose lags to the change a new one
reads (:meth:`PhaseHistory.exact_lags_s`). [-]"""
EXACT_NEAR_S = 1.0
"""... and only those first published no more than this nearer or farther ahead: a feed's period. [s]"""

BLOCKING_CLASSES = frozenset({PhaseClass.RED, PhaseClass.UNKNOWN})


@dataclass(frozen=True, slots=True)
class CycleStats:
    """What one signal group has been seen to do: a snapshot of a :class:`PhaseHistory`. Durations [s], sorted."""

    durations_s: Mapping[PhaseClass, tuple[float, ...]] = field(default_factory=dict)
    following: Mapping[PhaseClass, PhaseClass] = field(default_factory=dict)  # the class seen after each class
    current: PhaseClass | None = None
    since_unix_s: float | None = None  # the latest instant the current phase can have begun (first seen)
    resumed: bool = False  # the current phase's minEndTime was held and runs again (:class:`PhaseHistory`)
    resumed_excess_s: Mapping[PhaseClass, tuple[float, ...]] = field(default_factory=dict)  # end - minEnd, resumed phases
    linked_end_unix_s: tuple[float, float] | None = None  # the current phase's (likely, late) end from another group's change (:class:`ChangeLinks`)
    linked_ends_unix_s: tuple[float, ...] = ()  # the current phase's end from another group's change, one per lag seen (:class:`ChangeLinks`)
    # per class, the readings of its phases seen whole that carried a finite window (:meth:`PhaseHistory.window_law`;
    # arrays, left out of ==: they follow from the same readings as the durations)
    window_law_s: Mapping[PhaseClass, tuple] = field(default_factory=dict, compare=False)
    state_id: int = -1  # the intersection's state now (:class:`IntersectionHistory`; -1: not known)
    window_weight: Mapping[PhaseClass, float] = field(default_factory=dict)  # the window law's share in the pool, per class (:meth:`PhaseHistory.window_weight`)
    ends_unix_s: Mapping[PhaseClass, tuple[float, ...]] = field(default_factory=dict)  # when phases of each class ended
    cycle_classes: frozenset = frozenset()  # classes told better by the point of the cycle they end at than by their durations
    period_s: float | None = None  # the controller's fixed cycle, if its changes keep to one (:func:`~spat_feed.prediction.predictor.cycle_period_s`)
    period_error_s: float = 0.0  # ... and its standard error (:func:`~spat_feed.prediction.predictor.period_fit_s`)
    # (durations, from, to): past phases of the current class while the intersection was in its state now (:meth:`PhaseHistory.spans_in`)
    state_spans_s: tuple | None = None
    state_entered_s: float | None = None  # how long after the current phase began the intersection entered its state now
    stage_weight: Mapping[PhaseClass, float] = field(default_factory=dict)  # the stage's law's share in ``state``, per class (:meth:`PhaseHistory.stage_weight`)
    # the current phase's exact published end (minEndTime = maxEndTime) and how long after such ends its class changed
    # in the past, for ends first published as far ahead (:meth:`PhaseHistory.exact_lags_s`); () until enough are seen
    exact_end_unix_s: float | None = None
    exact_lags_s: tuple[float, ...] = ()
    # the forecast chained after the phase in progress, as views of this snapshot made it (:func:`_chain`); not an init
    # field: each snapshot has its own (``replace`` makes a new one), and it goes with the snapshot
    chains: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    def ends(self, cls: PhaseClass) -> tuple[float, ...]:
        """The instants phases of ``cls`` ended at, if enough are seen, else ()."""
        e = self.ends_unix_s.get(cls, ())
        return e if len(e) >= MIN_PHASES_SEEN else ()

    def after_resumed(self, cls: PhaseClass) -> tuple[float, ...]:
        """How long after their ``minEndTime`` resumed phases of ``cls`` ended (sorted), if enough are seen, else ()."""
        d = self.resumed_excess_s.get(cls, ())
        return d if len(d) >= MIN_RESUMED_SEEN else ()

    def durations(self, cls: PhaseClass) -> tuple[float, ...]:
        """The durations seen of ``cls`` if there are enough to go by, else ()."""
        d = self.durations_s.get(cls, ())
        return d if len(d) >= MIN_PHASES_SEEN else ()

    @property
    def cycle_s(self) -> float | None:
        """Median cycle: the sum of the median durations around the cycle of classes seen (None if not closed)."""
        cls, total, seen = self.current, 0.0, set()
        while cls is not None and cls not in seen and (d := self.durations(cls)):
            seen.add(cls)
            total += _quantile(d, 0.5)
            cls = self.following.get(cls)
        return total if cls is not None and cls == self.current and seen else None


def _quantile(sorted_s: Sequence[float], q: float) -> float:
    """The ``q`` quantile of sorted samples (nearest rank, up: conservative for a late end)."""
    return sorted_s[min(len(sorted_s) - 1, max(0, math.ceil(q * len(sorted_s)) - 1))]


def _scored(score: list[float], errors) -> None:
    """Add one phase's errors of two laws to ``score`` = [n, first's mean squared error, second's]: a running mean
    over about :data:`METHOD_MEMORY` phases. [s²]"""
    score[0] += 1
    w = max(1.0 / score[0], 1.0 / METHOD_MEMORY)
    score[1] += w * (errors[0] ** 2 - score[1])
    score[2] += w * (errors[1] ** 2 - score[2])


def _share(score) -> float:
    """The first law's share in a pool of two scored by :func:`_scored`: in inverse proportion to the mean squared
    errors (Bates and Granger, :meth:`PhaseHistory.window_weight`); half each until :data:`MIN_PHASES_SEEN` phases
    are scored. [-]"""
    n, first, second = score
    return 0.5 if n < MIN_PHASES_SEEN or first + second <= 0.0 else second / (first + second)


class PhaseHistory:
    """Learns one (intersection, signal group) from successive readings: the durations of its phases, by class.

    Feed it every accepted reading of the group (``update``); it keeps the last ``keep`` completed phases of
    each class and the class that followed each. A change is dated at the first reading that shows it (the
    feed's period is the error); across a gap longer than ``max_gap_s`` the phase in progress is not timed, unless
    it went on (the same class on both sides, and it cannot have ended yet or cannot have ended and come back).

    Given plans, it also follows the published ``minEndTime`` of the phase in progress: an actuated controller
    counts it down, *holds* it while it extends the phase (it moves later with the clock), and once it runs again
    (*resumed*) the phase ends at or soon after it (2019-05-01: reds within 1.5 s of it 97 % of the time, against
    36 % before any hold). For each class it keeps how long after the ``minEndTime`` of a resumed phase the phase
    ended, reading by reading; and, for every phase seen whole, each reading that carried a finite window: how long
    the phase had run, how far ahead its ``minEndTime`` and ``maxEndTime`` were, the intersection's state, and how long
    after ``max(reading, minEndTime)`` the phase ended (:meth:`window_law`, what
    :func:`~spat_feed.prediction.predictor.ends_given_window` reads).
    Pure: no clock, the caller passes the reading's instant (Unix seconds, the plan's axis).
    """

    __slots__ = ("keep", "max_gap_s", "_durations", "_following", "_current", "_since", "_exact", "_last_t", "_min_end", "_held", "_resumed",
                 "_resumed_min_ends", "_excess", "_sorted", "_ends", "ended", "_path", "_paths", "_window", "_windowed", "_laws", "_window_score", "_stage_score",
                 "_exact_first", "_after_exact")  # fmt: skip

    def __init__(self, keep: int = 40, max_gap_s: float = 5.0) -> None:
        self.keep, self.max_gap_s = keep, max_gap_s
        self._durations: dict[PhaseClass, deque[float]] = {}
        self._following: dict[PhaseClass, PhaseClass] = {}
        self._current: PhaseClass | None = None
        self._since: float | None = None  # the latest instant the current phase can have begun
        self._exact = False  # whether that is when it began (its change seen, with no gap before)
        self._last_t: float | None = None
        self._min_end: float | None = None  # the phase in progress: its minEndTime at the last reading
        self._held = self._resumed = False  # ... held since it began; running again since
        self._resumed_min_ends: list[float] = []  # ... its minEndTime at each reading since it resumed
        self._excess: dict[PhaseClass, deque[float]] = {}
        self._sorted: tuple | None = None  # the two above, sorted (until a phase ends)
        self._ends: dict[PhaseClass, deque[float]] = {}  # when phases of each class were seen to end
        self.ended: tuple | None = None  # the phase seen whole that the last reading ended: (class, start, end, durations and ends before it)
        self._path: list[tuple[float, int]] = []  # the phase in progress: (time since it began, the intersection's state) at each change of state
        self._paths: dict[PhaseClass, deque[tuple[float, tuple]]] = {}  # phases seen whole: (duration, their path)
        self._window: list[tuple[float, float, float]] = []  # the phase in progress: (t, minEndTime, maxEndTime) of each reading with a finite window
        self._windowed: dict[PhaseClass, deque[int]] = {}  # phases seen whole: how many readings with a finite window each gave its law
        self._laws: dict[PhaseClass, tuple] = {}  # ... and those readings (:meth:`window_law`)
        self._window_score: dict[PhaseClass, list[float]] = {}  # class -> [n, window law's mean squared error, durations'] (:meth:`_score_window`)
        self._stage_score: dict[PhaseClass, list[float]] = {}  # class -> [n, the stage's law's mean squared error, by the phase's start] (:meth:`_given_before`)
        self._exact_first: list[list[float]] = []  # the phase in progress: [exact end, first reading that published it], in order
        self._after_exact: dict[PhaseClass, deque[tuple[float, float]]] = {}  # class -> (how far ahead an exact end was first published, change - it)

    def update(self, t_unix_s: float, plan: Plan | MovementPhaseState | None) -> CycleStats:
        """Take one reading at ``t_unix_s`` (:meth:`record`) and return the :meth:`stats` after it."""
        self.record(t_unix_s, plan)
        return self.stats()

    def record(self, t_unix_s: float, plan: Plan | MovementPhaseState | None) -> bool:
        """Take one reading at ``t_unix_s``: the published plan (its state then) or the state itself. Returns
        whether the history changed (a new phase seen: the :meth:`stats` of before are out of date)."""
        if plan is None or isinstance(plan, FixedTimePlan):
            return False
        if self._last_t is not None and t_unix_s <= self._last_t:
            return False  # a repeat or an older reading
        state = plan if isinstance(plan, MovementPhaseState) else published_state(plan, t_unix_s)
        window = None if isinstance(plan, MovementPhaseState) else _published_window(plan, t_unix_s)
        min_end = None if window is None else window[0]
        cls = phase_class(state)
        gap = self._last_t is not None and t_unix_s - self._last_t > self.max_gap_s
        changed = cls != self._current
        if gap and not changed and self._went_on(t_unix_s):
            gap = False
        was_resumed = self._resumed
        if changed or gap:
            self.ended = None
            if changed and not gap and self._current is not None:
                if self._exact:
                    before = self.stats()
                    self.ended = (self._current, self._since, t_unix_s, before.durations(self._current), before.ends(self._current),
                                  self._given_before(t_unix_s))  # fmt: skip
                    self._durations.setdefault(self._current, deque(maxlen=self.keep)).append(t_unix_s - self._since)
                    self._paths.setdefault(self._current, deque(maxlen=self.keep)).append((t_unix_s - self._since, tuple(self._path)))
                    if self._window:
                        self._score_window(t_unix_s, before, self.ended[5])
                        self._add_to_law(self._current, self._window_readings(t_unix_s))
                self._following[self._current] = cls
                self._ends.setdefault(self._current, deque(maxlen=self.keep)).append(t_unix_s)
                excess = self._excess.setdefault(self._current, deque(maxlen=RESUMED_KEEP))
                excess.extend(t_unix_s - m for m in self._resumed_min_ends)
                # the change came after the last reading that did not show it: no earlier than that after each exact end
                lags = self._after_exact.setdefault(self._current, deque(maxlen=RESUMED_KEEP))
                lags.extend((end - first, max(0.0, self._last_t - end)) for end, first in self._exact_first)
                self._sorted = None
            # first seen now: it began now or before (a start dated late makes its end late: the safe side for a red)
            self._since, self._exact = t_unix_s, changed and not gap and self._current is not None
            self._current = cls
            self._path, self._window, self._exact_first = [], [], []
            self._held = self._resumed = False
            self._resumed_min_ends = []
        elif min_end is not None and self._min_end is not None:
            if min_end - self._min_end >= HOLD_STEP_S:  # moved later: held
                self._held, self._resumed = True, False
            elif self._held and abs(min_end - self._min_end) < HOLD_STEP_S:  # put again after a hold: resumed
                self._resumed = True
            if self._resumed and min_end >= t_unix_s:
                self._resumed_min_ends.append(min_end)
        self._min_end = min_end
        self._last_t = t_unix_s
        new_exact = False  # a new exact end published (the stats' ``exact_end_unix_s``, ``exact_lags_s`` change)
        if window is not None and math.isfinite(window[1]):
            self._window.append((t_unix_s, *window))
            seen = self._exact_first and abs(self._exact_first[-1][0] - window[1]) < EXACT_S
            if window[1] - window[0] < EXACT_S and window[1] >= t_unix_s and not seen:
                self._exact_first.append([window[1], t_unix_s])
                new_exact = True
        return changed or gap or self._resumed != was_resumed or new_exact

    def _went_on(self, t_unix_s: float) -> bool:
        """Across a gap in the readings, with the same class on both sides: the phase in progress went on if it
        cannot have ended yet (seen from its start, it has run less than the shortest phase of its class), or cannot
        have ended and come back (the gap is shorter than the shortest phase of the class that follows it)."""
        own = self._durations.get(self._current, ())
        after = self._durations.get(self._following.get(self._current), ())
        if self._exact and len(own) >= MIN_PHASES_SEEN and t_unix_s - self._since < min(own):
            return True
        return len(after) >= MIN_PHASES_SEEN and t_unix_s - self._last_t < min(after)

    def stats(self) -> CycleStats:
        """A frozen snapshot to pass along with a reading (``PlanReading.cycle``)."""
        if self._sorted is None:
            self._sorted = tuple({c: tuple(sorted(d)) for c, d in dd.items()} for dd in (self._durations, self._excess))
        durations, excess = self._sorted
        law = self.window_law()
        ends = {c: tuple(e) for c, e in self._ends.items()}
        return CycleStats(durations, dict(self._following), self._current, self._since, self._resumed, excess, ends_unix_s=ends, window_law_s=law,
                          window_weight={c: self.window_weight(c) for c in self._window_score},
                          stage_weight={c: _share(self._stage_score[c]) for c in self._stage_score},
                          exact_end_unix_s=self._exact_first[-1][0] if self._exact_first else None, exact_lags_s=self.exact_lags_s())  # fmt: skip

    def exact_lags_s(self) -> tuple[float, ...]:
        """How long after an exact published end (minEndTime = maxEndTime) the phase in progress changes class, by the
        phases of its class seen whole: the lags after the :data:`EXACT_NEAREST` ends first published about as far
        ahead as its latest exact end was (sorted); () without such an end or before :data:`MIN_PHASES_SEEN` are seen.

        Only ends first published within :data:`EXACT_NEAR_S` as far ahead count (none: the end is the change). A red's
        exact end is its change as published (the lags after them moved greens later: 2019-05-01 -0.04 points).
        J2735 gives a movement state's own end. A feed that publishes a go phase as one state ("unavailable") states
        the end of its green and then that of its amber (2019-05-17: the green's exact end about 7 s ahead, then the
        amber's 3 s), or only the amber's: the red begins when the amber ends, and an end first published more than an
        amber ahead is, in such a feed, its green's. Read as the change, it put the red an amber early (docs/ADVISOR.md,
        "the cycles still lost" (c)); a feed whose exact ends are its changes gives lags of 0, the end as before."""
        past = self._after_exact.get(self._current) if self._exact_first and self._current is not PhaseClass.RED else None
        if not past or len(past) < MIN_PHASES_SEEN:
            return ()
        end, first = self._exact_first[-1]
        pairs = np.asarray(past)
        off = np.abs(pairs[:, 0] - (end - first))
        nearest = np.argsort(off, kind="stable")[:EXACT_NEAREST]
        nearest = nearest[off[nearest] <= EXACT_NEAR_S]
        return tuple(np.sort(pairs[nearest, 1]).tolist())

    def _score_window(self, end_unix_s: float, before: CycleStats, given: np.ndarray | None) -> None:
        """Score the window law and the durations on the phase in progress, which ends at ``end_unix_s``: the likely
        end each said (on the history ``before`` it) at its last reading with a window :data:`SCORE_AHEAD_S` or more
        before the end; ``given``: the durations the intersection's state gave then (``state``), else those not yet
        outlasted. A running mean of each one's squared error over about :data:`METHOD_MEMORY` phases."""
        law = before.window_law_s.get(self._current)
        k = bisect.bisect_right([r[0] for r in self._window], max(self._since, end_unix_s - SCORE_AHEAD_S)) - 1
        if law is None or k < 0:
            return
        t, lo, hi = self._window[k]
        el, floor = t - self._since, max(t, lo)
        states = [s for a, s in self._path if a <= el]
        by_window = ends_given_window(law, self._since, t, lo, hi, states[-1] if states else -1)
        own = given if given is not None else [d for d in before.durations(self._current) if d > el]
        if by_window is None or not len(own):
            return
        errors = (sample_quantile(np.sort(by_window), 0.5) - end_unix_s, max(self._since + sample_quantile(np.sort(own), 0.5), floor) - end_unix_s)
        _scored(self._window_score.setdefault(self._current, [0, 0.0, 0.0]), errors)

    def window_weight(self, cls: PhaseClass) -> float:
        """The window law's share of the forecast of ``cls`` where it is pooled with the durations: the weights of the
        two in inverse proportion to their mean squared errors (:meth:`_score_window`), as in the combination of
        forecasts of Bates and Granger [1]; half each until :data:`MIN_PHASES_SEEN` phases are scored. [-]

        References
        ----------
        .. [1] J. M. Bates and C. W. J. Granger, "The combination of forecasts," Oper. Res. Q., vol. 20, pp. 451-468,
           1969, doi:10.2307/3008764.
        """
        return _share(self._window_score.get(cls, (0, 0.0, 0.0)))

    def _window_readings(self, end_unix_s: float) -> tuple[np.ndarray, ...]:
        """The readings with a finite window of the phase in progress, which ends at ``end_unix_s``, as arrays: how
        long it had run, how far ahead ``minEndTime`` (0 once past) and ``maxEndTime`` were, the intersection's state,
        how long after ``max(reading, minEndTime)`` it ended, and its duration. [s]"""
        t, lo, hi = np.array(self._window).T
        floor = np.maximum(t, lo)
        at, states = (np.array(x) for x in zip(*self._path)) if self._path else (np.empty(0), np.empty(0, dtype=np.int64))
        k = np.searchsorted(at, t - self._since, side="right")
        state = np.where(k > 0, np.r_[states, -1][k - 1], -1).astype(np.int64)
        return t - self._since, floor - t, hi - t, state, end_unix_s - floor, np.full(len(t), end_unix_s - self._since)

    def _add_to_law(self, cls: PhaseClass, readings: tuple[np.ndarray, ...]) -> None:
        """Append a phase's :meth:`_window_readings` to the class's law, dropping the oldest phase past ``keep``."""
        sizes = self._windowed.setdefault(cls, deque())
        old = self._laws.get(cls)
        drop = sizes.popleft() if len(sizes) >= self.keep else 0
        self._laws[cls] = readings if old is None else tuple(np.concatenate([o[drop:], r]) for o, r in zip(old, readings))
        sizes.append(len(readings[0]))

    def window_law(self) -> dict[PhaseClass, tuple[np.ndarray, ...]]:
        """Per class, the readings with a finite window of its last ``keep`` phases seen whole (:meth:`_window_readings`,
        each of the six arrays concatenated over the phases)."""
        return dict(self._laws)

    @property
    def current(self) -> PhaseClass | None:
        """The class of the phase in progress (None before the first reading)."""
        return self._current

    def _given_before(self, end_unix_s: float) -> np.ndarray | None:
        """The durations ``state`` gave :data:`SCORE_AHEAD_S` before the phase in progress ended at ``end_unix_s``
        (:func:`~spat_feed.prediction.predictor.durations_given_state`), what the cycle is scored against; and the
        score of its two laws then, by the phase's start and by the stage's (their likely ends' squared errors, a
        running mean over about :data:`METHOD_MEMORY` phases: :meth:`stage_weight`)."""
        el = max(0.0, end_unix_s - SCORE_AHEAD_S - self._since)
        then = [(at, s) for at, s in self._path if at <= el]
        if not then:
            return None
        entered, state = then[-1]
        spans = self.spans_in(self._current, state)
        by_phase = durations_given_state(spans, el)
        if by_phase is None:
            return None
        by_stage = durations_given_stage(spans, el, entered)
        if by_stage is not None:
            errors = [max(el, sample_quantile(np.sort(x), 0.5)) - (end_unix_s - self._since) for x in (by_stage, by_phase)]
            _scored(self._stage_score.setdefault(self._current, [0, 0.0, 0.0]), errors)
        return durations_given_state(spans, el, entered, self.stage_weight(self._current))

    def stage_weight(self, cls: PhaseClass) -> float:
        """The share of the stage's law in the ``state`` law of ``cls``
        (:func:`~spat_feed.prediction.predictor.durations_given_state`): in inverse proportion to its mean squared
        error against the law by the phase's start, as :meth:`window_weight`; half each until scored. [-]"""
        return _share(self._stage_score.get(cls, (0, 0.0, 0.0)))

    @property
    def entered_s(self) -> float | None:
        """How long after the phase in progress began the intersection entered its state now (None: not known). [s]"""
        return self._path[-1][0] if self._path else None

    def note_state(self, t_unix_s: float, state: int) -> None:
        """The intersection's state (an id of every group's class, :class:`IntersectionHistory`) from ``t_unix_s`` on."""
        if self._since is not None and (not self._path or self._path[-1][1] != state):
            self._path.append((t_unix_s - self._since, state))

    def spans_in(self, cls: PhaseClass | None, state: int) -> tuple[tuple[float, ...], tuple[float, ...], tuple[float, ...]] | None:
        """The phases of ``cls`` seen whole while the intersection was in ``state``: each one's duration and the span
        of its own time (from, to) it spent so, as three tuples; None when none was. [s]"""
        out = [(d, el, path[k + 1][0] if k + 1 < len(path) else d)
               for d, path in self._paths.get(cls, ()) for k, (el, s) in enumerate(path) if s == state]  # fmt: skip
        return None if not out else tuple(zip(*out))


LINK_TOLERANCE_S = 1.5
"""A link holds for a phase end that came within this of the link's median lag (the feed's period is 1 s). [s]"""

LINK_SHARE = 0.9
"""Share of the phase ends seen that a link must have held for, to say when the phase in progress ends. [-]"""

MIN_LINKS_SEEN = 10
"""Phase ends seen with a link before it says anything. [-]"""


class ChangeLinks:
    """Learns which change of *another* signal group of the intersection each group's phases end a steady time
    after: the controller's stage sequence, read from the stream (no signal plan needed).

    A controller runs its stages in order, and the intergreen between one stage's green and the next is fixed:
    on the Antwerp controller K648, group 1's green came 10.6 s after group 10's green ended (96 % within 1.5 s),
    groups 5, 7 and 8's 17.0 s after group 12's (95 %). Once such a change is seen, the phase it ends is known
    to about a second, 10-20 s ahead, where the group's own durations and ``minEndTime`` are seconds off (reds
    10-20 s ahead: mean error 1.3 -> 0.2 s on 2019-05-01, 4.8 -> 0.2 s on 2019-05-17).

    For each (group, class of its phase) and each *change* of another group (group, class before, class after),
    it keeps the lags from the change's last instant within a phase to that phase's end (last ``keep``). A link
    speaks once :data:`MIN_LINKS_SEEN` lags are seen and :data:`LINK_SHARE` of them lie within
    :data:`LINK_TOLERANCE_S` of their median: then, once its change comes during a phase of the group, the phase
    ends likely at the change plus the median lag, late at its :data:`LATE_QUANTILE` (the latest such change
    speaks). A gap over ``max_gap_s`` forgets the changes and phases in progress. Pure: the caller passes the
    reading's instant.
    """

    __slots__ = ("keep", "max_gap_s", "_current", "_last_change", "_lags", "_links", "_last_t")

    def __init__(self, keep: int = 40, max_gap_s: float = 5.0) -> None:
        self.keep, self.max_gap_s = keep, max_gap_s
        self._current: dict[int, tuple[PhaseClass, float, bool]] = {}  # group -> (class, since, since exact)
        self._last_change: dict[tuple[int, PhaseClass, PhaseClass], float] = {}  # (group, before, after) -> last instant
        self._lags: dict[tuple[int, PhaseClass, tuple], deque[float]] = {}
        self._links: dict[tuple[int, PhaseClass, tuple], tuple[float, float] | None] = {}  # (median, late) when it holds
        self._last_t: float | None = None

    def record(self, t_unix_s: float, classes: Mapping[int, PhaseClass | None]) -> bool:
        """Take one reading of the intersection: the published class of each group (at least of each whose class
        may have changed since the last reading); returns whether a class changed."""
        if self._last_t is not None and t_unix_s <= self._last_t:
            return False
        if self._last_t is not None and t_unix_s - self._last_t > self.max_gap_s:
            self._current, self._last_change = {}, {}
        self._last_t = t_unix_s
        changes = []
        for g, cls in classes.items():
            if cls is None:
                continue
            now = self._current.get(g)
            if now is not None and now[0] is cls:
                continue
            if now is not None:
                changes.append((g, now[0], cls))
                if now[2]:  # a phase seen whole: learn the lag of every other group's change within it
                    for key, at in self._last_change.items():
                        if key[0] != g and now[1] <= at < t_unix_s:
                            lags = self._lags.setdefault((g, now[0], key), deque(maxlen=self.keep))
                            lags.append(t_unix_s - at)
                            self._links.pop((g, now[0], key), None)
            self._current[g] = (cls, t_unix_s, now is not None)
        for key in changes:
            self._last_change[key] = t_unix_s
        return bool(changes)

    def _link(self, index: tuple[int, PhaseClass, tuple]) -> tuple[float, float, tuple[float, ...]] | None:
        """(median, late, every lag) of a link that holds, else None."""
        if index not in self._links:
            lags = sorted(self._lags.get(index, ()))
            link = None
            if len(lags) >= MIN_LINKS_SEEN:
                median = _quantile(lags, 0.5)
                if sum(abs(x - median) <= LINK_TOLERANCE_S for x in lags) >= LINK_SHARE * len(lags):
                    link = (median, _quantile(lags, LATE_QUANTILE), tuple(lags))
            self._links[index] = link
        return self._links[index]

    def end_of(self, group: int) -> tuple[float, float] | None:
        """(likely, late) end of ``group``'s phase in progress from the latest linked change seen in it, else None."""
        ends = self.ends_of(group)
        return None if not ends else (_quantile(ends, 0.5), _quantile(ends, LATE_QUANTILE))

    def ends_of(self, group: int) -> tuple[float, ...]:
        """The end of ``group``'s phase in progress after the latest linked change seen in it, one instant per lag
        seen (sorted), else ()."""
        now = self._current.get(group)
        if now is None:
            return ()
        best = None  # the latest change; of changes at one instant, the link whose lags spread least
        for key, at in self._last_change.items():
            if key[0] != group and at >= now[1] and (link := self._link((group, now[0], key))):
                rank = (at, link[0] - link[1], -link[0], key)  # (the key: one answer whatever order the groups came in)
                if best is None or rank > best[0]:
                    best = (rank, tuple(at + x for x in link[2]))
        return () if best is None else best[1]


METHOD_MEMORY = 10
"""Phases over which the running error of each method is kept (an exponential mean). [-]"""

PERIOD_EVERY = (20, 640)
"""Phase ends (of all groups) between two searches for the controller's cycle (~5-10 ms each): the first after 20,
each next one twice as far off, found or not (a period found is re-checked less and less often), at most 640 apart. [-]"""


class IntersectionHistory:
    """What the receiver learns of one intersection's signal groups: each group's :class:`PhaseHistory` and the
    :class:`ChangeLinks` between them. ``record`` each message's plans; ``stats(group)`` is the group's
    :class:`CycleStats` (cached until the group's history or a link changes)."""

    __slots__ = ("groups", "links", "_stats", "period_s", "_ends_since_period", "_period_every", "_errors", "_states", "_state", "period_error_s")

    def __init__(self) -> None:
        self.groups: dict[int, PhaseHistory] = {}
        self.links = ChangeLinks()
        self._stats: dict[int, CycleStats] = {}
        self.period_s: float | None = None  # the controller's cycle, if its changes keep to one (cycle_period_s)
        self.period_error_s = 0.0  # ... its standard error (period_fit_s)
        self._ends_since_period = 0
        self._period_every = PERIOD_EVERY[0]
        self._errors: dict[tuple[int, PhaseClass], list[float]] = {}  # (group, class) -> [n, cycle's mean error, durations']
        self._states: dict[tuple, int] = {}  # the intersection's states seen (every group's class) -> id
        self._state = -1  # the state now

    def record(self, t_unix_s: float, plans: Mapping[int, Plan | MovementPhaseState | None]) -> None:
        """Take one message: each signal group's plan (or state) at ``t_unix_s``."""
        changed = {}
        for g, plan in plans.items():
            history = self.groups.get(g)
            if history is None:
                history = self.groups[g] = PhaseHistory()
            if history.record(t_unix_s, plan):
                self._stats.pop(g, None)
                changed[g] = history.current
                if history.ended is not None:
                    self._score(g, history.ended)
        if changed:
            state = tuple((g, h.current) for g, h in self.groups.items())
            self._state = self._states.setdefault(state, len(self._states))
            for h in self.groups.values():
                h.note_state(t_unix_s, self._state)
        if self.links.record(t_unix_s, changed):
            self._stats.clear()  # a change may start a link for any group
            self._ends_since_period += len(changed)
            if self._ends_since_period >= self._period_every:
                self._ends_since_period = 0
                ends = [e for h in self.groups.values() for e in h.stats().ends_unix_s.values()]
                self.period_s, self.period_error_s = None, 0.0
                if (found := cycle_period_s(ends)) is not None:  # refined by least squares, with its standard error
                    self.period_s, self.period_error_s = period_fit_s(ends, found)
                self._period_every = min(2 * self._period_every, PERIOD_EVERY[1])

    def _score(self, group: int, ended: tuple) -> None:
        """Score the cycle and the durations on a phase seen whole (:func:`~spat_feed.prediction.predictor.scored_errors_s`):
        a running mean of each one's error over about the last :data:`METHOD_MEMORY` phases of the class."""
        cls, since, end, durations, ends, given = ended
        errors = scored_errors_s(since, end, durations, ends, self.period_s, given)
        if errors is None:
            return
        score = self._errors.setdefault((group, cls), [0, 0.0, 0.0])
        score[0] += 1
        w = max(1.0 / score[0], 1.0 / METHOD_MEMORY)
        score[1] += w * (errors[0] - score[1])
        score[2] += w * (errors[1] - score[2])

    def cycle_classes(self, group: int) -> frozenset:
        """The classes of ``group`` whose ends the cycle has told better than the durations (at least
        :data:`MIN_PHASES_SEEN` phases scored)."""
        return frozenset(c for (g, c), (n, by_cycle, by_duration) in self._errors.items() if g == group and n >= MIN_PHASES_SEEN and by_cycle < by_duration)

    def stats(self, group: int) -> CycleStats | None:
        """``group``'s snapshot (:meth:`PhaseHistory.stats` with the linked end of its phase in progress)."""
        cycle = self._stats.get(group)
        if cycle is None and (history := self.groups.get(group)) is not None:
            ends = self.links.ends_of(group)
            linked = (_quantile(ends, 0.5), _quantile(ends, LATE_QUANTILE)) if ends else None
            cycle = self._stats[group] = replace(history.stats(), linked_end_unix_s=linked, linked_ends_unix_s=ends, period_s=self.period_s, period_error_s=self.period_error_s,
                                                 cycle_classes=self.cycle_classes(group) if self.period_s is not None else frozenset(),
                                                 state_spans_s=history.spans_in(history.current, self._state), state_id=self._state,
                                                 state_entered_s=history.entered_s)  # fmt: skip
        return cycle


def _published_window(plan: UncertainPlan, t_unix_s: float) -> tuple[float, float] | None:
    """The ``(minEndTime, maxEndTime)`` of the published phase (:func:`published_state`; ``inf`` for an unknown
    ``maxEndTime``), None when it has none."""
    i = _published_index(plan, t_unix_s)
    return (plan.changes[i].min_end_s, plan.changes[i].max_end_s) if i < len(plan.changes) else None


@dataclass(frozen=True, slots=True)
class PlanReading:
    """One light's plan (Unix axis) as read from a SPaT source, with the reading's freshness. ``plan`` None: no data.

    ``cycle``: what the signal group has been seen to do (:meth:`PhaseHistory.stats`), to bound the phases after
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


def published_state(plan: UncertainPlan, t_unix_s: float) -> MovementPhaseState:
    """The state the plan says holds unless a change has surely come (the lowest possible index at ``t_unix_s``).
    A phase past its ``minEndTime`` is still this state: it may end any moment, it is not unknown."""
    return plan.states[_published_index(plan, t_unix_s)]


def _published_index(plan: UncertainPlan, t_unix_s: float) -> int:
    """The lowest index the plan's state can have at ``t_unix_s``: changes that have surely come."""
    return sum(1 for c in plan.changes if c.max_end_s <= t_unix_s)


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
    current = cycle.current is cls and len(out) - 2 <= _published_index(plan, t_unix_s)  # the phase in progress, not a later one
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
    while their shortest durations add up to less than the horizon: each one's class, shortest duration, the median
    and :data:`LATE_QUANTILE` of its end (:func:`~spat_feed.prediction.predictor.next_end`) and its :func:`_levels`.

    What :func:`_continued` chains after the phase in progress; kept in the snapshot (``CycleStats.chains``, by class,
    samples and horizon): between two changes of a group's history the end of its phase in progress is often the same
    set of samples from reading to reading (on the bench's observations the chain was kept in 1 of 4 views of 2019-05-17
    and 2 of 3 of US 1136), every car at the light reads the same, and the forecast after it depends on nothing else. [s]"""
    key = (cls, samples.tobytes(), horizon_s)
    kept = cycle.chains.get(key)
    if kept is not None:
        return kept
    out = []
    total_s = 0.0
    while total_s < horizon_s + CHAIN_MARGIN_S:
        nxt = cycle.following.get(cls)
        d = cycle.durations(nxt) if nxt is not None else ()
        if not d:
            break
        cls = nxt
        samples = next_end(cycle, cls, samples)
        levels = samples[_level_ranks(len(samples))]
        levels.setflags(write=False)  # (kept: shared by every view)
        out.append((cls, d[0], sample_quantile(samples, 0.5), sample_quantile(samples, LATE_QUANTILE), levels))
        total_s += d[0]
    if len(cycle.chains) >= CHAINS_KEPT:
        cycle.chains.clear()
    cycle.chains[key] = kept = tuple(out)
    return kept


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
    """True when the plan cannot say the state at ``t_unix_s``: the published state (:func:`published_state`) is
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
    i = _published_index(plan, t_reading_unix_s)
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
