"""What each signal group has been seen to do, learnt reading by reading from the SPaT stream: the receiver's memory.

:class:`PhaseHistory` learns one signal group (its phases' durations by class, the class after each, the published
``minEndTime`` held and resumed, the readings of published windows, the exact ends and how long after them the phase
changed), :class:`ChangeLinks` the steady lags from one group's change to another's phase end (the controller's stage
sequence), and :class:`IntersectionHistory` keeps both for one intersection, with its fixed cycle if it keeps one
and the score of each forecast method. A group's history is handed on as :class:`CycleStats`, a frozen snapshot that
goes with a reading (``PlanReading.cycle``) to :mod:`spat_feed.prediction.predictor`, which forecasts the phase ends
from it, and to :mod:`spat_feed.prediction.observe`, which turns them into the advisor's views.

Pure: no clock, no I/O; the caller passes each reading's instant (Unix seconds, the plan's axis).
"""

from __future__ import annotations

import bisect
import math
from collections import deque
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from spat_feed.prediction.predictor import (
    EXACT_S,
    SCORE_AHEAD_S,
    _mixed,
    cycle_period_s,
    durations_given_stage,
    durations_given_state,
    period_fit_s,
    sample_quantile,
    says_when,
    scored_errors_s,
    window_laws,
)
from spat_feed.timing.plans import (
    FixedTimePlan,
    MovementPhaseState,
    PhaseClass,
    Plan,
    phase_class,
    published_index,
    published_state,
    published_window,
)


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

RECENT_PHASES = 20
"""The latest phases of a class whose ``state`` law is pooled with that of every phase kept (``keep``, 40), by
their scored errors (:meth:`PhaseHistory.recent_weight`): an actuated controller's cycle drifts with the traffic
(Antwerp 2019-05-01: its median 89 s at 16:00, 70 s at 19:00), and 40 phases are an hour of it. [-]"""

POOL_SCORE_AHEAD_S = (10.0, SCORE_AHEAD_S, 40.0)
"""How long before each phase end the two laws of each pool (the stage's and the phase's, the latest phases' and
every phase's, the window law and the durations) are scored (:meth:`PhaseHistory._given_before`,
:meth:`PhaseHistory._score_window`): across the horizons advice reads a forecast at (an approach takes up to a minute),
their squared errors averaged per phase. At :data:`SCORE_AHEAD_S` alone a share followed one instant of each of the
last ~10 phases. [s]"""

