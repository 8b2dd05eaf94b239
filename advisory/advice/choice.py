"""Choosing a plan under uncertain signal timing: expected cost over the light's equally likely timings.

Where a light's changes are uncertain (an actuated controller, a predicted phase end), the advisor does not pick a
speed by rules; it prices every candidate plan (a target speed and how to reach it, or driving normally) on each
of the light's ``N`` equally likely timings (``LightView.scenario_red_windows_s``, quantiles of the predictor's
forecast) and chooses the cheapest in expectation (docs/ADVISOR.md, "Under uncertainty"):

* **Outcome of a plan in one timing**: the car follows the plan from now to a point ``x_end`` past the last line
  planned for, where every plan is back at the speed limit. If it reaches a line inside a red of that timing (or
  within the after-red margin), it brakes comfortably to a stop at the line instead, waits for the green and
  launches at the regular driver's rate.
* **Cost**: paper Eq. 4 (electricity plus battery wear, :mod:`advisory.physics.model`) of that motion, plus a price
  on time (``advisory.physics.params.TIME_VALUE_USD_PER_S``, the lookup tables' own: the one at which cruising
  at the limit is the cheapest steady speed). Priced per step from rate tables made once
  per vehicle with the model itself (:func:`rate_tables`).
* **Chance constraint**: a plan may make a stop likelier than driving normally only up to ``stop_risk_frac``.
  The safety rule is a hard constraint: a published red is red in every timing (``spat_feed.prediction.observe
  .red_hold_s``), so a plan that crosses it stops in all of them and is never advised.

Pure numerics; no advice wording here (:mod:`advisory.advice.advisor` words the choice).
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
from numba import njit

from advisory.physics.energy import road_load_force_n
from advisory.physics.model import I_AUX, pack, step_battery_power_w, step_cost_usd
from advisory.physics.params import VehicleParams, model_params

RATE_DV_MPS = 0.25
RATE_V_MAX_MPS = 45.0
"""Speed grid of the rate tables. [m/s]"""

CRUISE, ACCEL_COMFORT, ACCEL_NORMAL, BRAKE_COMFORT, BRAKE_FIRM, COAST = range(6)
"""Rows of the rate tables: how the speed changes."""

STEP_S = 0.5
"""Time step of the priced motion. [s]"""

EDGE_S = 2.0
"""A timing's change to red is known to within a couple of seconds (its neighbours in the forecast are seconds apart):
the chance of meeting the red rises from 0 to 1 over this long before its start, so that reaching the line later is
never free of risk between two timings. [s]"""

WAIT_CAP_S = 150.0
"""A red whose end no timing knows is priced as a wait this long. [s]"""


@lru_cache(maxsize=16)
def rate_tables(vehicle: VehicleParams, comfort_mps2: float, normal_mps2: float, firm_mps2: float) -> tuple[np.ndarray, np.ndarray, float]:
    """Cost rate [$/s] on the speed grid (``i * RATE_DV_MPS``) for each row (cruise, accelerate comfortably or at
    the regular driver's rate, brake comfortably or firmly, coast), the coasting deceleration [m/s²] on the grid,
    and the cost rate standing still [$/s]. Paper Eq. 4 on the flat, from the project's model (paper prices)."""
    p, m_c, m_pre = pack(model_params(vehicle))
    v = np.arange(0.0, RATE_V_MAX_MPS + RATE_DV_MPS, RATE_DV_MPS)
    h = 0.1
    coast = np.array([road_load_force_n(max(x, 1e-3), 0.0, vehicle.mass_kg, vehicle.rolling_coef, vehicle.rolling_speed_coef_s_per_m,
                                        vehicle.drag_coef, vehicle.frontal_area_m2, vehicle.air_density_kg_per_m3) for x in v]) / vehicle.mass_kg  # fmt: skip
    rates = np.empty((6, v.size))
    for row, a in ((CRUISE, 0.0), (ACCEL_COMFORT, comfort_mps2), (ACCEL_NORMAL, normal_mps2), (BRAKE_COMFORT, -comfort_mps2), (BRAKE_FIRM, -firm_mps2)):
        for i, x in enumerate(v):
            v0, v1 = max(x - 0.5 * a * h, 0.0), max(x + 0.5 * a * h, 0.0)
            rates[row, i] = step_cost_usd(step_battery_power_w(v0, v1, h, 0.0, p), h, p, m_c, m_pre) / h
    idle = step_cost_usd(p[I_AUX], 1.0, p, m_c, m_pre)  # auxiliaries only
    rates[COAST, :] = idle  # no wheel power: the auxiliaries alone
    return rates, coast, float(idle)


@njit(cache=True, inline="always")
def lerp_uniform(table, step, q):
    """``table`` (values on the grid ``i * step``) read at ``q`` by linear interpolation, clamped at both ends (the
    advisor's coast tables and the rate tables here)."""
    u = q / step
    i = int(u)
    if i >= table.size - 1:
        return table[-1]
    if i < 0:
        return table[0]
    return table[i] + (u - i) * (table[i + 1] - table[i])


@njit(cache=True, inline="always")
def _at(table, v):
    return lerp_uniform(table, RATE_DV_MPS, v)


@njit(cache=True)
def _drive(vt, mode, reaction_s, accel_row, accel_mps2, v0, d_stop_m, x_end_m, v_lim, rates, coast, comfort, firm, normal):
    """Follow one plan from speed ``v0``: a reaction at ``v0``, the change to ``vt`` (``mode`` as the advisor's
    kernels: 0 coast down or speed up, 1 brake gently then coast, 2 brake gently, 3 firmly; speeding up in row
    ``accel_row`` at ``accel_mps2``), then hold; past ``d_stop_m[-1]`` speed up at ``normal`` to ``v_lim``, to
    ``x_end_m``. Returns (cost, time) to ``x_end_m`` and, per line ``j``, (cost, time) to a comfortable stop at it
    (braking from where such a stop must begin). [$], [s]"""
    n = d_stop_m.size
    stop_usd = np.full(n, np.inf)
    stop_s = np.full(n, np.inf)
    t, x, v, usd = 0.0, 0.0, v0, 0.0
    coasting = False
    j = 0
    for _ in range(4000):
        # a comfortable stop at the next line must begin now
        while j < n and x < d_stop_m[j] and d_stop_m[j] - x <= v * v / (2.0 * comfort) + v * STEP_S:
            tb = v / comfort
            k = 8
            c = 0.0
            for q in range(k):
                c += _at(rates[BRAKE_COMFORT], v * (1.0 - (q + 0.5) / k)) * tb / k
            stop_usd[j], stop_s[j] = usd + c, t + tb
            j += 1
        if j < n and x >= d_stop_m[j]:
            j += 1  # passed it (its stop was taken before)
        if x >= x_end_m:
            break
        past = x >= d_stop_m[n - 1]
        target = v_lim if past else vt  # the speed the change stops at (coasting in mode 1 has none)
        if past:
            a, row = (normal, ACCEL_NORMAL) if v < v_lim - 1e-9 else (0.0, CRUISE)
        elif t < reaction_s:
            a, row = 0.0, CRUISE
        elif coasting or (mode == 1 and v <= vt + 1e-9):
            coasting = True
            a, row = -_at(coast, v), COAST
        elif v > vt + 1e-9:
            a, row = (-_at(coast, v), COAST) if mode == 0 else (-firm, BRAKE_FIRM) if mode == 3 else (-comfort, BRAKE_COMFORT)
        elif v < vt - 1e-9:
            a, row = accel_mps2, accel_row
        else:
            a, row = 0.0, CRUISE
        h = STEP_S
        v1 = v + a * h
        if a > 0.0 and v1 > target:
            v1, h = target, (target - v) / a
        elif a < 0.0 and not coasting and v1 < target < v:
            v1, h = target, (v - target) / -a
        if v1 < 0.0:
            v1, h = 0.0, v / -a
        if v1 <= 0.0 and v <= 0.0 and t >= reaction_s:
            return np.inf, np.inf, stop_usd, stop_s  # stopped short of the lines: not a plan
        h = max(h, 1e-6)
        usd += _at(rates[row], 0.5 * (v + v1)) * h
        x += 0.5 * (v + v1) * h
        v = v1
        t += h
    return usd, t, stop_usd, stop_s


@njit(cache=True)
def expected_costs(vts, modes, reactions, accel_rows, accels, v0, d_m, windows, n_windows, x_end_m, v_lim, after_red_s, lam_usd_per_s,
                   cross_s, rates, coast, idle_usd_per_s, comfort, firm, normal):  # fmt: skip
    """Expected cost [$] (motion plus ``lam_usd_per_s`` per second to ``x_end_m``) and chance of a stop [-] of each
    candidate plan (m,), over the equally likely timings ``windows`` (lines, timings, k, 2: red windows, padded with
    +inf) of the lines ``d_m`` (lines,), reached at ``cross_s`` (m, lines) as the plans go."""
    m, n_lines, n_sc = vts.size, d_m.size, windows.shape[1]
    cost = np.empty(m)
    p_stop = np.empty(m)
    # after a stop: the launch from rest to the limit at the regular driver's rate (midpoint rule, 16 steps)
    launch_s = v_lim / normal
    launch_m = 0.5 * v_lim * launch_s
    launch_usd = 0.0
    for q in range(16):
        launch_usd += _at(rates[ACCEL_NORMAL], v_lim * (q + 0.5) / 16) * launch_s / 16
    for c in range(m):
        usd, t_end, stop_usd, stop_s = _drive(vts[c], modes[c], reactions[c], accel_rows[c], accels[c], v0, d_m, x_end_m, v_lim, rates, coast, comfort, firm, normal)
        if not np.isfinite(t_end):
            cost[c], p_stop[c] = np.inf, 1.0
            continue
        total, stops = 0.0, 0.0
        for s in range(n_sc):
            blocked, wait_end, w = -1, 0.0, 0.0
            for j in range(n_lines):
                tc = cross_s[c, j]
                for k in range(n_windows):
                    a, b = windows[j, s, k, 0], windows[j, s, k, 1]
                    if a - EDGE_S < tc < b + after_red_s:
                        blocked, wait_end = j, min(b, tc + WAIT_CAP_S)
                        w = 1.0 if tc >= a else (tc - (a - EDGE_S)) / EDGE_S
                        break
                if blocked >= 0:
                    break
            if blocked < 0 or w < 1.0:
                total += (1.0 - w) * (usd + lam_usd_per_s * t_end)
                if blocked < 0:
                    continue
            stops += w
            t_stop = stop_s[blocked]
            if not np.isfinite(t_stop):  # too close to stop comfortably: a hard stop, as costly as one can be
                t_stop = tc
            wait = max(wait_end - t_stop, 0.0)
            rest_m = max(x_end_m - d_m[blocked] - launch_m, 0.0)
            rest_s = rest_m / v_lim
            c_usd = (stop_usd[blocked] if np.isfinite(stop_usd[blocked]) else usd) + idle_usd_per_s * wait + launch_usd + _at(rates[CRUISE], v_lim) * rest_s
            total += w * (c_usd + lam_usd_per_s * (t_stop + wait + launch_s + rest_s))
        cost[c] = total / n_sc
        p_stop[c] = stops / n_sc
    return cost, p_stop
