"""The lights' timings as the choice under uncertainty prices them (:func:`mixture_timings`): each uncertain light's
forecast (its equally likely timings, stated or read off its windows: :func:`implied_timings`) and a wide component
(:func:`wide_component`) weighted by the chance of a change outside the window the light states, the lights' timings
paired at no rank correlation. Packed for :func:`advisory.advice.choice.expected_costs` (docs/ADVISOR.md, "The choice
on the distribution").
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np
from numba import njit

from advisory.advice.views import LightView, Timings, packed_windows_s


IMPLIED_TIMINGS = 20
"""Timings read off a view that states none (:func:`implied_timings`). [-]"""


def implied_timings(light: LightView) -> tuple:
    """Equally likely timings of a light whose view gives its (earliest, likely, latest) windows but no timings: each
    change read as uniform on each side of its likely instant (half the chance either side), as the observation reads a
    published window without a forecast (``spat_feed.prediction.observe._pick``); the likely windows alone when the
    views do not pair up. An exact light: its windows, in every timing."""
    likely, sure = light.likely_red_windows_s, light.red_windows_s
    if likely is None:
        return (sure,) * IMPLIED_TIMINGS
    late = light.late_red_windows_s or tuple((a, b) for (a, _), (_, b) in zip(likely, sure))  # no latest start stated: the likely one
    if not len(likely) == len(sure) == len(late):
        return (likely,) * IMPLIED_TIMINGS
    out = []
    for k in range(IMPLIED_TIMINGS):
        q = (k + 0.5) / IMPLIED_TIMINGS
        side = (lambda lo, mid, hi: lo + (mid - lo) * q / 0.5) if q <= 0.5 else (lambda lo, mid, hi: mid + (hi - mid) * (q - 0.5) / 0.5 if math.isfinite(hi) else hi)
        out.append(tuple((side(s0, l0, t0), max(side(l1, l1, s1), side(s0, l0, t0))) for (s0, s1), (l0, l1), (t0, _) in zip(sure, likely, late)))
    return tuple(out)


WIDE_LEVELS = (1, 6, 13, 18)
"""The forecast's timings (of :data:`IMPLIED_TIMINGS`, by index: levels ~0.08, 0.33, 0.68, 0.93) that the wide
component of the mixture stretches (:func:`wide_component`). [-]"""
WIDE_STRETCH = 2.0
"""How much farther from the median timing the wide component puts each change: a copy of the forecast with twice its
spread. [-]"""


@lru_cache(maxsize=16)
def wide_levels(n: int) -> np.ndarray:
    """The indices of :data:`WIDE_LEVELS` among ``n`` timings (:func:`wide_component`)."""
    return np.array([round(level * (n - 1) / (IMPLIED_TIMINGS - 1)) for level in WIDE_LEVELS], dtype=np.int64)


WIDE_FLOOR_FRAC = 0.15
"""The wide component puts a change no nearer its median instant than this share of the time to it, at its outer
levels (less at its inner ones): a change 20 s ahead known to no better than 2-3 s. [-]"""


@njit(cache=True, inline="always")
def _spread(dev, t_med, q):
    """A change's deviation from its median instant ``t_med`` [s] in the wide component: ``dev`` (the forecast's,
    stretched), or at least ``WIDE_FLOOR_FRAC * t_med * q`` on the side of level ``q`` (-1 .. 1). [s]"""
    floor = WIDE_FLOOR_FRAC * max(t_med, 0.0) * q
    return floor if abs(floor) > abs(dev) else dev


@njit(cache=True, error_model="numpy")
def wide_component(timings, levels, stretch):
    """The wide component of one light's mixture: a copy of the forecast's equally likely timings (packed: ``timings``
    (n, k, 2), each timing's windows in order, padded with +inf) with ``stretch`` (:data:`WIDE_STRETCH`) times its
    spread about its median timing, at the ``levels`` (:func:`wide_levels`, one timing each), so that the outer timings
    are not the forecast's extremes (a forecast from a few dozen past phases is its sample: a change outside every
    timing came 7-10 s past the outer ones on the recorded controllers). Its weight is the chance of a change outside
    the window the light states (:func:`mixture_timings`). Windows pair up by their order (the k-th red of each timing; one
    past the median's horizon stays as it is). A red on now never ends earlier than in every timing (the published red
    is held: the safety rule); no change comes before now; a level whose stretched reds run into each other is that
    level's own timing. Returns (len(levels), k, 2), padded with +inf (``tests/test_choice.py`` holds the plain
    reading of these steps, on tuples). [s]"""
    n, k = timings.shape[0], timings.shape[1]
    out = np.full((levels.size, k, 2), np.inf)
    med = n // 2
    c_med = 0
    while c_med < k and np.isfinite(timings[med, c_med, 0]):  # (a window's start is finite; a pad's is inf)
        c_med += 1
    for li in range(levels.size):
        i = levels[li]
        c = 0
        while c < k and np.isfinite(timings[i, c, 0]):
            c += 1
        into_each_other = False
        for w in range(c):
            a, b = timings[i, w, 0], timings[i, w, 1]
            am, bm = (timings[med, w, 0], timings[med, w, 1]) if w < c_med else (a, b)
            q = 2.0 * (i + 0.5) / n - 1.0  # the level's side and distance from the median, -1 .. 1
            b2 = bm + _spread(stretch * (b - bm), bm, q) if np.isfinite(b) and np.isfinite(bm) else b
            if a <= 0.0:  # red on now: its end no earlier than every timing says
                e = np.inf
                for r in range(n):
                    if timings[r, w, 1] < e:
                        e = timings[r, w, 1]
                a2, b2 = a, (e if e > b2 else b2)
            else:
                a2 = am + _spread(stretch * (a - am), am, q) if np.isfinite(a) and np.isfinite(am) else a
                if np.isfinite(a) and np.isfinite(am) and 0.0 > a2:
                    a2 = 0.0
                if a2 > b2:
                    b2 = a2
            out[li, w, 0], out[li, w, 1] = a2, b2
            if w > 0 and a2 < out[li, w - 1, 1]:
                into_each_other = True
        if into_each_other:
            out[li, :c] = timings[i, :c]
    return out


def _resampled(timings: tuple, n: int) -> tuple:
    """``n`` of the equally likely ``timings``, evenly by level (the same ones where there are ``n``)."""
    return timings if len(timings) == n else tuple(timings[k * len(timings) // n] for k in range(n))


GOLDEN_FRAC = (math.sqrt(5.0) - 1.0) / 2.0
"""The golden ratio's fraction: the most evenly spread sequence ``k * GOLDEN_FRAC mod 1`` (Weyl), by which
:func:`_paired` orders a light's timings. [-]"""


