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
   form). If no speed is feasible: prepare to stop.
4. **Hysteresis**: the previous target is kept while it stays feasible and close; ``speak`` is raised only
   when the action changes, or the target moves by ``speak_change_mps``.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import lru_cache

import numpy as np

from advisory.energy import road_load_force_n
from advisory.params import PAPER_54KWH, VehicleParams

MPH_PER_MPS = 1 / 0.44704
KMH_PER_MPS = 3.6
SLOW_FIRST_FRAC = 0.97
"""A "coast" advice whose target is below this share of the current speed is worded "Slow to X, then coast";
otherwise the braking part is negligible and it is "Lift off and coast". [-]"""


@dataclass(frozen=True, slots=True)
class LightView:
    """One light ahead, as the advisor sees it. Times are relative to now. [m], [s]

    ``red_windows_s``: upcoming red intervals ``(start, end)`` relative to now, conservative: an uncertain
    change to red counts from its earliest possible time, a change to green from its latest. A window with
    ``start <= 0`` means red now. At least the windows of the next ~2 minutes.
    """

    intersection_id: int
    distance_m: float
    fresh: bool = True
    confidence_frac: float = 1.0
    red_windows_s: tuple[tuple[float, float], ...] = ()

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

    def as_dict(self) -> dict:
        return {k: getattr(self, k) for k in self.__slots__}


@dataclass(frozen=True, slots=True)
class AdvisorParams:
    """Advisor settings. Units in names."""

    min_cruise_speed_mps: float = 10 * 0.44704  # slowest speed ever advised (a creep towards a red)
    reaction_s: float = 1.0
    comfort_decel_mps2: float = 1.5
    firm_decel_mps2: float = 3.0  # "brake to X" when gentle braking cannot make the green (regular driver: 4)
    comfort_accel_mps2: float = 1.5
    too_close_s: float = 3.0  # closer than this many seconds to the line at current speed: no advice
    too_close_m: float = 15.0
    short_wait_s: float = 3.0
    min_confidence_frac: float = 0.5
    hysteresis_mps: float = 1.0
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
    d = max(distance_m, 0.0)
    d_react = v0_mps * reaction
    if d <= d_react:
        out = np.full(vt.shape, d / v0_mps if v0_mps > 0 else np.inf)
        return out if out.ndim else float(out)
    d -= d_react
    v, x, t = coast_profile(params.vehicle)
    rv, rx, rt = v[::-1], x[::-1], t[::-1]  # ascending speed for interpolation
    with np.errstate(divide="ignore", invalid="ignore"):
        if mode == "brake_coast":  # brake gently to the target, then coast all the way
            dec = params.comfort_decel_mps2
            v1 = np.minimum(vt, v0_mps)
            d_b = (v0_mps**2 - v1**2) / (2.0 * dec)
            during = reaction + (v0_mps - np.sqrt(np.maximum(v0_mps**2 - 2.0 * dec * d, 0.0))) / dec
            x0, t0 = np.interp(v1, rv, rx), np.interp(v1, rv, rt)
            xs = x0 + d - d_b
            after = np.where(xs > x[-1], np.inf, reaction + (v0_mps - v1) / dec + np.interp(xs, x, t) - t0)
            out = np.where(d <= d_b, during, after)
        else:
            out = np.empty(vt.shape)
            slower = vt < v0_mps
            coast = slower & (mode == "auto")
            if coast.any():  # lift off and coast down to the target, then hold it
                vc = vt[coast]
                x0, t0 = np.interp(v0_mps, rv, rx), np.interp(v0_mps, rv, rt)
                x1, t1 = np.interp(vc, rv, rx), np.interp(vc, rv, rt)
                during = reaction + np.interp(x0 + d, x, t) - t0
                out[coast] = np.where(d <= x1 - x0, during, np.where(vc > 0, reaction + (t1 - t0) + (d - (x1 - x0)) / vc, np.inf))
            ramp = ~coast
            if ramp.any():  # a constant-rate change (speeding up; or braking in the brake / firm modes)
                vr, down = vt[ramp], slower[ramp]
                rate = np.where(down, params.firm_decel_mps2 if mode == "firm" else params.comfort_decel_mps2, params.comfort_accel_mps2)
                d_ramp = np.abs(v0_mps**2 - vr**2) / (2.0 * rate)
                v_line = np.sqrt(np.maximum(v0_mps**2 + 2.0 * np.where(down, -rate, rate) * d, 0.0))
                during = np.where(v_line > 0, reaction + np.abs(v_line - v0_mps) / rate, np.inf)
                after = np.where(vr > 0, reaction + np.abs(v0_mps - vr) / rate + (d - d_ramp) / vr, np.inf)
                out[ramp] = np.where(d <= d_ramp, during, after)
    return out if out.ndim else float(out)


