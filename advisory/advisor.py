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

from dataclasses import dataclass, field, replace

import numpy as np

MPH_PER_MPS = 1 / 0.44704
KMH_PER_MPS = 3.6


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
    """One advisory. ``action``: cruise, ease_off, accelerate, stop, resume or none (no speed advice)."""

    action: str
    reason: str
    target_speed_mps: float | None = None
    light_red: bool | None = None
    seconds_to_change_s: float | None = None
    message: str = ""
    speak: bool = False
    source: str = "rules"  # "dp_table" when the target came from the lookup tables

    def as_dict(self) -> dict:
        return {k: getattr(self, k) for k in self.__slots__}


@dataclass(frozen=True, slots=True)
class AdvisorParams:
    """Advisor settings. Units in names."""

    min_cruise_speed_mps: float = 20 * 0.44704  # drivers found < 20 mph hard to hold (paper Sec. 4.4)
    reaction_s: float = 1.0
    comfort_decel_mps2: float = 1.5
    comfort_accel_mps2: float = 1.5
    too_close_s: float = 3.0  # closer than this many seconds to the line at current speed: no advice
    too_close_m: float = 15.0
    short_wait_s: float = 3.0
    min_confidence_frac: float = 0.5
    hysteresis_mps: float = 1.0
    speak_change_mps: float = 5 * 0.44704
    speed_step_mps: float = 0.44704  # candidates in whole mph: the spoken number is the advised one
    units: str = "mph"

    def __post_init__(self) -> None:
        if self.units not in ("mph", "kmh"):
            raise ValueError("units must be 'mph' or 'kmh'")


@dataclass(frozen=True, slots=True)
class AdvisorMemory:
    """What the advisor remembers between fixes of one trip (for hysteresis and the speak flag)."""

    last: Advice | None = None
    spoken: Advice | None = None
    history: tuple[str, ...] = field(default=())


def crossing_time_s(distance_m: float, v0_mps: float, v_target_mps: float, params: AdvisorParams) -> float:
    """Time to reach a line ``distance_m`` ahead: reaction at v0, comfortable ramp to the target, cruise. [s]"""
    d = max(distance_m, 0.0)
    d_react = v0_mps * params.reaction_s
    if d <= d_react:
        return d / v0_mps if v0_mps > 0 else np.inf
    d -= d_react
    rate = params.comfort_decel_mps2 if v_target_mps < v0_mps else params.comfort_accel_mps2
    d_ramp = abs(v0_mps**2 - v_target_mps**2) / (2.0 * rate)
    if d <= d_ramp:  # the line comes during the ramp
        disc = v0_mps**2 + 2.0 * (rate if v_target_mps >= v0_mps else -rate) * d
        v_line = np.sqrt(max(disc, 0.0))
        return params.reaction_s + abs(v_line - v0_mps) / rate if v_line > 0 else np.inf
    t_ramp = abs(v0_mps - v_target_mps) / rate
    return params.reaction_s + t_ramp + (d - d_ramp) / v_target_mps if v_target_mps > 0 else np.inf


def feasible_speeds_mps(obs: Observation, params: AdvisorParams) -> np.ndarray:
    """Candidate cruise speeds in [min cruise, limit] that cross the next two lines on green. [m/s]"""
    speeds = np.arange(params.min_cruise_speed_mps, obs.speed_limit_mps + 1e-9, params.speed_step_mps)
    speeds = np.unique(np.append(speeds, obs.speed_limit_mps))
    ok = np.ones(speeds.size, dtype=bool)
    for light in obs.lights[:2]:
        for n, v in enumerate(speeds):
            if ok[n] and light.is_red_at(crossing_time_s(light.distance_m, obs.speed_mps, v, params)):
                ok[n] = False
    return speeds[ok]


def _say_speed(speed_mps: float, units: str) -> str:
    return f"{round(speed_mps * (MPH_PER_MPS if units == 'mph' else KMH_PER_MPS)):d}"


def phrase(advice: Advice, units: str = "mph") -> str:
    """Short, voice-ready English for an advisory (numbers rounded, speed in mph or km/h)."""
    unit_word = "miles per hour" if units == "mph" else "kilometers per hour"
    t = advice.seconds_to_change_s
    when = "" if t is None or t <= 0 else f"{round(t):d} seconds"
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
    verb = {"ease_off": "Ease off to", "accelerate": "Speed up to", "cruise": "Hold"}[advice.action]
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
    feasible = feasible_speeds_mps(replace(obs, lights=usable), params)
    if feasible.size == 0 and len(usable) > 1:  # no speed makes both greens: plan for the next light only
        feasible = feasible_speeds_mps(replace(obs, lights=usable[:1]), params)
    if feasible.size == 0:
        arrival = crossing_time_s(nxt.distance_m, obs.speed_mps, obs.speed_mps, params) if obs.speed_mps > 0 else np.inf
        if red and nxt.seconds_to_green() - arrival < params.short_wait_s and obs.speed_mps > 0:
            return Advice("none", "short_wait", light_red=red, seconds_to_change_s=to_change)
        slowest = crossing_time_s(nxt.distance_m, obs.speed_mps, params.min_cruise_speed_mps, params)
        return Advice("stop", "red_ahead", target_speed_mps=0.0, light_red=red,
                      seconds_to_change_s=nxt.seconds_to_green_after(min(arrival, slowest)))
    target, source = float(feasible.max()), "rules"
    if tables is not None:
        wanted = tables.target_speed_mps(obs)
        if wanted is not None:  # the DP's speed, snapped to the nearest feasible one
            target, source = float(feasible[np.argmin(np.abs(feasible - wanted))]), "dp_table"
    last = memory.last
    if (
        last is not None
        and last.target_speed_mps is not None
        and last.action in ("cruise", "ease_off", "accelerate")
        and abs(last.target_speed_mps - target) < params.hysteresis_mps
        and np.any(np.abs(feasible - last.target_speed_mps) < 1e-9)
    ):
        target = last.target_speed_mps
    if target < obs.speed_mps - params.hysteresis_mps:
        action = "ease_off"
    elif target > obs.speed_mps + params.hysteresis_mps:
        action = "accelerate"
    else:
        action = "cruise"
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
    advice = _decide(obs, memory, params, tables)
    speak = _meaningful_change(advice, memory.spoken, params)
    advice = replace(advice, message=phrase(advice, params.units), speak=speak and bool(phrase(advice, params.units)))
    spoken = advice if advice.speak else memory.spoken
    if advice.action == "none" and advice.reason in ("too_close", "short_wait"):
        spoken = memory.spoken  # silence keeps the last spoken advice as the reference
    return advice, AdvisorMemory(last=advice, spoken=spoken, history=(memory.history + (advice.action,))[-10:])