@lru_cache(maxsize=16)
def _paired(n: int, j: int) -> np.ndarray:
    """The order in which light ``j``'s ``n`` equally likely timings (sorted by level) meet the first light's k-th:
    the first light's own order, and for the next lights a fixed permutation at no rank correlation with it, so each
    light's timings are all there, each once, as in a Latin hypercube pairing (M. D. McKay, R. J. Beckman and W. J.
    Conover, Technometrics 21, 1979, doi:10.2307/1268522), with no chance drawn (the advice is the same on the same
    readings).

    Examples
    --------
    >>> _paired(5, 0).tolist(), sorted(_paired(5, 1).tolist())
    ([0, 1, 2, 3, 4], [0, 1, 2, 3, 4])
    """
    order = np.arange(n) if j == 0 else np.argsort(((np.arange(n) + 0.5) * GOLDEN_FRAC * j) % 1.0, kind="stable")
    order.setflags(write=False)  # (cached: shared by every call)
    return order


def mixture_timings(lights: tuple[LightView, ...]) -> tuple[np.ndarray, np.ndarray]:
    """The lights' timings packed for :func:`advisory.advice.choice.expected_costs`: red windows (lines, timings, k, 2),
    padded with +inf, and each timing's weight (timings,), summing to 1. An exact light has one timing in all of them;
    where every light is exact, there is that one timing, of weight 1.

    The mixture of each uncertain light: its forecast (equally likely timings, ``LightView.scenario_red_windows_s`` or
    read off its windows, :func:`implied_timings`), and the wide component (:func:`wide_component`) weighted by the
    chance that a change comes outside the window the light states: ``1 - confidence_frac`` (J2735: the probability
    that the change comes within it; the lowest of the lights planned for). Within a light the timings are comonotone
    (every change at one level of its forecast: a red that comes late ends late); across lights they are paired at no
    rank correlation (:func:`_paired`): two lights' changes are not one forecast's (the k-th of each, comonotone, made a
    green that comes early at the first light always come with a red that comes early at the second: docs/ADVISOR.md).
    The wide components pair up as they are."""
    uncertain = [light.likely_red_windows_s is not None or light.scenario_red_windows_s is not None for light in lights]
    forecast = [light.scenario_red_windows_s or implied_timings(light) if u else implied_timings(light) for light, u in zip(lights, uncertain)]
    n_fc = max(len(timings) for timings in forecast) if any(uncertain) else 1  # (every light exact: one timing, weight 1)
    forecast = [_resampled(timings, n_fc) for timings in forecast]
    packed = tuple(np.require(fc.array_s, float, "CW") if u and isinstance(fc, Timings)  # (one type for the kernel: contiguous, writable)
                   else packed_windows_s(fc if u else fc[:1], _most_windows(fc if u else fc[:1])) for fc, u in zip(forecast, uncertain))  # fmt: skip
    if any(uncertain):  # each light's parts: its forecast as paired, then its wide component
        stated = min(light.confidence_frac for light, u in zip(lights, uncertain) if u)
        outside = min(max(1.0 - stated, 1.0 / n_fc), 1.0)
        weights = np.empty(n_fc + len(WIDE_LEVELS))
        weights[:n_fc], weights[n_fc:] = (1.0 - outside) / n_fc, outside / len(WIDE_LEVELS)
    else:
        weights = np.full(n_fc, 1.0 / n_fc)
    return _stacked(packed, np.array(uncertain), _orders(n_fc, len(lights)), wide_levels(n_fc), WIDE_STRETCH, weights.size), weights