@lru_cache(maxsize=64)
def _candidates_mps(low_mps: float, limit_mps: float, step_mps: float) -> np.ndarray:
    speeds = np.unique(np.append(np.arange(low_mps, limit_mps + 1e-9, step_mps), limit_mps))
    speeds.setflags(write=False)
    return speeds


def feasible_speeds_mps(
    obs: Observation, params: AdvisorParams, mode: str = "auto", reaction_s: float | None = None, lights=None
) -> np.ndarray:
    """Candidate cruise speeds in [min cruise, limit] that cross the next two lines on green. [m/s]

    ``lights`` replaces ``obs.lights`` (the advisor checks subsets of the lights ahead).
    """
    speeds = _candidates_mps(params.min_cruise_speed_mps, obs.speed_limit_mps, params.speed_step_mps)
    ok = np.ones(speeds.size, dtype=bool)
    for light in (obs.lights if lights is None else lights)[:2]:
        ok &= _green_crossing(light, crossing_time_s(light.distance_m, obs.speed_mps, speeds, params, mode, reaction_s))
    return speeds[ok]


def _green_crossing(light: LightView, t_s):
    """Where the line is reached (finite time) and not during a (conservative) red (scalar or array)."""
    t = np.asarray(t_s, dtype=float)
    red = np.zeros(t.shape, dtype=bool)
    for start, end in light.red_windows_s:
        red |= (start <= t) & (t < end)
    return np.isfinite(t) & ~red


def _say_speed(speed_mps: float, units: str) -> str:
    return f"{round(speed_mps * (MPH_PER_MPS if units == 'mph' else KMH_PER_MPS)):d}"


def phrase(advice: Advice, units: str = "mph") -> str:
    """Short, voice-ready English for an advisory (numbers rounded, speed in mph or km/h)."""
    unit_word = "miles per hour" if units == "mph" else "kilometers per hour"
    t = advice.seconds_to_change_s
    when = "" if t is None or round(t) < 1 else f"{round(t):d} seconds"
    if advice.action == "none":
        return {
            "no_spat": "No signal data. Drive normally.",
            "stale_spat": "Signal data is out of date. Drive normally.",
            "low_confidence": "Signal timing uncertain. Drive normally.",
            "off_route": "Off the route. Advice paused.",
        }.get(advice.reason, "")
    speed = "" if advice.target_speed_mps is None else f"{_say_speed(advice.target_speed_mps, units)} {unit_word}"
    light = ""
    if when:
        light = f"Green in {when}. " if advice.light_red else f"Red in {when}. "
    if advice.action == "stop":
        return f"Red light ahead. Prepare to stop. Green in {when}." if when else "Red light ahead. Prepare to stop."
    if advice.action == "resume":
        return f"Last light passed. Resume {speed}."
    if advice.action == "coast":
        speed_now = advice.current_speed_mps if advice.current_speed_mps is not None else np.inf
        if advice.target_speed_mps is not None and advice.target_speed_mps < SLOW_FIRST_FRAC * speed_now:
            return f"{light}Slow to {speed}, then coast."
        return f"{light}Lift off and coast."
    verb = {"ease_off": "Ease off to", "slow_down": "Slow down to", "brake_to": "Brake to", "accelerate": "Speed up to", "cruise": "Hold"}[advice.action]
    return f"{light}{verb} {speed}."


def _light_timing(light: LightView) -> tuple[bool, float | None]:
    if light.red_now:
        return True, light.seconds_to_green()
    return False, light.seconds_to_red()


