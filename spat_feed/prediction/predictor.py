r"""When a signal group's phases end: a distribution for each coming change, from the past only.

One interface for every kind of controller: :func:`forecast` takes what the controller publishes now (the plan of
a reading: the current state, its ``minEndTime``, ``maxEndTime``) and what the group has been seen to do
(:class:`~spat_feed.prediction.history.CycleStats`, learnt reading by reading by
:class:`~spat_feed.prediction.history.IntersectionHistory`), and returns a :class:`ChangeForecast` for the end
of the current phase and of the phases after it (up to ``horizon_s``). Each forecast is a set of equally likely
instants (at most :data:`N_SAMPLES`; ``inf`` where nothing seen bounds it), so any quantile (the inverse of their
distribution function, as ``history``'s quantiles of durations), the likely time
(median) and central intervals (:meth:`ChangeForecast.interval`) come from one object, and a hard lower bound
``earliest_unix_s`` (no change comes before it) that advice may rely on.

Where the samples come from, in the order they are trusted (each *method* names one):

``linked``
    A change of another group of the intersection that this group's phases end a steady time after has come
    (the controller's stage sequence, :class:`~spat_feed.prediction.history.ChangeLinks`): the instant of that
    change plus each lag seen that is not yet past, nor before the published ``minEndTime`` (a phase that went on
    past its lags is the case the link does not know, a phase skipped; a ``minEndTime`` held past the usual lag says
    the controller extends the phase, and the longer lags seen say by how much: the usual lag held at ``minEndTime``
    put such reds 6 s early in ``test_a_link_whose_lags_the_published_min_end_has_passed_speaks_by_the_lags_left``;
    with fewer than :data:`MIN_SEEN` lags left, the methods below say).
``resumed``
    The published ``minEndTime`` was held (moved later with the clock) and runs again: it plus each excess
    (end - minEndTime) seen of resumed phases of the class; pooled half and half with ``state`` where that speaks
    (the excess is two-humped, the end at ``minEndTime`` or a stage later, and the other groups tell which).
``cycle``
    A coordinated controller (its changes come back at the same point of a fixed cycle, the period found by
    :func:`cycle_period_s`, refined by :func:`period_fit_s`): each past duration from the phase's start, moved to the
    nearest point of the cycle where the latest phases of the class ended (every pair of the two), each point spread
    by the period's standard error times the cycles it was moved over, and a cycle later for each one that has passed
    while the phase goes on (a phase not ended at its force-off ends at a later one).
``state``
    The durations of the past phases of the class that, as long after they began as this one now, saw the
    intersection in the state it is in now (every signal group's class), where at least :data:`MIN_SEEN` did: on an
    actuated controller what its phases do depends on which stage runs, and this tells it from the stream alone
    (no signal plan, no detectors; :meth:`~spat_feed.prediction.history.PhaseHistory.spans_in`); pooled with the
    *stage's* law, the same phases counted from when the intersection entered that state (those that stayed in it as
    long as this one has: a stage's end is told by how long the stage has run), each with a share in inverse
    proportion to its scored mean squared error (:func:`durations_given_state`); that law read from the latest
    phases of the class only (``CycleStats.recent_spans_s``: an actuated controller's cycle drifts with the traffic)
    pooled with it the same way (``recent_weight``); the plain durations below weigh :data:`PRIOR_PHASES` phases in it.
``duration``
    Each past duration of the class from the phase's start, given that it has run this long (the empirical
    conditional distribution: durations it has already outlasted are out).
the window law (pooled into ``resumed``, ``state`` and ``duration``; the method keeps their name)
    Where the controller publishes a window that says when (a known ``maxEndTime``, or a ``minEndTime`` ahead:
    :func:`says_when`), what it says is part of the forecast: of the readings of past phases of the class that
    carried one (and outlasted how long this phase has run), the :data:`WINDOW_NEIGHBOURS` nearest to the reading now, the intersection in the same state first, then by the sum of the differences in
    seconds of how far ahead ``minEndTime`` and ``maxEndTime`` were and how long the phase had run; each says the
    phase ends as long after ``max(now, minEndTime)`` as that one did after its own (:func:`ends_given_window`);
    read also from the readings of the latest phases of the class only and pooled with it by scored error, as
    ``state``'s (:func:`window_ends`: the same drift with the traffic). A held ``minEndTime`` (moved later with the
    clock: the controller extends the phase) and a ``maxEndTime`` counting down to a force-off read differently
    from a duration alone. The two laws are pooled (a linear opinion pool [2]), each with a share in inverse
    proportion to its mean squared error, scored per (group, class) at each phase end
    (:meth:`~spat_feed.prediction.history.PhaseHistory.window_weight`; half each until scored): on Antwerp each
    one's median errs about as much as the other's, on different changes, so the pool beats either.
``published``
    The controller's window is exact (``maxEndTime - minEndTime`` under :data:`EXACT_S`): then.
``window``
    A published window that says when, and no duration seen that the phase has not outlasted: the window law alone
    (below: the readings of past phases with a like window, each phase's length then saying nothing); with no such
    readings yet and a known ``maxEndTime``, evenly spread in ``[minEndTime, maxEndTime]`` (on 2019-05-01 a red of
    71 s that had outlasted its 13 minutes of history, ``maxEndTime`` 163 s ahead, was put 66 s late so).

Between ``cycle`` and ``duration`` (``state`` is the latter, conditioned) the one that has erred less for that (group, class) wins: at each phase end the
likely end each would have said :data:`SCORE_AHEAD_S` before it is scored (:func:`scored_errors_s`, a running mean kept by
:class:`~spat_feed.prediction.history.IntersectionHistory`). A state-only coordinated controller earns the cycle
(2024-04-15, device 1136: ends within a few seconds of a fixed point of its 75 s cycle); the actuated Antwerp
controller, whose changes drift off any period, keeps the durations. Nothing here is fitted to one controller.

Every sample is at least the hard bound (``max(now, minEndTime)``; a published phase never ends before its
``minEndTime``, :mod:`spat_feed.transport.recorded`'s README): one that would end earlier ends there (the
controller holds it). ``maxEndTime`` is soft (real phases outlast it 6-12 % of the time) and is not a bound.
The phases after the current one chain the same way: their ends are every sum of the previous end's samples and
the next class's durations (moved to the cycle where that class is ``cycle``), reduced to :data:`N_SAMPLES`
quantiles.

Pure: no clock, no I/O; the caller passes the instant. Numbers in seconds on the plan's (Unix) axis.

.. [2] C. Genest and J. V. Zidek, "Combining probability distributions: a critique and an annotated bibliography,"
   Statist. Sci., vol. 1, pp. 114-135, 1986, doi:10.1214/ss/1177013825.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from numba import njit

from spat_feed.timing.plans import PhaseClass, UncertainPlan, phase_class

EXACT_LAG_MAX_S = 6.0
"""The longest amber (MUTCD 4D.26): how long after an exact end of a go phase published as "unavailable" its red may
begin, before the group's history says (:func:`current_end`). [s]"""
_UNKNOWN_LAGS_S = tuple(np.linspace(0.0, EXACT_LAG_MAX_S, 7).tolist())  # that lag, 0 .. EXACT_LAG_MAX_S, equally likely [s]
EXACT_S = 0.5
"""A published window narrower than this is exact (fixed-time, exact SPaT): the change comes then. [s]"""