@lru_cache(maxsize=16)
def _orders(n: int, n_lines: int) -> np.ndarray:
    """:func:`_paired`'s order of ``n`` timings for each of ``n_lines`` lights. (n_lines, n)"""
    orders = np.stack([_paired(n, j) for j in range(n_lines)])
    orders.setflags(write=False)
    return orders


@njit(cache=True)
def _stacked(packed, uncertain, orders, levels, stretch, n_rows):
    """:func:`mixture_timings`'s array from each light's packed timings (``packed[j]``: (timings, k_j, 2); an exact
    light's one timing): an uncertain light's forecast in the order ``orders[j]`` gives, then its wide component
    (:func:`wide_component`); an exact light's timing in every row. (lines, ``n_rows``, k, 2), padded with +inf. [s]"""
    k = 1
    for j in range(len(packed)):
        k = max(k, packed[j].shape[1])
    out = np.full((len(packed), n_rows, k, 2), np.inf)
    for j in range(len(packed)):
        block = packed[j]
        kj = block.shape[1]
        if uncertain[j]:
            n = orders.shape[1]
            for r in range(n):
                out[j, r, :kj] = block[orders[j, r]]
            wide = wide_component(block, levels, stretch)
            for r in range(wide.shape[0]):
                out[j, n + r, :kj] = wide[r]
        else:
            for r in range(n_rows):
                out[j, r, :kj] = block[0]
    return out


def _most_windows(timings) -> int:
    """The most windows of one of the timings (tuples, or packed: ``(timings, k, 2)``)."""
    return timings.shape[1] if isinstance(timings, np.ndarray) else max((len(w) for w in timings), default=0)


