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

The parts it decides with live beside it: the data (:mod:`advisory.advice.views`), the car's motion
(:mod:`advisory.advice.kinematics`), the wording (:mod:`advisory.advice.wording`) and the lights' timings for the
choice (:mod:`advisory.advice.mixture`).
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np

from advisory.advice import choice
from advisory.advice.kinematics import (KEEP_MODES, MODE_CODES, MODE_NAMES, Lines, candidates_mps, crossing_time_s, crossing_times_s, crossings,
                                        drives_normally, green_crossing, kernel_args, keeps, line_speeds_mps, normal_crossing_s, search,
                                        slowed_into_red)
from advisory.advice.mixture import mixture_timings
from advisory.advice.screening import screened
from advisory.advice.views import Advice, AdvisorMemory, AdvisorParams, LightView, Observation, countdown_view, light_timing, time_price
from advisory.advice.wording import phrase

LINE_SPEED_TIE_MPS = 0.2
"""Targets whose speeds at the next line differ by less than this count as equally close to the tables'
wanted speed there; the tie goes to the target nearest it. [m/s]"""


def _past_next_green(light: LightView, obs: Observation, params: AdvisorParams) -> bool:
    """The advice's horizon: a normal drive (no advice: speeding up to the limit at ``normal_accel_mps2``) reaches the
    line only after the light's next green to begin has ended (the start of its second red window, as each change is
    likely). A plan then aims at a green after that one: two cycles out, on a timing that a real controller publishes
    one phase ahead (J2735: the current phase's end, the next at best) and that a predictor knows less well the
    farther it looks. Within it the advisor plans for the current green or the next one, never a later one. [-]"""
    starts = sorted(start for start, end in countdown_view(light).red_windows_s if end > 0.0)
    return len(starts) >= 2 and normal_crossing_s(light.distance_m, obs, params) > starts[1]


def _known_ahead(lights: tuple[LightView, ...], obs: Observation, params: AdvisorParams) -> tuple[LightView, ...]:
    """The lights the advice can plan for: those before the first that a normal drive (no advice: speeding up to the
    limit at ``normal_accel_mps2``) reaches in a phase whose state nobody knows (``LightView.unknown_windows_s``: J2735
    "unavailable" that the group's history cannot read). What the car meets there is no basis for a plan: in the
    lights' timings such a phase blocks like a red, so a plan priced through it slowed the car for it, or for the green
    after it, where the regular driver went through (2019-05-01 groups 5-6: group 6 publishes a green of ~8 s, then
    "unavailable" for ~65 s, no red at all; "Second light: red in 7 seconds. Slow down to 34 km/h": +17..+24 % in four
    approaches). None left (the next light itself): no data, said so."""
    for i, light in enumerate(lights):
        if light.unknown_windows_s and light.unknown_at(normal_crossing_s(light.distance_m, obs, params)):
            return lights[:i]
    return lights


def _binding(lights: tuple[LightView, ...], obs: Observation, params: AdvisorParams) -> int:
    """Which light the advice is for (index into ``lights``): the first one that the car, holding its speed, would
    not cross on green (with the after-red margin); the next light if it makes them all. The countdown names it."""
    if obs.speed_mps <= 0.0:
        return 0
    for i, light in enumerate(lights):
        if not green_crossing(light, light.distance_m / obs.speed_mps, params.green_margin_s):
            return i
    return 0


def _timed(action: str, reason: str, target: float | None, lights: tuple[LightView, ...], i: int, source: str = "rules",
           first: tuple[bool, float | None] | None = None) -> Advice:
    """An advice whose countdown is light ``i``'s; ``first``: the first light's :func:`light_timing`, where known."""
    red, to_change = first if i == 0 and first is not None else light_timing(lights[i])
    return Advice(action, reason, target, red, to_change, source=source, light_ahead=i + 1, light_id=lights[i].intersection_id)