N_SAMPLES = 64
"""Samples kept per forecast (its quantiles, evenly spaced). [-]"""

MIN_SEEN = 3
"""Phases of a class needed before their durations say anything (as ``history.MIN_PHASES_SEEN``). [-]"""

PRIOR_PHASES = MIN_SEEN
"""What the plain durations of a class weigh, in phases, in the law that the phases seen in the intersection's state
now give (method ``state``): from ``n`` such phases, ``(n F_state + a F_plain) / (n + a)`` (the predictive law of a
Dirichlet process with the plain durations as its base measure [1]). With a few phases alone the law is too narrow
(its 80 % interval held 74.5 % of the changes on Antwerp; 76.4 % with the prior).

.. [1] T. S. Ferguson, "A Bayesian analysis of some nonparametric problems," Ann. Statist., vol. 1, pp. 209-230,
   1973, doi:10.1214/aos/1176342360. [-]"""

PERIOD_RANGE_S = (30.0, 240.0)
"""Cycle lengths searched by :func:`cycle_period_s` (traffic signal cycles: 30 s to 4 min). [s]"""

MIN_PERIOD_ENDS = 20
"""Changes of a (group, class) needed before they count towards a period (with fewer, chance alone concentrates
them: the mean resultant length of ``n`` uniform angles is about ``0.89 / sqrt(n)``). [-]"""

MIN_PERIOD_CONCENTRATION = 0.5
"""Mean resultant length of the changes on the cycle below which no period is said (uniform phases give
~1/sqrt(n); a controller with a fixed cycle 0.8-1). [-]"""


def sample_quantile(sorted_s, q: float) -> float:
    """The ``q`` quantile of sorted, equally likely samples: the inverse of their distribution function (the smallest
    sample with at least ``q`` of them at or before it; ``inf`` in an unbounded tail), as ``history``'s quantiles of
    durations.

    Examples
    --------
    >>> sample_quantile([1.0, 2.0, 3.0, 4.0], 0.5), sample_quantile([1.0, 2.0, 3.0, 4.0], 0.9)
    (2.0, 4.0)
    """
    return float(sorted_s[min(len(sorted_s) - 1, max(0, math.ceil(q * len(sorted_s) - 1e-9) - 1))])


@dataclass(frozen=True, slots=True)
class ChangeForecast:
    """When the phase of class ``ends`` (followed by ``then``) ends: equally likely instants, and a hard bound.

    ``samples_unix_s``: sorted, shape ``(n,)``, ``n <= N_SAMPLES``; ``inf`` for "not before anything seen".
    ``earliest_unix_s``: no change before it (``minEndTime``, or the shortest durations seen after a hard bound).
    """

    ends: PhaseClass
    then: PhaseClass | None
    earliest_unix_s: float
    samples_unix_s: np.ndarray
    method: str

    def quantile(self, q: float) -> float:
        """The ``q`` quantile of the end instant (:func:`sample_quantile`). [s]"""
        return sample_quantile(self.samples_unix_s, q)

    @property
    def likely_unix_s(self) -> float:
        """The median end: J2735 ``likelyTime``. [s]"""
        return self.quantile(0.5)

    def interval(self, level: float) -> tuple[float, float]:
        """The central ``level`` interval (``0.8``: the 10 % and 90 % quantiles). [s]"""
        return self.quantile(0.5 - level / 2.0), self.quantile(0.5 + level / 2.0)

    def within_frac(self, t_unix_s: float, half_width_s: float) -> float:
        """Share of the samples within ``half_width_s`` of ``t_unix_s``: the chance the change comes there. [-]"""
        s = self.samples_unix_s
        return float(np.count_nonzero(np.abs(s - t_unix_s) <= half_width_s)) / len(s)


N_PAIRED = 16
"""Samples of each side paired where two sets combine (durations with cycle points, ends with durations). [-]"""


def _reduced(samples, n: int = N_SAMPLES) -> np.ndarray:
    """Sorted samples, at most ``n`` of them (evenly spaced quantiles, ``inf`` kept)."""
    s = np.sort(np.asarray(samples, dtype=float))
    return s if len(s) <= n else s[_spread_indices(len(s), n)]