EXACT_NEAREST = 20
"""Past exact ends, the nearest in how far ahead they were first published, whose lags to the change a new one
reads (:meth:`PhaseHistory.exact_lags_s`). [-]"""
EXACT_NEAR_S = 1.0
"""... and only those first published no more than this nearer or farther ahead: a feed's period. [s]"""


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
    # per class, the readings of its phases seen whole whose window said when (:func:`says_when`, :meth:`PhaseHistory.window_law`;
    # arrays, left out of ==: they follow from the same readings as the durations)
    window_law_s: Mapping[PhaseClass, tuple] = field(default_factory=dict, compare=False)
    state_id: int = -1  # the intersection's state now (:class:`IntersectionHistory`; -1: not known)
    window_weight: Mapping[PhaseClass, float] = field(default_factory=dict)  # the window law's share in the pool, per class (:meth:`PhaseHistory.window_weight`)
    ends_unix_s: Mapping[PhaseClass, tuple[float, ...]] = field(default_factory=dict)  # when phases of each class ended
    cycle_classes: frozenset = frozenset()  # classes told better by the point of the cycle they end at than by their durations
    period_s: float | None = None  # the controller's fixed cycle, if its changes keep to one (:func:`~spat_feed.prediction.predictor.cycle_period_s`)
    period_error_s: float = 0.0  # ... and its standard error (:func:`~spat_feed.prediction.predictor.period_fit_s`)
    # (durations, from, to, visit): past phases of the current class while the intersection was in its state now (:meth:`PhaseHistory.spans_in`)
    state_spans_s: tuple | None = None
    state_entered_s: float | None = None  # how long after the current phase began the intersection entered its state now
    state_visit: int = 0  # ... for the how-many-th time since the phase began (0: the first)
    stage_weight: Mapping[PhaseClass, float] = field(default_factory=dict)  # the stage's law's share in ``state``, per class (:meth:`PhaseHistory.stage_weight`)
    recent_spans_s: tuple | None = None  # ``state_spans_s`` of the latest :data:`RECENT_PHASES` phases of the class only
    recent_weight: Mapping[PhaseClass, float] = field(default_factory=dict)  # their law's share in ``state``, per class (:meth:`PhaseHistory.recent_weight`)
    recent_window_n: Mapping[PhaseClass, int] = field(default_factory=dict)  # the last readings of ``window_law_s`` that are its latest :data:`RECENT_PHASES` phases'
    recent_window_weight: Mapping[PhaseClass, float] = field(default_factory=dict)  # their law's share in the window law, per class (:meth:`PhaseHistory.recent_window_weight`)
    # the current phase's exact published end (minEndTime = maxEndTime) and how long after such ends its class changed
    # in the past, for ends first published as far ahead (:meth:`PhaseHistory.exact_lags_s`); () until enough are seen
    exact_end_unix_s: float | None = None
    exact_lags_s: tuple[float, ...] = ()
    # the forecast chained after the phase in progress, as views of this snapshot made it
    # (:func:`~spat_feed.prediction.observe._chain`); not an init field: each snapshot has its own (``replace`` makes a
    # new one), and it goes with the snapshot
    chains: dict = field(default_factory=dict, init=False, repr=False, compare=False)
    # the classes that chain after each class, with their models (:func:`~spat_feed.prediction.observe._chain_steps`):
    # the snapshot's alone, made once
    chain_steps: dict = field(default_factory=dict, init=False, repr=False, compare=False)

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


def past_its_events(plan: Plan | MovementPhaseState | None, t_unix_s: float) -> bool:
    """Whether a reading at ``t_unix_s`` is past every change it publishes (each ``maxEndTime`` at or before it): it
    says what ended, not the phase now, so a history takes it as no reading. (Read as a phase, it is a 1 s "unknown"
    after each phase so ended: SUMO stamps a phase due to switch at that step with ``maxEndTime`` = the stamp, 2 % of
    its readings; the group's cycle then went red -> unknown -> red and never green, its reds' likely end 150-200 s
    out where SUMO published a window ending in 43 s. None in the three recordings.)"""
    changes = getattr(plan, "changes", ())
    return bool(changes) and not isinstance(plan, FixedTimePlan) and published_index(plan, t_unix_s) == len(changes)


def _quantile(sorted_s: Sequence[float], q: float) -> float:
    """The ``q`` quantile of sorted samples (nearest rank, up: conservative for a late end)."""
    return sorted_s[min(len(sorted_s) - 1, max(0, math.ceil(q * len(sorted_s)) - 1))]


def _scored(score: list[float], errors) -> None:
    """Add one phase's errors of two laws to ``score`` = [n, first's mean squared error, second's]: a running mean
    over about :data:`METHOD_MEMORY` phases; ``errors``: pairs (first, second), one per horizon it was scored at
    (:data:`POOL_SCORE_AHEAD_S`), their squares averaged first. [s²]"""
    e = np.asarray(errors, dtype=float).reshape(-1, 2)
    score[0] += 1
    w = max(1.0 / score[0], 1.0 / METHOD_MEMORY)
    score[1] += w * (float(np.mean(e[:, 0] ** 2)) - score[1])
    score[2] += w * (float(np.mean(e[:, 1] ** 2)) - score[2])


def _errors(laws, floor_s: float, truth_s: float) -> tuple[float, float]:
    """The errors of two laws given by samples on one phase: each one's likely end (its median, no earlier than
    ``floor_s``: the phase had not ended then) against ``truth_s``, when it ended. [s]"""
    return tuple(max(floor_s, sample_quantile(np.sort(x), 0.5)) - truth_s for x in laws)


def _scored_pairs(scores: dict, cls: PhaseClass, errors) -> None:
    """:func:`_scored` ``cls``'s score in ``scores`` (a class's first) with a phase's ``errors``, if any."""
    if errors:
        _scored(scores.setdefault(cls, [0, 0.0, 0.0]), errors)


