"""The car's motion under advice: the coast-down profile, the time to reach a stop line and the speed there in each way
of changing speed (:data:`MODE_CODES`), which candidate cruise speeds cross the lines ahead on green
(:func:`green_mask`, :func:`first_feasible`, :func:`feasible_speeds_mps`), and every candidate plan's crossing times
(:func:`crossings`, with the plans a red bars: one no amber announces, or any of an exact light). numba kernels take arrays
(:class:`Lines` packs the lights for them); the wrappers unpack :class:`~advisory.advice.views.AdvisorParams`.
"""

from __future__ import annotations

import math
from functools import lru_cache
from typing import NamedTuple

import numpy as np
from numba import njit

from advisory.advice import choice
from advisory.advice.views import AdvisorParams, LightView, Observation
from advisory.physics.energy import road_load_force_n
from advisory.physics.params import VehicleParams


@lru_cache(maxsize=16)
def coast_profile(vehicle: VehicleParams, v_max_mps: float = 40.0, dt_s: float = 0.05) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """
    Coast-down (zero wheel power, flat) from ``v_max_mps`` to rest: speed [m/s] (decreasing), distance [m]
    and time [s] since the start, shape (n,). Coasting from v0 to v1 takes ``x(v1) - x(v0)`` and ``t(v1) - t(v0)``.
    """
    v, x, t = [v_max_mps], [0.0], [0.0]
    args = (vehicle.mass_kg, vehicle.rolling_coef, vehicle.rolling_speed_coef_s_per_m, vehicle.drag_coef,
            vehicle.frontal_area_m2, vehicle.air_density_kg_per_m3)
    while v[-1] > 0.0:
        decel = road_load_force_n(v[-1], 0.0, *args) / vehicle.mass_kg
        v_next = max(v[-1] - decel * dt_s, 0.0)
        h = dt_s if v_next > 0 else v[-1] / decel
        x.append(x[-1] + 0.5 * (v[-1] + v_next) * h)
        t.append(t[-1] + h)
        v.append(v_next)
    return np.array(v), np.array(x), np.array(t)


def coast_decel_mps2(v_mps: float, vehicle: VehicleParams) -> float:
    """Deceleration while coasting on the flat: road load over mass. [m/s²]"""
    return float(road_load_force_n(v_mps, 0.0, vehicle.mass_kg, vehicle.rolling_coef, vehicle.rolling_speed_coef_s_per_m,
                                   vehicle.drag_coef, vehicle.frontal_area_m2, vehicle.air_density_kg_per_m3)) / vehicle.mass_kg


MODE_CODES = {"auto": 0, "brake_coast": 1, "brake": 2, "firm": 3}
"""How the speed changes towards a target (see :func:`crossing_time_s`), as kernel codes."""


COAST_TABLE_DV_MPS = 0.01
COAST_TABLE_DX_M = 0.25
"""Steps of the uniform coast-down tables the kernels interpolate in O(1) (speed [m/s], distance [m])."""