def _mixed(samples, others, share: float) -> np.ndarray:
    """A linear pool of two laws given by samples: ``others`` with the share ``share`` of :data:`N_SAMPLES` samples,
    ``samples`` with the rest, each set as that many of its quantiles (repeated where it has fewer: a law of 3
    samples weighs its share, not 3 samples' worth). [s]

    Examples
    --------
    >>> _mixed(np.arange(100.0), np.full(3, -1.0), 0.25).tolist().count(-1.0), len(_mixed(np.arange(100.0), [], 0.0))
    (16, 100)
    """
    n_others = round(N_SAMPLES * share)
    if n_others <= 0 or not len(others):
        return np.asarray(samples, dtype=float)
    if n_others >= N_SAMPLES or not len(samples):
        return np.asarray(others, dtype=float)
    return np.concatenate([_quantiles(samples, N_SAMPLES - n_others), _quantiles(others, n_others)])


def _quantiles(samples, n: int) -> np.ndarray:
    """``n`` evenly spaced quantiles of the samples (sorted; a sample repeated where there are fewer than ``n``)."""
    s = np.sort(np.asarray(samples, dtype=float))
    return s[_spread_indices(len(s), n)]


@lru_cache(maxsize=1024)
def _spread_indices(length: int, n: int) -> np.ndarray:
    """``n`` indices evenly spread over ``range(length)``, first and last included."""
    return np.round(np.linspace(0, length - 1, n)).astype(np.int64)


def cycle_period_s(ends_unix_s: Sequence[Sequence[float]], step_s: float = 0.1) -> float | None:
    """The cycle of a controller whose changes come back at fixed points of it, else None. [s]

    ``ends_unix_s``: one sequence of change instants per (group, class). The period is the one in
    :data:`PERIOD_RANGE_S` at which those instants are most concentrated on the circle (the mean, over the
    sequences, of the resultant length of ``exp(2 pi i t / P)``), searched on a coarse grid then refined to
    ``step_s``; of periods within 5 % of the best concentration the longest (a period's divisors concentrate
    the changes as well). None when even the best is below :data:`MIN_PERIOD_CONCENTRATION`.

    Examples
    --------
    >>> ends = [[1000.0 + 75.0 * k + j for k in range(MIN_PERIOD_ENDS)] for j in (3.0, 40.0)]
    >>> round(cycle_period_s(ends), 1)
    75.0
    """
    seqs = [np.asarray(e, dtype=float) for e in ends_unix_s if len(e) >= MIN_PERIOD_ENDS]
    if not seqs:
        return None

    times = np.concatenate([e - e[0] for e in seqs])
    which = np.repeat(np.arange(len(seqs)), [len(e) for e in seqs])
    counts = np.array([len(e) for e in seqs], dtype=float)

    def concentration(periods: np.ndarray) -> np.ndarray:
        phase = 2.0 * np.pi * times[None, :] / periods[:, None]
        c = np.stack([np.bincount(which, weights=row, minlength=len(seqs)) for row in np.cos(phase)]) / counts
        s = np.stack([np.bincount(which, weights=row, minlength=len(seqs)) for row in np.sin(phase)]) / counts
        return np.hypot(c, s).mean(axis=1)

    coarse = np.arange(PERIOD_RANGE_S[0], PERIOD_RANGE_S[1] + 1e-9, 1.0)
    r = concentration(coarse)
    good = coarse[r >= 0.95 * r.max()]
    best = None
    for p in good[::-1]:  # the longest first
        fine = np.arange(p - 1.0, p + 1.0 + 1e-9, step_s)
        rf = concentration(fine)
        if rf.max() >= MIN_PERIOD_CONCENTRATION and (best is None or rf.max() >= 0.95 * best[1]):
            best = (float(fine[rf.argmax()]), float(rf.max()))
            break
    return None if best is None else best[0]


def period_fit_s(ends_unix_s: Sequence[Sequence[float]], period_s: float) -> tuple[float, float]:
    """The period found by :func:`cycle_period_s`, refined, and its standard error: each sequence of changes of a
    (group, class) with :data:`MIN_PERIOD_ENDS` or more gives, by least squares of where its changes fall on the cycle
    against their cycle's number ``k``, a correction of the period (the slope) and its variance (the residuals'
    variance over the sum of squared ``k - mean k``); the sequences' corrections are averaged in inverse proportion
    to their variances, the standard error is that of the average. [s] A class whose changes fall on the same reading
    of every cycle (residuals 0; 1e-9 s² keeps the division finite) fixes the period to the readings' clock: on US
    1136 75.000 s, standard error ~1e-6 s. (A reading's quantization, 1/12 s², as the least residual variance put it a
    few ms off, and forecasts of an instant that the same 1 s readings date then came after the reading that saw
    the change: US 1136's 80 % intervals 82 -> 79 %, docs/history/PREDICTION.md.)

    A period is known only as well as the changes that gave it: on US 1136 the search's 0.1 s grid and the changes'
    jitter (a few seconds) put it at 75.1 s 34 minutes in, 75.0 s later; a change 40 cycles back, moved to now by
    75.1 s, is 4 s off, and a forecast that moves it so without saying it is sure and wrong (predict-eval's
    ``coverage_by_width``: the cycle's forecasts 2-5 s wide held 34 % of their changes at 80 %).

    Examples
    --------
    >>> jitter = (0.5, -0.5, -0.5, 0.5)  # the changes half a second either side of a 75 s cycle, found as 75.1 s
    >>> ends = [[1000.0 + 75.0 * k + j + jitter[k % 4] for k in range(MIN_PERIOD_ENDS)] for j in (3.0, 40.0)]
    >>> p, se = period_fit_s(ends, 75.1)
    >>> round(p, 6), round(se, 4)
    (75.0, 0.0145)
    """
    info = weighted = 0.0
    for e in sorted(ends_unix_s, key=tuple):  # (in one order whatever order the groups came in: the same sums)
        if len(e) < MIN_PERIOD_ENDS:
            continue
        e = np.asarray(e, dtype=float)
        k = np.round((e - e[0]) / period_s)
        at = _wrap(e - e[0] - k * period_s, period_s)
        kc = k - k.mean()
        ss = float(kc @ kc)
        if ss <= 0.0:
            continue
        slope = float(kc @ (at - at.mean())) / ss
        variance = max(float(np.sum((at - at.mean() - slope * kc) ** 2)) / (len(e) - 2), 1e-9) / ss
        info += 1.0 / variance
        weighted += slope / variance
    return (period_s, 0.0) if info <= 0.0 else (period_s + weighted / info, 1.0 / math.sqrt(info))