def _kept(lines: Lines, usable: tuple[LightView, ...], obs: Observation, params: AdvisorParams, last: Advice) -> bool:
    """A driver already following ``last`` (no new reaction delay) still makes every green, with the margin."""
    keep_mode = KEEP_MODES[last.action]
    if keeps(lines, obs, params, keep_mode, last.target_speed_mps):
        return True
    if keep_mode != "brake_coast":
        return False
    # a coasting driver may be below the target already (it coasts on): check its own coast, margin included
    keep_target = min(last.target_speed_mps, obs.speed_mps)
    return all(
        green_crossing(light, crossing_time_s(light.distance_m, obs.speed_mps, keep_target, params, keep_mode, 0.0), params.green_margin_s)
        for light in usable
    )


def _held(obs: Observation, memory: AdvisorMemory, params: AdvisorParams) -> Advice | None:
    """Through a short dropout: the last advice, re-checked on the last SPaT (its windows, aged); no new advice, but a
    stop at a light known to show no amber (``LightView.amber_s`` 0, where no driver sees a red coming): where the plan
    the driver follows (driving normally where none) would reach its line inside a red that the last reading admits
    (its windows widened for the clock and aged, never narrowed: a red that may begin stays possible until data says
    otherwise), "prepare to stop" once a stop must begin (:func:`_stop_due`) while the firm rate still stops the car.
    Told only "Signal data delayed.", a driver went on into such a red (issue 31: closed-loop seeds 361 and 1392). Where
    the light shows an amber (or may: every real feed's unknown amber) the eye decides, and nothing new is said on stale
    data. ``None`` when the dropout is too long (or nothing was advised and no stop is due): the plain "out of date"."""
    nxt, last = obs.lights[0], memory.last
    if not nxt.red_windows_s or nxt.age_s > params.hold_stale_s:
        return None
    usable = tuple(light for light in obs.lights[:2] if light.red_windows_s)
    red, to_change = light_timing(nxt)
    plan = last is not None and last.action in KEEP_MODES and last.target_speed_mps is not None
    if last is not None and (last.action == "stop" or (plan and _kept(Lines.of(usable), usable, obs, params, last))):
        return Advice(last.action, "stale_spat", last.target_speed_mps, red, to_change, source=last.source)
    v, d = float(obs.speed_mps), float(nxt.distance_m)
    if plan:
        arrival = crossing_time_s(d, v, last.target_speed_mps, params, KEEP_MODES[last.action], 0.0)
    else:
        arrival = normal_crossing_s(d, obs, params)
    if nxt.amber_s == 0.0 and v > 0.0 and nxt.is_red_at(arrival) and _stop_due(d, v, params) and v * v <= 2.0 * params.firm_decel_mps2 * d:
        return Advice("stop", "stale_spat", 0.0, red, to_change)
    return None if last is None else Advice("none", "stale_spat", light_red=red, seconds_to_change_s=to_change)


def _stop_due(distance_m: float, v_mps: float, params: AdvisorParams) -> bool:
    """A stop for a line ``distance_m`` ahead must be said now: within a reaction and ``stop_lead_s`` at ``v_mps`` of
    where a comfortable stop must begin ("prepare to stop"; farther out, a lift-off or "Red light ahead."). [-]"""
    return distance_m <= v_mps * (params.reaction_s + params.stop_lead_s) + v_mps * v_mps / (2.0 * params.comfort_decel_mps2)


def _said_bound_mps(bound_mps: float, said_above: bool | None, params: AdvisorParams) -> float:
    """The speed between two words, moved by ``hysteresis_mps`` away from the side the words said last were said from
    (``said_above``; ``None``: neither was said, the bound as it is): those words stay while the speed is within the band
    of the bound on their side (the band in which the advice holds rather than nudge, section 4). Without it, a driver
    who keeps the speed just past a bound (the closed-loop driver drifts 1 m/s above low targets) heard the two words
    in turn every other second, the plan unchanged. [m/s]"""
    return bound_mps if said_above is None else bound_mps - params.hysteresis_mps if said_above else bound_mps + params.hysteresis_mps


