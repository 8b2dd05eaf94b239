"""numba kernels of the DP: arrays in, arrays out, no defaults (STYLE.md section 5)."""

from __future__ import annotations

import numpy as np
from numba import njit

from advisory.physics.model import I_AUX, step_battery_power_w, step_cost_usd

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
def forward_pass(
    speed_mps,
    band_lo,
    band_hi,
    stage_m,
    grade_frac,
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
    cost_usd,
    time_s,
    parent,
):
    """
    Forward DP over distance stages with labels carrying exact arrival times.

    Shapes: ``speed_mps`` (n_v,); ``band_lo/band_hi`` (n_v,) next-speed index range allowed by the
    acceleration limits; ``grade_frac`` (K,); ``stop_*``/``is_stop``/``t_lo_s`` (K + 1,);
    ``t_rem_min_s`` (K + 1, n_v); outputs ``cost_usd``, ``time_s``, ``parent`` (K + 1, n_v, n_bins).

    Cell (k, i, b) holds the cheapest path found that reaches stage k at speed i at an exact time in
    ``[t_lo[k] + b bin_s, t_lo[k] + (b + 1) bin_s)``, with that exact time. ``parent`` >= 0 encodes the
    previous stage's cell ``i_prev * n_bins + b_prev``; ``-(b_prev + 2)`` a dwell at standstill in the
    same stage; -1 the start. Red checks and the time limit use exact times, so no rounding of time can
    let a path cross a stop line during red. Labels that cannot reach the end by ``t_max_s`` even at the
    fastest (``t_rem_min_s``) are never stored, so they cannot displace feasible ones.
    """
    n_stage = cost_usd.shape[0] - 1
    n_v = speed_mps.shape[0]
    n_bins = cost_usd.shape[2]
    occ_lo = np.full((n_stage + 1, n_v), n_bins, dtype=np.int64)
    occ_hi = np.full((n_stage + 1, n_v), -1, dtype=np.int64)
    cost_usd[0, i_start, 0] = 0.0
    time_s[0, i_start, 0] = 0.0
    parent[0, i_start, 0] = -1
    occ_lo[0, i_start] = 0
    occ_hi[0, i_start] = 0
    # standstill: only accessories draw power
    idle_cost = step_cost_usd(p[I_AUX], dwell_s, p, m_c_rates, m_prefactor)
    max_band = 0
    for i in range(n_v):
        max_band = max(max_band, band_hi[i] - band_lo[i] + 1)
    step_dt = np.empty((n_v, max_band))
    step_usd = np.empty((n_v, max_band))
    for k in range(n_stage):
        if k == 0 or grade_frac[k] != grade_frac[k - 1]:  # transition table: once per distinct grade
            for i in range(n_v):
                for j in range(band_hi[i] - band_lo[i] + 1):
                    v, v2 = speed_mps[i], speed_mps[band_lo[i] + j]
                    if v + v2 <= 0.0:
                        step_dt[i, j] = np.inf
                        continue
                    dt = 2.0 * stage_m / (v + v2)
                    battery_w = step_battery_power_w(v, v2, dt, grade_frac[k], p)
                    step_dt[i, j] = dt
                    step_usd[i, j] = step_cost_usd(battery_w, dt, p, m_c_rates, m_prefactor)
        # dwell at standstill (never on a stop line), bins in ascending order so waits chain
        if allow_dwell and speed_mps[0] == 0.0 and not is_stop[k] and occ_hi[k, 0] >= 0:
            b = occ_lo[k, 0]
            while b < n_bins and b <= occ_hi[k, 0]:
                c0 = cost_usd[k, 0, b]
                if c0 < np.inf:
                    t2 = time_s[k, 0, b] + dwell_s
                    if t2 + t_rem_min_s[k, 0] <= t_max_s + LATE_TOL_S:
                        b2 = int((t2 - t_lo_s[k]) / bin_s)
                        if b2 < n_bins and c0 + idle_cost < cost_usd[k, 0, b2]:
                            cost_usd[k, 0, b2] = c0 + idle_cost
                            time_s[k, 0, b2] = t2
                            parent[k, 0, b2] = -(b + 2)
                            if b2 > occ_hi[k, 0]:
                                occ_hi[k, 0] = b2
                b += 1
        k2 = k + 1
        stop_next = is_stop[k2]
        red_start, red_len, cycle = stop_red_start_s[k2], stop_red_s[k2], stop_cycle_s[k2]
        t_lo2 = t_lo_s[k2]
        for i in range(n_v):
            if occ_hi[k, i] < 0:
                continue
            b_lo, b_hi = occ_lo[k, i], occ_hi[k, i] + 1
            cost_row, time_row = cost_usd[k, i], time_s[k, i]
            for j in range(band_hi[i] - band_lo[i] + 1):
                dt = step_dt[i, j]
                if dt == np.inf:
                    continue
                i2 = band_lo[i] + j
                step = step_usd[i, j]
                slack = t_max_s + LATE_TOL_S - t_rem_min_s[k2, i2]
                cost_next, time_next, parent_next = cost_usd[k2, i2], time_s[k2, i2], parent[k2, i2]
                lo2, hi2 = occ_lo[k2, i2], occ_hi[k2, i2]
                for b in range(b_lo, b_hi):
                    c0 = cost_row[b]
                    if c0 == np.inf:
                        continue
                    t2 = time_row[b] + dt
                    if t2 > slack:
                        continue
                    if stop_next and is_red(t2, red_start, red_len, cycle):
                        continue
                    b2 = int((t2 - t_lo2) / bin_s)
                    if b2 >= n_bins:
                        continue
                    c2 = c0 + step
                    if c2 < cost_next[b2]:
                        cost_next[b2] = c2
                        time_next[b2] = t2
                        parent_next[b2] = i * n_bins + b
                        if b2 < lo2:
                            lo2 = b2
                        if b2 > hi2:
                            hi2 = b2
                occ_lo[k2, i2], occ_hi[k2, i2] = lo2, hi2
