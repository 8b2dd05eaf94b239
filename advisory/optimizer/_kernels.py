"""numba kernels of the DP: arrays in, arrays out, no defaults (STYLE.md section 5)."""

from __future__ import annotations

import numpy as np
from numba import njit

from advisory.physics.model import I_AUX, arc_cost_usd, step_cost_usd

RED_TOL_S = 1e-9
"""A crossing this close after a red ends counts as green (25 nm at 88.5 km/h), never earlier."""

LATE_TOL_S = 1e-9
"""Rounding allowance on the trip-time limit: a path at the limit all the way sums many stage times."""


@njit(cache=True)
def is_red(t_s, red_start_s, red_s, cycle_s):
    """Red at ``t_s`` for a fixed-time light whose red phases are [red_start + k cycle, + red_s)."""
    phase = (t_s - red_start_s) % cycle_s
    return phase < red_s - RED_TOL_S


@njit(cache=True)
def red_left_s(t_s, red_start_s, red_s, cycle_s):
    """Seconds until the red phase containing ``t_s`` ends (0 when ``t_s`` is green)."""
    phase = (t_s - red_start_s) % cycle_s
    return red_s - phase if phase < red_s - RED_TOL_S else 0.0


@njit(cache=True, inline="always")
def _open(cost_usd, occ_lo, occ_hi, k, i, b):
    """Make cell (k, i, b) usable: a (stage, speed) row is initialised (to inf) only over the bins in use,
    ``[occ_lo, occ_hi]``, so the rest of the tables is never written (nor paged in)."""
    lo, hi = occ_lo[k, i], occ_hi[k, i]
    if hi < 0:
        cost_usd[k, i, b] = np.inf
        occ_lo[k, i] = b
        occ_hi[k, i] = b
    elif b < lo:
        cost_usd[k, i, b:lo] = np.inf
        occ_lo[k, i] = b
    elif b > hi:
        cost_usd[k, i, hi + 1 : b + 1] = np.inf
        occ_hi[k, i] = b


@njit(cache=True, inline="always")
def _relax(cost_usd, time_s, parent, occ_lo, occ_hi, k, i, b, c, t, code):
    """Keep label (cost c, exact time t, parent code) in cell (k, i, b) if it is cheaper."""
    _open(cost_usd, occ_lo, occ_hi, k, i, b)
    if c < cost_usd[k, i, b]:
        cost_usd[k, i, b] = c
        time_s[k, i, b] = t
        parent[k, i, b] = code


@njit(cache=True)
def step_tables(speed_mps, band_lo, band_hi, stage_m, grade_frac, step_substeps, p, m_c_rates, m_prefactor, step_dt, step_usd):
    """Duration and cost of every move of one stage (grade ``grade_frac``): from node i to node ``band_lo[i] + j``.

    Fills ``step_dt``/``step_usd`` (n_v, widest band); a move between two standstills gets an infinite duration.
    """
    for i in range(speed_mps.shape[0]):
        for j in range(band_hi[i] - band_lo[i] + 1):
            v, v2 = speed_mps[i], speed_mps[band_lo[i] + j]
            if v + v2 <= 0.0:
                step_dt[i, j] = np.inf
                step_usd[i, j] = np.inf
                continue
            dt = 2.0 * stage_m / (v + v2)
            step_dt[i, j] = dt
            step_usd[i, j] = arc_cost_usd(v, v2, dt, grade_frac, step_substeps, p, m_c_rates, m_prefactor)


@njit(cache=True, inline="always")
def _priced(usd, dt_s, lam):
    """Cost of a move plus ``lam`` per second of it (inf stays inf, also with ``lam`` = 0)."""
    return usd + lam * dt_s if usd < np.inf else np.inf