@lru_cache(maxsize=16)
def _members(n: int, k: int) -> np.ndarray:
    """Which of ``n`` equally likely timings (sorted by level) stand for ``k`` equal strata of the levels: in stratum
    ``i``, the timing nearest its middle level ``(i + 0.5) / k`` (of two as near, the one nearer the median), so that
    the members are symmetric about the median as the timings are.

    Examples
    --------
    >>> _members(20, 8).tolist(), _members(20, 10).tolist()
    ([1, 3, 6, 8, 11, 13, 16, 18], [1, 3, 5, 7, 9, 10, 12, 14, 16, 18])
    """
    pos = (np.arange(k) + 0.5) * n / k - 0.5  # the middle level's place among the timings' indices
    idx = np.where(np.arange(k) < k / 2, np.floor(pos + 0.5), np.ceil(pos - 0.5)).astype(np.int64)
    idx.setflags(write=False)
    return idx


@lru_cache(maxsize=16)
def _member_rows(n: int, k: int, n_lines: int) -> np.ndarray:
    """The rows of :func:`mixture_timings`'s array (``n`` timings of the forecast, then the wide component's) that
    make the mixture of ``k`` members (:func:`fewer_members`), per line (n_lines, k + len(WIDE_LEVELS)): light ``j``'s
    members (:func:`_members`) in the order :func:`_paired` gives ``k`` timings, found where ``n`` timings put them."""
    rows = np.empty((n_lines, k + len(WIDE_LEVELS)), dtype=np.int64)
    for j in range(n_lines):
        where = np.argsort(_paired(n, j))  # the row of each level
        rows[j, :k] = where[_members(n, k)[_paired(k, j)]]
        rows[j, k:] = n + np.arange(len(WIDE_LEVELS))
    rows.setflags(write=False)
    return rows


def fewer_members(windows: np.ndarray, weights: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """The mixture of :func:`mixture_timings` (``windows``, ``weights``; some light uncertain) with each light's forecast
    stood for by ``k`` of its timings, one per equal stratum of its levels (:func:`_members`: a stratified sample,
    M. D. McKay, R. J. Beckman and W. J. Conover, Technometrics 21, 1979), paired across lights as ``k`` timings are
    (:func:`_paired`), the forecast's weight shared by them; the wide component as it is. Every member is one of the
    forecast's timings, its red windows as they are: fewer timings, none changed. The whole mixture where ``k`` is
    not fewer."""
    rows = member_rows(windows.shape[1] - len(WIDE_LEVELS), k, windows.shape[0])
    if rows.shape[1] == 0:
        return windows, weights
    return rows_of(windows, weights, rows, windows.shape[1] - len(WIDE_LEVELS), k)


_NO_ROWS = np.empty((0, 0), dtype=np.int64)
_NO_ROWS.setflags(write=False)


def member_rows(n: int, k: int, n_lines: int) -> np.ndarray:
    """The rows of :func:`mixture_timings`'s array (``n`` timings of the forecast, then the wide component's) that
    :func:`fewer_members` takes for ``k`` members, per line (n_lines, k + len(WIDE_LEVELS)); none (n_lines, 0) where
    ``k`` is not fewer than ``n``."""
    return _member_rows(n, k, n_lines) if k < n else _NO_ROWS.reshape(n_lines, 0)


@njit(cache=True)
def rows_of(windows, weights, rows, n, k):
    """:func:`fewer_members`'s mixture: line ``j``'s timings ``rows[j]`` of ``windows``, the first ``k`` sharing the
    weight of the ``n`` forecast timings, the rest (the wide component) weighted as they are."""
    out = np.empty((windows.shape[0], rows.shape[1], windows.shape[2], 2))
    for j in range(windows.shape[0]):
        for q in range(rows.shape[1]):
            out[j, q] = windows[j, rows[j, q]]
    w = np.empty(rows.shape[1])
    w[:k] = weights[:n].sum() / k
    w[k:] = weights[n:]
    return out, w