def _crawling(v_mps: float, last: Advice | None, params: AdvisorParams) -> bool:
    """Too slow for a lift-off far from a red to ask anything (the car pulls away at a crawl): below the slowest speed
    ever advised (``min_cruise_speed_mps``), where "Red light ahead." alone is said (on it a driver keeps a crawl, no
    slower than that speed); above it "Lift off and coast", the words said last kept within the band
    (:func:`_said_bound_mps`). With the bound alone the two words moved the car across it each way: "Lift off and
    coast" at 10 mph, a coast 0.1 m/s below it, "Red light ahead.", back to 10 mph: they flipped every other second
    for 130 s (no-amber seed 1526). [-]"""
    said = last is not None and last.reason == "red_ahead" and last.action in ("none", "coast")
    return v_mps < _said_bound_mps(params.min_cruise_speed_mps, last.action == "coast" if said else None, params)


def _speed_word(target_mps: float, v_mps: float, last: Advice | None, params: AdvisorParams) -> str:
    """How a plan to hold ``target_mps`` (no braking asked) is said at ``v_mps``: "Ease off to" above the band of
    ``hysteresis_mps`` around it, "Speed up to" below, "Hold" within. The same target said last as "Ease off to" (or
    "Speed up to") stays so while the speed is above it (below it): true still, the car not there yet
    (:func:`_said_bound_mps`: the band's edge moved to the target on the side said). The word changes only where it
    would no longer be true, or with the target. With the band's edges alone, no-amber seed 1520's driver (1 m/s above
    a 14 mph target, the band's edge) heard "Hold 14" and "Ease off to 14" in turn for 16 s. [-]"""
    said = last.action if last is not None and last.reason == "green_wave" and last.target_speed_mps == target_mps else None
    if v_mps > _said_bound_mps(target_mps + params.hysteresis_mps, True if said == "ease_off" else None, params):
        return "ease_off"
    if v_mps < _said_bound_mps(target_mps - params.hysteresis_mps, False if said == "accelerate" else None, params):
        return "accelerate"
    return "cruise"