def _wrap(x: np.ndarray, period_s: float) -> np.ndarray:
    """``x`` moved into ``[-period/2, period/2)``."""
    return (x + 0.5 * period_s) % period_s - 0.5 * period_s


@lru_cache(maxsize=4096)
def _class_model(durations_s: tuple[float, ...], ends_unix_s: tuple[float, ...], on_cycle: bool) -> tuple[np.ndarray, np.ndarray | None]:
    """A class's durations (:data:`N_PAIRED` quantiles) and, where the class is told by the cycle, the instants its
    latest :data:`N_PAIRED` phases ended (the nearest cycles: the period's error moves them least, and a coordinated
    controller changes its plan by the time of day), else None. Cached: a group's history changes only when a phase
    ends."""
    return _reduced(durations_s, N_PAIRED), (np.sort(np.asarray(ends_unix_s[-N_PAIRED:], dtype=float)) if on_cycle and len(ends_unix_s) >= MIN_SEEN else None)


SCORE_AHEAD_S = 20.0
"""Methods are scored on what they said this long before a phase ended (the horizon advice leans on most). [s]"""


def scored_errors_s(since_unix_s: float, end_unix_s: float, durations_s: tuple[float, ...], ends_unix_s: tuple[float, ...],
                    period_s: float | None, given_s: np.ndarray | None = None) -> tuple[float, float] | None:  # fmt: skip
    """How far off the ``cycle`` and the ``duration`` method's likely end were :data:`SCORE_AHEAD_S` before a phase
    that began at ``since_unix_s`` ended at ``end_unix_s`` (or at its start, if shorter), on the history before it;
    None where either cannot say. ``given_s``: the durations ``state`` gave then (:func:`durations_given_state`),
    scored in place of the durations where given (what the cycle would replace). [s] What
    :class:`~spat_feed.prediction.history.IntersectionHistory` scores each class's methods by."""
    if period_s is None or len(durations_s) < MIN_SEEN or len(ends_unix_s) < MIN_SEEN:
        return None
    at = max(since_unix_s, end_unix_s - SCORE_AHEAD_S)
    d, ends = _class_model(durations_s, ends_unix_s, True)
    ahead = since_unix_s + (np.sort(given_s) if given_s is not None else d[since_unix_s + d > at])
    if not len(ahead):
        return None
    by_duration = sample_quantile(ahead, 0.5)
    on_cycle = _after(_on_cycle(since_unix_s + d, ends, period_s), at, period_s)
    by_cycle = sample_quantile(_reduced(on_cycle), 0.5)
    return abs(by_cycle - end_unix_s), abs(by_duration - end_unix_s)


def _on_cycle(raw_unix_s: np.ndarray, ends_unix_s: np.ndarray, period_s: float) -> np.ndarray:
    """Each raw end (a start plus a duration) moved to the nearest point of the cycle where a phase ended, for every
    pair of the two (``len(raw) * len(ends)`` instants, raw-major)."""
    raw = _reduced(raw_unix_s, N_PAIRED)
    return (raw[:, None] + _wrap(ends_unix_s[None, :] - raw[:, None], period_s)).ravel()


