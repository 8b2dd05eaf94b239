"""Choosing a plan under uncertain signal timing: expected cost over the light's equally likely timings.

Where a light's changes are uncertain (an actuated controller, a predicted phase end), the advisor does not pick a
speed by rules; it prices every candidate plan (a target speed and how to reach it, or driving normally) on each
of the light's ``N`` equally likely timings (``LightView.scenario_red_windows_s``, quantiles of the predictor's
forecast) and chooses the cheapest in expectation (docs/ADVISOR.md, "Under uncertainty"):

* **Outcome of a plan in one timing, with recourse**: the advice is made again every second, so the car follows the
  plan only until the light shows which timing it is in, then does the best it can knowing it, to a point ``x_end``
  past the last line planned for, where every plan is back at the speed limit (:func:`expected_costs`): a green that
  comes early (once the driver follows the plan) is met by speeding up to the limit from that instant (where that is
  cheaper and meets no red; also where the plan itself would have met a later red); a red on
  now that the plan would meet is ridden out (the plan until it ends, braking comfortably from where a stop at the
  line must begin, rolling on when the green comes, a stop if it does not come first); a red still to come that the
  plan would meet is glided to (from its amber, reaching the line after it, no slower than the slowest advised
  speed), or stopped for when it shows within a comfortable stop, or cleared in its amber when it shows where the car
  can no longer stop for it. "Prepare to stop" is a plan too: the car stops at the line whatever the light shows,
  rolling on only where a red on now ends while it brakes. The timings are the predictor's (quantiles of its
  forecast) and a wider component of the mixture (:func:`advisory.advice.mixture.wide_component`), each with its
  probability: the outer timings are not the forecast's extremes, and the wide ones weigh the chance of a change
  outside the window the light states.
* **Cost**: paper Eq. 4 (electricity plus battery wear, :mod:`advisory.physics.model`) of that motion, plus a price
  on time: the road's, the least at which cruising at its limit is the cheapest steady speed
  (:func:`steady_time_value_usd_per_s`; the lookup tables' ``TIME_VALUE_USD_PER_S`` is the same rule at 55 mph).
  Priced per step from rate tables made once per vehicle with the model itself (:func:`rate_tables`).
* **Chance constraint**: a plan may make a stop likelier than driving normally only up to ``stop_risk_frac``.
  The safety rule is a hard constraint: a published red is red in every timing (``spat_feed.prediction.observe
  .red_hold_s``), and a plan that reaches the line inside it (in every timing) is never advised; nor, at a light that
  shows no amber, or whose timing is exact, one that reaches the line where a red may be on (the caller's, from
  :func:`advisory.advice.kinematics.crossings`; "prepare to stop" stops there).

Pure numerics; no advice wording here (:mod:`advisory.advice.advisor` words the choice). The kernels divide only by
what cannot be 0 (a speed where it is held above 0, a step, a deceleration, a window's edge of at least
:data:`EDGE_S`), so they are compiled with numba's numpy error model: no check for a zero divisor at each division
(~10 % of the pricing on US 1136's bench observations; the same numbers to the last bit).
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

AMBER_STOP_MPS2 = 4.0
"""A driver stops for an amber it can stop for at this deceleration, and clears the line in one it cannot (the regular
driver's hardest braking). [m/s²]"""

AMBER_MIN_S = 3.0
"""An amber lasts at least this long where the light shows one of unstated length (the shortest yellow change interval,
MUTCD 4D.26). [s]"""

AMBER_MAX_S = 6.0
"""An amber of unstated length lasts at most this long (the longest yellow change interval, MUTCD 4D.26): when it
shows, and so whether the car can still stop for it, is known only to within the two. [s]"""

WAIT_CAP_S = 150.0
"""A red whose end no timing knows is priced as lasting this long from its start (the same instant for every plan: a
plan that gets there later waits less, not as long). [s]"""


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


EXACT_EDGE_S = 1e-3
""":data:`EDGE_S` of an exact light (fixed-time plans, exact SPaT: one timing, weight 1): its changes come when it says,
and a crossing a millisecond before its red (or its amber) does not meet it; not 0, so that no edge divides by 0. [s]"""

MAX_KNOTS = 4000
"""Steps of one priced motion at most (:data:`STEP_S` each, fewer where a speed is reached mid-step). [-]"""


@njit(cache=True, error_model="numpy")
def _drive(vt, mode, reaction_s, accel_row, accel_mps2, v0, d_stop_m, x_end_m, v_lim, rates, coast, comfort, firm, normal, path, dense=False):
    """Follow one plan from speed ``v0``: a reaction at ``v0``, the change to ``vt`` (``mode`` as the advisor's
    kernels: 0 coast down or speed up, 1 brake gently then coast, 2 brake gently, 3 firmly; speeding up in row
    ``accel_row`` at ``accel_mps2``), then hold; past ``d_stop_m[-1]`` speed up at ``normal`` to ``v_lim``, to
    ``x_end_m``. Writes the motion's knots into ``path`` (4, n): time [s], position [m], speed [m/s] and cost so far
    [$]. Returns (cost, time) to ``x_end_m`` (inf: the plan stops short of the lines), the number of knots, per line
    ``j`` the state (time, position, speed, cost) where a comfortable stop at it must begin (inf where the plan never
    is that far from it: too close to stop comfortably), and whether the motion is free of its target: slowing towards
    it (modes 0, 2, 3) until past the last line, never within 1e-9 m/s of it, so that the motion to any lower target is
    this one, step for step (:func:`_lower_free`).

    A steady hold (the speed held after the reaction, or the limit past the lines) is one straight segment of
    ``path`` (unless ``dense``: every step's knot): its steps are taken as every other step (the same sums, so the
    knots kept are the same numbers, and so are the cost, the time and the stops' states), but only the knots where
    something happens (a stop must begin, a line is passed, the last step) are written; between them position, speed
    and cost are linear in time, as the readers of ``path`` interpolate (:func:`_state_at`, :func:`_no_stop_s`: the
    same instants and states to rounding, 1e-15 of a plan's cost). On US 1136's bench observations that is half the
    knots (14,500 -> 7,000 a fix), and the pricing searches through fewer.

    The mode acts only while the speed is above the target: a motion that starts at or below it is the same in modes
    0, 2 and 3 (speeding up, then holding), and in mode 1 a coast whatever the target (:func:`_same_motion`).

    A coast in mode 1 lasts until the last line is passed; where the farthest it can roll before stopping (at the least
    coasting deceleration of the table, ``v² / 2 min(coast)``, more than any sum of its steps, 1e-9 of it and a micrometre
    spare for rounding) ends short of that line, the plan stops short and no further step is taken (unless ``dense``):
    a quarter of the steps on the bench observations were those of plans that coast to a halt."""
    n = d_stop_m.size
    brake = np.full((n, 4), np.inf)
    t, x, v, usd = 0.0, 0.0, v0, 0.0
    coasting = False
    reached = False  # the target acted before the last line (not free of it)
    floor_mps2 = np.nan  # the least coasting deceleration (found once the car coasts)
    j = 0
    k = 0
    steps = 0
    while steps < MAX_KNOTS:
        path[0, k], path[1, k], path[2, k], path[3, k] = t, x, v, usd
        k += 1
        # a comfortable stop at the next line must begin now
        while j < n and x < d_stop_m[j] and d_stop_m[j] - x <= v * v / (2.0 * comfort) + v * STEP_S:
            brake[j, 0], brake[j, 1], brake[j, 2], brake[j, 3] = t, x, v, usd
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
            if not coasting:
                floor_mps2 = coast.min()
            coasting = reached = True
            a, row = -_at(coast, v), COAST
            if not dense and x + v * v / (2.0 * floor_mps2) * (1.0 + 1e-9) + 1e-6 < d_stop_m[n - 1] and steps + v / (floor_mps2 * STEP_S) + 2.0 < MAX_KNOTS:
                return np.inf, np.inf, k, brake, False  # it coasts to a halt short of the last line: not a plan
        elif v > vt + 1e-9:
            a, row = (-_at(coast, v), COAST) if mode == 0 else (-firm, BRAKE_FIRM) if mode == 3 else (-comfort, BRAKE_COMFORT)
        elif v < vt - 1e-9:
            a, row = accel_mps2, accel_row
            reached = True
        else:
            a, row = 0.0, CRUISE
            reached = True
        h = STEP_S
        v1 = v + a * h
        if a > 0.0 and v1 > target:
            v1, h = target, (target - v) / a
        elif a < 0.0 and not coasting and v1 < target < v:
            v1, h = target, (v - target) / -a
            reached = True  # (only before the last line: past it the target is the limit, reached speeding up)
        if v1 < 0.0:
            v1, h = 0.0, v / -a
        if v1 <= 0.0 and v <= 0.0 and t >= reaction_s:
            return np.inf, np.inf, k, brake, False  # stopped short of the lines: not a plan
        if x + 0.5 * (v + v1) * h > x_end_m:  # the last step ends at x_end_m (a whole step past it priced time not driven)
            d = x_end_m - x
            disc = v * v + 2.0 * a * d
            h = d / v if abs(a) < 1e-12 else (np.sqrt(disc) - v) / a if disc >= 0.0 else h
            v1 = v + a * h
        h = max(h, 1e-6)
        steady = not dense and a == 0.0 and h == STEP_S and v1 > 0.0 and (past or t >= reaction_s)
        usd += _at(rates[row], 0.5 * (v + v1)) * h
        x += 0.5 * (v + v1) * h
        v = v1
        t += h
        steps += 1
        if steady:
            # a steady hold: on to the next knot where something happens (the loop's checks above: a comfortable stop
            # at the next line must begin, a line is passed, the last step), by the same steps, none written between
            du, dx = _at(rates[row], 0.5 * (v + v)) * STEP_S, 0.5 * (v + v) * STEP_S
            to_stop_m = v * v / (2.0 * comfort) + v * STEP_S
            d_next, d_last = d_stop_m[j] if j < n else np.inf, d_stop_m[n - 1]
            while steps < MAX_KNOTS and not (x >= x_end_m or x + dx > x_end_m or (x >= d_last) != past or x >= d_next or d_next - x <= to_stop_m):
                usd += du
                x += dx
                t += STEP_S
                steps += 1
    path[0, k], path[1, k], path[2, k], path[3, k] = t, x, v, usd
    return usd, t, k + 1, brake, not reached


@njit(cache=True, error_model="numpy")
def _ramps(rates, comfort, normal):
    """Cost [$] of speeding up from rest to each grid speed at ``normal``, and of braking from it to rest at ``comfort``
    (cumulative, on the rate tables' speed grid)."""
    n = rates.shape[1]
    up, down = np.zeros(n), np.zeros(n)
    for i in range(1, n):
        v = (i - 0.5) * RATE_DV_MPS
        up[i] = up[i - 1] + _at(rates[ACCEL_NORMAL], v) * RATE_DV_MPS / normal
        down[i] = down[i - 1] + _at(rates[BRAKE_COMFORT], v) * RATE_DV_MPS / comfort
    return up, down


@njit(cache=True, inline="always")
def _state_at(path, n, tau):
    """Position, speed and cost so far of a priced motion (``path``, ``n`` knots) at time ``tau`` (linear in the step)."""
    if tau <= path[0, 0]:
        return path[1, 0], path[2, 0], path[3, 0]
    if tau >= path[0, n - 1]:
        return path[1, n - 1], path[2, n - 1], path[3, n - 1]
    lo, hi = 0, n - 1
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if path[0, mid] <= tau:
            lo = mid
        else:
            hi = mid
    f = (tau - path[0, lo]) / max(path[0, hi] - path[0, lo], 1e-12)
    return (path[1, lo] + f * (path[1, hi] - path[1, lo]), path[2, lo] + f * (path[2, hi] - path[2, lo]),
            path[3, lo] + f * (path[3, hi] - path[3, lo]))  # fmt: skip


@njit(cache=True, inline="always")
def _no_stop_s(path, n, d_line, decel):
    """When the car of a priced motion (``path``, ``n`` knots) can no longer stop before a line ``d_line`` ahead at
    ``decel`` (the distance left shorter than v² / 2 decel; linear between knots); inf if it always can. [s]"""
    g_prev = np.inf
    for i in range(n):
        g = d_line - path[1, i] - path[2, i] * path[2, i] / (2.0 * decel)
        if g < 0.0:
            if i == 0:
                return path[0, 0]
            return path[0, i - 1] + g_prev / (g_prev - g) * (path[0, i] - path[0, i - 1])
        g_prev = g
    return np.inf


@njit(cache=True, inline="always")
def _go_s(d_m, v0, reaction_s, v_lim, normal):
    """Time [s] to a point ``d_m`` ahead speeding up to ``v_lim`` at ``normal`` after ``reaction_s`` at ``v0``."""
    if d_m <= v0 * reaction_s:
        return d_m / v0 if v0 > 0.0 else 0.0
    d = d_m - v0 * reaction_s
    d_acc = (v_lim * v_lim - v0 * v0) / (2.0 * normal)
    if d <= d_acc:
        return reaction_s + (np.sqrt(v0 * v0 + 2.0 * normal * d) - v0) / normal
    return reaction_s + (v_lim - v0) / normal + (d - d_acc) / v_lim


@njit(cache=True, inline="always")
def _go_usd(x_m, v0, reaction_s, x_end_m, v_lim, rates, up, normal, lam):
    """Cost [$] with time priced at ``lam``, and time [s], from position ``x_m`` at speed ``v0`` to ``x_end_m``: a
    reaction at ``v0``, speeding up to ``v_lim`` at ``normal``, then cruising."""
    d_acc = (v_lim * v_lim - v0 * v0) / (2.0 * normal)
    rest_m = max(x_end_m - x_m - v0 * reaction_s - d_acc, 0.0)
    t = reaction_s + (v_lim - v0) / normal + rest_m / v_lim
    usd = _at(rates[CRUISE], v0) * reaction_s + _at(up, v_lim) - _at(up, v0) + _at(rates[CRUISE], v_lim) * rest_m / v_lim
    return usd + lam * t, t


@njit(cache=True, inline="always")
def _later_usd(x_m, t_s, v_mps, reaction_s, j, s, lines):
    """What the lines after line ``j`` add [$] (time priced at ``lam``) to the recourse of timing ``s`` of a car at
    ``x_m`` [m] at ``t_s`` [s] and ``v_mps`` that drives on as the regular driver would (a reaction ``reaction_s``, then
    speeding up to ``v_lim`` at ``normal``; :func:`_go_usd` prices that as free of reds): at the first of them where it
    meets a red (or its amber) of the timing, a stop (braked comfortably from the speed it has there, a wait until the
    red ends, a launch), weighted by the chance of meeting it (:func:`_met`). A car stopped at one light, or glided
    to its green, meets the next light later than the plan did: where the greens of the two are offset for a car at
    the limit, it often waits there too (2019-05-01 groups 8-9: a lift-off for light 1's amber priced as waiting at
    light 1 alone, where the regular driver waited at light 2; the car waited at both, 65 s lost). ``lines``: the
    lines and their timings as :func:`expected_costs` has them (``d_m``, ``windows``, ``n_windows``, ``after_red_s``,
    ``clear_s``, ``edge_s``, ``v_lim``, ``rates``, ``up``, ``down``, ``idle_usd_per_s``, ``comfort``, ``normal``, ``lam``)."""
    d_m, windows, n_windows, after_red_s, clear_s, edge_s, v_lim, rates, up, down, idle_usd_per_s, comfort, normal, lam = lines
    for i in range(j + 1, d_m.size):
        dist = d_m[i] - x_m
        if dist <= 0.0:
            continue
        ti = t_s + _go_s(dist, v_mps, reaction_s, v_lim, normal)
        k, w = _met(ti, windows, i, s, n_windows, after_red_s, -1, clear_s[i], edge_s[i])
        if k < 0:
            continue
        vi = min(np.sqrt(v_mps * v_mps + 2.0 * normal * max(dist - v_mps * reaction_s, 0.0)), v_lim)
        if vi <= 0.0:
            return 0.0
        b = windows[i, s, k, 1]
        if not np.isfinite(b):
            b = max(windows[i, s, k, 0], 0.0) + WAIT_CAP_S
        wait = max(b - ti - vi / (2.0 * comfort), 0.0)
        ramps_m = vi * vi / (2.0 * comfort) + vi * vi / (2.0 * normal)
        return w * (_at(down, vi) + _at(up, vi) - _at(rates[CRUISE], vi) * ramps_m / vi + idle_usd_per_s * wait
                    + lam * (vi / (2.0 * comfort) + wait + vi / (2.0 * normal)))  # fmt: skip
    return 0.0


@njit(cache=True, inline="always")
def _early_green_usd(c, s, n_first, path, n_knots, cross_s, windows, n_windows, after_red_s, d_m, reaction_s, v_lim, normal, clear_s, edge_s, x_end_m,
                     rates, up, lam, followed_s):  # fmt: skip
    """Cost [$] (time priced at ``lam``) of plan ``c`` in timing ``s`` where a red of one of the first ``n_first`` lines ends
    before the plan reaches that line (its green comes early) and once the driver follows the plan (``followed_s`` on,
    its reaction: before, the car drives as it did, and driving on is a candidate of its own): the plan until then, a
    reaction, then speeding up to the limit, where that meets no red of the timing at any line; the cheapest such
    instant, inf if none."""
    best = np.inf
    for j in range(n_first):
        tc = cross_s[c, j]
        for k in range(n_windows):
            b = windows[j, s, k, 1]
            if not max(followed_s, 0.0) < b <= tc - after_red_s:
                continue
            x, v, u = _state_at(path, n_knots, b)
            if x >= d_m[j]:
                continue
            ok = True
            for i in range(d_m.size):
                if d_m[i] > x:
                    ki, _ = _met(b + _go_s(d_m[i] - x, v, reaction_s, v_lim, normal), windows, i, s, n_windows, after_red_s, k if i == j else -1, clear_s[i],
                                 edge_s[i])
                    if ki >= 0:
                        ok = False
            if ok:
                g, tg = _go_usd(x, v, reaction_s, x_end_m, v_lim, rates, up, normal, lam)
                best = min(best, u + g + lam * b)
    return best


@njit(cache=True, inline="always")
def _met(tc, windows, j, s, n_windows, after_red_s, skip, amber_s, edge_s):
    """Window index (and the chance [-] of meeting it) of timing ``s`` at line ``j`` that a crossing at ``tc`` meets:
    inside a red, the margin after it or the amber (``amber_s``) before a red still to come, or within ``edge_s`` before
    that (likelier the closer: :data:`EDGE_S`, or :data:`EXACT_EDGE_S` at an exact light); -1 if none."""
    for k in range(n_windows):
        if k == skip:
            continue
        a, b = windows[j, s, k, 0], windows[j, s, k, 1]
        if a > 0.0:
            a = max(a - amber_s, 0.0)
        if a - edge_s < tc < b + after_red_s:
            return k, 1.0 if tc >= a else (tc - (a - edge_s)) / edge_s
    return -1, 0.0


@njit(cache=True, inline="always")
def _stop_usd(tb, xb, vb, ub, usd, tc, green_s, d_line, x_end_m, v_lim, rates, up, down, idle_usd_per_s, comfort, normal, lam):
    """Cost [$] (time priced at ``lam``) of a stop at a line ``d_line`` ahead and the drive on to ``x_end_m``: braked
    comfortably from the state (``tb`` [s], ``xb`` [m], ``vb`` [m/s], ``ub`` [$]) where such a stop must begin (none,
    ``tb`` inf: the car too close for that, as costly as the plan's whole motion ``usd``, stopped at its crossing ``tc``),
    a wait until ``green_s``, then a launch at ``normal`` to ``v_lim``."""
    t_stop = tb + vb / comfort if np.isfinite(tb) else tc
    wait = max(green_s - t_stop, 0.0)
    launch_s = v_lim / normal
    rest_m = max(x_end_m - d_line - 0.5 * v_lim * launch_s, 0.0)
    stop_usd = ub + _at(down, vb) if np.isfinite(tb) else usd
    return (stop_usd + idle_usd_per_s * wait + _at(up, v_lim) + _at(rates[CRUISE], v_lim) * rest_m / v_lim
            + lam * (t_stop + wait + launch_s + rest_m / v_lim))  # fmt: skip


@njit(cache=True, error_model="numpy")
def expected_costs(vts, modes, reactions, accel_rows, accels, v0, d_m, windows, n_windows, x_end_m, v_lim, after_red_s, lam_usd_per_s,
                   cross_s, rates, coast, idle_usd_per_s, comfort, firm, normal, reaction_s, min_speed_mps, clear_s, weights, stop_plan,
                   amber_max_s, edge_s, skip=None, must=None, anchor=-1, risk_frac=np.inf):  # fmt: skip
    """Expected cost [$] (motion plus ``lam_usd_per_s`` per second to ``x_end_m``), chance of a stop [-], and whether
    the plan crosses a red of every timing (the hard constraint) of each candidate plan (m,), over the timings
    ``windows`` (lines, timings, k, 2: red windows, padded with +inf), of probability ``weights`` (timings,: summing to
    1), of the lines ``d_m`` (lines,), reached at
    ``cross_s`` (m, lines) as the plans go. The amber before a red still to come (``clear_s`` (lines,): how long at
    least, 0 where the light shows none; ``amber_max_s`` (lines,): how long at most) comes before its window; ``edge_s``
    (lines,): how well a line's changes are known (:func:`_met`: :data:`EDGE_S`, or :data:`EXACT_EDGE_S` where its
    timing is exact).

    **With recourse**: the advice is made again every second, so in each timing the car follows the plan only until
    the light shows what that timing is, then does the best it can knowing it (module docstring):

    * a red that ends before the plan reaches the line (the green comes early), after the plan's reaction: from that
      instant, a reaction, then speeding up to the limit, if that is cheaper and meets no red of the timing, whether or
      not the plan itself meets a later red (:func:`_early_green_usd`);
    * a red on now that the plan would meet: the plan until its end; if a comfortable stop must begin first, braking
      until the red ends (rolling on from the speed then) or to a stop;
    * a red still to come that the plan would meet, shown (its amber) before a comfortable stop must begin: from then
      a glide that reaches the line ``after_red_s`` after that red's end, held no lower than ``min_speed_mps``, else a
      stop at the line; shown where the car can no longer stop at :data:`AMBER_STOP_MPS2`, the amber is cleared (if the
      car is over the line before the red); shown in between, a stop. A red shows with its amber, ``clear_s`` before
      it.

    A plan flagged in ``stop_plan`` (m,) is "prepare to stop" at the first line it meets a red at: its motion is the
    plan's (a lift-off: the driver coasts until a comfortable stop must begin), and a red still to come that it meets is
    stopped for wherever the car can stop for it (no glide to its end); a green on arrival is driven through (the
    driver's eye at its decision point), a red on now that ends first is rolled through, as for any plan.

    A stop (or a roll below ``min_speed_mps``) counts in the chance of a stop. The hard constraint is about the light
    as published now: a plan is through a red when it reaches the line inside a red (or amber) on now in every timing,
    or, where the light shows no amber, inside any red of every timing.

    **Pruned** (the advisor's choice, :func:`advisory.advice.advisor._choose`: the same choice as pricing every plan,
    for less): candidates in ``skip`` (m,) are not priced (cost inf, through: the caller found them through a red).
    Given ``must`` (m,), the candidate ``anchor`` (driving normally) is priced first, and every candidate not in
    ``must`` stops being priced where it cannot be allowed (cost inf): through a red (the hard constraint: not driven;
    one whose motion would have stopped short of the lines costs inf, and the advisor never chooses a plan of cost
    inf), or its chance of a stop past ``p_stop[anchor] + risk_frac + 1e-9`` (the advisor's chance constraint; a sum
    of chances never shrinks as timings are added, so a partial sum past it is a whole sum past it; ``p_stop`` holds
    the partial one). The candidates are priced in the order of their motions (:func:`_pricing_order`), so that those of one
    motion come one after the other: a candidate of the last priced one's motion by its arguments (:func:`_same_motion`)
    is not driven again, and one whose motion, crossings and flags are the last priced one's (a lift-off to a speed the
    car never coasts down to before the lines: the same motion whatever the target) gets its results. On the recorded
    controllers' bench observations (``bench/bench_predictor.py``'s) that is 66 motions driven and 1,007 timings priced
    a fix, against 74 and 1,202 in the candidates' own order."""
    up, down, order, paths = prepared(vts, modes, v0, anchor, rates, comfort, normal)
    return priced(vts, modes, reactions, accel_rows, accels, v0, d_m, windows, n_windows, x_end_m, v_lim, after_red_s, lam_usd_per_s, cross_s, rates, coast,
                  idle_usd_per_s, comfort, firm, normal, reaction_s, min_speed_mps, clear_s, weights, stop_plan, amber_max_s, edge_s, skip, must, anchor,
                  risk_frac, up, down, order, paths)  # fmt: skip


@njit(cache=True, error_model="numpy")
def prepared(vts, modes, v0, anchor, rates, comfort, normal):
    """What :func:`priced` needs of the candidates alone, made once for any number of pricings of them: the ramps
    (:func:`_ramps`), the pricing order (:func:`_pricing_order`) and room for two motions (2, 4, :data:`MAX_KNOTS` + 1)."""
    up, down = _ramps(rates, comfort, normal)
    return up, down, _pricing_order(vts, modes, v0, anchor), np.empty((2, 4, MAX_KNOTS + 1))


@njit(cache=True, error_model="numpy")
def priced(vts, modes, reactions, accel_rows, accels, v0, d_m, windows, n_windows, x_end_m, v_lim, after_red_s, lam_usd_per_s, cross_s, rates, coast,
           idle_usd_per_s, comfort, firm, normal, reaction_s, min_speed_mps, clear_s, weights, stop_plan, amber_max_s, edge_s, skip, must, anchor, risk_frac, up,
           down, order, paths):  # fmt: skip
    """:func:`expected_costs`, given what :func:`prepared` makes of the candidates (``paths`` is overwritten): a caller
    that prices the same candidates twice makes it once (:func:`advisory.advice.screening.screened`)."""
    m, n_lines, n_sc = vts.size, d_m.size, windows.shape[1]
    cost = np.empty(m)
    p_stop = np.empty(m)
    through = np.zeros(m, dtype=np.bool_)
    cur, prev, prev_knots, prev_brake, prev_usd, prev_t_end = 0, -1, 0, np.empty((n_lines, 4)), 0.0, 0.0
    held, held_free = -1, False  # the last candidate whose motion paths[1 - cur] holds (prev's, or one found the same), free of its target
    no_stop = np.empty(n_lines)
    stop_cap = np.inf
    for c in order:
        if skip is not None and skip[c]:
            cost[c], p_stop[c], through[c] = np.inf, 1.0, True
            continue
        prune = must is not None and not must[c]
        sure_through = False
        for j in range(n_lines):  # the hard constraint: a crossing inside a red of every timing
            sure = True
            for s in range(n_sc):
                k, w = _met(cross_s[c, j], windows, j, s, n_windows, after_red_s, -1, 0.0, edge_s[j])
                if k < 0 or w < 1.0 or cross_s[c, j] < windows[j, s, k, 0] or (windows[j, s, k, 0] > 0.0 and clear_s[j] > 0.0):
                    sure = False
                    break
            if sure:
                sure_through = True
        if prune and sure_through:
            cost[c], p_stop[c], through[c] = np.inf, 1.0, True
            continue
        driven = held < 0 or not (_same_motion(c, held, vts, modes, reactions, accel_rows, accels, v0)
                                  or (held_free and _lower_free(c, held, vts, modes, reactions, accel_rows, accels, v0)))
        if driven:
            path = paths[cur]
            usd, t_end, n_knots, brake, free = _drive(vts[c], modes[c], reactions[c], accel_rows[c], accels[c], v0, d_m, x_end_m, v_lim, rates, coast,
                                                comfort, firm, normal, path)  # fmt: skip
            if not np.isfinite(t_end):
                cost[c], p_stop[c] = np.inf, 1.0
                continue
        else:  # the last priced candidate's motion, as driven
            path, usd, t_end, n_knots, brake = paths[1 - cur], prev_usd, prev_t_end, prev_knots, prev_brake
        through[c] = sure_through
        if (prev >= 0 and _same_flags(c, prev, cross_s, stop_plan, reactions, must)
                and (not driven or _same_path(path, n_knots, brake, paths[1 - cur], prev_knots, prev_brake))):  # fmt: skip
            cost[c], p_stop[c] = cost[prev], p_stop[prev]
            if driven:
                held, held_free = c, free
            continue
        if driven:
            cur = 1 - cur
            held_free = free
        held = c
        prev, prev_knots, prev_brake, prev_usd, prev_t_end = c, n_knots, brake, usd, t_end
        no_stop[:] = np.nan  # when the car can no longer stop for each line: found once an amber there needs it
        total, stops = 0.0, 0.0
        plan = usd + lam_usd_per_s * t_end
        tail = (d_m, windows, n_windows, after_red_s, clear_s, edge_s, v_lim, rates, up, down, idle_usd_per_s, comfort, normal, lam_usd_per_s)
        for s in range(n_sc):
            if prune and stops > stop_cap:
                total = np.inf  # not to be allowed: not priced further
                break
            blocked, kb, w = -1, -1, 0.0
            for j in range(n_lines):
                kb, w = _met(cross_s[c, j], windows, j, s, n_windows, after_red_s, -1, clear_s[j], edge_s[j])
                if kb >= 0:
                    blocked = j
                    break
            amber = blocked >= 0 and windows[blocked, s, kb, 0] > 0.0 and clear_s[blocked] > 0.0 and cross_s[c, blocked] < windows[blocked, s, kb, 0]
            if amber:
                # a red still to come, after an amber, that the car would be over the line before: the amber's onset is
                # known to within edge_s as the red's start is (_met), and to within its length (``clear_s`` to
                # ``amber_max_s``), uniform between; where it shows while the car can still stop for it at
                # AMBER_STOP_MPS2 the car stops, where it shows later the car clears it (a knife edge priced as a chance:
                # a plan a second slower than another stops for an amber that the other clears)
                a = windows[blocked, s, kb, 0]
                first, last = max(a - amber_max_s[blocked], 0.0) - 0.5 * edge_s[blocked], max(a - clear_s[blocked], 0.0) + 0.5 * edge_s[blocked]
                if np.isnan(no_stop[blocked]):
                    no_stop[blocked] = _no_stop_s(path, n_knots, d_m[blocked], AMBER_STOP_MPS2)
                w = min(max((no_stop[blocked] - first) / (last - first), 0.0), 1.0)
            early = np.inf  # the recourse of a green that comes early (none for "prepare to stop": it stops whatever)
            if not stop_plan[c] and (w < 1.0 or blocked >= 0):
                early = _early_green_usd(c, s, n_lines if blocked < 0 else blocked + 1, path, n_knots, cross_s, windows, n_windows, after_red_s, d_m,
                                         reaction_s, v_lim, normal, clear_s, edge_s, x_end_m, rates, up, lam_usd_per_s, reactions[c])  # fmt: skip
            if w < 1.0 and stop_plan[c]:
                # told to stop, the car stops at the line however the light shows (braked from where a comfortable stop
                # must begin), then pulls away: dear wherever the light is likely green
                j = max(blocked, 0)
                t_go = brake[j, 0] + brake[j, 2] / comfort if np.isfinite(brake[j, 0]) else cross_s[c, j]
                total += weights[s] * (1.0 - w) * (_stop_usd(brake[j, 0], brake[j, 1], brake[j, 2], brake[j, 3], usd, cross_s[c, j], 0.0, d_m[j], x_end_m,
                                                             v_lim, rates, up, down, idle_usd_per_s, comfort, normal, lam_usd_per_s)
                                                   + _later_usd(d_m[j], t_go, 0.0, 0.0, j, s, tail))  # fmt: skip
                stops += weights[s] * (1.0 - w)
                if blocked < 0:
                    continue
            elif w < 1.0:
                # the plan goes through: unless a green comes early, where speeding up from then is cheaper
                total += weights[s] * (1.0 - w) * min(plan, early)
                if blocked < 0:
                    continue
            # the plan meets the red of line ``blocked``: what the car does once the timing shows itself
            a, b = windows[blocked, s, kb, 0], windows[blocked, s, kb, 1]
            if not np.isfinite(b):
                b = max(a, 0.0) + WAIT_CAP_S
            tb, xb, vb, ub = brake[blocked, 0], brake[blocked, 1], brake[blocked, 2], brake[blocked, 3]
            d_line = d_m[blocked]
            stopped = True
            shown, x, v, u = 0.0, 0.0, 0.0, 0.0
            if a > 0.0:  # a red still to come: it shows with its amber
                shown = max(a - clear_s[blocked], 0.0)
                x, v, u = _state_at(path, n_knots, shown)
            if a > 0.0 and (v <= 0.0 or (d_line - x <= 0.0 and not amber)):
                c_usd = plan  # over the line before it showed (or stopped short: the plan's own)
                stopped = False
            elif a > 0.0 and shown < tb and not stop_plan[c]:
                # shown before a stop must begin: glide to the line to reach it after the red, no slower than allowed
                d = d_line - x
                vg = min(v, d / max(b + after_red_s - shown, 1e-6))
                if vg >= min_speed_mps:
                    g, tg = _go_usd(d_line, vg, 0.0, x_end_m, v_lim, rates, up, normal, lam_usd_per_s)
                    c_usd = u + _at(rates[CRUISE], vg) * d / vg + g + lam_usd_per_s * (shown + d / vg) + _later_usd(d_line, shown + d / vg, vg, 0.0, blocked, s, tail)
                    stopped = False
                else:  # a stop at the line: hold the speed to where it must begin, brake, wait, launch
                    hold_m = max(d - v * v / (2.0 * comfort), 0.0)
                    t_stop = shown + hold_m / v + v / comfort
                    wait = max(b - t_stop, 0.0)
                    g, tg = _go_usd(d_line, 0.0, 0.0, x_end_m, v_lim, rates, up, normal, lam_usd_per_s)
                    c_usd = (u + _at(rates[CRUISE], v) * hold_m / v + _at(down, v) + idle_usd_per_s * wait + g + lam_usd_per_s * (t_stop + wait)
                             + _later_usd(d_line, t_stop + wait, 0.0, 0.0, blocked, s, tail))  # fmt: skip
            elif a <= 0.0 and b <= tb:
                # red now, over before a stop must begin: on with the plan until then, then speed up
                x, v, u = _state_at(path, n_knots, b)
                g, tg = _go_usd(x, v, reaction_s, x_end_m, v_lim, rates, up, normal, lam_usd_per_s)
                c_usd = u + g + lam_usd_per_s * b + _later_usd(x, b, v, reaction_s, blocked, s, tail)
                stopped = False
            elif a <= 0.0 and np.isfinite(tb) and b < tb + vb / comfort:
                # red now, over while the car brakes for it: roll on from the speed then
                vr = vb - comfort * (b - tb)
                xr = xb + (vb * vb - vr * vr) / (2.0 * comfort)
                g, tg = _go_usd(xr, vr, reaction_s, x_end_m, v_lim, rates, up, normal, lam_usd_per_s)
                c_usd = ub + _at(down, vb) - _at(down, vr) + g + lam_usd_per_s * b + _later_usd(xr, b, vr, reaction_s, blocked, s, tail)
                stopped = vr < min_speed_mps
            else:
                # a stop at the line (braked from where it must begin; too close for that: as costly as one can be)
                t_go = max(tb + vb / comfort if np.isfinite(tb) else cross_s[c, blocked], b)
                c_usd = (_stop_usd(tb, xb, vb, ub, usd, cross_s[c, blocked], b, d_line, x_end_m, v_lim, rates, up, down, idle_usd_per_s, comfort, normal,
                                   lam_usd_per_s)
                         + _later_usd(d_line, t_go, 0.0, 0.0, blocked, s, tail))  # fmt: skip
            if early < c_usd:
                # a green before the red the plan would meet (a slow plan that reaches the line after the red on now and
                # into the next one): the car speeds up as it comes, as where the plan meets no red
                c_usd, stopped = early, False
            total += weights[s] * w * c_usd
            if stopped:
                stops += weights[s] * w
        cost[c] = total
        p_stop[c] = stops
        if c == anchor:
            stop_cap = stops + risk_frac + 1e-9
    return cost, p_stop, through


@njit(cache=True)
def allowed(c, p_stop, through, anchor, risk_frac):
    """Whether plan ``c`` may be chosen: not through a red (``through``, the hard constraint) and a chance of a stop at
    most ``risk_frac`` above driving normally's (candidate ``anchor``: the chance constraint). [-]"""
    return p_stop[c] <= p_stop[anchor] + risk_frac + 1e-9 and not through[c]


@njit(cache=True)
def least_cost(cost, p_stop, through, anchor, stop, risk_frac, keep, margin_usd):
    """The plan chosen (index into the candidates (m,), as :func:`expected_costs` priced them; ``through``: a red met,
    the hard constraint): of the plans allowed (not through a red, a chance of a stop at most ``risk_frac`` above
    driving normally's, candidate ``anchor``; the last, the plan followed now, only where ``keep``), the least expected
    cost, the first of equals (a NaN cost, the first such, as ``np.argmin`` finds it); none allowed at a finite cost
    (those left stop short of the line, coasting to a halt), ``stop`` (a stop comes whatever the plan; where every plan
    allowed cost inf, the least fell on plan 0, through a red of every timing). Then the plan followed now where allowed
    and it costs no more than that one by ``margin_usd`` (a new reaction's worth), else the plan ``stop`` so."""
    m = cost.size
    best, least, nan_at, finite = 0, np.inf, -1, False
    for c in range(m):
        if allowed(c, p_stop, through, anchor, risk_frac) and (keep or c < m - 1):
            if np.isnan(cost[c]):
                nan_at = c if nan_at < 0 else nan_at
            else:
                finite = finite or np.isfinite(cost[c])
                if cost[c] < least:
                    best, least = c, cost[c]
    best = stop if not finite else nan_at if nan_at >= 0 else best
    if keep and allowed(m - 1, p_stop, through, anchor, risk_frac) and cost[m - 1] <= cost[best] + margin_usd:
        return m - 1  # the plan followed now, unless another is better by more than a new reaction costs
    if allowed(stop, p_stop, through, anchor, risk_frac) and cost[stop] <= cost[best] + margin_usd:
        return stop  # as good a plan as any (within a reaction's worth): the stop it comes to, said
    return best


@njit(cache=True)
def _pricing_order(vts, modes, v0, anchor):
    """The order in which :func:`expected_costs` prices the candidates (m,): ``anchor`` first (none: -1), then by motion,
    so that the candidates of one motion come one after the other: by the mode that acts (:func:`_same_motion`: modes
    0, 2 and 3 at a target the car is not above are one, 0), then by target, fastest first (a lift-off's coast is
    the same to every target it never reaches, the slowest ones, and so a coast in mode 1 to a target at or above the
    car's speed, which follows them). Any order gives the same results."""
    m = vts.size
    by_mode = np.empty(m, dtype=np.int64)
    for c in range(m):
        below = v0 <= vts[c] + 1e-9
        by_mode[c] = -1 if c == anchor else 0 if below and modes[c] != 1 else modes[c]
    by_target = np.argsort(-vts, kind="mergesort")
    order = np.empty(m, dtype=np.int64)
    k = 0
    for g in range(by_mode.min() if m else 0, by_mode.max() + 1 if m else 0):  # (a stable sort by mode of the targets' order, as a second argsort was)
        for c in by_target:
            if by_mode[c] == g:
                order[k] = c
                k += 1
    return order


@njit(cache=True, inline="always")
def _same_motion(c, last, vts, modes, reactions, accel_rows, accels, v0):
    """Candidates ``c`` and ``last`` make the same motion (:func:`_drive`), by their arguments: the same reaction and
    speeding up, and the same target and mode, where the mode acts (the car's speed ``v0`` above the target); at or
    below it, modes 0, 2 and 3 are one (speeding up to the target), and mode 1 is a coast whatever the target."""
    if reactions[c] != reactions[last] or accel_rows[c] != accel_rows[last] or accels[c] != accels[last]:
        return False
    below_c, below_last = v0 <= vts[c] + 1e-9, v0 <= vts[last] + 1e-9
    if below_c and below_last and (modes[c] == 1) == (modes[last] == 1):
        return modes[c] == 1 or vts[c] == vts[last]
    return modes[c] == modes[last] and vts[c] == vts[last]


@njit(cache=True, inline="always")
def _lower_free(c, last, vts, modes, reactions, accel_rows, accels, v0):
    """Candidate ``c`` makes the motion of ``last`` where that motion is free of its target (:func:`_drive`: slowing
    towards it until past the last line, never reaching it), by their arguments: the same reaction and speeding up, and
    either the same mode of slowing (0, 2 or 3) and a lower target (the car slows the same way, and does not reach that
    one either), or ``last`` coasting down (mode 0) and ``c`` a coast whatever its target (mode 1 at a target the car
    is not above: the same steps). On the bench observations a lift-off coasts past the lines above the slowest third
    of its targets."""
    if reactions[c] != reactions[last] or accel_rows[c] != accel_rows[last] or accels[c] != accels[last] or not vts[last] < v0 - 1e-9:
        return False
    if modes[c] == 1:
        return modes[last] == 0 and v0 <= vts[c] + 1e-9
    return modes[c] == modes[last] and modes[c] != 1 and vts[c] < vts[last]


@njit(cache=True, inline="always")
def _same_flags(c, last, cross_s, stop_plan, reactions, must):
    """Candidates ``c`` and ``last`` of one motion are priced alike (:func:`expected_costs`): the same crossings,
    flags and reaction (a green that comes early is taken only once the driver follows the plan)."""
    if stop_plan[c] != stop_plan[last] or reactions[c] != reactions[last] or (must is not None and must[c] != must[last]):
        return False
    for j in range(cross_s.shape[1]):
        if cross_s[c, j] != cross_s[last, j]:
            return False
    return True


@njit(cache=True, inline="always")
def _same_path(path, n_knots, brake, last_path, last_knots, last_brake):
    """Two priced motions are the same: the same knots (``path``, ``n_knots``) and states where stops must begin
    (``brake``)."""
    if n_knots != last_knots:
        return False
    for j in range(brake.shape[0]):
        for i in range(4):
            if brake[j, i] != last_brake[j, i]:  # (inf == inf; a NaN, never written, would differ)
                return False
    for i in range(4):
        for k in range(n_knots):
            if path[i, k] != last_path[i, k]:
                return False
    return True


def steady_time_value_usd_per_s(rates: np.ndarray, speed_mps: float) -> float:
    r"""The least price on time [$/s] at which cruising at ``speed_mps`` is the cheapest steady speed: with cost rate
    :math:`P(v)` [$/s] (the cruise row of :func:`rate_tables`), cost per metre :math:`(P + \lambda) / v` is least at
    :math:`v` where :math:`\lambda = v P'(v) - P(v)`. Time priced lower, a plan dawdles below the limit for its own sake;
    priced higher, it buys seconds with energy. ``advisory.physics.params.TIME_VALUE_USD_PER_S`` is this price at the
    paper car's 55 mph (24.6 m/s). Never below 0."""
    v = np.arange(rates.shape[1]) * RATE_DV_MPS
    i = min(max(int(round(speed_mps / RATE_DV_MPS)), 1), v.size - 2)
    slope = (rates[CRUISE, i + 1] - rates[CRUISE, i - 1]) / (2.0 * RATE_DV_MPS)
    return max(float(speed_mps * slope - np.interp(speed_mps, v, rates[CRUISE])), 0.0)