@lru_cache(maxsize=64)
def _candidate_plans(low_mps: float, limit_mps: float, step_mps: float, reaction_s: float, accel_mps2: float, normal_accel_mps2: float) -> tuple:
    """The candidate plans of :func:`_choose`, made once per road and driver (not per fix): targets, modes, reactions,
    accelerations and rate rows (m,) of every advised speed in each mode, then driving normally (the limit, no reaction,
    the regular driver's rate), "prepare to stop" (a lift-off: its target, the car's speed, is set per fix) and the
    plan followed now (set per fix). Shared: copy before writing (targets and modes are)."""
    speeds = candidates_mps(low_mps, limit_mps, step_mps)
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
    speeds, v0, reaction, brake, firm, accel, *coast_tables = kernel_args(obs, params, None)
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
    lines = Lines.of(usable)
    d_m = lines.distances_m
    rates, coast, idle = choice.rate_tables(params.vehicle, params.comfort_decel_mps2, params.normal_accel_mps2, params.firm_decel_mps2)
    x_end = float(d_m[-1]) + v_lim * v_lim / (2.0 * params.normal_accel_mps2)
    windows, weights = mixture_timings(usable)
    lam_road = _road_time_value_usd_per_s(params, v_lim) if params.time_value_usd_per_s is None else params.time_value_usd_per_s
    lam = lam_road * time_price(obs)  # the car's time and its followers' (Observation.followers)
    exact = np.array([light.likely_red_windows_s is None and light.scenario_red_windows_s is None for light in usable])
    edge = np.where(exact, choice.EXACT_EDGE_S, choice.EDGE_S)  # (an exact light's changes come when it says)
    # the amber before each red: at least ``clear``, at most ``amber_max`` (an exact light's stated one: that long)
    clear = np.array([0.0 if light.amber_s == 0.0 else light.amber_s if e and light.amber_s else min(light.amber_s or choice.AMBER_MIN_S, choice.AMBER_MIN_S)
                      for light, e in zip(usable, exact)])
    # where no amber warns of a light's reds, or its timing is exact (a red published is never planned as green: the
    # amber before it is priced, the red is not driven into), no plan reaches the line where one may be on (the sure
    # windows), nor, slowing the car at a light without amber, within the margin before one may begin (the feasibility
    # of the rules, :func:`advisory.advice.kinematics.green_mask`); "prepare to stop" stops at the red it meets
    cross, crossed = crossings(vts, modes, reactions, accels, d_m, v0, brake, firm, *coast_tables, lines.windows_s, lines.no_amber, exact, stop_plan,
                               params.green_margin_s)  # fmt: skip
    # priced as the choice needs them (choice.expected_costs, "pruned"): driving normally first and in full, and the
    # stop plan; a plan that cannot be allowed (through a red, or a stop likelier than driving normally's by more than
    # ``stop_risk_frac``) is not priced further. The same choice as pricing every plan (tests/test_choice.py); screened
    # (screening.screened): the plans priced on a sample of the timings first, the few best of them on all
    must = np.zeros(vts.size, dtype=np.bool_)
    must[normal] = must[stop] = True
    must[-1] = keep  # (kept where it costs no more than the best: its cost, even inf, counts)
    skip = crossed & ~must
    skip[-1] |= not keep  # (no plan followed now: its slot is not a candidate)
    amber_max = np.array([0.0 if light.amber_s == 0.0 else light.amber_s or choice.AMBER_MAX_S for light in usable])

    args = (vts, modes, reactions, rows, accels, v0, d_m, windows, windows.shape[2], x_end, v_lim, params.green_margin_s, lam, cross, rates, coast, idle,
            brake, firm, params.normal_accel_mps2, params.reaction_s, params.min_cruise_speed_mps, clear, weights, stop_plan, amber_max, edge, skip, must,
            normal, params.stop_risk_frac)  # (choice.expected_costs's arguments)
    # exact timing (:func:`_into_amber`): its one timing, every plan priced on it; else screened
    cost, p_stop, through = choice.expected_costs(*args) if weights.size == 1 else screened(args, m, n_modes)
    through |= crossed
    best = choice.least_cost(cost, p_stop, through, normal, stop, params.stop_risk_frac, keep, lam * params.reaction_s)
    if (best == normal and weights.size == 1 and choice.allowed(m - 1, p_stop, through, normal, params.stop_risk_frac)
            and not (not red and to_change is not None and float(cross[normal, 0]) < to_change)):  # fmt: skip
        best = m - 1  # exact timing, driving normally the best plan and no red before it: the limit, said as the rules say it
    while (best < n_modes * m and best % m < m - 1 and vts[best + 1] < v - params.hysteresis_mps and cost[best + 1] == cost[best]
           and p_stop[best + 1] == p_stop[best] and not through[best + 1]):  # fmt: skip
        # of one motion's targets, the highest still said as a slowing (below the band around the car's speed): a
        # lift-off over the lines before it slows to its target is the same plan to every target below the speed it
        # comes to (choice.expected_costs prices them alike, to the bit); the first of equals said "Ease off to 10 mph"
        # to a car that coasts from 30 to 27 mph over the line
        best += 1
    if best == normal:  # nothing does better than driving on as the driver would (the red may come late): no speed advice
        arrival = float(cross[normal, 0])
        reason = "tight_green" if not red and to_change is not None and arrival < to_change else "low_confidence"
        return Advice("none", reason, light_red=red, seconds_to_change_s=to_change)
    if stop_plan[best]:
        # "prepare to stop" is the plan: said when a stop must begin soon; farther out lift off (its motion until then:
        # arriving later only helps, the red may end first), or nothing while the car pulls away at a crawl (the light
        # it is about: the first the car as it goes would not cross on green; a stop only at the next one)
        # the light it is about: the first that the stop plan's own motion (a lift-off) meets in a red, where it stops
        # (by the car's speed held, a light made 0.4 s before a red no amber announces named the next light's green:
        # "Red light ahead. Green in 45 seconds. Lift off and coast." for a stop at this one, never said "stop")
        i = next((j for j in range(len(usable)) if not green_crossing(usable[j], float(cross[stop, j]), params.green_margin_s)
                  or slowed_into_red(usable[j], float(cross[stop, j]), params.green_margin_s)), _binding(usable, obs, params))  # fmt: skip
        if i == 0 and red and v > 0.0 and nxt.seconds_to_green() - crossing_time_s(nxt.distance_m, v, v, params) < params.short_wait_s:
            return Advice("none", "short_wait", light_red=red, seconds_to_change_s=to_change)  # a stop to wait a moment: none
        if i == 0 and _stop_due(nxt.distance_m, v, params):  # (at a crawl too: the stop is the plan, as the rules say it)
            return Advice("stop", "red_ahead", target_speed_mps=0.0, light_red=red, seconds_to_change_s=to_change)
        if _crawling(v, last, params):  # pulling away at a crawl: what is ahead, said
            return _timed("none", "red_ahead", None, usable, i, first=(red, to_change))
        # lift off only: the words and the driver's motion are a lift-off (the stop, when it comes, is braked then)
        keep_target = last is not None and last.action == "coast" and last.reason == "red_ahead" and last.target_speed_mps is not None
        return _timed("coast", "red_ahead", last.target_speed_mps if keep_target else v, usable, i, first=(red, to_change))
    target, mode = min(float(vts[best]), v_lim), MODE_NAMES[int(modes[best])]
    # the words say the motion the plan was priced in (a driver told "slow down" brakes, told "hold" lifts off)
    if mode == "brake_coast":
        action = "coast"
    elif target < v and mode in ("brake", "firm"):
        action = "slow_down" if mode == "brake" else "brake_to"
    else:
        action = _speed_word(target, v, last, params)
    return _timed(action, "green_wave", target, usable, _binding(usable, obs, params), first=(red, to_change))