@njit(cache=True)
def cost_to_go_bounds(
    band_lo, band_hi, stage_grade, step_dt_s, step_usd, terminal_cost_usd, terminal_time_s, is_stop, light_stage, arc_k_lo,
    stop_dt_s, stop_usd, launch_dt_s, launch_usd, rest_dt_s, rest_usd, lam_usd_per_s,
):
    """
    Bounds on the cost still to pay, for the pruning of ``forward_pass``: ``(w (n_lam, K + 1, n_v), halt_w (n_lam, n_l))``.

    ``w[n, k, i]`` is the cheapest completion from stage k at speed i to the end state of cost + ``lam[n]`` x its
    duration (terminal cost and time included), over every move ``forward_pass`` allows (stage moves, stop arcs,
    launches, timed launches) with red lights and the trip-time limit ignored and waits left out (they cost and
    last >= 0); ``halt_w[n, l]`` the same from the halt before light l. A completion of duration D costs at least
    ``w - lam D`` (Lagrangian relaxation of the time limit), so a label at time t, which has at most
    ``t_max - t`` left, still has to pay at least ``max_n (w[n] - lam[n] (t_max - t))``; with ``lam = 0`` this is
    the time-free bound. A backward DP on the same moves: consistent along every move.
    """
    n_lam = lam_usd_per_s.shape[0]
    n_stage = stage_grade.shape[0]
    n_v = band_lo.shape[0]
    n_light = light_stage.shape[0]
    n_launch = launch_usd.shape[0]
    lb = np.full((n_lam, n_stage + 1, n_v), np.inf)
    halt_lb = np.full((n_lam, n_light), np.inf)
    light_of = np.full(n_stage + 1, -1, dtype=np.int64)
    for l in range(n_light):
        light_of[light_stage[l]] = l
    for n in range(n_lam):
        lam = lam_usd_per_s[n]
        w, halt_w = lb[n], halt_lb[n]
        for i in range(n_v):
            w[n_stage, i] = _priced(terminal_cost_usd[i], terminal_time_s[i], lam)
        for k in range(n_stage - 1, -1, -1):
            g = stage_grade[k]
            l = light_of[k + 1]
            if l >= 0:  # every stage past light l is done: the halt before it launches to any of them within reach
                kl = k + 1
                k_end = n_stage if l + 1 == n_light else light_stage[l + 1]
                for m in range(n_launch):
                    if kl + 1 + m > k_end:
                        break
                    for j in range(n_v):
                        halt_w[l] = min(halt_w[l], _priced(launch_usd[m, j], launch_dt_s[m, j], lam) + w[kl + 1 + m, j])
            for i in range(n_v):
                best = np.inf
                for j in range(band_hi[i] - band_lo[i] + 1):
                    best = min(best, _priced(step_usd[g, i, j], step_dt_s[g, i, j], lam) + w[k + 1, band_lo[i] + j])
                w[k, i] = best
            for l in range(n_light):
                kl = light_stage[l]
                if not (arc_k_lo[l] <= k < kl):
                    continue
                for i in range(n_v):  # a stop arc to the halt
                    w[k, i] = min(w[k, i], _priced(stop_usd[kl - k - 1, i], stop_dt_s[kl - k - 1, i], lam) + halt_w[l])
                if not is_stop[k]:  # a timed launch from a standstill here
                    k_end = n_stage if l + 1 == n_light else light_stage[l + 1]
                    for k2 in range(kl + 1, min(k_end, k + rest_usd.shape[0]) + 1):
                        for j in range(1, n_v):
                            w[k, 0] = min(w[k, 0], _priced(rest_usd[k2 - k - 1, j], rest_dt_s[k2 - k - 1, j], lam) + w[k2, j])
    return lb, halt_lb


