"""The two-light advisor: what the driver hears, from position, speed and the next two lights' timing.

Pure: ``advise(observation, memory, params, tables)`` returns ``(Advice, new memory)``. No clock, no I/O; the
service converts GPS fixes and SPaT readings into an :class:`Observation` (times relative to *now*).

How the advice is made (docs/ADVISOR.md):

1. **Suppression** (as in-car systems such as Audi's Traffic Light Information do): no speed advice when the
   next light's SPaT is missing, stale or of low confidence, when the car is too close to the stop line to
   act, or when the wait at red would only be a few seconds. Said plainly ("No signal data.").
2. **Feasible cruise speeds**: for each candidate speed, the car (after a reaction time and a comfortable
   speed change) crosses each of the next two stop lines at an instant that is green under the
   *conservative* red windows (uncertain changes widened to their [min, max] window). Only feasible
   speeds within [min cruise speed, limit] are ever advised.
3. **Target**: among feasible speeds, the DP lookup tables' target for this position, speed and signal
   phase when the tables match the live SPaT; otherwise the highest feasible speed (the rule-based closed
   form). If none: prepare to stop when a stop is near, "Red light ahead." when far.
4. **Hysteresis**: the previous target is kept while it stays feasible and close; ``speak`` is raised only when
   the action changes, or the target moves by ``speak_change_mps``.

Under uncertain timing (an actuated or predicted light) the plan of least expected cost over the lights' equally
likely timings, each plan priced with recourse, replaces 2-4 (:func:`_choose`, :mod:`advisory.advice.choice`;
docs/ADVISOR.md, "The choice on the distribution"); the ordered rules it replaced are gone.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from numba import njit

from advisory.advice import choice
from advisory.physics.energy import road_load_force_n
from advisory.physics.params import PAPER_54KWH, VehicleParams

MPH_PER_MPS = 1 / 0.44704
KMH_PER_MPS = 3.6
SLOW_FIRST_FRAC = 0.97
"""A "coast" advice whose target is below this share of the current speed is worded "Slow to X, then coast";
otherwise the braking part is negligible and it is "Lift off and coast". [-]"""


class Timings(tuple):
    """A light's equally likely timings (``LightView.scenario_red_windows_s``: one tuple of red windows ``(start, end)``
    per timing) that also carries them packed, ``array_s``: shape ``(timings, k, 2)``, each timing's windows in order,
    padded with +inf (``k`` the most windows of a timing). The observation makes them so
    (:func:`spat_feed.prediction.observe.light_view`), and :func:`_timings` takes the array as it is instead of packing
    the tuples again (20 timings' windows: ~25 us a view). As a tuple it is the plain tuple of its timings. [s]

    Examples
    --------
    >>> t = Timings.packed((((0.0, 10.0),), ((0.0, 12.0), (50.0, 60.0))))
    >>> t == (((0.0, 10.0),), ((0.0, 12.0), (50.0, 60.0))), t.array_s.shape, t.array_s[0, 1].tolist()
    (True, (2, 2, 2), [inf, inf])
    """

    array_s: np.ndarray

    @classmethod
    def packed(cls, timings) -> Timings:
        """The timings (tuples of windows), packed."""
        out = cls(timings)
        out.array_s = _packed(out, max((len(w) for w in out), default=0))
        return out


def _packed(timings, k: int) -> np.ndarray:
    """Timings (tuples of windows) as an array ``(len(timings), k, 2)`` padded with +inf: one flat list, one np.array
    call (a slice assignment per timing cost 30 us a fix). [s]"""
    flat: list[float] = []
    for windows in timings:
        for window in windows:
            flat += window
        flat += (np.inf,) * (2 * (k - len(windows)))
    return np.array(flat, dtype=float).reshape(len(timings), k, 2)


@dataclass(frozen=True, slots=True)
class LightView:
    """One light ahead, as the advisor sees it. Times are relative to now. [m], [s]

    ``red_windows_s``: upcoming red intervals ``(start, end)`` relative to now, conservative: an uncertain
    change to red counts from its earliest possible time, a change to green from its latest. A window with
    ``start <= 0`` means red now. At least the windows of the next ~2 minutes.

    Under uncertainty (an actuated light) two more views. ``likely_red_windows_s``: each change at its likely
    instant (the countdown; whether a stop is likely; what a plan aims between when the conservative windows leave
    no speed; it contains every red that minEnd guarantees). ``late_red_windows_s``: each change at its latest
    instant: a car reaching the line inside a likely red but before such a red begins may still beat it as it is,
    and is not slowed for the green after it; a driver's display may rely on a red lasting until then.
    """

    intersection_id: int
    distance_m: float
    fresh: bool = True
    confidence_frac: float = 1.0
    red_windows_s: tuple[tuple[float, float], ...] = ()
    likely_red_windows_s: tuple[tuple[float, float], ...] | None = None  # every change at its likely time; None: as red_windows_s
    late_red_windows_s: tuple[tuple[float, float], ...] | None = None  # every change at its latest; None: not known
    age_s: float = 0.0  # how old the SPaT behind this view is (a dropout: not fresh, windows of the last reading) [s]
    unknown_windows_s: tuple[tuple[float, float], ...] = ()  # phases whose state nothing reads, at their likely times [s]
    """Within the windows above, the phases whose state is unknown (J2735 ``unavailable`` or ``dark`` that the
    group's history cannot read, where they end: not the open tail past what it can bound), as each change is
    likely: no plan crosses in them, but they are not a red: no stop is asked for them (the driver is told there is
    no data)."""

    scenario_red_windows_s: tuple[tuple[tuple[float, float], ...], ...] | None = None
    """Under uncertainty, the red windows of each of the light's equally likely timings (every change at one quantile
    of its forecast, :mod:`advisory.advice.choice`); None: the timing is exact (``red_windows_s``). A window begins
    with the amber before its red, where the light shows one."""
    amber_s: float | None = None
    """The amber the light shows before each red, where its source knows it: None (unknown) is some amber, as traffic
    law requires; 0: none (a green may turn red at once). [s]"""

    queue_m: float | None = None
    """The queue standing back from the stop line that the controller published with a fresh reading (J2735
    ``queueLength``; queue-aware advice counts its cars first, :func:`advisory.advice.queue.estimate`); None: not said. [m]"""

    def likely_red_at(self, t_s: float) -> bool:
        """Red at ``t_s`` seconds from now if every change comes at its likely time (exact plans: :meth:`is_red_at`);
        a phase of unknown state is not a red."""
        windows = self.red_windows_s if self.likely_red_windows_s is None else self.likely_red_windows_s
        return any(start <= t_s < end for start, end in windows) and not self.unknown_at(t_s)

    def unknown_at(self, t_s: float) -> bool:
        """The state at ``t_s`` seconds from now is unknown (as each change is likely)."""
        return any(start <= t_s < end for start, end in self.unknown_windows_s)

    @property
    def red_now(self) -> bool:
        return any(start <= 0.0 < end for start, end in self.red_windows_s)

    def is_red_at(self, t_s: float) -> bool:
        """Red (conservatively) at ``t_s`` seconds from now; a crossing at the exact green start is allowed."""
        return any(start <= t_s < end for start, end in self.red_windows_s)

    def seconds_to_green(self) -> float:
        """0 if green now, else seconds until the current red surely ends. [s]"""
        for start, end in self.red_windows_s:
            if start <= 0.0 < end:
                return end
        return 0.0

    def seconds_to_green_after(self, t_s: float) -> float:
        """Seconds from now until the red covering ``t_s`` from now surely ends (``t_s`` if green then). [s]"""
        for start, end in self.red_windows_s:
            if start <= t_s < end:
                return end
        return t_s

    def seconds_to_red(self) -> float | None:
        """Seconds until the next red may begin (0 if red now), None if none is known. [s]"""
        starts = [max(start, 0.0) for start, end in self.red_windows_s if end > 0.0]
        return min(starts) if starts else None


@dataclass(frozen=True, slots=True)
class Observation:
    """What the advisor knows at one instant. ``lights``: the lights ahead, nearest first."""

    speed_mps: float
    speed_limit_mps: float
    lights: tuple[LightView, ...] = ()
    position_m: float | None = None  # along the corridor, for the DP tables
    on_route: bool = True
    zone_exit: bool = False  # left the route past its last light: the advice ends, nothing is wrong
    followers: float = 0.0
    """Cars expected behind this one that a slower plan holds up (the service's estimate in traffic:
    :func:`advisory.advice.queue.estimate`; 0 on an empty road). Each loses what the car loses, so every price the
    advisor puts on time lost is ``1 + followers`` times its own (:func:`time_price`). [-]"""


ACTIONS = ("cruise", "ease_off", "coast", "slow_down", "brake_to", "accelerate", "stop", "resume", "none")
"""Every ``Advice.action`` the advisor gives (the service's API enumerates these: keep them in step)."""
REASONS = ("green_wave", "red_ahead", "past_lights", "off_route", "no_spat", "stale_spat", "low_confidence", "too_close", "short_wait", "tight_green",
           "far_ahead")
"""Every ``Advice.reason`` the advisor gives (the service's API enumerates these: keep them in step)."""


@dataclass(frozen=True, slots=True)
class Advice:
    """One advisory. ``action``: cruise, ease_off (lift off and coast down to the target, then hold it),
    coast (brake gently to the target, then keep coasting to the light), slow_down (brake gently to the
    target, then hold it), brake_to (brake firmly to it, then hold), accelerate, stop, resume, or none (no
    speed advice; ``reason`` says why)."""

    action: str
    reason: str
    target_speed_mps: float | None = None
    light_red: bool | None = None
    seconds_to_change_s: float | None = None
    message: str = ""
    speak: bool = False
    source: str = "rules"  # "dp_table" when the target came from the lookup tables
    current_speed_mps: float | None = None  # the car's speed when advised ("Slow to X, then coast" vs "Lift off")
    light_ahead: int = 1  # which light the countdown (light_red, seconds_to_change_s) is about: 1 next, 2 the one after
    light_id: int | None = None  # that light's intersection id (None: no countdown)

    @property
    def counts_down_to(self) -> str | None:
        """What ``seconds_to_change_s`` counts down to: "green" while the light is red now, "red" while it is not;
        None without a countdown (unknown or never). Always the light's next change (``light_id``), never a later one."""
        if self.light_red is None or self.seconds_to_change_s is None or not math.isfinite(self.seconds_to_change_s):
            return None
        return "green" if self.light_red else "red"

    def as_dict(self) -> dict:
        return {k: getattr(self, k) for k in self.__slots__}


def time_price(obs: Observation) -> float:
    """How many cars lose the time a plan gives up: this one and the followers it holds up (``1 + obs.followers``).
    The price on time (``time_value_usd_per_s``, the choice under uncertainty) is multiplied by it, and the time a plan
    may give up for its energy (``table_slack_s``, the tables' target) divided by it (issue 28: the traffic behind; the
    service's own check counts it alike, :func:`advisory.advice.queue.gives_up_green`). [-]

    Examples
    --------
    >>> time_price(Observation(10.0, 20.0)), time_price(Observation(10.0, 20.0, followers=1.5))
    (1.0, 2.5)
    """
    return 1.0 + max(obs.followers, 0.0)


@dataclass(frozen=True, slots=True)
class AdvisorParams:
    """Advisor settings. Units in names."""

    min_cruise_speed_mps: float = 10 * 0.44704  # slowest speed ever advised (a creep towards a red)
    reaction_s: float = 1.0
    green_margin_s: float = 2.0  # advised crossings at least this long after a red ends (driver reaction, tracking error) [s]
    comfort_decel_mps2: float = 1.5
    firm_decel_mps2: float = 3.0  # "brake to X" when gentle braking cannot make the green (regular driver: 4)
    comfort_accel_mps2: float = 1.5
    normal_accel_mps2: float = 2.0  # how a driver speeds up with no advice (the regular driver's rate, paper Sec. 2)
    too_close_s: float = 3.0  # closer than this many seconds to the line at current speed: no advice
    too_close_m: float = 15.0
    short_wait_s: float = 3.0
    table_slack_s: float = 3.0  # the tables' target reaches the lines at most this much later than the fastest feasible one [s]
    min_confidence_frac: float = 0.5
    stop_lead_s: float = 2.0  # "prepare to stop" this long before a comfortable stop must begin (earlier: "Red light ahead.") [s]
    hold_stale_s: float = 30.0  # through a dropout this short the last advice is held (re-checked on the last SPaT) [s]
    hysteresis_mps: float = 1.0
    stop_risk_frac: float = 0.1  # uncertain timing: a plan may make a stop likelier than driving normally by at most this [-]
    time_value_usd_per_s: float | None = None  # uncertain timing: the price on time; None: the road's (choice.steady_time_value_usd_per_s) [$/s]
    speak_change_mps: float = 5 * 0.44704
    speed_step_mps: float = 0.44704  # candidates in whole mph: the spoken number is the advised one
    units: str = "mph"
    vehicle: VehicleParams = PAPER_54KWH  # for the coast-down profile

    def __post_init__(self) -> None:
        if self.units not in ("mph", "kmh"):
            raise ValueError("units must be 'mph' or 'kmh'")


@dataclass(frozen=True, slots=True)
class AdvisorMemory:
    """What the advisor remembers between fixes of one trip (for hysteresis and the speak flag)."""

    last: Advice | None = None
    spoken: Advice | None = None


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


LINE_SPEED_TIE_MPS = 0.2
"""Targets whose speeds at the next line differ by less than this count as equally close to the tables'
wanted speed there; the tie goes to the target nearest it. [m/s]"""

MODE_CODES = {"auto": 0, "brake_coast": 1, "brake": 2, "firm": 3}
"""How the speed changes towards a target (see :func:`crossing_time_s`), as kernel codes."""


COAST_TABLE_DV_MPS = 0.01
COAST_TABLE_DX_M = 0.25
"""Steps of the uniform coast-down tables the kernels interpolate in O(1) (speed [m/s], distance [m])."""


@lru_cache(maxsize=16)
def _coast_arrays(vehicle: VehicleParams) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The coast-down profile on uniform grids: distance and time from the top speed down to speed ``i dv``
    (ascending speed), and time to cover distance ``j dx``. [m], [s], [s]"""
    v, x, t = coast_profile(vehicle)
    v_grid = np.arange(0.0, v[0] + COAST_TABLE_DV_MPS, COAST_TABLE_DV_MPS)
    x_grid = np.arange(0.0, x[-1] + COAST_TABLE_DX_M, COAST_TABLE_DX_M)
    x_of_v, t_of_v = np.interp(v_grid, v[::-1], x[::-1]), np.interp(v_grid, v[::-1], t[::-1])
    return x_of_v, t_of_v, np.interp(x_grid, x, t)


_lerp = choice.lerp_uniform


@njit(cache=True)
def _time_to_line_s(d_m, v0, vt, mode, reaction_s, brake_mps2, firm_mps2, accel_mps2, x_of_v, t_of_v, t_of_x):
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
def _line_speeds_mps(d_m, v0, vt, mode, reaction_s, brake_mps2, firm_mps2, accel_mps2, x_of_v, t_of_v, t_of_x):
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
def _crossing_times_s(d_m, v0, vt, mode, reaction_s, brake_mps2, firm_mps2, accel_mps2, x_of_v, t_of_v, t_of_x):
    out = np.empty(vt.size)
    for i in range(vt.size):
        out[i] = _time_to_line_s(d_m, v0, vt[i], mode, reaction_s, brake_mps2, firm_mps2, accel_mps2, x_of_v, t_of_v, t_of_x)
    return out


@njit(cache=True, inline="always")
def _in_red(tc, windows_s, j, slowing, no_amber, after_red_s):
    """A crossing at ``tc`` of line ``j`` inside a red of ``windows_s`` (padded red windows, (lines, k, 2)), or within
    ``after_red_s`` after one ends, or, for a plan that slows the car (``slowing``) at a light that shows no amber
    (``no_amber``, (lines,)), as long before one begins (:func:`_green_mask`)."""
    before_red_s = after_red_s if slowing and no_amber[j] else 0.0
    for k in range(windows_s.shape[1]):
        a = windows_s[j, k, 0]
        if (a - before_red_s if a > 0.0 else a) <= tc < windows_s[j, k, 1] + after_red_s:
            return True
    return False


@njit(cache=True)
def _red_crossings(cross, windows_s, slowing, no_amber, after_red_s):
    """Which plans (m,) reach a line that shows no amber inside a red of ``windows_s`` or its margins (:func:`_in_red`;
    ``cross``: time to each line (m, lines), ``slowing``: the plans that slow the car (m,)). bool (m,)"""
    out = np.zeros(cross.shape[0], dtype=np.bool_)
    for c in range(cross.shape[0]):
        for j in range(cross.shape[1]):
            if no_amber[j] and _in_red(cross[c, j], windows_s, j, slowing[c], no_amber, after_red_s):
                out[c] = True
    return out


@njit(cache=True)
def _green_mask(speeds, distances_m, windows_s, no_amber, n_lines, after_red_s, v0, mode, reaction_s, brake_mps2, firm_mps2, accel_mps2, x_of_v, t_of_v,
                t_of_x):  # fmt: skip
    """Per candidate speed: each of the first ``n_lines`` lines reached on green, at least ``after_red_s``
    after a red ends and, for a plan that slows the car at a light that shows no amber (``no_amber``, (lines,)), as
    long before a red to come begins (``windows_s``: padded red windows, (lines, k, 2)). bool (n,)

    The margin before a red's start (issue 28): a slowing plan is a speed change the driver makes a reaction late and
    tracks loosely, as it is after a red's end; "Slow to 25 mph, then coast" priced 0.25 s before a red with no amber
    crossed 0.5 s into it (docs/TRAFFIC.md, the ``--spat-queue`` red entry). A plan that holds or speeds up is the
    regular driver's own motion, over the line no later than planned; where an amber comes first, it warns the driver
    (who clears it or stops, as without advice)."""
    ok = np.ones(speeds.size, dtype=np.bool_)
    for i in range(speeds.size):
        slowing = mode == 1 or speeds[i] < v0 - 1e-9
        for j in range(n_lines):
            tc = _time_to_line_s(distances_m[j], v0, speeds[i], mode, reaction_s, brake_mps2, firm_mps2, accel_mps2, x_of_v, t_of_v, t_of_x)
            if not np.isfinite(tc) or _in_red(tc, windows_s, j, slowing, no_amber, after_red_s):
                ok[i] = False
                break
    return ok


@njit(cache=True)
def _first_feasible(speeds, distances_m, windows_s, no_amber, after_red_s, v0, reaction_s, brake_mps2, firm_mps2, accel_mps2, x_of_v, t_of_v, t_of_x):
    """The advisor's search in one call: all lines, else the first alone; in each, the modes in the order
    auto, brake_coast, brake, firm (:data:`MODE_CODES`). Returns (lines used, mode code, mask of speeds)."""
    n = distances_m.size
    ok = np.zeros(speeds.size, dtype=np.bool_)
    for attempt in range(2 if n > 1 else 1):
        n_lines = n if attempt == 0 else 1
        for mode in range(4):
            ok = _green_mask(speeds, distances_m, windows_s, no_amber, n_lines, after_red_s, v0, mode, reaction_s, brake_mps2, firm_mps2, accel_mps2, x_of_v,
                             t_of_v, t_of_x)  # fmt: skip
            if ok.any():
                return n_lines, mode, ok
    return n, 0, ok


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
    vt = np.asarray(v_target_mps, dtype=float)
    reaction = params.reaction_s if reaction_s is None else reaction_s
    out = _crossing_times_s(float(distance_m), float(v0_mps), vt.reshape(-1), MODE_CODES[mode], float(reaction),
                            params.comfort_decel_mps2, params.firm_decel_mps2, params.comfort_accel_mps2, *_coast_arrays(params.vehicle))  # fmt: skip
    return out.reshape(vt.shape) if vt.ndim else float(out[0])


@lru_cache(maxsize=64)
def _candidates_mps(low_mps: float, limit_mps: float, step_mps: float) -> np.ndarray:
    speeds = np.append(np.arange(low_mps, limit_mps - 1e-6, step_mps), limit_mps)  # the limit once, exactly
    speeds.setflags(write=False)
    return speeds


@dataclass(frozen=True, slots=True)
class _Lines:
    """The lights to cross, packed for the kernels: distances (n,), red windows (n, k, 2), padded with +inf, and
    which lights show no amber (n,)."""

    distances_m: np.ndarray
    windows_s: np.ndarray
    no_amber: np.ndarray

    @classmethod
    def of(cls, lights) -> _Lines:
        k = max(max((len(light.red_windows_s) for light in lights), default=0), 1)
        flat: list[float] = []  # one flat list, one np.array call: the cheapest packing (runs once per fix)
        for light in lights:
            for start, end in light.red_windows_s:
                flat += (start, end)
            flat += (np.inf,) * (2 * (k - len(light.red_windows_s)))
        windows = np.array(flat, dtype=float).reshape(len(lights), k, 2)
        return cls(np.array([light.distance_m for light in lights], dtype=float), windows, np.array([light.amber_s == 0.0 for light in lights], dtype=np.bool_))


def _kernel_args(obs: Observation, params: AdvisorParams, reaction_s: float | None) -> tuple:
    speeds = _candidates_mps(params.min_cruise_speed_mps, obs.speed_limit_mps, params.speed_step_mps)
    reaction = params.reaction_s if reaction_s is None else reaction_s
    return speeds, float(obs.speed_mps), float(reaction), params.comfort_decel_mps2, params.firm_decel_mps2, params.comfort_accel_mps2, *_coast_arrays(params.vehicle)


def _green(lines: _Lines, obs: Observation, params: AdvisorParams, mode: str, speeds: np.ndarray, reaction_s: float | None = None, n_lines: int | None = None) -> np.ndarray:
    """Which of ``speeds`` reach each of the first ``n_lines`` lines (all by default) on green. bool (n,)"""
    _, v0, reaction, *rest = _kernel_args(obs, params, reaction_s)
    n = lines.distances_m.size if n_lines is None else n_lines
    return _green_mask(speeds, lines.distances_m, lines.windows_s, lines.no_amber, n, params.green_margin_s, v0, MODE_CODES[mode], reaction, *rest)


def _feasible(lines: _Lines, obs: Observation, params: AdvisorParams, mode: str, reaction_s: float | None = None, n_lines: int | None = None) -> np.ndarray:
    speeds = _candidates_mps(params.min_cruise_speed_mps, obs.speed_limit_mps, params.speed_step_mps)
    return speeds[_green(lines, obs, params, mode, speeds, reaction_s, n_lines)]


def _keeps(lines: _Lines, obs: Observation, params: AdvisorParams, mode: str, target_mps: float, n_lines: int | None = None) -> bool:
    """A driver already following ``target_mps`` in ``mode`` (so no new reaction delay) still makes every green:
    the target is still a candidate speed and feasible (one speed through the kernel, not all candidates)."""
    if not params.min_cruise_speed_mps - 1e-9 <= target_mps <= obs.speed_limit_mps + 1e-9:
        return False
    return bool(_green(lines, obs, params, mode, np.array([float(target_mps)]), 0.0, n_lines)[0])


MODE_NAMES = {code: name for name, code in MODE_CODES.items()}


def _search(lines: _Lines, obs: Observation, params: AdvisorParams) -> tuple[int, str, np.ndarray]:
    """Lift off and coast (or speed up) if that makes the greens; brake gently only if coasting cannot;
    firmly only if gentle braking cannot; if no speed makes all lines, plan for the next one alone.
    Returns (lines planned for, mode, feasible speeds)."""
    speeds, v0, reaction, *rest = _kernel_args(obs, params, None)
    n_lines, mode, ok = _first_feasible(speeds, lines.distances_m, lines.windows_s, lines.no_amber, params.green_margin_s, v0, reaction, *rest)
    return n_lines, MODE_NAMES[mode], _earliest_green(speeds, ok)


def _earliest_green(speeds: np.ndarray, ok: np.ndarray) -> np.ndarray:
    """The feasible speeds that make the earliest greens: the run of consecutive feasible candidates that ends at
    the fastest one. A gap in the run is a red between two greens; a slower run aims at a later green, a whole
    cycle lost (the tables' value of time prices a crawl to the next green below a brisk run to this one, but the
    paper's optimum is held to the regular driver's trip time, and the driver would not wait a cycle for it)."""
    idx = np.flatnonzero(ok)
    if idx.size == 0:
        return speeds[ok]
    gaps = np.flatnonzero(np.diff(idx) > 1)
    first = idx[gaps[-1] + 1] if gaps.size else idx[0]
    return speeds[first : idx[-1] + 1]


def feasible_speeds_mps(
    obs: Observation, params: AdvisorParams, mode: str = "auto", reaction_s: float | None = None, lights=None
) -> np.ndarray:
    """Candidate cruise speeds in [min cruise, limit] that cross the next two lines on green. [m/s]

    ``lights`` replaces ``obs.lights`` (the advisor checks subsets of the lights ahead).
    """
    return _feasible(_Lines.of((obs.lights if lights is None else lights)[:2]), obs, params, mode, reaction_s)


def _green_crossing(light: LightView, t_s: float, after_red_s: float) -> bool:
    """The line is reached (finite time), not during a (conservative) red nor within ``after_red_s`` after one ends."""
    return bool(np.isfinite(t_s)) and not any(start <= t_s < end + after_red_s for start, end in light.red_windows_s)


def _slowed_into_red(light: LightView, t_s: float, margin_s: float) -> bool:
    """A slowing plan reaches a light that shows no amber within ``margin_s`` before a red begins (the margin
    :func:`_green_mask` keeps before such a red)."""
    return light.amber_s == 0.0 and any(0.0 < start and start - margin_s <= t_s < start for start, _ in light.red_windows_s)


def _normal_drive_s(distance_m: float, obs: Observation, params: AdvisorParams) -> float:
    """Time to a line ``distance_m`` ahead driving normally: speeding up to the limit at ``normal_accel_mps2`` at once
    (no advice to react to), the kernel's "auto" motion. [s]"""
    return _time_to_line_s(float(distance_m), float(obs.speed_mps), float(obs.speed_limit_mps), MODE_CODES["auto"], 0.0, params.comfort_decel_mps2,
                           params.firm_decel_mps2, params.normal_accel_mps2, *_coast_arrays(params.vehicle))  # fmt: skip


def published_speed_mps(speed_mps: float) -> float:
    """An advised speed as the API publishes it (``target_speed_mps``): rounded down to 0.01 m/s, so never above
    the limit. [m/s]

    Examples
    --------
    >>> published_speed_mps(24.5872)  # 55 mph
    24.58
    """
    return math.floor(speed_mps * 100.0 + 1e-9) / 100.0


def spoken_speed(speed_mps: float, units: str) -> int:
    """The whole km/h or mph heard, and shown by the app (``speedIn`` in ``server/static/lib/units.js``, the same
    operations): the published speed (:func:`published_speed_mps`) converted, halves rounded up. One rounding for
    both, so the number heard is the number seen (before: the voice rounded the exact speed, 55 mph -> "89 km/h",
    the screen the published one, 88).

    Examples
    --------
    >>> spoken_speed(24.5872, "kmh"), spoken_speed(24.5872, "mph"), spoken_speed(12.5, "kmh")
    (88, 55, 45)
    """
    x = published_speed_mps(speed_mps) * (MPH_PER_MPS if units == "mph" else KMH_PER_MPS)
    n = math.floor(x)
    return n + 1 if x - n >= 0.5 else n  # JavaScript's Math.round, to the bit


def _say_speed(speed_mps: float, units: str) -> str:
    return f"{spoken_speed(speed_mps, units):d}"


def _say_seconds(t_s: float | None) -> str:
    """"1 second", "12 seconds"; "" when unknown, infinite or under half a second. Whole seconds as a display shows
    the API's ``seconds_to_change_s`` (0.1 s, then halves up): the number heard is the number seen."""
    if t_s is None or not math.isfinite(t_s):
        return ""
    n = math.floor(round(t_s, 1) + 0.5)
    if n < 1:
        return ""
    return "1 second" if n == 1 else f"{n:d} seconds"


def phrase(advice: Advice, units: str = "mph") -> str:
    """Short, voice-ready English for an advisory (numbers rounded, speed in mph or km/h).

    The countdown is about the light the speed is chosen for (``advice.light_ahead``): "Second light: green in
    20 seconds. Slow to 40 kilometers per hour." when the next light is passed on green anyway."""
    unit_word = "miles per hour" if units == "mph" else "kilometers per hour"
    when = _say_seconds(advice.seconds_to_change_s)
    speed = "" if advice.target_speed_mps is None else f"{_say_speed(advice.target_speed_mps, units)} {unit_word}"
    if advice.reason == "stale_spat" and advice.action != "none":  # a dropout: the last advice, held
        return f"Signal data delayed. Keep to {speed}." if advice.action != "stop" else "Signal data delayed. Prepare to stop."
    if advice.action == "none":
        if advice.reason == "red_ahead":
            if advice.light_red is False:  # green now, red before the car gets there: the countdown is to that red
                return f"Red in {when}." if when else "Red light ahead."
            return f"Red light ahead. Green in {when}." if when else "Red light ahead."
        if advice.reason == "tight_green":
            return f"Red in {when}. Drive normally." if when else "Drive normally."
        if advice.reason == "stale_spat" and advice.light_red is not None:
            return "Signal data delayed."  # a short dropout: no new advice, and no push back to the limit
        return {
            "no_spat": "No signal data. Drive normally.",
            "stale_spat": "Signal data is out of date. Drive normally.",
            "low_confidence": "Signal timing uncertain. Drive normally.",
            "off_route": "Off the route. Advice paused.",
            "past_lights": "Last light passed. Advice ends.",
            "far_ahead": "Next light too far ahead for advice.",
        }.get(advice.reason, "")
    light = ""
    if when:
        light = f"Green in {when}. " if advice.light_red else f"Red in {when}. "
        if advice.light_ahead == 2:
            light = f"Second light: {light[0].lower()}{light[1:]}"
    if advice.action == "stop":
        if advice.light_red is False and when:  # green now, red on arrival: the number is the time to that red
            return f"Red in {when}. Prepare to stop."
        return f"Red light ahead. Prepare to stop. Green in {when}." if when else "Red light ahead. Prepare to stop."
    if advice.action == "resume":
        return f"Last light passed. Resume {speed}."
    if advice.action == "coast":
        if advice.reason == "red_ahead":  # a red whose end is uncertain, far ahead: lift off, no stop yet
            if advice.light_red is False and when:
                return f"Red in {when}. Lift off and coast."
            return f"Red light ahead. Green in {when}. Lift off and coast." if when else "Red light ahead. Lift off and coast."
        speed_now = advice.current_speed_mps if advice.current_speed_mps is not None else np.inf
        if advice.target_speed_mps is not None and advice.target_speed_mps < SLOW_FIRST_FRAC * speed_now:
            return f"{light}Slow to {speed}, then coast."
        return f"{light}Lift off and coast."
    verb = {"ease_off": "Ease off to", "slow_down": "Slow down to", "brake_to": "Brake to", "accelerate": "Speed up to", "cruise": "Hold"}[advice.action]
    return f"{light}{verb} {speed}."


def _light_timing(light: LightView) -> tuple[bool, float | None]:
    """Red now, and the seconds to the next change, as likely (an actuated green past its minEnd is still green)."""
    light = _countdown_view(light)
    if light.red_now:
        return True, light.seconds_to_green()
    return False, light.seconds_to_red()


KEEP_MODES = {"slow_down": "brake", "brake_to": "firm", "coast": "brake_coast", "ease_off": "auto", "accelerate": "auto", "cruise": "auto"}
"""How a driver following each action changes speed (the mode its feasibility is re-checked in)."""


def _past_next_green(light: LightView, obs: Observation, params: AdvisorParams) -> bool:
    """The advice's horizon: a normal drive (no advice: speeding up to the limit at ``normal_accel_mps2``) reaches the
    line only after the light's next green to begin has ended (the start of its second red window, as each change is
    likely). A plan then aims at a green after that one: two cycles out, on a timing that a real controller publishes
    one phase ahead (J2735: the current phase's end, the next at best) and that a predictor knows less well the
    farther it looks. Within it the advisor plans for the current green or the next one, never a later one. [-]"""
    starts = sorted(start for start, end in _countdown_view(light).red_windows_s if end > 0.0)
    return len(starts) >= 2 and _normal_drive_s(light.distance_m, obs, params) > starts[1]


def _binding(lights: tuple[LightView, ...], obs: Observation, params: AdvisorParams) -> int:
    """Which light the advice is for (index into ``lights``): the first one that the car, holding its speed, would
    not cross on green (with the after-red margin); the next light if it makes them all. The countdown names it."""
    if obs.speed_mps <= 0.0:
        return 0
    for i, light in enumerate(lights):
        if not _green_crossing(light, light.distance_m / obs.speed_mps, params.green_margin_s):
            return i
    return 0


def _timed(action: str, reason: str, target: float | None, lights: tuple[LightView, ...], i: int, source: str = "rules") -> Advice:
    """An advice whose countdown is light ``i``'s."""
    red, to_change = _light_timing(lights[i])
    return Advice(action, reason, target, red, to_change, source=source, light_ahead=i + 1, light_id=lights[i].intersection_id)


def _kept(lines: _Lines, usable: tuple[LightView, ...], obs: Observation, params: AdvisorParams, last: Advice) -> bool:
    """A driver already following ``last`` (no new reaction delay) still makes every green, with the margin."""
    keep_mode = KEEP_MODES[last.action]
    if _keeps(lines, obs, params, keep_mode, last.target_speed_mps):
        return True
    if keep_mode != "brake_coast":
        return False
    # a coasting driver may be below the target already (it coasts on): check its own coast, margin included
    keep_target = min(last.target_speed_mps, obs.speed_mps)
    return all(
        _green_crossing(light, crossing_time_s(light.distance_m, obs.speed_mps, keep_target, params, keep_mode, 0.0), params.green_margin_s)
        for light in usable
    )


def _countdown_view(light: LightView) -> LightView:
    """The light with each change at its likely instant (what is said: "Green in 12 seconds")."""
    if light.likely_red_windows_s is None:
        return light
    return LightView(light.intersection_id, light.distance_m, light.fresh, light.confidence_frac, light.likely_red_windows_s)


def _held(obs: Observation, memory: AdvisorMemory, params: AdvisorParams) -> Advice | None:
    """Through a short dropout: the last advice, re-checked on the last SPaT (its windows, aged); no new advice.
    ``None`` when the dropout is too long (or nothing was advised): then the plain "out of date"."""
    nxt, last = obs.lights[0], memory.last
    if not nxt.red_windows_s or nxt.age_s > params.hold_stale_s or last is None:
        return None
    usable = tuple(light for light in obs.lights[:2] if light.red_windows_s)
    red, to_change = _light_timing(nxt)
    if last.action == "stop" or (last.action in KEEP_MODES and last.target_speed_mps is not None and _kept(_Lines.of(usable), usable, obs, params, last)):
        return Advice(last.action, "stale_spat", last.target_speed_mps, red, to_change, source=last.source)
    return Advice("none", "stale_spat", light_red=red, seconds_to_change_s=to_change)


@njit(cache=True)
def _cross_matrix(vts, modes, reactions, accels, d_m, v0, brake_mps2, firm_mps2, x_of_v, t_of_v, t_of_x):
    """Time to each line (m, lines) of each candidate plan, in the motion of :func:`crossing_time_s`. [s]"""
    out = np.empty((vts.size, d_m.size))
    for c in range(vts.size):
        for j in range(d_m.size):
            out[c, j] = _time_to_line_s(d_m[j], v0, vts[c], modes[c], reactions[c], brake_mps2, firm_mps2, accels[c], x_of_v, t_of_v, t_of_x)
    return out


IMPLIED_TIMINGS = 20
"""Timings read off a view that states none (:func:`_implied_timings`). [-]"""


def _implied_timings(light: LightView) -> tuple:
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
component of the mixture stretches (:func:`_wide_component`). [-]"""
WIDE_STRETCH = 2.0
"""How much farther from the median timing the wide component puts each change: a copy of the forecast with twice its
spread. [-]"""


@lru_cache(maxsize=16)
def _wide_levels(n: int) -> np.ndarray:
    """The indices of :data:`WIDE_LEVELS` among ``n`` timings (:func:`_wide_component`)."""
    return np.array([round(level * (n - 1) / (IMPLIED_TIMINGS - 1)) for level in WIDE_LEVELS], dtype=np.int64)


@njit(cache=True, error_model="numpy")
def _wide_component(timings, levels, stretch):
    """The wide component of one light's mixture: a copy of the forecast's equally likely timings (packed: ``timings``
    (n, k, 2), each timing's windows in order, padded with +inf) with ``stretch`` (:data:`WIDE_STRETCH`) times its
    spread about its median timing, at the ``levels`` (:func:`_wide_levels`, one timing each), so that the outer timings
    are not the forecast's extremes (a forecast from a few dozen past phases is its sample: a change outside every
    timing came 7-10 s past the outer ones on the recorded controllers). Its weight is the chance of a change outside
    the window the light states (:func:`_timings`). Windows pair up by their order (the k-th red of each timing; one
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
            b2 = bm + stretch * (b - bm) if np.isfinite(b) and np.isfinite(bm) else b
            if a <= 0.0:  # red on now: its end no earlier than every timing says
                e = np.inf
                for r in range(n):
                    if timings[r, w, 1] < e:
                        e = timings[r, w, 1]
                a2, b2 = a, (e if e > b2 else b2)
            else:
                a2 = am + stretch * (a - am) if np.isfinite(a) and np.isfinite(am) else a
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


def _timings(lights: tuple[LightView, ...]) -> tuple[np.ndarray, np.ndarray]:
    """The lights' timings packed for :func:`advisory.advice.choice.expected_costs`: red windows (lines, timings, k, 2),
    padded with +inf, and each timing's weight (timings,), summing to 1. An exact light has one timing in all of them.

    The mixture of each uncertain light: its forecast (equally likely timings, ``LightView.scenario_red_windows_s`` or
    read off its windows, :func:`_implied_timings`), and the wide component (:func:`_wide_component`) weighted by the
    chance that a change comes outside the window the light states: ``1 - confidence_frac`` (J2735: the probability
    that the change comes within it; the lowest of the lights planned for). Within a light the timings are comonotone
    (every change at one level of its forecast: a red that comes late ends late); across lights they are paired at no
    rank correlation (:func:`_paired`): two lights' changes are not one forecast's (the k-th of each, comonotone, made a
    green that comes early at the first light always come with a red that comes early at the second: docs/ADVISOR.md).
    The wide components pair up as they are."""
    uncertain = [light.likely_red_windows_s is not None or light.scenario_red_windows_s is not None for light in lights]
    forecast = [light.scenario_red_windows_s or _implied_timings(light) if u else _implied_timings(light) for light, u in zip(lights, uncertain)]
    n_fc = max(len(timings) for timings in forecast)
    forecast = [_resampled(timings, n_fc) for timings in forecast]
    if any(uncertain):  # each light's parts: its forecast as paired, then its wide component
        per_light = [(_paired_timings(fc, n_fc, j) if u else fc,
                      _wide_component(fc.array_s if isinstance(fc, Timings) else _packed(fc, _most_windows(fc)), _wide_levels(n_fc), WIDE_STRETCH)
                      if u else fc[:1] * len(WIDE_LEVELS))
                     for j, (fc, u) in enumerate(zip(forecast, uncertain))]  # fmt: skip
        stated = min(light.confidence_frac for light, u in zip(lights, uncertain) if u)
        outside = min(max(1.0 - stated, 1.0 / n_fc), 1.0)
        weights = np.concatenate((np.full(n_fc, (1.0 - outside) / n_fc), np.full(len(WIDE_LEVELS), outside / len(WIDE_LEVELS))))
    else:
        per_light, weights = [(fc,) for fc in forecast], np.full(n_fc, 1.0 / n_fc)
    k = max(max(_most_windows(part) for parts in per_light for part in parts), 1)
    out = np.full((len(lights), weights.size, k, 2), np.inf)
    for i, parts in enumerate(per_light):
        n = 0
        for part in parts:
            block = part if isinstance(part, np.ndarray) else _packed(part, k)
            out[i, n : n + len(block), : block.shape[1]] = block
            n += len(block)
    return out, weights


def _most_windows(timings) -> int:
    """The most windows of one of the timings (tuples, or packed: ``(timings, k, 2)``)."""
    return timings.shape[1] if isinstance(timings, np.ndarray) else max((len(w) for w in timings), default=0)


def _paired_timings(timings: tuple, n: int, j: int):
    """Light ``j``'s ``n`` timings in the order :func:`_paired` gives: packed where they come packed (:class:`Timings`),
    else as a tuple."""
    order = _paired(n, j)
    return timings.array_s[order] if isinstance(timings, Timings) else tuple(timings[i] for i in order)


@lru_cache(maxsize=64)
def _candidate_plans(low_mps: float, limit_mps: float, step_mps: float, reaction_s: float, accel_mps2: float, normal_accel_mps2: float) -> tuple:
    """The candidate plans of :func:`_choose`, made once per road and driver (not per fix): targets, modes, reactions,
    accelerations and rate rows (m,) of every advised speed in each mode, then driving normally (the limit, no reaction,
    the regular driver's rate), "prepare to stop" (a lift-off: its target, the car's speed, is set per fix) and the
    plan followed now (set per fix). Shared: copy before writing (targets and modes are)."""
    speeds = _candidates_mps(low_mps, limit_mps, step_mps)
    m, n_modes = speeds.size, len(MODE_CODES)
    vts = np.concatenate((np.tile(speeds, n_modes), [limit_mps, limit_mps, limit_mps]))
    modes = np.concatenate((np.repeat(np.arange(n_modes), m), [0, MODE_CODES["brake_coast"], 0])).astype(np.int64)
    reactions = np.concatenate((np.full(n_modes * m, reaction_s), [0.0, reaction_s, 0.0]))
    accels = np.concatenate((np.full(n_modes * m, accel_mps2), [normal_accel_mps2, accel_mps2, accel_mps2]))
    rows = np.where(accels == accel_mps2, choice.ACCEL_COMFORT, choice.ACCEL_NORMAL).astype(np.int64)
    return vts, modes, reactions, accels, rows


@lru_cache(maxsize=64)
def _road_time_value_usd_per_s(params: AdvisorParams, v_lim_mps: float) -> float:
    """The road's price on time (:func:`advisory.advice.choice.steady_time_value_usd_per_s`), once per road."""
    rates, _, _ = choice.rate_tables(params.vehicle, params.comfort_decel_mps2, params.normal_accel_mps2, params.firm_decel_mps2)
    return choice.steady_time_value_usd_per_s(rates, v_lim_mps)


def _choose(obs: Observation, usable: tuple[LightView, ...], last: Advice | None, params: AdvisorParams, red: bool, to_change: float | None) -> Advice:
    """Under uncertain timing: the plan of least expected cost over the lights' equally likely timings, among those
    that make a stop no likelier than driving normally by more than ``stop_risk_frac`` (:mod:`advisory.advice.choice`),
    then worded: a plan for a green ("Ease off to 40"), a lift-off or a stop for a red that comes whatever the plan,
    or no speed advice where driving normally is the best plan."""
    nxt = usable[0]
    v, v_lim = float(obs.speed_mps), float(obs.speed_limit_mps)
    speeds, v0, reaction, brake, firm, accel, *coast_tables = _kernel_args(obs, params, None)
    # the candidates: every speed in each of the advisor's modes (lift off, brake then coast, brake gently, firmly),
    # driving normally (no reaction, the regular driver's rate, to the limit), "prepare to stop" (lift off, then a stop
    # at the line for a red met: choice.expected_costs), and the plan the driver follows now (no new reaction)
    m, n_modes = speeds.size, len(MODE_CODES)
    # (a lift-off for a likely red is a plan followed too: coasting on, it is kept as any other while it is as good)
    keep = last is not None and last.reason in ("green_wave", "red_ahead") and last.target_speed_mps is not None and last.action in KEEP_MODES
    vts, modes, reactions, accels, rows = _candidate_plans(params.min_cruise_speed_mps, v_lim, params.speed_step_mps, reaction, accel, params.normal_accel_mps2)
    vts, modes = vts.copy(), modes.copy()
    vts[-2], vts[-1] = v, last.target_speed_mps if keep else v_lim
    modes[-1] = MODE_CODES[KEEP_MODES[last.action]] if keep else 0
    normal, stop = n_modes * m, n_modes * m + 1
    stop_plan = np.zeros(vts.size, dtype=np.bool_)
    stop_plan[stop] = True
    stop_plan[-1] = keep and last.reason == "red_ahead"  # a lift-off for a red, followed now: the same plan
    d_m = np.array([light.distance_m for light in usable], dtype=float)
    cross = _cross_matrix(vts, modes, reactions, accels, d_m, v0, brake, firm, *coast_tables)
    rates, coast, idle = choice.rate_tables(params.vehicle, params.comfort_decel_mps2, params.normal_accel_mps2, params.firm_decel_mps2)
    x_end = float(d_m[-1]) + v_lim * v_lim / (2.0 * params.normal_accel_mps2)
    windows, weights = _timings(usable)
    lam_road = _road_time_value_usd_per_s(params, v_lim) if params.time_value_usd_per_s is None else params.time_value_usd_per_s
    lam = lam_road * time_price(obs)  # the car's time and its followers' (Observation.followers)
    clear = np.array([0.0 if light.amber_s == 0.0 else min(light.amber_s or choice.AMBER_MIN_S, choice.AMBER_MIN_S) for light in usable])
    # no amber warns of a light's reds: no plan reaches the line where one may be on (the sure windows), nor, slowing the
    # car, within the margin before one may begin (the feasibility of the rules, :func:`_green_mask`)
    lines = _Lines.of(usable)
    crossed = _red_crossings(cross, lines.windows_s, (modes == MODE_CODES["brake_coast"]) | (vts < v - 1e-9), lines.no_amber, params.green_margin_s)
    # priced as the choice needs them (choice.expected_costs, "pruned"): driving normally first and in full, and the
    # stop plan; a plan that cannot be allowed (through a red, or a stop likelier than driving normally's by more than
    # ``stop_risk_frac``) is not priced further. The same choice as pricing every plan (tests/test_choice.py)
    must = np.zeros(vts.size, dtype=np.bool_)
    must[normal] = must[stop] = True
    must[-1] = keep  # (kept where it costs no more than the best: its cost, even inf, counts)
    skip = crossed & ~must
    skip[-1] |= not keep  # (no plan followed now: its slot is not a candidate)
    cost, p_stop, through = choice.expected_costs(vts, modes, reactions, rows, accels, v0, d_m, windows, windows.shape[2], x_end, v_lim,
                                                  params.green_margin_s, lam, cross, rates, coast, idle, brake, firm,
                                                  params.normal_accel_mps2, params.reaction_s, params.min_cruise_speed_mps, clear, weights, stop_plan,
                                                  np.array([0.0 if light.amber_s == 0.0 else light.amber_s or choice.AMBER_MAX_S for light in usable]),
                                                  skip, must, normal, params.stop_risk_frac)  # fmt: skip
    through |= crossed
    allowed = (p_stop <= p_stop[normal] + params.stop_risk_frac + 1e-9) & ~through
    if not keep:
        allowed[-1] = False
    priced = np.where(allowed, cost, np.inf)
    # none allowed at a finite cost (those left stop short of the line: coasting to a halt): a stop comes whatever the
    # plan. (Was ``allowed.any()``: where every allowed plan cost inf, argmin fell on plan 0, through a red of every timing)
    best = int(np.argmin(priced)) if np.isfinite(priced).any() else stop
    reaction_usd = lam * params.reaction_s
    if keep and allowed[-1] and cost[-1] <= cost[best] + reaction_usd:
        best = vts.size - 1  # the plan followed now, unless another is better by more than a new reaction costs
    elif allowed[stop] and cost[stop] <= cost[best] + reaction_usd:
        best = stop  # as good a plan as any (within a reaction's worth): the stop it comes to, said
    if p_stop[best] >= 0.5 and any(light.unknown_at(float(cross[normal, j])) for j, light in enumerate(usable)):
        # what comes as the car goes is a phase whose state nobody knows: no stop is asked for it (the regular driver
        # went through it), and no plan slows the car for the green after it: no data, said so
        return Advice("none", "no_spat", light_red=red, seconds_to_change_s=to_change)
    if best == normal:  # nothing does better than driving on as the driver would (the red may come late): no speed advice
        arrival = float(cross[normal, 0])
        reason = "no_spat" if nxt.unknown_at(arrival) else "tight_green" if not red and to_change is not None and arrival < to_change else "low_confidence"
        return Advice("none", reason, light_red=red, seconds_to_change_s=to_change)
    if stop_plan[best]:
        # "prepare to stop" is the plan: said when a stop must begin soon; farther out lift off (its motion until then:
        # arriving later only helps, the red may end first), or nothing while the car pulls away at a crawl (the light
        # it is about: the first the car as it goes would not cross on green; a stop only at the next one)
        # the light it is about: the first that the stop plan's own motion (a lift-off) meets in a red, where it stops
        # (by the car's speed held, a light made 0.4 s before a red no amber announces named the next light's green:
        # "Red light ahead. Green in 45 seconds. Lift off and coast." for a stop at this one, never said "stop")
        i = next((j for j in range(len(usable)) if not _green_crossing(usable[j], float(cross[stop, j]), params.green_margin_s)
                  or _slowed_into_red(usable[j], float(cross[stop, j]), params.green_margin_s)), _binding(usable, obs, params))  # fmt: skip
        if i == 0 and red and v > 0.0 and nxt.seconds_to_green() - crossing_time_s(nxt.distance_m, v, v, params) < params.short_wait_s:
            return Advice("none", "short_wait", light_red=red, seconds_to_change_s=to_change)  # a stop to wait a moment: none
        if v < params.min_cruise_speed_mps:  # pulling away at a crawl: what is ahead, said
            return _timed("none", "red_ahead", None, usable, i)
        if i == 0 and nxt.distance_m <= v * (params.reaction_s + params.stop_lead_s) + v * v / (2.0 * params.comfort_decel_mps2):
            return Advice("stop", "red_ahead", target_speed_mps=0.0, light_red=red, seconds_to_change_s=to_change)
        # lift off only: the words and the driver's motion are a lift-off (the stop, when it comes, is braked then)
        keep_target = last is not None and last.action == "coast" and last.reason == "red_ahead" and last.target_speed_mps is not None
        return _timed("coast", "red_ahead", last.target_speed_mps if keep_target else v, usable, i)
    target, mode = min(float(vts[best]), v_lim), MODE_NAMES[int(modes[best])]
    # the words say the motion the plan was priced in (a driver told "slow down" brakes, told "hold" lifts off)
    if mode == "brake_coast":
        action = "coast"
    elif target < v and mode in ("brake", "firm"):
        action = "slow_down" if mode == "brake" else "brake_to"
    elif target < v - params.hysteresis_mps:
        action = "ease_off"
    elif target > v + params.hysteresis_mps:
        action = "accelerate"
    else:
        action = "cruise"
    return _timed(action, "green_wave", target, usable, _binding(usable, obs, params))


def _decide(obs: Observation, memory: AdvisorMemory, params: AdvisorParams, tables) -> Advice:
    if not obs.on_route:
        return Advice("none", "past_lights" if obs.zone_exit else "off_route")
    if not obs.lights:
        v = obs.speed_limit_mps
        return Advice("resume" if obs.speed_mps < v - 1.0 else "cruise", "past_lights", target_speed_mps=v)
    nxt = obs.lights[0]
    if not nxt.fresh:
        held = _held(obs, memory, params)
        return held if held is not None else Advice("none", "stale_spat" if nxt.red_windows_s else "no_spat")
    if nxt.confidence_frac < params.min_confidence_frac:
        return Advice("none", "low_confidence")
    red, to_change = _light_timing(nxt)
    if _past_next_green(nxt, obs, params):
        # so far out that even a normal drive reaches the line after the light's next green has ended: any speed
        # advised now would aim two greens or more ahead (issue 29: "Green in 24 seconds. Ease off to 43 km/h"
        # 1.8 km out); the countdown stays (it is true), the advice waits until the next green is in reach
        return Advice("none", "far_ahead", light_red=red, seconds_to_change_s=to_change)
    if nxt.distance_m < max(params.too_close_m, obs.speed_mps * params.too_close_s):
        return Advice("none", "too_close", light_red=red, seconds_to_change_s=to_change)
    usable = tuple(light for light in obs.lights[:2] if light.fresh and light.confidence_frac >= params.min_confidence_frac)
    last = memory.last
    if any(light.likely_red_windows_s is not None or light.scenario_red_windows_s is not None for light in usable):
        return _choose(obs, usable, last, params, red, to_change)  # uncertain timing: the plan of least expected cost
    both = _Lines.of(usable)
    if last is not None and last.target_speed_mps is not None and last.action in KEEP_MODES:
        # the driver is already following the last advice: keep it while it still works (no new reaction delay)
        if _kept(both, usable, obs, params, last):
            action = last.action if last.action != "accelerate" or last.target_speed_mps > obs.speed_mps + params.hysteresis_mps else "cruise"
            return _timed(action, last.reason, last.target_speed_mps, usable, _binding(usable, obs, params), last.source)
    n_lines, mode, feasible = _search(both, obs, params)
    to_red = None if red else nxt.seconds_to_red()  # (every light here is exact: uncertain ones went to _choose)
    if to_red is not None and (normal_s := _normal_drive_s(nxt.distance_m, obs, params)) < to_red:
        planned_s = crossing_time_s(nxt.distance_m, obs.speed_mps, float(feasible.max()), params, mode) if feasible.size else np.inf
        if planned_s >= to_red:
            # green now, and a normal drive (speeding up to the limit at the regular driver's rate: no advice to react
            # to) is over the line before the red, where no comfortable speed is: a plan for the green after the red,
            # or a "prepare to stop", would lose a cycle that the driver makes without advice
            return Advice("none", "tight_green", light_red=False, seconds_to_change_s=to_change)
    if feasible.size == 0:
        arrival = crossing_time_s(nxt.distance_m, obs.speed_mps, obs.speed_mps, params) if obs.speed_mps > 0 else np.inf
        if red and nxt.seconds_to_green() - arrival < params.short_wait_s and obs.speed_mps > 0:
            return Advice("none", "short_wait", light_red=red, seconds_to_change_s=to_change)
        slowest = crossing_time_s(nxt.distance_m, obs.speed_mps, params.min_cruise_speed_mps, params, "brake")
        if nxt.unknown_windows_s and not (nxt.likely_red_at(arrival) or nxt.likely_red_at(slowest)):
            # a phase whose state nobody knows (a group published "unavailable" between its greens: the regular
            # driver went through it, the advised one was stopped): no "prepare to stop", no data, said so
            reason = "no_spat" if nxt.unknown_at(arrival) or nxt.unknown_at(slowest) else "low_confidence"
            return Advice("none", reason, light_red=red, seconds_to_change_s=to_change)
        v = obs.speed_mps
        to_green = _countdown_view(nxt).seconds_to_green_after(min(arrival, slowest))
        far = nxt.distance_m > v * (params.reaction_s + params.stop_lead_s) + v * v / (2.0 * params.comfort_decel_mps2)
        if far and not math.isfinite(to_green):
            # far from a red whose end is unknown: no stop asked for yet (a stop so far out halted the car 220 m
            # short of the line), but lift off: arriving later only helps (the red may end first), and what coasting
            # sheds the stop would have braked away anyway. Not at a crawl (launching from the light before): there
            # only what is ahead. A known end keeps the early gentle stop (the advisor re-plans from it)
            if v < params.min_cruise_speed_mps:
                return Advice("none", "red_ahead", light_red=red, seconds_to_change_s=to_change)
            keep = last is not None and last.action == "coast" and last.reason == "red_ahead" and last.target_speed_mps is not None
            return Advice("coast", "red_ahead", last.target_speed_mps if keep else v, red, to_change)
        # the countdown is the light's next change (to red while it is green now), never the green after a red to come
        return Advice("stop", "red_ahead", target_speed_mps=0.0, light_red=red, seconds_to_change_s=to_change)
    target, source = float(feasible.max()), "rules"
    if tables is not None:
        wanted = tables.target_speed_mps(obs)
        if wanted is not None:  # the DP's speed at the next stop line: the feasible target that reaches the line nearest it
            _, v0, reaction, *rest = _kernel_args(obs, params, None)
            # no lingering: at most ``table_slack_s`` later over the lines planned for than the fastest feasible speed
            last_m = float(both.distances_m[n_lines - 1])
            arrive = _crossing_times_s(last_m, v0, feasible, MODE_CODES[mode], reaction, *rest)
            feasible = feasible[arrive <= arrive[-1] + params.table_slack_s / time_price(obs)]  # followers: less time given up
            miss = np.abs(_line_speeds_mps(float(nxt.distance_m), v0, feasible, MODE_CODES[mode], reaction, *rest) - wanted)
            # targets still being braked to at the line reach it alike: of those, the one nearest the wanted speed
            close = feasible[miss <= miss.min() + LINE_SPEED_TIE_MPS]
            target, source = float(close[np.argmin(np.abs(close - wanted))]), "dp_table"
    if last is not None and last.target_speed_mps is not None and last.action in ("cruise", "ease_off", "accelerate", "slow_down", "coast") and last.reason == "green_wave":
        # the driver is already following the last plan: keep it while it still works (no new reaction delay); not
        # a lift-off for a red whose end was unknown ("Red light ahead. Lift off and coast."): a plan now, for a green
        keep_mode = {"slow_down": "brake", "coast": "brake_coast"}.get(last.action, "auto")
        if abs(last.target_speed_mps - target) < params.speak_change_mps and _keeps(both, obs, params, keep_mode, last.target_speed_mps, n_lines):
            target, mode = last.target_speed_mps, keep_mode
    if mode == "brake_coast":
        action = "coast"
    elif target < obs.speed_mps - params.hysteresis_mps:
        action = {"brake": "slow_down", "firm": "brake_to"}.get(mode, "ease_off")
    elif target > obs.speed_mps + params.hysteresis_mps:
        action = "accelerate"
    else:
        action = "cruise"
        near = feasible[np.abs(feasible - obs.speed_mps) <= params.hysteresis_mps]
        if near.size:  # within the band: hold the speed the car has, don't nudge it by a mile per hour
            target = float(near[np.argmin(np.abs(near - obs.speed_mps))])
    return _timed(action, "green_wave", min(target, obs.speed_limit_mps), usable, _binding(usable[:n_lines], obs, params), source)


def _meaningful_change(new: Advice, old: Advice | None, params: AdvisorParams) -> bool:
    if old is None:
        return new.action != "none" or new.reason in ("no_spat", "stale_spat", "low_confidence", "off_route", "red_ahead", "past_lights")
    if (new.action, new.reason) != (old.action, old.reason):
        return new.reason not in ("too_close", "short_wait", "far_ahead")
    if new.target_speed_mps is not None and old.target_speed_mps is not None:
        return abs(new.target_speed_mps - old.target_speed_mps) >= params.speak_change_mps
    return False


def advise(
    obs: Observation, memory: AdvisorMemory | None = None, params: AdvisorParams | None = None, tables=None
) -> tuple[Advice, AdvisorMemory]:
    """
    The advisory for one observation, and the memory to pass with the next one.

    Never advises a speed above the limit or one that reaches a stop line during (conservative) red; when no
    speed is sure (an actuated light), a plan on the likely changes that is never faster than now and never into
    a red that minEnd guarantees (docs/ADVISOR.md, 1a). With missing or low-confidence SPaT it gives no speed
    advice and says so; through a short dropout it holds the last advice, re-checked, and makes no new one.
    ``tables``: optional :class:`advisory.advice.tables.AdviceTables` (DP lookup); ``None`` uses the rules alone.
    """
    memory = memory or AdvisorMemory()
    params = params or AdvisorParams()
    a = _decide(obs, memory, params, tables)
    # (constructor calls, not dataclasses.replace: this runs once a second per car)
    # the light the countdown is about: the next one unless the advice named another (the one after it, ``_timed``)
    light_id = a.light_id if a.light_id is not None or a.light_red is None or not obs.lights else obs.lights[0].intersection_id
    advice = Advice(a.action, a.reason, a.target_speed_mps, a.light_red, a.seconds_to_change_s, source=a.source, current_speed_mps=obs.speed_mps,
                    light_ahead=a.light_ahead, light_id=light_id)
    message = phrase(advice, params.units)
    speak = bool(message) and _meaningful_change(advice, memory.spoken, params)
    advice = Advice(a.action, a.reason, a.target_speed_mps, a.light_red, a.seconds_to_change_s, message, speak, a.source, obs.speed_mps, a.light_ahead, light_id)
    spoken, last = (advice if advice.speak else memory.spoken), advice
    if advice.reason == "stale_spat" and advice.light_red is not None:
        # a short dropout: the driver goes on with the plan it follows; that stays the plan when data returns
        spoken, last = (advice if advice.speak else memory.spoken), memory.last
    if advice.action == "none" and advice.reason in ("too_close", "short_wait", "far_ahead"):
        # silence: the driver goes on with what it was told, so that stays the plan to re-check (and the
        # reference for speaking) when the advisor talks again
        spoken, last = memory.spoken, memory.last
    return advice, AdvisorMemory(last=last, spoken=spoken)