def _decide(obs: Observation, memory: AdvisorMemory, params: AdvisorParams, tables) -> Advice:
    if not obs.on_route:
        return Advice("none", "past_lights" if obs.zone_exit else "off_route")
    if not obs.lights:  # past the last light: back to the limit ("Resume" said stays while true: section 1b)
        v, last = obs.speed_limit_mps, memory.last
        said = last is not None and last.reason == "past_lights" and last.action == "resume" and last.target_speed_mps == v
        slow = obs.speed_mps < _said_bound_mps(v - params.hysteresis_mps, False if said else None, params)
        return Advice("resume" if slow else "cruise", "past_lights", target_speed_mps=v)
    nxt = obs.lights[0]
    if not nxt.fresh:
        held = _held(obs, memory, params)
        return held if held is not None else Advice("none", "stale_spat" if nxt.red_windows_s else "no_spat")
    if nxt.confidence_frac < params.min_confidence_frac:
        return Advice("none", "low_confidence")
    shown = countdown_view(nxt)  # (once: each change at its likely instant, for the countdown and the horizon)
    red, to_change = light_timing(shown)
    if _past_next_green(shown, obs, params):
        # so far out that even a normal drive reaches the line after the light's next green has ended: any speed
        # advised now would aim two greens or more ahead (issue 29: "Green in 24 seconds. Ease off to 43 km/h"
        # 1.8 km out); the countdown stays (it is true), the advice waits until the next green is in reach
        return Advice("none", "far_ahead", light_red=red, seconds_to_change_s=to_change)
    if nxt.distance_m < max(params.too_close_m, obs.speed_mps * params.too_close_s):
        return Advice("none", "too_close", light_red=red, seconds_to_change_s=to_change)
    usable = _known_ahead(tuple(light for light in obs.lights[:2] if light.fresh and light.confidence_frac >= params.min_confidence_frac), obs, params)
    if not usable:  # a normal drive meets the next light in a phase whose state nobody knows: no stop asked, no plan
        return Advice("none", "no_spat", light_red=red, seconds_to_change_s=to_change)
    last = memory.last
    if any(light.likely_red_windows_s is not None or light.scenario_red_windows_s is not None for light in usable):
        return _choose(obs, usable, last, params, red, to_change)  # uncertain timing: the plan of least expected cost
    ruled = _ruled(obs, usable, last, params, tables, red, to_change)  # exact timing: the rules, unless their plan meets an amber
    return _choose(obs, usable, last, params, red, to_change) if _into_amber(ruled, usable, obs, params) else ruled