def _decide(obs: Observation, memory: AdvisorMemory, params: AdvisorParams, tables) -> Advice:
    if not obs.on_route:
        return Advice("none", "off_route")
    if not obs.lights:
        v = obs.speed_limit_mps
        return Advice("resume" if obs.speed_mps < v - 1.0 else "cruise", "past_lights", target_speed_mps=v)
    nxt = obs.lights[0]
    if not nxt.fresh:
        return Advice("none", "stale_spat" if nxt.red_windows_s else "no_spat")
    if nxt.confidence_frac < params.min_confidence_frac:
        return Advice("none", "low_confidence")
    red, to_change = _light_timing(nxt)
    if nxt.distance_m < max(params.too_close_m, obs.speed_mps * params.too_close_s):
        return Advice("none", "too_close", light_red=red, seconds_to_change_s=to_change)
    usable = tuple(light for light in obs.lights[:2] if light.fresh and light.confidence_frac >= params.min_confidence_frac)
    last = memory.last
    modes = {"slow_down": "brake", "brake_to": "firm", "coast": "brake_coast", "ease_off": "auto", "accelerate": "auto", "cruise": "auto"}
    if last is not None and last.target_speed_mps is not None and last.action in modes and usable:
        # the driver is already following the last advice: keep it while it still works (no new reaction delay)
        keep_mode = modes[last.action]
        keep_target = last.target_speed_mps
        if keep_mode == "brake_coast":
            keep_target = min(keep_target, obs.speed_mps)
        still = feasible_speeds_mps(obs, params, keep_mode, reaction_s=0.0, lights=usable)
        ok = np.any(np.abs(still - last.target_speed_mps) < 1e-9) or (
            keep_mode == "brake_coast" and all(
                bool(_green_crossing(light, crossing_time_s(light.distance_m, obs.speed_mps, keep_target, params, keep_mode, 0.0))) for light in usable
            )
        )
        if ok:
            return replace(last, light_red=red, seconds_to_change_s=to_change, message="", speak=False,
                           action=last.action if last.action != "accelerate" or last.target_speed_mps > obs.speed_mps + params.hysteresis_mps else "cruise")
    # Lift off and coast (or speed up) if that makes the greens; brake gently only if coasting cannot;
    # if no speed makes both lights, plan for the next one alone.
    for lights in (usable, usable[:1]) if len(usable) > 1 else (usable,):
        for mode in ("auto", "brake_coast", "brake", "firm"):
            feasible = feasible_speeds_mps(obs, params, mode, lights=lights)
            if feasible.size:
                break
        if feasible.size:
            break
    if feasible.size == 0:
        arrival = crossing_time_s(nxt.distance_m, obs.speed_mps, obs.speed_mps, params) if obs.speed_mps > 0 else np.inf
        if red and nxt.seconds_to_green() - arrival < params.short_wait_s and obs.speed_mps > 0:
            return Advice("none", "short_wait", light_red=red, seconds_to_change_s=to_change)
        slowest = crossing_time_s(nxt.distance_m, obs.speed_mps, params.min_cruise_speed_mps, params, "brake")
        return Advice("stop", "red_ahead", target_speed_mps=0.0, light_red=red,
                      seconds_to_change_s=nxt.seconds_to_green_after(min(arrival, slowest)))
    target, source = float(feasible.max()), "rules"
    if tables is not None:
        wanted = tables.target_speed_mps(obs)
        if wanted is not None:  # the DP's speed at the next stop line, snapped to the nearest feasible one
            target, source = float(feasible[np.argmin(np.abs(feasible - wanted))]), "dp_table"
    if last is not None and last.target_speed_mps is not None and last.action in ("cruise", "ease_off", "accelerate", "slow_down", "coast"):
        # the driver is already following the last advice: keep it while it still works (no new reaction delay)
        keep_mode = {"slow_down": "brake", "coast": "brake_coast"}.get(last.action, "auto")
        still = feasible_speeds_mps(obs, params, keep_mode, reaction_s=0.0, lights=lights)
        if abs(last.target_speed_mps - target) < params.speak_change_mps and np.any(np.abs(still - last.target_speed_mps) < 1e-9):
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
    return Advice(action, "green_wave", target_speed_mps=min(target, obs.speed_limit_mps), light_red=red,
                  seconds_to_change_s=to_change, source=source)


def _meaningful_change(new: Advice, old: Advice | None, params: AdvisorParams) -> bool:
    if old is None:
        return new.action != "none" or new.reason in ("no_spat", "stale_spat", "low_confidence", "off_route")
    if (new.action, new.reason) != (old.action, old.reason):
        return new.reason not in ("too_close", "short_wait")
    if new.target_speed_mps is not None and old.target_speed_mps is not None:
        return abs(new.target_speed_mps - old.target_speed_mps) >= params.speak_change_mps
    return False


def advise(
    obs: Observation, memory: AdvisorMemory | None = None, params: AdvisorParams | None = None, tables=None
) -> tuple[Advice, AdvisorMemory]:
    """
    The advisory for one observation, and the memory to pass with the next one.

    Never advises a speed above the limit or one that reaches a stop line during (conservative) red;
    with missing, stale or low-confidence SPaT it gives no speed advice and says so.
    ``tables``: optional :class:`advisory.tables.AdviceTables` (DP lookup); ``None`` uses the rules alone.
    """
    memory = memory or AdvisorMemory()
    params = params or AdvisorParams()
    advice = replace(_decide(obs, memory, params, tables), current_speed_mps=obs.speed_mps)
    speak = _meaningful_change(advice, memory.spoken, params)
    advice = replace(advice, message=phrase(advice, params.units), speak=speak and bool(phrase(advice, params.units)))
    spoken = advice if advice.speak else memory.spoken
    if advice.action == "none" and advice.reason in ("too_close", "short_wait"):
        spoken = memory.spoken  # silence keeps the last spoken advice as the reference
    return advice, AdvisorMemory(last=advice, spoken=spoken)