def _visit(path, k: int) -> int:
    """The how-many-th time (from 0) a phase's ``path`` ((since the phase began, state) entries) is in the state of its
    ``k``-th entry there. [-]"""
    return sum(1 for _, s in path[:k] if s == path[k][1])


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
    ended, reading by reading; and, for every phase seen whole, each reading whose window said when (a known
    ``maxEndTime`` or a ``minEndTime`` ahead, :func:`~spat_feed.prediction.predictor.says_when`): how long
    the phase had run, how far ahead its ``minEndTime`` and ``maxEndTime`` were, the intersection's state, and how long
    after ``max(reading, minEndTime)`` the phase ended (:meth:`window_law`, what
    :func:`~spat_feed.prediction.predictor.ends_given_window` reads).
    Pure: no clock, the caller passes the reading's instant (Unix seconds, the plan's axis).
    """

    __slots__ = ("keep", "max_gap_s", "_durations", "_following", "_current", "_since", "_exact", "_last_t", "_min_end", "_held", "_resumed",
                 "_resumed_min_ends", "_excess", "_sorted", "_ends", "ended", "_path", "_paths", "_window", "_windowed", "_laws", "_window_score", "_stage_score", "_recent_score",
                 "_recent_window_score",
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
        self._window: list[tuple[float, float, float]] = []  # the phase in progress: (t, minEndTime, maxEndTime) of each reading whose window says when
        self._windowed: dict[PhaseClass, deque[int]] = {}  # phases seen whole: how many readings with a window each gave its law
        self._laws: dict[PhaseClass, tuple] = {}  # ... and those readings (:meth:`window_law`)
        self._window_score: dict[PhaseClass, list[float]] = {}  # class -> [n, window law's mean squared error, durations'] (:meth:`_score_window`)
        self._stage_score: dict[PhaseClass, list[float]] = {}  # class -> [n, the stage's law's mean squared error, by the phase's start] (:meth:`_given_before`)
        self._recent_score: dict[PhaseClass, list[float]] = {}  # class -> [n, the recent phases' law's mean squared error, all phases'] (:meth:`_given_before`)
        self._recent_window_score: dict[PhaseClass, list[float]] = {}  # class -> [n, as ``_recent_score``, of the window law] (:meth:`_score_window`)
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
        if self._last_t is not None and t_unix_s <= self._last_t or past_its_events(plan, t_unix_s):
            return False  # a repeat or an older reading, or one that says nothing of the phase now
        self.ended = None  # set by the reading that ends a phase only: scored once
        state = plan if isinstance(plan, MovementPhaseState) else published_state(plan, t_unix_s)
        window = None if isinstance(plan, MovementPhaseState) else published_window(plan, t_unix_s)
        min_end = None if window is None else window[0]
        cls = phase_class(state)
        gap = self._last_t is not None and t_unix_s - self._last_t > self.max_gap_s
        changed = cls != self._current
        if gap and not changed and self._went_on(t_unix_s):
            gap = False
        was_resumed = self._resumed
        if changed or gap:
            if changed and not gap and self._current is not None:
                if self._exact:
                    before = self.stats()
                    self.ended = (self._current, self._since, t_unix_s, before.durations(self._current), before.ends(self._current),
                                  (given := self._given_before(t_unix_s)).get(SCORE_AHEAD_S))  # fmt: skip
                    self._durations.setdefault(self._current, deque(maxlen=self.keep)).append(t_unix_s - self._since)
                    self._paths.setdefault(self._current, deque(maxlen=self.keep)).append((t_unix_s - self._since, tuple(self._path)))
                    if self._window:
                        self._score_window(t_unix_s, before, given)
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
        if window is not None and says_when(*window, t_unix_s):
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
        """A frozen snapshot to pass along with a reading (``PlanReading.cycle``, :mod:`spat_feed.prediction.observe`)."""
        if self._sorted is None:
            self._sorted = tuple({c: tuple(sorted(d)) for c, d in dd.items()} for dd in (self._durations, self._excess))
        durations, excess = self._sorted
        law = self.window_law()
        ends = {c: tuple(e) for c, e in self._ends.items()}
        return CycleStats(durations, dict(self._following), self._current, self._since, self._resumed, excess, ends_unix_s=ends, window_law_s=law,
                          window_weight={c: self.window_weight(c) for c in self._window_score},
                          stage_weight={c: _share(self._stage_score[c]) for c in self._stage_score},
                          recent_weight={c: _share(self._recent_score[c]) for c in self._recent_score},
                          recent_window_n={c: sum(list(n)[-RECENT_PHASES:]) for c, n in self._windowed.items()},
                          recent_window_weight={c: _share(self._recent_window_score[c]) for c in self._recent_window_score},
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
        amber ahead is, in such a feed, its green's. Read as the change, it put the red an amber early (docs/history/ADVISOR.md,
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

    def _score_window(self, end_unix_s: float, before: CycleStats, given: Mapping[float, np.ndarray]) -> None:
        """Score the window law and the durations on the phase in progress, which ends at ``end_unix_s``: the likely
        end each said (on the history ``before`` it) at its last reading with a window each of
        :data:`POOL_SCORE_AHEAD_S` or more before the end; ``given``: by those horizons, the durations the
        intersection's state gave then (``state``), else those not yet outlasted. A running mean of each one's
        squared error over about :data:`METHOD_MEMORY` phases."""
        law = before.window_law_s.get(self._current)
        if law is None:
            return
        times = [r[0] for r in self._window]
        by_recent, by_durations = [], []
        for ahead_s in POOL_SCORE_AHEAD_S:
            k = bisect.bisect_right(times, max(self._since, end_unix_s - ahead_s)) - 1
            if k < 0:
                continue
            t, lo, hi = self._window[k]
            el, floor = t - self._since, max(t, lo)
            states = [s for a, s in self._path if a <= el]
            by_window, recent = window_laws(law, before.recent_window_n.get(self._current), self._since, t, lo, hi, states[-1] if states else -1)
            if recent is not None:
                by_recent.append(_errors((recent, by_window), floor, end_unix_s))
                by_window = _mixed(by_window, recent, self.recent_window_weight(self._current))
            own = given.get(ahead_s)
            own = own if own is not None else [d for d in before.durations(self._current) if d > el]
            if by_window is not None and len(own):
                by_durations.append(_errors((by_window, self._since + np.asarray(own)), floor, end_unix_s))
        _scored_pairs(self._recent_window_score, self._current, by_recent)
        _scored_pairs(self._window_score, self._current, by_durations)

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
        """The readings with a window (:func:`says_when`) of the phase in progress, which ends at ``end_unix_s``, as
        arrays: how long it had run, how far ahead ``minEndTime`` (0 once past) and ``maxEndTime`` (``inf``: unknown)
        were, the intersection's state, how long after ``max(reading, minEndTime)`` it ended, and its duration. [s]"""
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
        """Per class, the readings with a window of its last ``keep`` phases seen whole (:meth:`_window_readings`,
        each of the six arrays concatenated over the phases)."""
        return dict(self._laws)

    @property
    def current(self) -> PhaseClass | None:
        """The class of the phase in progress (None before the first reading)."""
        return self._current

    def _given_before(self, end_unix_s: float) -> dict[float, np.ndarray]:
        """By each of :data:`POOL_SCORE_AHEAD_S`, the durations ``state`` gave that long before the phase in progress
        ended at ``end_unix_s`` (:func:`~spat_feed.prediction.predictor.durations_given_state`; at
        :data:`SCORE_AHEAD_S`, what the cycle is scored against); and the score of its two laws then, by the phase's
        start and by the stage's (their likely ends' squared errors, a running mean over about :data:`METHOD_MEMORY`
        phases: :meth:`stage_weight`), and of the law of every phase kept and of the latest :data:`RECENT_PHASES`
        (:meth:`recent_weight`)."""
        at = []  # per horizon: (it, how long the phase had run, since when in its state, the spans of every phase and of the latest)
        for ahead_s in POOL_SCORE_AHEAD_S:
            el = max(0.0, end_unix_s - ahead_s - self._since)
            then = [(a, s) for a, s in self._path if a <= el]
            if then and (spans := self.spans_in(self._current, then[-1][1])) is not None and durations_given_state(spans, el) is not None:
                at.append((ahead_s, el, then[-1][0], spans, self.spans_in(self._current, then[-1][1], RECENT_PHASES), _visit(then, len(then) - 1)))
        truth_s = end_unix_s - self._since
        stage = [(durations_given_stage(spans, el, entered, visit), durations_given_state(spans, el)) for _, el, entered, spans, _, visit in at]
        _scored_pairs(self._stage_score, self._current, [_errors(laws, el, truth_s) for laws, (_, el, *_) in zip(stage, at) if laws[0] is not None])
        laws = [(durations_given_state(spans, el, entered, self.stage_weight(self._current), visit),
                 durations_given_state(recent, el, entered, self.stage_weight(self._current), visit)) for _, el, entered, spans, recent, visit in at]  # fmt: skip
        _scored_pairs(self._recent_score, self._current, [_errors((recent, every), el, truth_s) for (every, recent), (_, el, *_) in zip(laws, at) if recent is not None])
        return {ahead_s: every if recent is None else _mixed(every, recent, self.recent_weight(self._current)) for (every, recent), (ahead_s, *_) in zip(laws, at)}

    def stage_weight(self, cls: PhaseClass) -> float:
        """The share of the stage's law in the ``state`` law of ``cls``
        (:func:`~spat_feed.prediction.predictor.durations_given_state`): in inverse proportion to its mean squared
        error against the law by the phase's start, as :meth:`window_weight`; half each until scored. [-]"""
        return _share(self._stage_score.get(cls, (0, 0.0, 0.0)))

    def recent_window_weight(self, cls: PhaseClass) -> float:
        """The share of the latest :data:`RECENT_PHASES` phases' readings in the window law of ``cls``, pooled with
        every phase's kept (:meth:`window_law`), as :meth:`recent_weight`: the same drift moves them. [-]"""
        return _share(self._recent_window_score.get(cls, (0, 0.0, 0.0)))

    def recent_weight(self, cls: PhaseClass) -> float:
        """The share of the latest :data:`RECENT_PHASES` phases' law in the ``state`` law of ``cls``, pooled with
        every phase's kept: in inverse proportion to its mean squared error against the latter's, as
        :meth:`window_weight`; half each until scored. [-]"""
        return _share(self._recent_score.get(cls, (0, 0.0, 0.0)))

    @property
    def visit(self) -> int:
        """The how-many-th time (from 0) the phase in progress is in the intersection's state now. [-]"""
        return _visit(self._path, len(self._path) - 1) if self._path else 0

    @property
    def entered_s(self) -> float | None:
        """How long after the phase in progress began the intersection entered its state now (None: not known). [s]"""
        return self._path[-1][0] if self._path else None

    def note_state(self, t_unix_s: float, state: int) -> None:
        """The intersection's state (an id of every group's class, :class:`IntersectionHistory`) from ``t_unix_s`` on."""
        if self._since is not None and (not self._path or self._path[-1][1] != state):
            self._path.append((t_unix_s - self._since, state))

    def spans_in(self, cls: PhaseClass | None, state: int, latest: int | None = None) -> tuple[tuple[float, ...], ...] | None:
        """The phases of ``cls`` seen whole (the ``latest`` only, if given) while the intersection was in ``state``:
        each one's duration, the span of its own time (from, to) it spent so, and the how-many-th time (from 0) it
        entered that state then, as four tuples; None when none was. [s]"""
        paths = self._paths.get(cls, ())
        if latest is not None and len(paths) > latest:
            paths = list(paths)[-latest:]
        out = [(d, el, path[k + 1][0] if k + 1 < len(path) else d, _visit(path, k))
               for d, path in paths for k, (el, s) in enumerate(path) if s == state]  # fmt: skip
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
                                                 recent_spans_s=history.spans_in(history.current, self._state, RECENT_PHASES),
                                                 state_entered_s=history.entered_s, state_visit=history.visit)  # fmt: skip
        return cycle