def _into_amber(a: Advice, usable: tuple[LightView, ...], obs: Observation, params: AdvisorParams) -> bool:
    """The rules' plan ``a`` (a speed for a green, or driving normally, ``tight_green``) reaches a line inside the amber
    before a red still to come, at a light that states its amber (``LightView.amber_s``): then the choice decides, on the
    light's one timing, weight 1 (:func:`_choose`; docs/ADVISOR.md, section 2, "An amber the driver stops for"). The rules
    count an amber as green (:func:`advisory.advice.kinematics.green_mask`, the ``tight_green`` rule); the choice prices
    it as the driver meets it (:func:`advisory.advice.choice.expected_costs`: stopped for where it shows while the car
    can still stop at ``choice.AMBER_STOP_MPS2``, else cleared). Traced in SUMO (7th Street, fixed time, 600 veh/h, 10 %,
    seed 1, ``main.97``; docs/history/TRAFFIC.md, "What remains, as the sessions left it"): "Hold 30 mph" for a
    crossing 1.2 s before the red, 2.8 s into its 4 s amber, which showed 38 m out: the driver stopped and stood the
    red (42 s). [-]"""
    speed_plan = a.action in KEEP_MODES and a.target_speed_mps is not None and a.reason == "green_wave"
    if not (speed_plan or (a.action == "none" and a.reason == "tight_green")):
        return False
    for light in usable:
        if light.amber_s:  # (stated: None is an amber of unknown length, 0 none)
            d = light.distance_m
            t = crossing_time_s(d, obs.speed_mps, a.target_speed_mps, params, KEEP_MODES[a.action]) if speed_plan else normal_crossing_s(d, obs, params)
            if any(0.0 < start and start - light.amber_s <= t < start for start, _ in light.red_windows_s):
                return True
    return False