@lru_cache(maxsize=16)
def coast_arrays(vehicle: VehicleParams) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The coast-down profile on uniform grids: distance and time from the top speed down to speed ``i dv``
    (ascending speed), and time to cover distance ``j dx``. [m], [s], [s]"""
    v, x, t = coast_profile(vehicle)
    v_grid = np.arange(0.0, v[0] + COAST_TABLE_DV_MPS, COAST_TABLE_DV_MPS)
    x_grid = np.arange(0.0, x[-1] + COAST_TABLE_DX_M, COAST_TABLE_DX_M)
    x_of_v, t_of_v = np.interp(v_grid, v[::-1], x[::-1]), np.interp(v_grid, v[::-1], t[::-1])
    return x_of_v, t_of_v, np.interp(x_grid, x, t)


_lerp = choice.lerp_uniform


@njit(cache=True)
def time_to_line_s(d_m, v0, vt, mode, reaction_s, brake_mps2, firm_mps2, accel_mps2, x_of_v, t_of_v, t_of_x):
    """Time to a line ``d_m`` ahead for one target speed (see :func:`crossing_time_s`). [s]"""
    dv, dx = COAST_TABLE_DV_MPS, COAST_TABLE_DX_M
    d = max(d_m, 0.0)
    d_react = v0 * reaction_s
    if d <= d_react:
        return d / v0 if v0 > 0.0 else np.inf
    d -= d_react
    if mode == 1:  # brake gently to the target, then coast all the way
        v1 = min(vt, v0)
        d_b = (v0 * v0 - v1 * v1) / (2.0 * brake_mps2)
        if d <= d_b:
            return reaction_s + (v0 - np.sqrt(max(v0 * v0 - 2.0 * brake_mps2 * d, 0.0))) / brake_mps2
        xs = _lerp(x_of_v, dv, v1) + d - d_b
        if xs > x_of_v[0]:
            return np.inf
        return reaction_s + (v0 - v1) / brake_mps2 + _lerp(t_of_x, dx, xs) - _lerp(t_of_v, dv, v1)
    slower = vt < v0
    if slower and mode == 0:  # lift off and coast down to the target, then hold it
        x0, t0 = _lerp(x_of_v, dv, v0), _lerp(t_of_v, dv, v0)
        x1, t1 = _lerp(x_of_v, dv, vt), _lerp(t_of_v, dv, vt)
        if d <= x1 - x0:
            return reaction_s + _lerp(t_of_x, dx, x0 + d) - t0
        return reaction_s + (t1 - t0) + (d - (x1 - x0)) / vt if vt > 0.0 else np.inf
    # a constant-rate change (speeding up; or braking in the brake / firm modes)
    rate = (firm_mps2 if mode == 3 else brake_mps2) if slower else accel_mps2
    d_ramp = abs(v0 * v0 - vt * vt) / (2.0 * rate)
    if d <= d_ramp:
        v_line = np.sqrt(max(v0 * v0 + 2.0 * (-rate if slower else rate) * d, 0.0))
        return reaction_s + abs(v_line - v0) / rate if v_line > 0.0 else np.inf
    return reaction_s + abs(v0 - vt) / rate + (d - d_ramp) / vt if vt > 0.0 else np.inf


@njit(cache=True)
def _coast_speed_at(x_of_v, xs):
    """Speed [m/s] at coast-down distance ``xs`` from the top speed (``x_of_v`` decreases with speed)."""
    if xs >= x_of_v[0]:
        return 0.0
    lo, hi = 0, x_of_v.size - 1  # x_of_v[lo] > xs >= x_of_v[hi]
    if xs <= x_of_v[hi]:
        return hi * COAST_TABLE_DV_MPS
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if x_of_v[mid] > xs:
            lo = mid
        else:
            hi = mid
    return (lo + (x_of_v[lo] - xs) / (x_of_v[lo] - x_of_v[hi])) * COAST_TABLE_DV_MPS


@njit(cache=True)
def line_speeds_mps(d_m, v0, vt, mode, reaction_s, brake_mps2, firm_mps2, accel_mps2, x_of_v, t_of_v, t_of_x):
    """Speed on reaching a line ``d_m`` ahead, per target speed, in the motion of :func:`crossing_time_s`. (n,)"""
    dv = COAST_TABLE_DV_MPS
    out = np.empty(vt.size)
    for i in range(vt.size):
        d = max(d_m, 0.0) - v0 * reaction_s
        if d <= 0.0:
            out[i] = v0
            continue
        slower = vt[i] < v0
        if mode == 1 or (slower and mode == 0):
            v1 = min(vt[i], v0)
            d_b = (v0 * v0 - v1 * v1) / (2.0 * brake_mps2) if mode == 1 else 0.0
            if d <= d_b:
                out[i] = np.sqrt(max(v0 * v0 - 2.0 * brake_mps2 * d, 0.0))
                continue
            x0 = _lerp(x_of_v, dv, v1 if mode == 1 else v0)
            if mode == 0 and d > _lerp(x_of_v, dv, vt[i]) - x0:
                out[i] = vt[i]  # reached the target, then held it
            else:
                out[i] = _coast_speed_at(x_of_v, x0 + d - d_b)
            continue
        rate = (firm_mps2 if mode == 3 else brake_mps2) if slower else accel_mps2
        if abs(v0 * v0 - vt[i] * vt[i]) / (2.0 * rate) <= d:
            out[i] = vt[i]
        else:
            out[i] = np.sqrt(max(v0 * v0 + 2.0 * (-rate if slower else rate) * d, 0.0))
    return out


@njit(cache=True)
def crossing_times_s(d_m, v0, vt, mode, reaction_s, brake_mps2, firm_mps2, accel_mps2, x_of_v, t_of_v, t_of_x):
    out = np.empty(vt.size)
    for i in range(vt.size):
        out[i] = time_to_line_s(d_m, v0, vt[i], mode, reaction_s, brake_mps2, firm_mps2, accel_mps2, x_of_v, t_of_v, t_of_x)
    return out


@njit(cache=True, inline="always")
def _in_red(tc, windows_s, j, slowing, no_amber, after_red_s):
    """A crossing at ``tc`` of line ``j`` inside a red of ``windows_s`` (padded red windows, (lines, k, 2)), or within
    ``after_red_s`` after one ends, or, for a plan that slows the car (``slowing``) at a light that shows no amber
    (``no_amber``, (lines,)), as long before one begins (:func:`green_mask`)."""
    before_red_s = after_red_s if slowing and no_amber[j] else 0.0
    for k in range(windows_s.shape[1]):
        a = windows_s[j, k, 0]
        if (a - before_red_s if a > 0.0 else a) <= tc < windows_s[j, k, 1] + after_red_s:
            return True
    return False


@njit(cache=True)
def green_mask(speeds, distances_m, windows_s, no_amber, n_lines, after_red_s, v0, mode, reaction_s, brake_mps2, firm_mps2, accel_mps2, x_of_v, t_of_v,
                t_of_x):  # fmt: skip
    """Per candidate speed: each of the first ``n_lines`` lines reached on green, at least ``after_red_s``
    after a red ends and, for a plan that slows the car at a light that shows no amber (``no_amber``, (lines,)), as
    long before a red to come begins (``windows_s``: padded red windows, (lines, k, 2)). bool (n,)

    The margin before a red's start (issue 28): a slowing plan is a speed change the driver makes a reaction late and
    tracks loosely, as it is after a red's end; "Slow to 25 mph, then coast" priced 0.25 s before a red with no amber
    crossed 0.5 s into it (docs/history/TRAFFIC.md, the ``--spat-queue`` red entry). A plan that holds or speeds up is the
    regular driver's own motion, over the line no later than planned; where an amber comes first, it warns the driver
    (who clears it or stops, as without advice)."""
    ok = np.ones(speeds.size, dtype=np.bool_)
    for i in range(speeds.size):
        slowing = mode == 1 or speeds[i] < v0 - 1e-9
        for j in range(n_lines):
            tc = time_to_line_s(distances_m[j], v0, speeds[i], mode, reaction_s, brake_mps2, firm_mps2, accel_mps2, x_of_v, t_of_v, t_of_x)
            if not np.isfinite(tc) or _in_red(tc, windows_s, j, slowing, no_amber, after_red_s):
                ok[i] = False
                break
    return ok


@njit(cache=True)
def makes_greens(speed, distances_m, windows_s, no_amber, n_lines, after_red_s, v0, mode, reaction_s, brake_mps2, firm_mps2, accel_mps2, x_of_v, t_of_v,
                 t_of_x):  # fmt: skip
    """:func:`green_mask` of one speed, a bool (no array in or out: a plan followed now is re-checked at every fix)."""
    return green_mask(np.full(1, speed), distances_m, windows_s, no_amber, n_lines, after_red_s, v0, mode, reaction_s, brake_mps2, firm_mps2, accel_mps2,
                      x_of_v, t_of_v, t_of_x)[0]  # fmt: skip


@njit(cache=True)
def first_feasible(speeds, distances_m, windows_s, no_amber, after_red_s, v0, reaction_s, brake_mps2, firm_mps2, accel_mps2, x_of_v, t_of_v, t_of_x):
    """The advisor's search in one call: all lines, else the first alone; in each, the modes in the order
    auto, brake_coast, brake, firm (:data:`MODE_CODES`). Returns (lines used, mode code, ``lo``, ``hi``): the feasible
    speeds that make the earliest greens are ``speeds[lo:hi]``, the run of consecutive feasible candidates that ends at
    the fastest one (:func:`search`; empty where no mode makes a green)."""
    n = distances_m.size
    for attempt in range(2 if n > 1 else 1):
        n_lines = n if attempt == 0 else 1
        for mode in range(4):
            ok = green_mask(speeds, distances_m, windows_s, no_amber, n_lines, after_red_s, v0, mode, reaction_s, brake_mps2, firm_mps2, accel_mps2, x_of_v,
                            t_of_v, t_of_x)  # fmt: skip
            hi = ok.size
            while hi > 0 and not ok[hi - 1]:
                hi -= 1
            if hi > 0:
                lo = hi - 1
                while lo > 0 and ok[lo - 1]:
                    lo -= 1
                return n_lines, mode, lo, hi
    return n, 0, 0, 0


def crossing_time_s(
    distance_m: float, v0_mps: float, v_target_mps, params: AdvisorParams, mode: str = "auto", reaction_s: float | None = None
):
    """
    Time to reach a line ``distance_m`` ahead: reaction at v0, a speed change to the target, then cruise. [s]

    ``v_target_mps`` may be an array (one time per target). ``mode``: how the speed changes: "auto" (lift
    off and coast when slowing, accelerate comfortably when speeding up), "brake_coast" (brake gently to the
    target, then coast all the way), "brake" / "firm" (brake gently / firmly to the target, then hold).
    ``inf`` where the car would not reach the line.
    """
    reaction = params.reaction_s if reaction_s is None else reaction_s
    if type(v_target_mps) is float:  # one target: the scalar kernel (no array in or out)
        return time_to_line_s(float(distance_m), float(v0_mps), v_target_mps, MODE_CODES[mode], float(reaction), *motion_args(params))
    vt = np.asarray(v_target_mps, dtype=float)
    out = crossing_times_s(float(distance_m), float(v0_mps), vt.reshape(-1), MODE_CODES[mode], float(reaction), *motion_args(params))
    return out.reshape(vt.shape) if vt.ndim else float(out[0])


def line_speed_mps(distance_m: float, v0_mps: float, v_target_mps: float, params: AdvisorParams, mode: str = "auto", reaction_s: float | None = None) -> float:
    """The speed on reaching a line ``distance_m`` ahead in the motion of :func:`crossing_time_s` (same arguments, one
    target). [m/s]

    Examples
    --------
    >>> line_speed_mps(100.0, 10.0, 5.0, AdvisorParams(), "brake"), line_speed_mps(100.0, 5.0, 10.0, AdvisorParams())
    (5.0, 10.0)
    """
    reaction = params.reaction_s if reaction_s is None else reaction_s
    out = line_speeds_mps(float(distance_m), float(v0_mps), np.array([float(v_target_mps)]), MODE_CODES[mode], float(reaction), *motion_args(params))
    return float(out[0])


@lru_cache(maxsize=64)
def candidates_mps(low_mps: float, limit_mps: float, step_mps: float) -> np.ndarray:
    speeds = np.append(np.arange(low_mps, limit_mps - 1e-6, step_mps), limit_mps)  # the limit once, exactly
    speeds.setflags(write=False)
    return speeds


class Lines(NamedTuple):
    """The lights to cross, packed for the kernels: distances (n,), red windows (n, k, 2), padded with +inf, and
    which lights show no amber (n,). (A named tuple: made at every fix, cheaper than a frozen dataclass.)"""

    distances_m: np.ndarray
    windows_s: np.ndarray
    no_amber: np.ndarray

    @classmethod
    def of(cls, lights) -> Lines:
        n = len(lights)
        k = max(max((len(light.red_windows_s) for light in lights), default=0), 1)
        flat: list[float] = []  # one flat list, one np.array call: the cheapest packing (runs once per fix)
        for light in lights:
            for window in light.red_windows_s:
                flat += window
            flat += (np.inf,) * (2 * (k - len(light.red_windows_s)))
        flat += [light.distance_m for light in lights]
        packed = np.array(flat, dtype=float)  # windows, then distances
        return cls(packed[2 * n * k :], packed[: 2 * n * k].reshape(n, k, 2), np.array([light.amber_s == 0.0 for light in lights], dtype=np.bool_))


_MOTION: dict[int, tuple[AdvisorParams, tuple, tuple]] = {}
"""The kernels' arguments that depend on the advisor's settings alone, by the identity of the settings (kept alive
here, so their id is not reused): hashed once, not at every fix (a vehicle's dataclass hashes all its fields)."""


def _motion(params: AdvisorParams) -> tuple[AdvisorParams, tuple, tuple]:
    hit = _MOTION.get(id(params))
    if hit is None or hit[0] is not params:
        if len(_MOTION) >= 256:
            _MOTION.clear()
        coast = coast_arrays(params.vehicle)
        hit = _MOTION[id(params)] = (params, (params.comfort_decel_mps2, params.firm_decel_mps2, params.comfort_accel_mps2, *coast),
                                     (params.comfort_decel_mps2, params.firm_decel_mps2, params.normal_accel_mps2, *coast))  # fmt: skip
    return hit


def motion_args(params: AdvisorParams) -> tuple:
    """The kernels' last arguments (``brake_mps2, firm_mps2, accel_mps2, x_of_v, t_of_v, t_of_x``) for an advised plan:
    speeding up at ``comfort_accel_mps2``."""
    return _motion(params)[1]


def kernel_args(obs: Observation, params: AdvisorParams, reaction_s: float | None) -> tuple:
    speeds = candidates_mps(params.min_cruise_speed_mps, obs.speed_limit_mps, params.speed_step_mps)
    reaction = params.reaction_s if reaction_s is None else reaction_s
    return speeds, float(obs.speed_mps), float(reaction), *_motion(params)[1]


def _green(lines: Lines, obs: Observation, params: AdvisorParams, mode: str, speeds: np.ndarray, reaction_s: float | None = None, n_lines: int | None = None) -> np.ndarray:
    """Which of ``speeds`` reach each of the first ``n_lines`` lines (all by default) on green. bool (n,)"""
    _, v0, reaction, *rest = kernel_args(obs, params, reaction_s)
    n = lines.distances_m.size if n_lines is None else n_lines
    return green_mask(speeds, lines.distances_m, lines.windows_s, lines.no_amber, n, params.green_margin_s, v0, MODE_CODES[mode], reaction, *rest)


def _feasible(lines: Lines, obs: Observation, params: AdvisorParams, mode: str, reaction_s: float | None = None, n_lines: int | None = None) -> np.ndarray:
    speeds = candidates_mps(params.min_cruise_speed_mps, obs.speed_limit_mps, params.speed_step_mps)
    return speeds[_green(lines, obs, params, mode, speeds, reaction_s, n_lines)]


def keeps(lines: Lines, obs: Observation, params: AdvisorParams, mode: str, target_mps: float, n_lines: int | None = None) -> bool:
    """A driver already following ``target_mps`` in ``mode`` (so no new reaction delay) still makes every green:
    the target is still a candidate speed and feasible (one speed through the kernel, not all candidates)."""
    if not params.min_cruise_speed_mps - 1e-9 <= target_mps <= obs.speed_limit_mps + 1e-9:
        return False
    n = lines.distances_m.size if n_lines is None else n_lines
    return makes_greens(float(target_mps), lines.distances_m, lines.windows_s, lines.no_amber, n, params.green_margin_s, float(obs.speed_mps),
                        MODE_CODES[mode], 0.0, *motion_args(params))  # fmt: skip


MODE_NAMES = {code: name for name, code in MODE_CODES.items()}


def search(lines: Lines, obs: Observation, params: AdvisorParams) -> tuple[int, str, np.ndarray]:
    """Lift off and coast (or speed up) if that makes the greens; brake gently only if coasting cannot;
    firmly only if gentle braking cannot; if no speed makes all lines, plan for the next one alone.
    Returns (lines planned for, mode, feasible speeds): of the feasible speeds, those that make the earliest greens,
    the run of consecutive feasible candidates that ends at the fastest one. A gap in the run is a red between two
    greens; a slower run aims at a later green, a whole cycle lost (the tables' value of time prices a crawl to the
    next green below a brisk run to this one, but the paper's optimum is held to the regular driver's trip time, and
    the driver would not wait a cycle for it)."""
    speeds, v0, reaction, *rest = kernel_args(obs, params, None)
    n_lines, mode, lo, hi = first_feasible(speeds, lines.distances_m, lines.windows_s, lines.no_amber, params.green_margin_s, v0, reaction, *rest)
    return n_lines, MODE_NAMES[mode], speeds[lo:hi]


def feasible_speeds_mps(
    obs: Observation, params: AdvisorParams, mode: str = "auto", reaction_s: float | None = None, lights=None
) -> np.ndarray:
    """Candidate cruise speeds in [min cruise, limit] that cross the next two lines on green. [m/s]

    ``lights`` replaces ``obs.lights`` (the advisor checks subsets of the lights ahead).
    """
    return _feasible(Lines.of((obs.lights if lights is None else lights)[:2]), obs, params, mode, reaction_s)


def green_crossing(light: LightView, t_s: float, after_red_s: float) -> bool:
    """The line is reached (finite time), not during a (conservative) red nor within ``after_red_s`` after one ends."""
    return math.isfinite(t_s) and not any(start <= t_s < end + after_red_s for start, end in light.red_windows_s)


def slowed_into_red(light: LightView, t_s: float, margin_s: float) -> bool:
    """A slowing plan reaches a light that shows no amber within ``margin_s`` before a red begins (the margin
    :func:`green_mask` keeps before such a red)."""
    return light.amber_s == 0.0 and any(0.0 < start and start - margin_s <= t_s < start for start, _ in light.red_windows_s)


def normal_crossing_s(distance_m: float, obs: Observation, params: AdvisorParams) -> float:
    """Time to a line ``distance_m`` ahead driving normally: speeding up to the limit at ``normal_accel_mps2`` at once
    (no advice to react to), the kernel's "auto" motion. [s]"""
    return time_to_line_s(float(distance_m), float(obs.speed_mps), float(obs.speed_limit_mps), MODE_CODES["auto"], 0.0, *_motion(params)[2])


def drives_normally(lines: Lines, obs: Observation, params: AdvisorParams, n_lines: int | None = None) -> bool:
    """A normal drive (speeding up to the limit at ``normal_accel_mps2`` at once, no advice to react to: the motion of
    :func:`normal_crossing_s`) makes every green of the first ``n_lines`` lines (all by default), with the margin after
    a red, as an advised speed-up must (:func:`green_mask`). [-]"""
    n = lines.distances_m.size if n_lines is None else n_lines
    return makes_greens(float(obs.speed_limit_mps), lines.distances_m, lines.windows_s, lines.no_amber, n, params.green_margin_s, float(obs.speed_mps),
                        MODE_CODES["auto"], 0.0, *_motion(params)[2])  # fmt: skip


KEEP_MODES = {"slow_down": "brake", "brake_to": "firm", "coast": "brake_coast", "ease_off": "auto", "accelerate": "auto", "cruise": "auto"}
"""How a driver following each action changes speed (the mode its feasibility is re-checked in)."""


@njit(cache=True)
def crossings(vts, modes, reactions, accels, d_m, v0, brake_mps2, firm_mps2, x_of_v, t_of_v, t_of_x, windows_s, no_amber, exact, stop_plan, after_red_s):
    """Time to each line (m, lines) of each candidate plan, in the motion of :func:`crossing_time_s` [s], and which
    plans (m,) reach a line whose reds bar a crossing inside a red of ``windows_s`` or its margins (:func:`_in_red`; a
    plan slows the car in mode 1, or to a target below ``v0``): a line that shows no amber (``no_amber``, (lines,)), or
    one whose timing is exact (``exact``, (lines,)) for any plan but "prepare to stop" (``stop_plan``, (m,): it stops
    at the red it meets). bool (m,)"""
    cross = np.empty((vts.size, d_m.size))
    crossed = np.zeros(vts.size, dtype=np.bool_)
    for c in range(vts.size):
        slowing = modes[c] == 1 or vts[c] < v0 - 1e-9
        for j in range(d_m.size):
            cross[c, j] = time_to_line_s(d_m[j], v0, vts[c], modes[c], reactions[c], brake_mps2, firm_mps2, accels[c], x_of_v, t_of_v, t_of_x)
            if (no_amber[j] or (exact[j] and not stop_plan[c])) and _in_red(cross[c, j], windows_s, j, slowing, no_amber, after_red_s):
                crossed[c] = True
    return cross, crossed