def _spread_on_cycle(moved_unix_s: np.ndarray, ends_unix_s: np.ndarray, period_s: float, period_error_s: float, floor_unix_s: float = -math.inf) -> np.ndarray:
    """The instants :func:`_on_cycle` moved past changes (``ends_unix_s``) to, each spread by the period's standard
    error (:func:`period_fit_s`) times the cycles it was moved over (a three-point rule of the normal law: ``0,
    +-sqrt(3/2) sd``, equally likely: three times the instants), none before ``floor_unix_s``: a change 40 cycles back
    moved by a period 0.1 s off is 4 s off. [s]"""
    if period_error_s <= 0.0:
        return moved_unix_s
    origin = np.tile(ends_unix_s, len(moved_unix_s) // len(ends_unix_s))
    sd = math.sqrt(1.5) * period_error_s * np.abs(np.round((moved_unix_s - origin) / period_s))
    return np.maximum(np.concatenate([moved_unix_s - sd, moved_unix_s, moved_unix_s + sd]), floor_unix_s)


def _after(samples: np.ndarray, floor_unix_s: float, period_s: float | None) -> np.ndarray:
    """Samples no earlier than the hard bound: on a cycle, one that has passed moves a cycle on (the phase went on
    past that point); otherwise it is held at the bound (the controller holds a phase to its minEndTime)."""
    if period_s is not None:
        behind = samples < floor_unix_s
        if behind.any():
            samples = samples.copy()
            samples[behind] += np.ceil((floor_unix_s - samples[behind]) / period_s) * period_s
    return np.maximum(samples, floor_unix_s)


def _durations_ahead(since_unix_s: float | None, durations_s: Sequence[float], now_unix_s: float) -> np.ndarray:
    """End instants of the durations seen that the phase has not yet outlasted (empty if none is left)."""
    if since_unix_s is None or not durations_s:
        return np.empty(0)
    ends = since_unix_s + np.asarray(durations_s, dtype=float)
    return ends[ends > now_unix_s]


@lru_cache(maxsize=256)
def _as_arrays(spans: tuple[tuple[float, ...], ...]) -> tuple[np.ndarray, ...]:
    """The tuples as float arrays (cached: a group's spans change only when the intersection's state does)."""
    return tuple(np.asarray(x, dtype=float) for x in spans)


def durations_given_state(spans, elapsed_s: float, entered_s: float | None = None, stage_share: float = 0.0, visit: int = 0) -> np.ndarray | None:
    """The durations of the past phases of the class that, this long after they began, were in the intersection's
    state now (every group's class as now), if :data:`MIN_SEEN` were, else None. ``spans``: :class:`CycleStats`'s
    ``state_spans_s``, (durations, from, to[, visit]) tuples; ``visit``: the how-many-th time the phase in progress is
    in that state (:func:`durations_given_stage`). [s]

    With ``entered_s`` (how long after the phase began the intersection entered its state now), pooled with the
    durations the *stage* says, with the share ``stage_share``: each past phase of the class that stayed in that
    state at least as long as this one has so far ended as long after entering it as that one did
    (``entered + duration - from``): on an actuated controller a red waits for the stage that runs, and a stage's end
    is told by how long it has run, not by how long the red has (:func:`durations_given_stage`).

    Examples
    --------
    >>> spans = ((30.0, 30.0, 30.0, 50.0), (0.0, 0.0, 0.0, 20.0), (30.0, 30.0, 30.0, 50.0))  # three 30 s reds in it from their start, one 50 s from 20 s
    >>> durations_given_state(spans, 10.0).tolist(), sorted(set(durations_given_state(spans, 25.0, 20.0, 0.5).tolist()))
    ([30.0, 30.0, 30.0], [30.0, 50.0])
    """
    got = state_law(spans, elapsed_s, entered_s, stage_share, visit)
    return None if got is None else got[0]


def state_law(spans, elapsed_s: float, entered_s: float | None = None, stage_share: float = 0.0, visit: int = 0) -> tuple[np.ndarray, int] | None:
    """:func:`durations_given_state` and the number of past phases that were in the state (what the plain durations
    weigh against, :data:`PRIOR_PHASES`), or None. [s], [-]"""
    if spans is None:
        return None
    d, lo, hi = _as_arrays(spans)[:3]
    m = (lo <= elapsed_s) & (elapsed_s < hi)
    if (n := int(np.count_nonzero(m))) < MIN_SEEN:
        return None
    by_stage = None if entered_s is None or stage_share <= 0.0 else durations_given_stage(spans, elapsed_s, entered_s, visit)
    return (d[m] if by_stage is None else _mixed(d[m], by_stage, stage_share)), n


def durations_given_stage(spans, elapsed_s: float, entered_s: float, visit: int = 0) -> np.ndarray | None:
    """The durations of a phase now ``elapsed_s`` in, whose intersection entered its state now ``entered_s`` after it
    began, that past phases of the class in that state say when counted from their entering it: each one that stayed
    in it at least ``elapsed - entered`` ended ``entered + (duration - from)`` after this one began; None with fewer
    than :data:`MIN_SEEN`. ``spans``: as :func:`durations_given_state`, with a fourth tuple where given, the how-many-th
    time (from 0) the phase entered that state: only their spans of the same ``visit`` count (a red that ends a few
    seconds after a stage is in its starting state again then; read at its start, those last seconds said "3 s"). [s]

    Examples
    --------
    >>> durations_given_stage(((30.0, 30.0, 30.0, 50.0), (0.0, 0.0, 0.0, 20.0), (30.0, 30.0, 30.0, 50.0)), 25.0, 20.0).tolist()
    [50.0, 50.0, 50.0, 50.0]
    """
    d, lo, hi, *visits = _as_arrays(spans)
    m = hi - lo > elapsed_s - entered_s
    if visits:
        m &= visits[0] == visit
    return entered_s + (d - lo)[m] if np.count_nonzero(m) >= MIN_SEEN else None


WINDOW_NEIGHBOURS = N_SAMPLES // 2
"""Past readings that speak for the published window now (:func:`ends_given_window`): the pool's half of the
forecast's samples. [-]"""

OTHER_STATE_S = 1e6
"""What a reading in another intersection state counts in the distance of :func:`ends_given_window`: more than any
difference in seconds, so the same state comes first. [s]"""


UNBOUNDED_APART_S = 1e3
"""What a reading with an unknown ``maxEndTime`` counts against one with a known one in the distance of
:func:`ends_given_window` (and the other way round): more than any difference in seconds, less than another state. [s]"""


def says_when(min_end_unix_s: float, max_end_unix_s: float, now_unix_s: float) -> bool:
    """Whether a published window says something of when the phase ends: a known ``maxEndTime``, or a
    ``minEndTime`` still ahead (an actuated controller's red with no call publishes no ``maxEndTime``, but counts its
    ``minEndTime`` down; a state-only controller publishes neither, and its ``minEndTime`` is the reading's instant).

    Examples
    --------
    >>> says_when(100.0, math.inf, 90.0), says_when(90.0, math.inf, 90.0), says_when(90.0, 120.0, 95.0)
    (True, False, True)
    """
    return math.isfinite(max_end_unix_s) or min_end_unix_s > now_unix_s


@njit(cache=True)
def _window_distance_s(el_s, to_min_s, to_max_s, state, duration_s, elapsed_s: float, to_floor_s: float, to_max_end_s: float, state_id: int):
    """How far each past reading of a window law lies from the reading now (:func:`ends_given_window`), and how many
    speak: ``inf`` for one whose phase this one has outlasted (unless it has outlasted them all: then every one speaks,
    by its window alone). The sum, in this order, of the differences in seconds of how far ahead ``minEndTime`` was
    (``to_floor_s``: ``max(now, minEndTime) - now``) and ``maxEndTime`` (``to_max_end_s``; 0 where both are unknown,
    :data:`UNBOUNDED_APART_S` where one is, at most that), of how long the phase had run (not once outlasted), and
    :data:`OTHER_STATE_S` for a reading in another intersection state: one pass over the arrays, the numpy
    expressions' operations in their order (bit for bit). [s]"""
    n = len(el_s)
    n_alive = 0
    for i in range(n):
        if duration_s[i] > elapsed_s:
            n_alive += 1
    outlasted = n_alive == 0
    d = np.empty(n)
    for i in range(n):
        if not outlasted and not duration_s[i] > elapsed_s:
            d[i] = np.inf
            continue
        if math.isinf(to_max_end_s):
            apart = 0.0 if math.isinf(to_max_s[i]) else UNBOUNDED_APART_S
        else:
            apart = abs(to_max_s[i] - to_max_end_s)
            if apart > UNBOUNDED_APART_S:
                apart = UNBOUNDED_APART_S
        v = abs(to_min_s[i] - to_floor_s) + apart
        if not outlasted:
            v += abs(el_s[i] - elapsed_s)
        if state[i] != state_id:
            v += OTHER_STATE_S
        d[i] = v
    return d, n if outlasted else n_alive


def ends_given_window(law, since_unix_s: float, now_unix_s: float, min_end_unix_s: float, max_end_unix_s: float, state_id: int = -1) -> np.ndarray | None:
    """Samples of the end of a phase that began at ``since_unix_s``, now published with the window
    ``[min_end, max_end]`` (:func:`says_when`; ``inf``: an unknown ``maxEndTime``), from the readings of past phases of
    its class that carried one (``law``: :meth:`~spat_feed.prediction.history.PhaseHistory.window_law`'s arrays): of
    the readings of phases that outlasted this one's run so far, the :data:`WINDOW_NEIGHBOURS` nearest (the same
    intersection state ``state_id`` first, then by the sum of the differences of how long the phase had run and how far
    ahead ``minEndTime`` and ``maxEndTime`` were, an unknown ``maxEndTime`` :data:`UNBOUNDED_APART_S` from a known one
    and 0 from another unknown one: :func:`_window_distance_s`), each moved to now: ``max(now, min_end)`` plus how long after
    ``max(its reading, its minEndTime)`` its phase ended. A phase speaks by as many readings as lie near (a kernel weight on how alike its
    course was): on Antwerp 2019-05-01 (first 100 min) one reading per phase, the nearest 16 or 32 phases, erred
    more (ratio to the baseline 0.636 / 0.635 against 0.627). A phase that has outlasted every one seen is read by its
    window alone: all the readings, the nearest by ``minEndTime`` and ``maxEndTime`` (how long they had run says
    nothing of a phase longer than any of theirs). None with fewer than :data:`MIN_SEEN` such readings. [s]

    Examples
    --------
    >>> el = np.tile(np.arange(10.0), 5)  # five phases of 20 s that ended at their maxEndTime: their first 10 readings
    >>> law = (el, np.zeros(50), 20.0 - el, np.full(50, -1), 20.0 - el, np.full(50, 20.0))
    >>> s = ends_given_window(law, 100.0, 105.0, 100.0, 120.0)  # 5 s in, maxEndTime 15 s ahead
    >>> len(s), float(np.median(s)), float(s.min()), float(s.max())  # the readings 2-8 s in: 120 s, +-3 s
    (32, 120.0, 117.0, 123.0)
    """
    el, to_min, to_max, state, excess, duration = law
    elapsed_s, floor_unix_s = now_unix_s - since_unix_s, max(now_unix_s, min_end_unix_s)
    d, n = _window_distance_s(el, to_min, to_max, state, duration, elapsed_s, floor_unix_s - now_unix_s, max_end_unix_s - now_unix_s, state_id)
    if n < MIN_SEEN:
        return None
    k = min(WINDOW_NEIGHBOURS, n)
    return floor_unix_s + excess[np.argpartition(d, k - 1)[:k]]


def latest_readings(law, n_readings: int | None):
    """The window law (:func:`ends_given_window`) of a class's latest phases: the last ``n_readings`` of each of its
    arrays (``CycleStats.recent_window_n``); None where that is all of them (or none): the same law."""
    if not n_readings or n_readings >= len(law[0]):
        return None
    return tuple(a[-n_readings:] for a in law)


def window_laws(law, n_recent: int | None, since_unix_s: float, now_unix_s: float, min_end_unix_s: float, max_end_unix_s: float,
                state_id: int = -1) -> tuple[np.ndarray | None, np.ndarray | None]:  # fmt: skip
    """:func:`ends_given_window` on the readings of every phase kept and on those of the latest phases only (the last
    ``n_recent`` readings, :func:`latest_readings`), apart: what :func:`window_ends` pools and the history scores.
    The second is None where it is the same law or the first says nothing. [s]"""
    every = ends_given_window(law, since_unix_s, now_unix_s, min_end_unix_s, max_end_unix_s, state_id)
    recent = latest_readings(law, n_recent)
    recent = None if recent is None or every is None else ends_given_window(recent, since_unix_s, now_unix_s, min_end_unix_s, max_end_unix_s, state_id)
    return every, recent


def window_ends(cycle, cls: PhaseClass, since_unix_s: float, now_unix_s: float, min_end_unix_s: float, max_end_unix_s: float) -> np.ndarray | None:
    """:func:`ends_given_window` on the readings of every phase of ``cls`` kept, pooled with it on those of its latest
    phases only (:func:`window_laws`: an actuated controller's cycle drifts with the traffic), the latter's share
    the class's ``recent_window_weight`` (half until scored). None where the law says nothing. [s]"""
    law = cycle.window_law_s.get(cls)
    if law is None:
        return None
    every, recent = window_laws(law, cycle.recent_window_n.get(cls), since_unix_s, now_unix_s, min_end_unix_s, max_end_unix_s, cycle.state_id)
    return every if recent is None else _mixed(every, recent, cycle.recent_window_weight.get(cls, 0.5))


def _pooled(samples: np.ndarray, method: str, cycle, cls: PhaseClass, since_unix_s: float | None, now_unix_s: float,
            min_end_unix_s: float, max_end_unix_s: float) -> tuple[np.ndarray, str]:  # fmt: skip
    """``samples`` of ``method`` for the phase in progress pooled with :func:`window_ends`'s where the window
    says when (:func:`says_when`) and the class's readings say, the latter's share the class's ``window_weight`` (half until scored). Only
    for the phase in progress: the law is learnt from readings of phases in progress, with how long they had run."""
    if since_unix_s is None or not says_when(min_end_unix_s, max_end_unix_s, now_unix_s):
        return samples, method
    by_window = window_ends(cycle, cls, since_unix_s, now_unix_s, min_end_unix_s, max_end_unix_s)
    if by_window is None:
        return samples, method
    return _mixed(samples, by_window, cycle.window_weight.get(cls, 0.5)), method


def _by_durations(cycle, cls: PhaseClass, since_unix_s: float, now_unix_s: float, floor_unix_s: float, given: np.ndarray | None, n_given: int,
                  published_min_unix_s: float, published_max_unix_s: float, current: bool) -> tuple[np.ndarray, str] | None:  # fmt: skip
    """Samples of the end of the phase in progress by its class's durations: ``state`` where the intersection's state
    now speaks (``given``: :func:`durations_given_state`, from ``n_given`` phases), with the plain durations as its prior
    (:data:`PRIOR_PHASES`), else ``duration`` (those not yet outlasted); pooled with the window law where the phase is
    the current one (:func:`_pooled`). None when the phase has outlasted every duration seen and no state speaks."""
    ahead = _durations_ahead(since_unix_s, cycle.durations(cls), now_unix_s)
    if given is not None:
        pooled = _mixed(since_unix_s + given, ahead, PRIOR_PHASES / (n_given + PRIOR_PHASES)) if len(ahead) else since_unix_s + given
        return _pooled(_after(pooled, floor_unix_s, None), "state", cycle, cls, since_unix_s, now_unix_s, published_min_unix_s, published_max_unix_s)
    if not len(ahead):
        return None
    by_duration = _after(ahead, floor_unix_s, None)
    if not current:  # a later phase of the plan: the window law knows the phase in progress only
        return by_duration, "duration"
    return _pooled(by_duration, "duration", cycle, cls, since_unix_s, now_unix_s, published_min_unix_s, published_max_unix_s)


def current_end(cycle, cls: PhaseClass, since_unix_s: float | None, now_unix_s: float, published_min_unix_s: float = -math.inf,
                published_max_unix_s: float = math.inf, current: bool = True) -> tuple[np.ndarray, str] | None:  # fmt: skip
    """Samples of the end of the phase of class ``cls`` that began at ``since_unix_s`` (None: unknown), in progress
    at ``now_unix_s`` with the published window ``[minEndTime, maxEndTime]`` (module docstring), and the method; None
    when nothing bounds it. ``cycle``: the group's :class:`~spat_feed.prediction.history.CycleStats`; ``current``:
    the phase is the one the group is in (its hold and links are known), not a later one of the plan."""
    inf = math.inf
    floor_unix_s = max(now_unix_s, published_min_unix_s)
    if published_max_unix_s - published_min_unix_s < EXACT_S:  # an exact window: the controller says when its state ends
        lags = cycle.exact_lags_s if cycle is not None and current and cycle.exact_end_unix_s is not None \
            and abs(cycle.exact_end_unix_s - published_max_unix_s) < EXACT_S else ()  # fmt: skip
        if not lags and cls is PhaseClass.UNKNOWN and current:
            # a go phase published as one state ("unavailable"), before its history has told which end it states:
            # its green's (the red an amber later) or its amber's (the red then), either, the amber as long as a real one
            lags = _UNKNOWN_LAGS_S
        # the class changes that long after it (a go phase published as one state: its green's end, then its amber)
        return np.maximum(published_max_unix_s + np.asarray(lags or (0.0,)), floor_unix_s), "published"
    given, n_given = None, 0  # the durations of the phases of the class seen in the intersection's state now, this far in
    if cycle is not None and current and since_unix_s is not None:
        got = state_law(cycle.state_spans_s, now_unix_s - since_unix_s, cycle.state_entered_s, cycle.stage_weight.get(cls, 0.5), cycle.state_visit)
        if got is not None:  # (pooled with the stage's law; the prior is weighed against the phases seen)
            given, n_given = got
            recent = durations_given_state(cycle.recent_spans_s, now_unix_s - since_unix_s, cycle.state_entered_s, cycle.stage_weight.get(cls, 0.5), cycle.state_visit)
            if recent is not None:  # (pooled with the latest phases' law: the traffic drifts)
                given = _mixed(given, recent, cycle.recent_weight.get(cls, 0.5))
    if cycle is not None and current:
        linked = np.asarray(cycle.linked_ends_unix_s or cycle.linked_end_unix_s or (), dtype=float)  # every lag seen, or (likely, late)
        ahead = linked[linked >= floor_unix_s]  # the link has not failed (the phase went on past its lags, or minEndTime did) while some are ahead
        if len(ahead) >= min(MIN_SEEN, len(linked)) > 0:
            return _after(ahead, floor_unix_s, None), "linked"
        if cycle.resumed and (excess := cycle.after_resumed(cls)) and math.isfinite(published_min_unix_s):
            resumed = _after(published_min_unix_s + np.asarray(excess, dtype=float), floor_unix_s, None)
            if given is not None:  # pooled with the state's, half each
                resumed = _mixed(resumed, _after(since_unix_s + given, floor_unix_s, None), 0.5)
            return _pooled(resumed, "resumed", cycle, cls, since_unix_s, now_unix_s, published_min_unix_s, published_max_unix_s)
    durations = cycle.durations(cls) if cycle is not None else ()
    since = since_unix_s
    if durations and since is not None:
        period = cycle.period_s
        d, cycle_ends = _class_model(durations, cycle.ends(cls), period is not None and cls in cycle.cycle_classes)
        if cycle_ends is not None:
            on_cycle = _after(_on_cycle(since + d, cycle_ends, period), floor_unix_s, period)  # (a point passed: a cycle on)
            return _spread_on_cycle(on_cycle, cycle_ends, period, cycle.period_error_s, floor_unix_s), "cycle"
        own = _by_durations(cycle, cls, since, now_unix_s, floor_unix_s, given, n_given, published_min_unix_s, published_max_unix_s, current)
        if own is not None:
            return own
    if says_when(published_min_unix_s, published_max_unix_s, now_unix_s) and published_max_unix_s > floor_unix_s:
        # the window law alone (the phase has outlasted every duration seen), else a known window evenly
        by_window = _pooled(np.empty(0), "", cycle, cls, since, now_unix_s, published_min_unix_s, published_max_unix_s)[0] if cycle is not None and current else ()
        if len(by_window) or math.isfinite(published_max_unix_s):
            return (by_window if len(by_window) else np.linspace(floor_unix_s, published_max_unix_s, 9)), "window"
    if math.isfinite(published_max_unix_s):
        return np.array([max(floor_unix_s, published_max_unix_s)]), "window"
    return None if not durations else (np.array([inf]), "duration")


def class_model(cycle, cls: PhaseClass) -> tuple[np.ndarray, np.ndarray | None] | None:
    """:func:`_class_model` of ``cls`` in the group's history ``cycle`` (its durations; its latest ends where the cycle
    tells it), or None when no duration of the class is known: what :func:`ends_after` adds to a phase's start."""
    durations = cycle.durations(cls) if cycle is not None else ()
    if not durations:
        return None
    return _class_model(durations, cycle.ends(cls), cycle.period_s is not None and cls in cycle.cycle_classes)


def ends_after(start: np.ndarray, model: tuple[np.ndarray, np.ndarray | None], cycle) -> np.ndarray:
    """Samples of the end of a phase of a class (``model``: its :func:`class_model` in ``cycle``) that starts at one of
    ``start`` (sorted samples: their :data:`N_PAIRED` quantiles are paired with its durations)."""
    d, cycle_ends = model
    paired = start if len(start) <= N_PAIRED else start[_spread_indices(len(start), N_PAIRED)]
    raw = (paired[:, None] + d[None, :]).ravel()
    if cycle_ends is not None:
        finite = np.isfinite(raw)
        if finite.all():
            raw = _spread_on_cycle(_on_cycle(raw, cycle_ends, cycle.period_s), cycle_ends, cycle.period_s, cycle.period_error_s)
        elif finite.any():
            moved = _spread_on_cycle(_on_cycle(raw[finite], cycle_ends, cycle.period_s), cycle_ends, cycle.period_s, cycle.period_error_s)
            raw = np.concatenate([moved, raw[~finite]])
    return _reduced(raw)


def next_end(cycle, cls: PhaseClass, start: np.ndarray) -> np.ndarray | None:
    """Samples of the end of a phase of class ``cls`` that starts at one of ``start`` (sorted samples), or None when
    no duration of the class is known (:func:`ends_after`)."""
    model = class_model(cycle, cls)
    return None if model is None else ends_after(start, model, cycle)


def forecast(plan: UncertainPlan, t_unix_s: float, cycle, horizon_s: float = 180.0) -> list[ChangeForecast]:
    """The coming changes of a signal group at ``t_unix_s``: the end of the published phase, then the phases the
    history says follow, while they begin within ``horizon_s`` (module docstring). Empty when the published phase's
    end is bounded by nothing.

    ``plan``: the group's latest reading as a plan (:func:`spat_feed.timing.messages.plan_from_movement`: the
    published state and its window); ``cycle``: the group's :class:`~spat_feed.prediction.history.CycleStats` or None.
    """
    i = sum(1 for c in plan.changes if c.max_end_s <= t_unix_s)  # the published phase (changes that surely came)
    if i >= len(plan.changes):
        return []
    state_cls = phase_class(plan.states[i])
    change = plan.changes[i]
    floor = max(t_unix_s, change.min_end_s)
    since = cycle.since_unix_s if cycle is not None and cycle.current is state_cls else None
    got = current_end(cycle, state_cls, since, t_unix_s, change.min_end_s, change.max_end_s, current=True)
    if got is None:
        return []
    samples, method = got
    then = phase_class(plan.states[i + 1]) if i + 1 < len(plan.states) else None
    if then is PhaseClass.UNKNOWN and cycle is not None:
        then = cycle.following.get(state_cls, then)
    out = [ChangeForecast(state_cls, then, floor, _reduced(samples), method)]
    earliest = floor
    while cycle is not None and then is not None and then in cycle.following and out[-1].samples_unix_s[0] < t_unix_s + horizon_s:
        durations = cycle.durations(then)
        ends = next_end(cycle, then, out[-1].samples_unix_s)
        if ends is None:
            break
        earliest += min(durations)
        nxt = cycle.following.get(then)
        out.append(ChangeForecast(then, nxt, earliest, np.maximum(ends, earliest), "chain"))
        then = nxt
        if len(out) > 8:
            break
    return out