def _ruled(obs: Observation, usable: tuple[LightView, ...], last: Advice | None, params: AdvisorParams, tables, red: bool, to_change: float | None) -> Advice:
    """The rules on exact timing (section 2 of docs/ADVISOR.md): the plan followed kept while it makes every green, else
    the speeds that make the greens (:func:`advisory.advice.kinematics.search`), the DP tables' pick among them, a stop or
    a lift-off where none does, no advice where only a normal drive does (``tight_green``)."""
    nxt = usable[0]
    if not _plan_ahead(last, obs):  # the rules keep a plan while it is feasible: not one made for a light now behind
        last = None
    both = Lines.of(usable)
    if last is not None and last.target_speed_mps is not None and last.action in KEEP_MODES:
        # the driver is already following the last advice: keep it while it still works (no new reaction delay)
        if _kept(both, usable, obs, params, last):
            action = last.action if last.action != "accelerate" or last.target_speed_mps > obs.speed_mps + params.hysteresis_mps else "cruise"
            if not red and action in ("accelerate", "cruise") and _leads_away(last.target_speed_mps, obs, both, len(usable), params):
                return Advice("none", "tight_green", light_red=False, seconds_to_change_s=to_change)
            return _timed(action, last.reason, last.target_speed_mps, usable, _binding(usable, obs, params), last.source, (red, to_change))
    n_lines, mode, feasible = search(both, obs, params)
    to_red = None if red else nxt.seconds_to_red()  # (every light here is exact: uncertain ones went to _choose)
    if to_red is not None and (normal_s := normal_crossing_s(nxt.distance_m, obs, params)) < to_red:
        planned_s = crossing_time_s(nxt.distance_m, obs.speed_mps, float(feasible[-1]), params, mode) if feasible.size else np.inf
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
        to_green = countdown_view(nxt).seconds_to_green_after(min(arrival, slowest))
        far = not _stop_due(nxt.distance_m, v, params)
        if far and not math.isfinite(to_green):
            # far from a red whose end is unknown: no stop asked for yet (a stop so far out halted the car 220 m
            # short of the line), but lift off: arriving later only helps (the red may end first), and what coasting
            # sheds the stop would have braked away anyway. Not at a crawl (launching from the light before): there
            # only what is ahead. A known end keeps the early gentle stop (the advisor re-plans from it)
            if _crawling(v, last, params):
                return Advice("none", "red_ahead", light_red=red, seconds_to_change_s=to_change)
            keep = last is not None and last.action == "coast" and last.reason == "red_ahead" and last.target_speed_mps is not None
            return Advice("coast", "red_ahead", last.target_speed_mps if keep else v, red, to_change)
        # the countdown is the light's next change (to red while it is green now), never the green after a red to come
        return Advice("stop", "red_ahead", target_speed_mps=0.0, light_red=red, seconds_to_change_s=to_change)
    target, source = float(feasible[-1]), "rules"  # (the fastest: candidates ascend, kinematics.candidates_mps)
    if tables is not None:
        wanted = tables.target_speed_mps(obs)
        if wanted is not None:  # the DP's speed at the next stop line: the feasible target that reaches the line nearest it
            _, v0, reaction, *rest = kernel_args(obs, params, None)
            # no lingering: at most ``table_slack_s`` later over the lines planned for than the fastest feasible speed
            last_m = float(both.distances_m[n_lines - 1])
            arrive = crossing_times_s(last_m, v0, feasible, MODE_CODES[mode], reaction, *rest)
            feasible = feasible[arrive <= arrive[-1] + params.table_slack_s / time_price(obs)]  # followers: less time given up
            miss = np.abs(line_speeds_mps(float(nxt.distance_m), v0, feasible, MODE_CODES[mode], reaction, *rest) - wanted)
            # targets still being braked to at the line reach it alike: of those, the one nearest the wanted speed
            close = feasible[miss <= miss.min() + LINE_SPEED_TIE_MPS]
            target, source = float(close[np.argmin(np.abs(close - wanted))]), "dp_table"
    if last is not None and last.target_speed_mps is not None and last.action in ("cruise", "ease_off", "accelerate", "slow_down", "coast") and last.reason == "green_wave":
        # the driver is already following the last plan: keep it while it still works (no new reaction delay); not
        # a lift-off for a red whose end was unknown ("Red light ahead. Lift off and coast."): a plan now, for a green
        keep_mode = {"slow_down": "brake", "coast": "brake_coast"}.get(last.action, "auto")
        if abs(last.target_speed_mps - target) < params.speak_change_mps and keeps(both, obs, params, keep_mode, last.target_speed_mps, n_lines):
            target, mode = last.target_speed_mps, keep_mode
    if not red and mode == "auto" and target >= obs.speed_mps - params.hysteresis_mps and _leads_away(target, obs, both, n_lines, params):
        return Advice("none", "tight_green", light_red=False, seconds_to_change_s=to_change)
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
    return _timed(action, "green_wave", min(target, obs.speed_limit_mps), usable, _binding(usable[:n_lines], obs, params), source, (red, to_change))