@njit(cache=True)
def light_bounds(speed_mps, band_lo, band_hi, step_dt_s, step_usd, stage_grade, is_stop, allow_dwell, lb_line_usd, halt_lb_usd,
                 stop_usd, k_line, n_back, tau_bin_s, n_tau):
    """
    A bound on the cost still to pay that sees one light: ``h (n_back + 1, n_v, n_tau)``, ``h[d, i, m]`` at d stages
    before the line (stage ``k_line - d``) at speed i, for paths that reach the line no sooner than
    ``m tau_bin_s`` from now (a label that cannot reach it before its red ends must take that long).

    Returned in single precision, lowered by 1e-6 of itself (more than a float32 rounding: still a lower bound).
    A backward DP over the moves of ``forward_pass`` up to the line: stage moves, whose durations count rounded
    up to whole ``tau_bin_s`` (so every path that takes that long is admitted: a lower bound), and a stop arc to
    the halt (``stop_usd`` row d - 1, then at least ``halt_lb_usd``: the halt can wait any time). At the line
    (d = 0) no time is left to spend before it: the time-free bound ``lb_line_usd`` (K + 1, n_v) of
    ``cost_to_go_bounds`` there, and no path for m > 0. A car at standstill off a stop line can wait, so its
    row is its time-free bound, whatever m (that bound also covers its timed launches).
    """
    n_v = speed_mps.shape[0]
    h = np.full((n_back + 1, n_v, n_tau), np.inf)
    for j in range(n_v):
        h[0, j, 0] = lb_line_usd[k_line, j]
    for d in range(1, n_back + 1):
        k = k_line - d
        g = stage_grade[k]
        hd, nxt = h[d], h[d - 1]
        for i in range(n_v):
            stop = stop_usd[d - 1, i] + halt_lb_usd
            for m in range(n_tau):
                hd[i, m] = stop
            for j in range(band_hi[i] - band_lo[i] + 1):
                dt = step_dt_s[g, i, j]
                if dt == np.inf:
                    continue
                c = step_usd[g, i, j]
                i2 = band_lo[i] + j
                r = int(np.ceil(dt / tau_bin_s + 1e-9))  # rounded up: a weaker requirement after the move
                row, nxt_row = hd[i], nxt[i2]
                v0 = c + nxt_row[0]
                for m in range(min(r + 1, n_tau)):  # the move alone takes long enough
                    row[m] = min(row[m], v0)
                for m in range(r + 1, n_tau):
                    row[m] = min(row[m], c + nxt_row[m - r])
        if allow_dwell and speed_mps[0] == 0.0 and not is_stop[k]:
            for m in range(n_tau):  # it can wait at no cost in the bound: no requirement on time
                hd[0, m] = min(hd[0, 0], lb_line_usd[k, 0])
    out = np.empty(h.shape, dtype=np.float32)  # stored in single precision, lowered by 1e-6 of itself: still below
    flat, flat_out = h.ravel(), out.ravel()
    for n in range(flat.shape[0]):
        v = flat[n]
        flat_out[n] = np.float32(v - 1e-6 * abs(v)) if v < np.inf else np.inf
    return out


@njit(cache=True, inline="always")
def _beyond(c, t, bound, k, i, lam_usd_per_s, t_max_s, limit_usd):
    """Whether a label (cost c, time t) at (k, i) cannot finish within ``limit_usd``, by the bounds
    ``bound[n, k, i] - lam[n] (t_max - t)`` of ``cost_to_go_bounds``."""
    for n in range(lam_usd_per_s.shape[0]):
        if c + bound[n, k, i] - lam_usd_per_s[n] * (t_max_s + LATE_TOL_S - t) > limit_usd:
            return True
    return False


@njit(cache=True)
def best_end(cost_usd, time_s, occ_lo, occ_hi, terminal_cost_usd, terminal_time_s, t_max_s):
    """The cheapest label of the last stage (tables (n_v, n_bins), valid over ``[occ_lo, occ_hi]`` per speed) plus
    its terminal cost, among those whose end state is reached by ``t_max_s``: ``(i * n_bins + b, total)``, or
    ``(0, inf)`` when there is none; ties go to the first in (speed, bin) order."""
    n_bins = cost_usd.shape[1]
    flat, best = 0, np.inf
    for i in range(cost_usd.shape[0]):
        for b in range(occ_lo[i], occ_hi[i] + 1):
            c = cost_usd[i, b]
            if c < np.inf and time_s[i, b] + terminal_time_s[i] <= t_max_s + LATE_TOL_S and c + terminal_cost_usd[i] < best:
                flat, best = i * n_bins + b, c + terminal_cost_usd[i]
    return flat, best


@njit(cache=True)
def count_labels(cost_usd, occ_lo, occ_hi):
    """Cells holding a label (the tables are valid only over each row's range in use)."""
    n = 0
    for k in range(cost_usd.shape[0]):
        for i in range(cost_usd.shape[1]):
            for b in range(occ_lo[k, i], occ_hi[k, i] + 1):
                if cost_usd[k, i, b] < np.inf:
                    n += 1
    return n


