"""Screening the candidate plans of the choice under uncertainty (:func:`screened`): every plan priced on a few of
the lights' timings, the few best of them on all (docs/ADVISOR.md, "The choice on the distribution", the ``advise()``
row of the measured table).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from advisory.advice.choice import prepared, priced
from advisory.advice.mixture import WIDE_LEVELS, member_rows, rows_of

SCREEN_MEMBERS = 8
"""Timings of each light's forecast (of its 20) that the screening prices the plans on (:func:`screened`). At 4 the
sample misses a short red's earliest ends (a queue's red ending in 2.3-5 s read as ending late: tests/test_queue.py's
car held at 27 mph, not slowed to 10). [-]"""
SCREEN_STRIDE = 2
"""The screening prices every this-many-th advised speed of each mode (1 mph apart: the candidates' costs are jagged
at that scale, each timing's red a step); a plan it keeps is priced in full with the speeds next to it. At 3 (and 4
plans kept) US 1136 kept 59.8 % of hindsight, under the 60 % it must keep. [-]"""
SCREEN_KEEP = 5
"""Plans the screening keeps, the cheapest of those allowed on its timings (:func:`screened`). [-]"""


def screened(args: tuple, m: int, n_modes: int) -> tuple:
    """The candidates' expected costs, chances of a stop and hard-constraint flags as
    :func:`advisory.advice.choice.expected_costs` gives them on ``args`` (its arguments: the lights' mixture, ``skip``
    not priced, ``must``, ``anchor`` driving normally, plans past the chance constraint ``risk_frac`` above it not priced
    further), for the plans that can be chosen; the rest come back not priced (cost inf, through a red).

    The grid (``n_modes`` modes of ``m`` advised speeds each, first in the candidates; the plans after it, driving
    normally, stop and the plan followed, are always priced in full) is screened: every :data:`SCREEN_STRIDE`-th
    speed of each mode (and each speed next to one in ``skip``: a narrow run between two reds is not stepped over) is
    priced on :data:`SCREEN_MEMBERS` of each light's timings (:func:`advisory.advice.mixture.fewer_members`, a
    stratified sample), its chance constraint loosened by one member's weight (the sample's resolution); the
    :data:`SCREEN_KEEP` cheapest allowed there, with the speeds between them and the next screened ones, are then
    priced on the whole mixture. The choice is made on those prices: a plan is chosen only where allowed and clear of
    the hard constraint on the whole mixture, exactly as unscreened; what the screening can miss is a cheaper plan it
    ranked out: on the 10,200 recorded observations of ``bench/bench_predictor.py`` the advice changed in 4.9 %, the
    plan chosen costlier on the whole mixture by 0.09 % on average (docs/ADVISOR.md, "The choice on the distribution",
    *Screening*). Both passes and what lies between them run in one compiled call (:func:`_screened`)."""
    windows = args[7]
    return _screened(*args, member_rows(windows.shape[1] - len(WIDE_LEVELS), SCREEN_MEMBERS, windows.shape[0]), m, n_modes)


@njit(cache=True)
def _screened(vts, modes, reactions, accel_rows, accels, v0, d_m, windows, n_windows, x_end_m, v_lim, after_red_s, lam_usd_per_s, cross_s, rates, coast,
              idle_usd_per_s, comfort, firm, normal, reaction_s, min_speed_mps, clear_s, weights, stop_plan, amber_max_s, edge_s, skip, must, anchor,
              risk_frac, rows, m, n_modes):  # fmt: skip
    """:func:`screened`: :func:`advisory.advice.choice.expected_costs`'s arguments, then the screen's members of the
    mixture (``rows``: :func:`advisory.advice.mixture.member_rows`, none where the forecast has no more timings)."""
    few, few_weights = windows, weights
    if rows.shape[1] > 0:
        few, few_weights = rows_of(windows, weights, rows, windows.shape[1] - len(WIDE_LEVELS), rows.shape[1] - len(WIDE_LEVELS))
    slack = few_weights[0]  # one member's more of a stop than the choice allows
    up, down, order, paths = prepared(vts, modes, v0, anchor, rates, comfort, normal)  # (the same for both passes)
    cost, p_stop, through = priced(vts, modes, reactions, accel_rows, accels, v0, d_m, few, n_windows, x_end_m, v_lim, after_red_s, lam_usd_per_s, cross_s,
                                   rates, coast, idle_usd_per_s, comfort, firm, normal, reaction_s, min_speed_mps, clear_s, few_weights, stop_plan, amber_max_s,
                                   edge_s, _coarse_skip(skip, m, n_modes, SCREEN_STRIDE, anchor), must, anchor, risk_frac + slack, up, down, order, paths)  # fmt: skip
    kept = _kept_skip(skip, cost, p_stop, through, p_stop[anchor] + risk_frac + slack + 1e-9, m, n_modes, SCREEN_STRIDE, SCREEN_KEEP)
    return priced(vts, modes, reactions, accel_rows, accels, v0, d_m, windows, n_windows, x_end_m, v_lim, after_red_s, lam_usd_per_s, cross_s, rates, coast,
                  idle_usd_per_s, comfort, firm, normal, reaction_s, min_speed_mps, clear_s, weights, stop_plan, amber_max_s, edge_s, kept, must, anchor, risk_frac,
                  up, down, order, paths)  # fmt: skip


@njit(cache=True)
def _coarse_skip(skip, m, n_modes, stride, anchor):
    """The screening's ``skip`` (:func:`screened`): ``skip``, and in each mode's ``m`` speeds every speed but each
    ``stride``-th, the fastest, and those next to a skipped one; after the grid, every plan but ``anchor`` (its chance of
    a stop sets the screen's chance constraint; the others are priced on the whole mixture whatever the screen finds)."""
    out = skip.copy()
    for c in range(n_modes * m):
        i = c % m
        if i % stride != 0 and i != m - 1 and not skip[c - 1] and not skip[c + 1]:
            out[c] = True
    for c in range(n_modes * m, skip.size):
        out[c] = out[c] or c != anchor
    return out


@njit(cache=True)
def _kept_skip(skip, cost, p_stop, through, cap, m, n_modes, stride, keep):
    """The whole mixture's ``skip`` (:func:`screened`): the ``keep`` cheapest plans of the grid (``cost``) of a chance of
    a stop (``p_stop``) up to ``cap`` and not ``through`` a red, each with the speeds of its mode less than ``stride``
    away, and the plans after the grid, as in ``skip``; the rest skipped."""
    grid = n_modes * m
    ranked = np.full(grid, np.inf)
    for c in range(grid):
        if p_stop[c] <= cap and not through[c]:
            ranked[c] = cost[c]
    out = np.ones(skip.size, dtype=np.bool_)
    out[grid:] = skip[grid:]
    taken = np.zeros(grid, dtype=np.bool_)
    for _ in range(min(keep, grid)):
        c = -1  # the cheapest finite one not taken yet (ties: the first, as np.argmin; a sort of the grid cost 5 us)
        for d in range(grid):
            if not taken[d] and np.isfinite(ranked[d]) and (c < 0 or ranked[d] < ranked[c]):
                c = d
        if c < 0:
            break
        taken[c] = True
        row, i = c - c % m, c % m
        for q in range(max(i - stride + 1, 0), min(i + stride, m)):
            out[row + q] = skip[row + q]
    return out