def _leads_away(target_mps: float, obs: Observation, lines: Lines, n_lines: int, params: AdvisorParams) -> bool:
    """A plan to speed up to the limit or to hold the speed in the band below it ("Speed up to 55 mph", "Hold 53 mph")
    for a car that cars follow (``obs.followers``: a platoon pulling away behind it), where a normal drive (the regular
    driver's ``normal_accel_mps2`` at once, no advice to react to) makes the same greens: the advice is then to drive
    normally, with the traffic. The advised speed-up is planned, and driven, at the lone driver's
    ``comfort_accel_mps2`` (1.5 m/s², the closed loop's driver) after a reaction; every follower loses what the car
    loses (1.2 s from 10.9 m/s over 390 m), and the platoon's last car a green it made by under a second (traced in
    SUMO, paper_s400 fixed 600 veh/h, 50 %, seed 2: ``main.57`` told "Speed up to 88 kilometers per hour" 10 m past
    light 1 at 10.9 m/s, over light 2 1.0 s later than its unadvised twin; ``main.60``, three cars behind, lost that
    green, 30 s); the hold keeps a car 0.9 m/s under the limit to the line. The gentler rate buys nothing even alone:
    from 11 m/s to the limit, over the same distance, it saves 0.008 cent of energy and loses 0.63 s, 0.03 cent at the
    road's price on time (``choice.steady_time_value_usd_per_s``), 0.06 cent with one follower; it is kept for a car
    alone, as the lone driver's comfort. A car at the limit (within half a speed step: the advised speed nearest its
    own is the limit) is told to hold it, as before: the same motion. [-]"""
    return (obs.followers > 0.0 and target_mps >= obs.speed_limit_mps - 1e-9 and obs.speed_mps < obs.speed_limit_mps - 0.5 * params.speed_step_mps
            and drives_normally(lines, obs, params, n_lines))  # fmt: skip


def _plan_ahead(last: Advice | None, obs: Observation) -> bool:
    """Whether the plan the driver follows (``last``) is still for a light ahead: the light that set it
    (``Advice.light_id``, the binding light of :func:`_timed`) is one of ``obs.lights``. Over that light's line the
    plan has done its work; kept for the next light ("keep it while it still works"), a speed chosen for the light
    behind held the car below what the next light asks. (The choice under uncertain timing prices the plan followed
    against every other, :func:`_choose`: there it stays a candidate.) Traced in SUMO (7th Street, fixed time, 300 veh/h, 50 %,
    seed 1, docs/history/TRAFFIC.md): "Slow to 25 mph, then coast" for light 1's green, kept 165 m before light 2, whose
    green the limit reaches 4 s after it starts; planned afresh, the advisor says "Hold 30 mph". A plan that names no
    light: kept, as before."""
    if last is None or last.light_id is None:
        return True
    return any(light.intersection_id == last.light_id for light in obs.lights)


def _meaningful_change(new: Advice, old: Advice | None, params: AdvisorParams) -> bool:
    if old is None:
        return new.action != "none" or new.reason in ("no_spat", "stale_spat", "low_confidence", "off_route", "red_ahead", "past_lights")
    if (new.action, new.reason) != (old.action, old.reason):
        return new.reason not in ("too_close", "short_wait", "far_ahead")
    if new.target_speed_mps is not None and old.target_speed_mps is not None:
        return abs(new.target_speed_mps - old.target_speed_mps) >= params.speak_change_mps
    return False


DEFAULT_PARAMS = AdvisorParams()
"""The settings :func:`advise` uses when given none: one instance (frozen), so that the caches keyed by the settings'
identity (``kinematics._motion``) hit and those keyed by their value find them at once; a fresh one per call was built,
missed and hashed each time (10-15 us of the ~0.5-0.65 ms a call of ``bench/bench_predictor.py``'s observations)."""


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
    params = params or DEFAULT_PARAMS
    a = _decide(obs, memory, params, tables)
    # (constructor calls, not dataclasses.replace: this runs once a second per car)
    # the light the countdown is about: the next one unless the advice named another (the one after it, ``_timed``)
    light_id = a.light_id if a.light_id is not None or a.light_red is None or not obs.lights else obs.lights[0].intersection_id
    message = phrase(a, params.units, obs.speed_mps)  # (the words read the advice's fields, and the car's speed)
    speak = bool(message) and _meaningful_change(a, memory.spoken, params)
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