@njit(cache=True)
def forward_pass(
    speed_mps,
    band_lo,
    band_hi,
    stage_m,
    stage_grade,
    step_dt_s,
    step_usd,
    stop_red_start_s,
    stop_red_s,
    stop_cycle_s,
    is_stop,
    t_lo_s,
    bin_s,
    dwell_s,
    allow_dwell,
    t_max_s,
    t_rem_min_s,
    i_start,
    p,
    m_c_rates,
    m_prefactor,
    light_stage,
    arc_k_lo,
    stop_dt_s,
    stop_usd,
    launch_dt_s,
    launch_usd,
    launch_cross_s,
    rest_dt_s,
    rest_usd,
    cost_usd,
    time_s,
    parent,
    s_cost_usd,
    s_time_s,
    s_parent,
    lower_bound_usd,
    halt_bound_usd,
    lam_usd_per_s,
    upper_bound_usd,
    occ_lo,
    occ_hi,
    light_lb_usd,
    light_lb_len,
    line_t_min_s,
    tau_bin_s,
):
    """
    Forward DP over distance stages with labels carrying exact arrival times, plus exact stop arcs.

    Shapes: ``speed_mps`` (n_v,); ``band_lo/band_hi`` (n_v,) next-speed index range allowed by the
    acceleration limits; ``step_dt_s``/``step_usd`` (n_grades, n_v, widest band) the moves of a stage
    (``step_tables``), ``stage_grade`` (K,) which of them each stage uses; ``stop_*``/``is_stop``/``t_lo_s`` (K + 1,);
    ``t_rem_min_s`` (K + 1, n_v); outputs ``cost_usd``, ``time_s``, ``parent`` (K + 1, n_v, n_bins).

    Only the bins ``[occ_lo[k, i], occ_hi[k, i]]`` of a row are valid (the caller passes ``cost_usd``, ``time_s``,
    ``parent`` uninitialised, ``occ_lo`` = n_bins and ``occ_hi`` = -1; rows are initialised as they fill).
    Cell (k, i, b) holds the cheapest path found that reaches stage k at speed i at an exact time in
    ``[t_lo[k] + b bin_s, t_lo[k] + (b + 1) bin_s)``, with that exact time. ``parent`` >= 0 is the flat index
    of the previous cell (a stage transition, or a dwell at standstill in the same stage); -1 the start;
    ``-(2 + l n_bins + b)`` a launch from bin b of the halt before light l; ``-(2 + n_l n_bins + f)`` a timed
    launch from the standstill cell of flat index f (see below).

    **Stop arcs** (light l at stage ``light_stage[l]``, standstill ``stop_gap`` short of its line): from every
    label at a stage ``arc_k_lo[l] <= k < light_stage[l]``, brake at constant deceleration to a halt at the
    standstill (``stop_dt_s``/``stop_usd`` (K_arc, n_v), row n: from n + 1 stages before the line); wait there
    (``s_*`` tables (n_l, n_bins), waits in ``dwell_s`` steps); launch at constant acceleration to node j at
    stage ``light_stage + 1 + m`` (``launch_*`` (M, n_v), ``launch_cross_s`` the time from rest to the line). The launch leaves at the
    exact instant that crosses the line as the red ends (or at once when it is green), so stopping, waiting
    and launching are exact whatever the grid. **Timed launches**: from a standstill at any stage before a
    light (after the previous one), reached by a move (not by a wait there), the same exact launch across the
    line to node j at stage k2
    (``rest_dt_s``/``rest_usd`` (N, n_v): from rest over k2 - k stages), so a car that halts early crosses the
    line with speed exactly as it turns green. Red checks and the time limit use exact times throughout.

    **Pruning**: a label at time t whose cost plus ``max_n lower_bound_usd[n, k, i] - lam[n] (t_max - t)``
    (``halt_bound_usd[n, l]`` at a halt; see ``cost_to_go_bounds``) exceeds ``upper_bound_usd`` (finite) cannot
    finish within it and is dropped. No path within the limit is lost; as labels are binned, a bin may then
    keep another of its labels than it would without pruning (one whose bound, at an earlier time, is lower).
    Over the ``light_lb_len[l]`` stages before light l, a label of a stage move is also dropped when its cost plus
    ``light_lb_usd[l, d, i, m]`` (``light_bounds``, d stages before the line, m bins of ``tau_bin_s``) exceeds
    the limit, m being the least time it must still take to the line: ``line_t_min_s[k, i]`` (the fastest
    drive there), or longer, until the red ends, when that drive would arrive in the red. Only with a limit.
    """
    n_stage = stage_grade.shape[0]
    n_v = speed_mps.shape[0]
    n_bins = cost_usd.shape[2]
    n_light = light_stage.shape[0]
    n_launch = launch_dt_s.shape[0]
    inv_bin = 1.0 / bin_s
    n_lam = lam_usd_per_s.shape[0]
    halt_b = halt_bound_usd.reshape((n_lam, n_light, 1))  # indexed like lower_bound_usd
    _relax(cost_usd, time_s, parent, occ_lo, occ_hi, 0, i_start, 0, 0.0, 0.0, -1)
    # standstill: only accessories draw power (linear in time)
    idle_cost = step_cost_usd(p[I_AUX], dwell_s, p, m_c_rates, m_prefactor)
    idle_per_s = step_cost_usd(p[I_AUX], 1.0, p, m_c_rates, m_prefactor)
    light_of = np.full(n_stage + 1, -1, dtype=np.int64)
    light_ahead = np.full(n_stage + 1, -1, dtype=np.int64)  # the light whose bound ``light_lb_usd`` covers a stage
    for l in range(n_light):
        light_of[light_stage[l]] = l
        for k in range(max(arc_k_lo[l], light_stage[l] - light_lb_len[l]), light_stage[l]):
            light_ahead[k] = l
    n_tau = light_lb_usd.shape[3]
    inv_tau = 1.0 / tau_bin_s
    light_h = np.zeros(n_tau, dtype=np.float32)  # the bound row of the move at hand (when its target is before a light)
    h_top, t_line, l_start, l_red, l_cycle = np.inf, 0.0, 0.0, 1.0, 2.0
    for k in range(n_stage):
        step_dt, step_cost = step_dt_s[stage_grade[k]], step_usd[stage_grade[k]]
        # a light at this stage: its standstill is complete; wait there, then launch past the line
        l = light_of[k]
        if l >= 0:
            red_start, red_len, cycle = stop_red_start_s[k], stop_red_s[k], stop_cycle_s[k]
            for b in range(n_bins):  # waits, bins ascending so that they chain
                c0 = s_cost_usd[l, b]
                if c0 == np.inf:
                    continue
                t2 = s_time_s[l, b] + dwell_s
                b2 = int((t2 - t_lo_s[k]) * inv_bin)
                if _beyond(c0 + idle_cost, t2, halt_b, l, 0, lam_usd_per_s, t_max_s, upper_bound_usd):
                    continue
                if b2 < n_bins and t2 + t_rem_min_s[k, 0] <= t_max_s + LATE_TOL_S and c0 + idle_cost < s_cost_usd[l, b2]:
                    s_cost_usd[l, b2] = c0 + idle_cost
                    s_time_s[l, b2] = t2
                    s_parent[l, b2] = -(2 + l * n_bins + b)
            for b in range(n_bins):
                c0 = s_cost_usd[l, b]
                if c0 == np.inf:
                    continue
                t0 = s_time_s[l, b]
                code = -(2 + l * n_bins + b)
                k_end = n_stage if l + 1 == n_light else light_stage[l + 1]  # a launch never crosses the next light
                for m in range(n_launch):
                    k2 = k + 1 + m
                    if k2 > k_end:
                        break
                    for j in range(n_v):
                        dt = launch_dt_s[m, j]
                        if dt == np.inf:
                            continue
                        cross = launch_cross_s[m, j]
                        wait = red_left_s(t0 + cross, red_start, red_len, cycle)
                        t2 = t0 + wait + dt
                        if t2 > t_max_s + LATE_TOL_S - t_rem_min_s[k2, j]:
                            continue
                        if is_stop[k2] and is_red(t2, stop_red_start_s[k2], stop_red_s[k2], stop_cycle_s[k2]):
                            continue
                        c2 = c0 + wait * idle_per_s + launch_usd[m, j]
                        if _beyond(c2, t2, lower_bound_usd, k2, j, lam_usd_per_s, t_max_s, upper_bound_usd):
                            continue
                        b2 = int((t2 - t_lo_s[k2]) * inv_bin)
                        if b2 < n_bins:
                            _relax(cost_usd, time_s, parent, occ_lo, occ_hi, k2, j, b2, c2, t2, code)
        # dwell at standstill (never on a stop line), bins in ascending order so waits chain
        if allow_dwell and speed_mps[0] == 0.0 and not is_stop[k] and occ_hi[k, 0] >= 0:
            b = occ_lo[k, 0]
            while b < n_bins and b <= occ_hi[k, 0]:
                c0 = cost_usd[k, 0, b]
                if c0 < np.inf:
                    t2 = time_s[k, 0, b] + dwell_s
                    if t2 + t_rem_min_s[k, 0] <= t_max_s + LATE_TOL_S and not _beyond(
                        c0 + idle_cost, t2, lower_bound_usd, k, 0, lam_usd_per_s, t_max_s, upper_bound_usd
                    ):
                        b2 = int((t2 - t_lo_s[k]) * inv_bin)
                        if b2 < n_bins:
                            _relax(cost_usd, time_s, parent, occ_lo, occ_hi, k, 0, b2, c0 + idle_cost, t2, (k * n_v) * n_bins + b)
                b += 1
        # timed launches from a standstill at this stage across the next light: leave at the exact instant
        # that crosses the line as its red ends, accelerate at a constant rate to node j at stage k2
        if not is_stop[k] and occ_hi[k, 0] >= 0:
            for l in range(n_light):
                kl = light_stage[l]
                if not (arc_k_lo[l] <= k < kl):
                    continue
                k_end = n_stage if l + 1 == n_light else light_stage[l + 1]
                k_end = min(k_end, k + rest_dt_s.shape[0])
                ra, rl, cy = stop_red_start_s[kl], stop_red_s[kl], stop_cycle_s[kl]
                x_cross = (kl - k) * stage_m
                for b in range(occ_lo[k, 0], occ_hi[k, 0] + 1):
                    c0 = cost_usd[k, 0, b]
                    if c0 == np.inf or parent[k, 0, b] // (n_v * n_bins) == k:
                        continue  # empty, or reached by a wait here: the launch times its own wait
                    t0 = time_s[k, 0, b]
                    code = -(2 + n_light * n_bins + (k * n_v) * n_bins + b)
                    for k2 in range(kl + 1, k_end + 1):
                        dist = (k2 - k) * stage_m
                        for j in range(1, n_v):
                            dt = rest_dt_s[k2 - k - 1, j]
                            if dt == np.inf:
                                break  # speeds ascend: the rest need more than the acceleration limit
                            cross = np.sqrt(2.0 * x_cross * dist) / speed_mps[j]
                            wait = red_left_s(t0 + cross, ra, rl, cy)
                            t2 = t0 + wait + dt
                            if t2 > t_max_s + LATE_TOL_S - t_rem_min_s[k2, j]:
                                continue
                            if is_stop[k2] and is_red(t2, stop_red_start_s[k2], stop_red_s[k2], stop_cycle_s[k2]):
                                continue
                            c2 = c0 + wait * idle_per_s + rest_usd[k2 - k - 1, j]
                            if _beyond(c2, t2, lower_bound_usd, k2, j, lam_usd_per_s, t_max_s, upper_bound_usd):
                                continue
                            b2 = int((t2 - t_lo_s[k2]) * inv_bin)
                            if b2 < n_bins:
                                _relax(cost_usd, time_s, parent, occ_lo, occ_hi, k2, j, b2, c2, t2, code)
        # stop arcs from this stage to the standstill before each light ahead within reach
        for l in range(n_light):
            kl = light_stage[l]
            if not (arc_k_lo[l] <= k < kl):
                continue
            for i in range(n_v):
                if occ_hi[k, i] < 0:
                    continue
                dt = stop_dt_s[kl - k - 1, i]
                if dt == np.inf:
                    continue
                step = stop_usd[kl - k - 1, i]
                for b in range(occ_lo[k, i], occ_hi[k, i] + 1):
                    c0 = cost_usd[k, i, b]
                    if c0 == np.inf:
                        continue
                    t2 = time_s[k, i, b] + dt
                    if t2 + t_rem_min_s[kl, 0] > t_max_s + LATE_TOL_S:
                        continue
                    c2 = c0 + step
                    if _beyond(c2, t2, halt_b, l, 0, lam_usd_per_s, t_max_s, upper_bound_usd):
                        continue
                    b2 = int((t2 - t_lo_s[kl]) * inv_bin)
                    if b2 < n_bins and c2 < s_cost_usd[l, b2]:
                        s_cost_usd[l, b2] = c2
                        s_time_s[l, b2] = t2
                        s_parent[l, b2] = (k * n_v + i) * n_bins + b
        k2 = k + 1
        stop_next = is_stop[k2]
        red_start, red_len, cycle = stop_red_start_s[k2], stop_red_s[k2], stop_cycle_s[k2]
        t_lo2 = t_lo_s[k2]
        for i in range(n_v):
            if occ_hi[k, i] < 0:
                continue
            b_lo, b_hi = occ_lo[k, i], occ_hi[k, i] + 1
            cost_row, time_row = cost_usd[k, i], time_s[k, i]
            row_min = np.inf
            for b in range(b_lo, b_hi):
                row_min = min(row_min, cost_row[b])
            t_first = time_row[b_lo]  # the row's earliest label (its first bin in use holds one)
            base = (k * n_v + i) * n_bins
            for j in range(band_hi[i] - band_lo[i] + 1):
                dt = step_dt[i, j]
                if dt == np.inf:
                    continue
                i2 = band_lo[i] + j
                step = step_cost[i, j]
                slack = t_max_s + LATE_TOL_S - t_rem_min_s[k2, i2]
                bound = upper_bound_usd - lower_bound_usd[0, k2, i2] - step  # the time-free bound (lam[0] = 0)
                if row_min > bound:  # no label of this row can finish within the limit this way
                    continue
                if n_lam > 1 and _beyond(row_min + step, t_first + dt, lower_bound_usd, k2, i2, lam_usd_per_s, t_max_s, upper_bound_usd):
                    continue  # nor with the time-aware bounds, which grow with time: at the row's cheapest cost and earliest time
                for n in range(1, n_lam):  # past this time even the row's cheapest label could not finish within the limit
                    slack = min(slack, t_max_s + LATE_TOL_S - (row_min + step + lower_bound_usd[n, k2, i2] - upper_bound_usd) / lam_usd_per_s[n] + 1e-9)
                la = light_ahead[k2] if n_lam > 1 else -1  # the light's bound (only with a limit)
                if la >= 0:
                    light_h = light_lb_usd[la, light_stage[la] - k2, i2]
                    t_line = line_t_min_s[k2, i2]
                    m0 = min(int(t_line * inv_tau), n_tau - 1)
                    if row_min + step + light_h[m0] > upper_bound_usd:
                        continue  # reaching the line as soon as possible is already too dear
                    h_top = upper_bound_usd - step - light_h[n_tau - 1]  # labels cheaper than this pass whatever the light
                    kl = light_stage[la]
                    l_start, l_red, l_cycle = stop_red_start_s[kl], stop_red_s[kl], stop_cycle_s[kl]
                cost_next, time_next, parent_next = cost_usd[k2, i2], time_s[k2, i2], parent[k2, i2]
                lo2, hi2 = occ_lo[k2, i2], occ_hi[k2, i2]
                for b in range(b_lo, b_hi):  # times ascend with the bins: past the time limit, stop
                    c0 = cost_row[b]
                    if c0 > bound:  # also skips empty cells (inf)
                        continue
                    t2 = time_row[b] + dt
                    if t2 > slack:
                        break
                    if stop_next and is_red(t2, red_start, red_len, cycle):
                        continue
                    if n_lam > 1 and _beyond(c0 + step, t2, lower_bound_usd, k2, i2, lam_usd_per_s, t_max_s, upper_bound_usd):
                        continue
                    if la >= 0 and c0 > h_top:  # it must reach the line no sooner than its red ends
                        tau = t_line + red_left_s(t2 + t_line, l_start, l_red, l_cycle)
                        if c0 + step + light_h[min(int(tau * inv_tau), n_tau - 1)] > upper_bound_usd:
                            continue
                    b2 = int((t2 - t_lo2) * inv_bin)
                    if b2 >= n_bins:
                        break
                    if hi2 < 0:  # open the cell (see ``_open``)
                        cost_next[b2] = np.inf
                        lo2 = hi2 = b2
                    elif b2 < lo2:
                        cost_next[b2:lo2] = np.inf
                        lo2 = b2
                    elif b2 > hi2:
                        cost_next[hi2 + 1 : b2 + 1] = np.inf
                        hi2 = b2
                    c2 = c0 + step
                    if c2 < cost_next[b2]:
                        cost_next[b2] = c2
                        time_next[b2] = t2
                        parent_next[b2] = base + b
                occ_lo[k2, i2], occ_hi[k2, i2] = lo2, hi2
