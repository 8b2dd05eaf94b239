"""Closed-loop evaluation: a virtual driver follows the advisor through a scenario.

The driver asks for advice once a second and acts on it after a reaction delay. It tracks advised speeds
at comfortable rates, drifting *up* when the advised speed is low (the paper's field-test driver found
~20 mph hard to hold). It is also a human who sees the lights: like the regular driver, it decides at the
decision point before each stop line, brakes for a light that will be red on arrival at its current
speed (a red showing then must end ``red_end_margin_s`` before that arrival: the advice counts the seconds
to green), and after deciding to go neither slows down so much that a red catches it nor speeds up while
the light is still red. Everything else comes from the advice (a "stop": lift off, then brake at the comfortable
rate, or harder if that no longer stops it at the line, only until its line is behind or the car is at rest there with a display: then the
eye and the display say when to go; "Red light
ahead." alone: no speeding up towards it; advice that asks nothing new, such as "Signal data delayed.": it goes on
with what it was told);
``overrides`` counts the times the driver's own braking was needed although the advice did not say "stop".
What it knows of the lights it sees (issue 31): at a light that shows no amber (:func:`shows_amber`) its eye
cannot see a red coming, so a green its display says may turn red now (a window open since the driver last saw
red) or before the car is over the line (decided again when the display shows it, the driver having gone on), or that
it is told to stop for, is one it stops for where it still can at 4 m/s²; stopping on advice for a line that shows red now, where even 4 m/s² would roll it over the line,
it brakes harder (up to ``emergency_decel_mps2``); and a red that outlasts by a reaction time the green the display
promised when the driver went on is waited out by the eye (no new countdown is trusted for that red).

Two named drivers (:data:`DRIVERS`), the same but on amber and at launch: :data:`LENIENT` clears an amber it
reaches before the red (the regular driver's rule; already stopping for that line, it goes on stopping) and
speeds up at the regular driver's 2 m/s² when no speed is advised; :data:`CAREFUL` stops for any amber it can
stop for at the regular driver's hardest braking (4 m/s²) and launches at 1.5 m/s². Both follow the advice with a 1 s reaction. :meth:`DriverModel.regular` is
the same person without advice (the regular driver with its amber rule and launch), the fair baseline.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np

from advisory.advice.advisor import advise
from advisory.advice.kinematics import coast_decel_mps2
from advisory.advice.views import Advice, AdvisorMemory, AdvisorParams, LightView, Observation
from advisory.drivers.regular import DriverParams
from advisory.signals import FixedTimeSignal, Scenario, Signal, TimelineSignal
from advisory.trajectory import Trajectory


@dataclass(frozen=True, slots=True)
class DriverModel:
    """How the virtual driver follows advice. Units in names."""

    reaction_s: float = 1.0
    accel_mps2: float = 1.5
    decel_mps2: float = 1.5
    low_speed_mps: float = 25 * 0.44704  # below this advised speed the driver drifts up
    drift_mps: float = 1.0
    noise_mps: float = 0.0  # standard deviation of the tracking error, redrawn every advice
    min_coast_mps: float = 2.0  # below this the driver stops coasting and drives on
    red_end_margin_s: float = 1.0  # a red seen at the decision point must end this long before arrival to go on
    emergency_decel_mps2: float = 8.0  # a red the display did not announce: stop if this suffices, else go on
    coast_floor_frac: float = 0.7  # a coasting car keeps slowing past its target: plan with this share of it [-]
    last_call_decel_mps2: float = 3.0  # a car that went on towards a red still red where stopping takes this: it stops
    seed: int = 0
    amber: str = "clear"  # "clear": stops for an amber only if it would not clear the line before the red; "stop": for any it can stop for
    launch_accel_mps2: float | None = None  # speeding up with no speed advised (from a stop, back to the limit); None: the regular driver's

    def regular(self) -> DriverParams:
        """The regular driver this person is without advice: the paper's, with this driver's amber rule and launch."""
        base = DriverParams()
        return replace(base, amber=self.amber, accel_mps2=base.accel_mps2 if self.launch_accel_mps2 is None else self.launch_accel_mps2)


LENIENT = DriverModel()
"""Clears an amber it reaches before the red, launches at the regular driver's 2 m/s² (spat-eval's driver until issue 31)."""
CAREFUL = DriverModel(amber="stop", launch_accel_mps2=1.5)
"""Stops for any amber it can stop for at 4 m/s², launches at 1.5 m/s², otherwise follows the advice with a 1 s reaction."""
DRIVERS = {"lenient": LENIENT, "careful": CAREFUL}

REST_MPS = 0.01
"""Slower than this a car that stopped is at rest. The stop ends only to rounding: braking to rest within a step can
leave ~1e-17 m/s, and a car that reaches its stop point at a crawl (inside the stop gap) is braked at the rate that
stops it at the line, ``v²/2d``, which vanishes with ``v``: a creep of mm/s that lasts for hours. Waiting for an
exact 0 there kept the stop asked for in force at the line through every later green (issue 31). [m/s]"""


@dataclass(frozen=True, slots=True)
class ClosedLoopResult:
    trajectory: Trajectory
    advice: list[tuple[float, Advice]] = field(repr=False)
    overrides: int
    stops: int
    max_advised_mps: float
    surprises: int = 0  # reds the display did not announce (the light still red when its countdown said green, or an early red)


Feed = Callable[[float, float, float], Observation]
"""What the advisor is told at (t, x, v): the lights ahead as the SPaT source publishes them. ``LightView.intersection_id``
is the light's index in the scenario plus one."""


def belief(view: LightView | None, t_obs_s: float, position_m: float) -> TimelineSignal | None:
    """What the driver's display says of one light after the observation at ``t_obs_s``: its red windows on the
    scenario's axis, each change at its latest (a red that may not have begun is the driver's eyes' to judge, as
    for the regular driver; a red is not relied on to end before its latest); a fixed-time light's exact windows;
    None when it says nothing (no data, stale). A phase of unknown state is not shown as a red (nor as a green)."""
    if view is None or not view.fresh:
        return None
    windows = view.red_windows_s if view.late_red_windows_s is None else view.late_red_windows_s
    return TimelineSignal(position_m, tuple((t_obs_s + a, t_obs_s + b) for a, b in _minus(windows, view.unknown_windows_s)))


def _minus(windows, holes) -> list[tuple[float, float]]:
    """The parts of sorted, disjoint ``windows`` outside every interval of ``holes``."""
    out = list(windows)
    for h0, h1 in holes:
        out = [piece for a, b in out for piece in ((a, min(b, h0)), (max(a, h1), b)) if piece[0] < piece[1]]
    return out


def observe(scenario: Scenario, t_s: float, x_m: float, v_mps: float, horizon_s: float = 180.0) -> Observation:
    """The observation a perfect fixed-time SPaT feed gives at (t, x, v): the lights ahead, times from now."""
    lights = []
    for n, light in enumerate(scenario.signals):
        if light.position_m < x_m - 1e-9:
            continue
        windows = tuple((s - t_s, e - t_s) for s, e in light.red_intervals(t_s, t_s + horizon_s))
        lights.append(LightView(n + 1, light.position_m - x_m, True, 1.0, windows))
    return Observation(v_mps, scenario.speed_limit_mps, tuple(lights[:2]), position_m=x_m)


def simulate(
    scenario: Scenario,
    advisor: AdvisorParams | None = None,
    tables=None,
    driver: DriverModel | None = None,
    dt_s: float = 0.1,
    feed: Feed | None = None,
) -> ClosedLoopResult:
    """Drive ``scenario`` from entry to the zone end following the advisor; exact knots every ``dt_s``.

    ``scenario.signals`` are the truth. ``feed`` is what the advisor and the driver's display are told (default:
    a perfect fixed-time feed, :func:`observe`, so the display is the truth). The driver sees the light's present
    colour and the display's countdowns, never the truth's future: a light still red when its display said green
    (an actuated light switching late), or a red arriving before the display's earliest, is a *surprise*: the
    driver stops if it can (up to ``emergency_decel_mps2``), else goes on (a red entry, counted by the checks)."""
    advisor = advisor or AdvisorParams()
    driver = driver or DriverModel()
    rules = driver.regular()  # the regular driver's look-ahead, hardest braking, launch and amber rule
    rng = np.random.default_rng(driver.seed)
    v_lim = scenario.speed_limit_mps
    decision_m = rules.decision_distance_m(v_lim)
    t, x, v = 0.0, 0.0, scenario.initial_speed_mps
    knots = [(t, x, v)]
    memory = AdvisorMemory()
    pending: list[tuple[float, Advice, float, float]] = []  # (when acted on, advice, tracking error, its stop line)
    stop_line_m = np.inf  # the line the active advice is about
    active: Advice | None = None
    error = 0.0
    log: list[tuple[float, Advice]] = []
    committed: set[int] = set()
    braking_for: int | None = None
    overrides = stops = surprises = 0
    shown: list[Signal | None] = list(scenario.signals)  # the display's view of each light (perfect feed: the truth)
    surprised: dict[int, float] = {}  # light -> the red (by its end) that surprised the driver
    amber_seen: dict[int, float] = {}  # light -> the red (by its start) whose amber the driver has decided on
    amber_stop: set[int] = set()  # lights whose amber the driver stops for
    amber_go: set[int] = set()  # lights whose amber the driver has decided to clear
    green_since: dict[int, float] = {}
    seen_red: dict[int, float] = {}  # light -> when the driver last saw it red
    promised: dict[int, tuple[float, float]] = {}  # light -> (the red by its end, the green its display promised when the driver went on)
    max_advised = 0.0
    steps_per_advice = int(round(1.0 / dt_s))
    step = 0
    while x < scenario.zone_length_m - 1e-9 and t < 600.0:
        if step % steps_per_advice == 0:
            obs = observe(scenario, t, x, v) if feed is None else feed(t, x, v)
            if feed is not None:
                views = {lv.intersection_id: lv for lv in obs.lights}
                shown = [belief(views.get(n + 1), t, s.position_m) if s.position_m > x else None for n, s in enumerate(scenario.signals)]
                for n, d in enumerate(shown):  # since when the display has said green (the last red's end it announced)
                    if d is not None and (d.is_red(t) or green_since.get(n, np.inf) > t):
                        green_since[n] = d.next_green_start_s(t) if d.is_red(t) else t
            adv, memory = advise(obs, memory, advisor, tables)
            log.append((t, adv))
            if adv.target_speed_mps is not None:
                max_advised = max(max_advised, adv.target_speed_mps)
            line = min((s.position_m for s in scenario.signals if s.position_m > x + 1e-9), default=np.inf)
            pending.append((t + driver.reaction_s, adv, rng.normal(0.0, driver.noise_mps) if driver.noise_mps else 0.0, line))
        while pending and pending[0][0] <= t + 1e-9:
            _, new, err, line = pending.pop(0)
            if not _silent(new):
                active, error, stop_line_m = new, err, line
        if active is not None and active.action == "stop" and v <= REST_MPS and any(s.position_m == stop_line_m and d is not None for s, d in zip(scenario.signals, shown)):
            active = None  # the stop asked for is made: at rest, the eye and the display say when to go (the advice, "too close", is silent)
        # what the advice asks for
        if active is not None and active.action == "none" and active.reason == "red_ahead":
            v_cmd = min(max(v, advisor.min_cruise_speed_mps), v_lim)  # "Red light ahead.": no speeding up towards it (nor a crawl)
        elif active is None or active.target_speed_mps is None or active.action in ("none", "resume"):
            v_cmd = v_lim  # no speed advice: drive normally
        elif active.action == "stop":
            v_cmd = 0.0 if x < stop_line_m else v_lim  # a "stop" is void once its line is behind (crossed on green)
        else:
            v_cmd = active.target_speed_mps + (driver.drift_mps if active.target_speed_mps < driver.low_speed_mps else 0.0)
            v_cmd = min(max(v_cmd + error, 0.0), v_lim)
        rate_up, rate_down = driver.accel_mps2, driver.decel_mps2
        if active is None or active.target_speed_mps is None or active.action in ("none", "resume", "stop"):
            rate_up = rules.accel_mps2  # no speed asked for: the driver speeds up as the regular driver does
        if active is not None and active.action == "brake_to":
            rate_down = advisor.firm_decel_mps2
        if active is not None and active.action == "stop" and x < stop_line_m:
            to_line_m = stop_line_m - rules.stop_gap_m - x
            if v * v < 2.0 * driver.decel_mps2 * to_line_m:
                rate_down = coast_decel_mps2(v, advisor.vehicle)  # prepare to stop: lift off until a comfortable stop at the line needs braking
            else:  # then brake as it takes to stop there (told late, or a second's reaction behind: more than the comfortable rate)
                rate_down = max(rate_down, min(v * v / (2.0 * max(to_line_m, 1e-6)), rules.brake_max_mps2))
                if v * v > 2.0 * rules.brake_max_mps2 * (stop_line_m - x) and any(s.position_m == stop_line_m and s.is_red(t) for s in scenario.signals):
                    # even the regular driver's hardest braking rolls it over a line that shows red now (a light with no
                    # amber turned red while it stopped for it): nobody rolls into a red it can still stop for
                    rate_down = min(v * v / (2.0 * max(to_line_m, 1e-6)), driver.emergency_decel_mps2)
        # the driver's own eyes: decide once per light at the decision point, like the regular driver
        at_line = False  # waiting at a line still red (no lift-off rule eases that braking)
        ahead = [(n, s) for n, s in enumerate(scenario.signals) if s.position_m > x + 1e-9]
        if ahead:
            n, light = ahead[0]
            dist = light.position_m - x
            room = dist - rules.stop_gap_m
            red_now = bool(light.is_red(t))  # what the driver sees; the future only from the display
            if red_now:
                seen_red[n] = t
            display = shown[n]
            if display is None:  # nothing shown: a red lasts, a green holds (as far as the driver knows)
                green_at, next_red = (np.inf, np.inf) if red_now else (t, np.inf)
            elif red_now and not display.is_red(t):  # red although the display says green: when it ends is unknown
                green_at, next_red = np.inf, np.inf
            else:
                green_at = display.next_green_start_s(t) if red_now else t  # t itself when green
                # the next red to begin after any current one; green while the display says it may be red (a
                # window already open): the eye and the amber rule decide, where the light shows an amber; where it
                # shows none the eye cannot, and a red may begin now (unless that window is the end of the red the
                # driver saw end, shown longer for the feed clock's uncertainty)
                if red_now or not display.is_red(t):
                    next_red = display.next_red_start_s(display.next_green_start_s(green_at))
                else:
                    opened = max((a for a, b in display.reds_s if a <= t < b), default=-np.inf)
                    next_red = t if not shows_amber(light) and opened > seen_red.get(n, -np.inf) else np.inf
            heeded_m = max(decision_m, v * v / (2.0 * driver.decel_mps2) + rules.stop_gap_m)  # where a comfortable stop begins
            amber = dist <= heeded_m and bool(getattr(light, "is_amber", lambda _: False)(t))
            red_at = light.next_red_start_s(t) if amber else None
            if amber and amber_seen.get(n) != red_at:  # the regular driver's amber rule, wherever it is seen: stop if it
                amber_seen[n] = red_at  # would not clear the line before the red (any amber: careful) and can stop at its hardest braking
                late = rules.amber == "stop" or t + dist / max(v, 0.5) > red_at
                stopping = braking_for == n  # already stopping for this line (told to, or its own decision): it goes on
                if amber_stops(late, stopping, v * v / (2.0 * max(room, 1e-6)), rules.brake_max_mps2):
                    committed.discard(n)
                    amber_stop.add(n)
                    surprises += not stopping
                else:  # clears it in the amber: no slowing down (nor braking) until over the line
                    amber_stop.discard(n)
                    amber_go.add(n)
                    committed.add(n)
                    braking_for = None
            overdue = display is None or (not display.is_red(t) and t - green_since.get(n, -np.inf) >= driver.reaction_s)
            # or, rolling on (no stop asked for), still red where a stop at the line needs ``last_call_decel_mps2`` (a
            # red held longer since the driver committed: an actuated controller's late change): nobody rolls on into a
            # red they can still stop for (checked a step ahead: at a crawl the need grows from 3 to 4+ m/s² within a step)
            overdue = overdue or (red_now and v_cmd > 0.0 and v * v >= 2.0 * driver.last_call_decel_mps2 * max(room - v * dt_s, 1e-6))
            if n in committed and red_now and overdue:
                # committed, and the light shows red it was not expected to (a green a reaction time overdue): stop if at
                # all possible; counted once per red. A driver who went on again since, on the display's "green in 1
                # second", is not blind to the same red at the line (US 1136 group 8): it stops again where its last
                # call allows, no harder than the regular driver brakes (``brake_max_mps2``)
                first = surprised.get(n) != light.next_green_start_s(t)
                if first:
                    surprises += 1
                    surprised[n] = light.next_green_start_s(t)
                if v * v / (2.0 * max(room, 1e-6)) <= (driver.emergency_decel_mps2 if first else rules.brake_max_mps2):
                    committed.discard(n)
            if (n in committed and not red_now and not shows_amber(light) and next_red <= t + dist / max(v, 0.1)
                    and v * v <= 2.0 * rules.brake_max_mps2 * max(room, 1e-6)):
                committed.discard(n)  # went on at a light with no amber, and the display now shows a red that may begin before the car is over the line: it decides again
            promise = promised.get(n)
            if red_now and promise is not None and promise[0] == light.next_green_start_s(t) and t >= promise[1] + driver.reaction_s:
                green_at = np.inf  # the green the display promised when the driver went on has not come: it waits for the green it sees
            if amber and n in amber_stop and n not in committed:
                braking_for = n
            elif n not in committed and dist - v * dt_s <= decision_m:  # decide before the step that crosses it
                # go only if the light will be green on arrival at the current speed (a red now must end
                # ``red_end_margin_s`` before) and no red can begin before the car is over the line
                arrival = t + (dist / v if v > 0.1 else np.sqrt(2.0 * dist / driver.accel_mps2) + driver.reaction_s)
                # at a light that shows no amber the eye cannot see a red coming: told to stop for it, the driver stops
                # where it still can (elsewhere a green it sees, with the display's countdown, outweighs the advice)
                told_stop = active is not None and active.action == "stop" and stop_line_m == light.position_m and not shows_amber(light)
                if (red_now and (v <= 0.1 or green_at > arrival - driver.red_end_margin_s)) or next_red <= arrival or (
                    told_stop and v * v <= 2.0 * rules.brake_max_mps2 * max(room, 1e-6)
                ):
                    if braking_for != n and (active is None or active.action != "stop"):
                        overrides += 1
                    braking_for = n
                else:
                    committed.add(n)
                    braking_for = None
                    if red_now and (n not in promised or promised[n][0] != light.next_green_start_s(t)):
                        promised[n] = (light.next_green_start_s(t), green_at)  # (this red, the green the display promised)
            if braking_for == n:  # stop short of the line at the constant rate that gets there
                v_cmd = 0.0
                # (inside the stop gap already, at a crawl: stop short of the line itself, as gently as that allows)
                rate_down = min(v * v / (2.0 * room) if room > 1e-6 else v * v / (2.0 * max(dist - 0.05, 1e-3)),
                                driver.emergency_decel_mps2 if n in surprised else rules.brake_max_mps2)
            elif n in committed:
                if red_now:  # committed while red: it turns green before arrival at this speed, not faster
                    v_cmd = min(v_cmd, v)
                    if room <= v * dt_s:  # creeping up to a line still red: wait at it (it crept over the line)
                        v_cmd, rate_down = 0.0, min(v * v / (2.0 * max(dist - 0.05, 1e-3)), rules.brake_max_mps2)
                        at_line = True
                elif active is not None and active.action == "stop":
                    v_cmd = v_lim
                # going: slow down only if the line is still cleared, with a second to spare, before the next
                # red can begin (a coasting car keeps slowing after its target: count ``coast_floor_frac`` of it)
                if v_cmd < v:
                    coasting = active is not None and active.action in ("coast", "ease_off", "cruise")
                    v_to = max(driver.coast_floor_frac * v_cmd, driver.min_coast_mps) if coasting else v_cmd
                    rate = coast_decel_mps2(v, advisor.vehicle) if active is not None and active.action in ("ease_off", "cruise") else rate_down
                    if next_red <= t + _time_to_cover_s(dist, v, v_to, rate) + 1.0:
                        v_cmd = v
        clearing = bool(ahead) and ahead[0][0] in amber_go and braking_for != ahead[0][0] and not light.is_red(t)
        if clearing:
            v_cmd = max(v_cmd, v)  # clearing an amber: no slowing down before the line (coasting included)
        if braking_for is None and not at_line and active is not None and active.action in ("ease_off", "cruise") and v_cmd < v:
            rate_down = min(rate_down, coast_decel_mps2(v, advisor.vehicle))  # lift off: coast (not into a red at the line)
        if braking_for is None and not clearing and active is not None and active.action == "coast" and v <= v_cmd + 0.05:
            if v > driver.min_coast_mps:
                v_cmd, rate_down = 0.0, coast_decel_mps2(v, advisor.vehicle)  # target reached: keep coasting
            elif ahead and light.is_red(t):  # nobody coasts to a standstill: at a red, stop at the line
                room = ahead[0][1].position_m - x - rules.stop_gap_m
                v_cmd, rate_down = 0.0, (min(v * v / (2.0 * room), rules.brake_max_mps2) if room > 1e-6 else rules.brake_max_mps2)
            else:
                v_cmd = v_lim  # nobody coasts to a standstill: drive on
        gap = v_cmd - v
        a = min(max(gap / dt_s, -rate_down), rate_up)
        if v + a * dt_s < 0.0:  # comes to rest within the step: a knot where it stops
            h = v / -a
            x += 0.5 * v * h
            if 1e-9 < h < dt_s - 1e-9:  # (no knot within a nanosecond of another: times stay increasing)
                knots.append((t + h, x, 0.0))
            v_new = 0.0
        else:
            v_new = v + a * dt_s
            x += 0.5 * (v + v_new) * dt_s
        t += dt_s
        if v > 0.05 and v_new <= 0.05:
            stops += 1
        v = v_new
        knots.append((t, x, v))
        step += 1
    arr = np.array(knots)
    return ClosedLoopResult(Trajectory(arr[:, 0], arr[:, 1], arr[:, 2]), log, overrides, stops, max_advised, surprises)


def shows_amber(light: Signal) -> bool:
    """Whether the driver sees ``light``'s reds coming: a :class:`TimelineSignal` (an actuated or recorded light) does
    where it shows an amber before them; a fixed-time light is taken to (the paper's model has no amber; its display,
    exact, counts down to every red)."""
    return not isinstance(light, TimelineSignal) or any(b > a for a, b in light.ambers_s)


def amber_stops(late: bool, stopping: bool, need_mps2: float, hardest_mps2: float) -> bool:
    """Whether a driver who sees an amber stops for its line: where it would not clear the line before the red (or
    stops for any amber: ``late``), or is already stopping for that line (``stopping``), and a stop at the line needs
    no more than ``hardest_mps2`` (``need_mps2``: ``v²/2d``). A driver who does not stop clears the amber and is no
    longer braking for the line: one counted as clearing it while it went on braking stood at the line through the
    red and the green after it (issue 31; the SUMO driver's copy, issue 28).

    Examples
    --------
    >>> amber_stops(False, True, 3.4, 4.0), amber_stops(False, False, 3.4, 4.0), amber_stops(True, True, 4.1, 4.0)
    (True, False, False)
    """
    return (late or stopping) and need_mps2 <= hardest_mps2


def _silent(advice: Advice) -> bool:
    """Advice that asks nothing new: the driver goes on with what it was told (too close to act, a short wait, or
    "Signal data delayed." through a short dropout)."""
    return advice.action == "none" and (advice.reason in ("too_close", "short_wait") or (advice.reason == "stale_spat" and advice.light_red is not None))


def _time_to_cover_s(dist_m: float, v_mps: float, v_to_mps: float, decel_mps2: float) -> float:
    """Time to cover ``dist_m`` slowing at ``decel_mps2`` from ``v_mps`` to ``v_to_mps``, then holding it. [s]"""
    v_to = max(v_to_mps, 0.5)
    if v_mps <= v_to:
        return dist_m / max(v_mps, 0.5)
    d_brake = (v_mps**2 - v_to**2) / (2.0 * decel_mps2)
    if dist_m <= d_brake:
        return (v_mps - np.sqrt(max(v_mps**2 - 2.0 * decel_mps2 * dist_m, 0.0))) / decel_mps2
    return (v_mps - v_to) / decel_mps2 + (dist_m - d_brake) / v_to


@dataclass(frozen=True, slots=True)
class Evaluation:
    """One scenario: costs [$] and times [s] of the regular driver, the advised driver and the DP optimum."""

    name: str
    regular_usd: float
    advised_usd: float
    optimum_usd: float
    regular_s: float
    advised_s: float
    optimum_s: float
    stops: int
    overrides: int
    violations: tuple[str, ...]
    optimum_same_time_usd: float  # the DP allowed the advised driver's own trip time (if longer than the regular's)
    optimum_margin_usd: float  # the DP held to the advisor's margin: every red ends green_margin_s later
    optimum_limited_usd: float = float("nan")  # the DP held to the advised driver's limits: the margin and a reaction at entry
    optimum_limited_s: float = float("nan")

    def _kept(self, optimum_usd: float) -> float | None:
        saving = self.regular_usd - optimum_usd
        return None if saving < 1e-6 * self.regular_usd else (self.regular_usd - self.advised_usd) / saving

    @property
    def kept_frac(self) -> float | None:
        """Share of the DP's saving over the regular driver that the advised driver keeps (None if nothing to save)."""
        return self._kept(self.optimum_usd)

    @property
    def kept_same_time_frac(self) -> float | None:
        """The same share against the DP given the advised driver's trip time: slowness earns no credit."""
        return self._kept(self.optimum_same_time_usd)

    @property
    def kept_margin_frac(self) -> float | None:
        """The same share against the DP that, like the advice, crosses no line within the margin after a red."""
        return self._kept(self.optimum_margin_usd)

    @property
    def kept_limited_frac(self) -> float | None:
        """The yardstick of issue 13: the share against the DP held to the advised driver's own limits
        (:func:`limited_optimum`)."""
        return self._kept(self.optimum_limited_usd)


def evaluate(scenario: Scenario, params, tables=None, advisor: AdvisorParams | None = None, driver: DriverModel | None = None, grid=None) -> Evaluation:
    """Closed-loop run of ``scenario`` scored against the regular driver and the DP optimum (same end state).

    ``grid`` defaults to the study's (10 m stages). A coarser DP is a lenient yardstick: at 20 m the paper
    cases' optimum costs up to 5 % more (it cannot brake as finely), and the shares kept read ~5 points higher."""
    from advisory.evaluation.endstate import score_in_end_state
    from advisory.optimizer.dp import GridSpec, InfeasibleError, solve, time_limit_s
    from advisory.drivers.regular import regular_driver

    run = simulate(scenario, advisor, tables, driver)
    v_lim = scenario.speed_limit_mps
    regular = regular_driver(scenario)
    reg = score_in_end_state(regular, params, v_lim)
    adv = score_in_end_state(run.trajectory, params, v_lim)
    grid = grid or GridSpec()  # 10 m, 0.25 s bins: ~0.1 % above the study's refined optimum (STUDY_GRID, solve_case)
    t_max = time_limit_s(regular, params, scenario, grid)  # the paper's limit: the regular driver's time
    opt = score_in_end_state(solve(scenario, params, grid, t_max_s=t_max).trajectory, params, v_lim)
    same = opt
    if adv.time_s > reg.time_s + 1e-6:
        same = score_in_end_state(solve(scenario, params, grid, t_max_s=adv.time_s).trajectory, params, v_lim)
    margin_s = (advisor or AdvisorParams()).green_margin_s
    held = Scenario(scenario.name, tuple(replace(s, red_s=s.red_s + margin_s, green_s=s.green_s - margin_s) for s in scenario.signals),
                    scenario.zone_length_m, v_lim, scenario.initial_speed_mps)  # fmt: skip
    try:
        margin = score_in_end_state(solve(held, params, grid, t_max_s=t_max).trajectory, params, v_lim)
    except InfeasibleError:  # the margin makes the regular driver's time unreachable: the advised driver's then
        margin = score_in_end_state(solve(held, params, grid, t_max_s=max(t_max, adv.time_s) + 1.0).trajectory, params, v_lim)
    reaction_s = (advisor or AdvisorParams()).reaction_s
    limited = limited_optimum(held, params, grid, t_max, reaction_s) or limited_optimum(held, params, grid, max(t_max, adv.time_s) + 1.0, reaction_s)
    lim = score_in_end_state(limited, params, v_lim) if limited is not None else margin  # (as for the margin DP: the advised time if need be)
    return Evaluation(scenario.name, reg.cost_usd, adv.cost_usd, opt.cost_usd, reg.time_s, adv.time_s, opt.time_s,
                      run.stops, run.overrides, tuple(red_light_violations(run.trajectory, scenario)), same.cost_usd, margin.cost_usd,
                      lim.cost_usd, lim.time_s)  # fmt: skip


def limited_optimum(held: Scenario, params, grid, t_max_s: float, reaction_s: float) -> Trajectory | None:
    """The DP held to the advised driver's limits: ``held`` already ends every red ``green_margin_s`` later; the
    car also keeps its entry speed for the reaction time (like the advised driver, who acts on the first advice
    1 s after entry). The hold is a whole number of DP stages, the nearest below ``v0 * reaction_s`` (20 m, 0.81 s
    for the paper's 24.6 m/s and 10 m stages: a slightly quicker DP, a slightly stricter yardstick), one stage
    less where the grid cannot stop in time from there (light 1 red at entry: 10 m). The DP then starts there,
    its lights and reds shifted, within the same trip time. None if even no hold is feasible."""
    from advisory.optimizer.dp import InfeasibleError, solve

    v0 = held.initial_speed_mps
    for hold_m in np.arange(np.floor(v0 * reaction_s / grid.stage_m + 1e-9) * grid.stage_m, -1e-9, -grid.stage_m):
        hold_s = hold_m / v0 if v0 > 0 else 0.0
        if any(s.position_m <= hold_m for s in held.signals):
            continue
        shifted = Scenario(held.name, tuple(replace(s, position_m=s.position_m - hold_m, red_start_s=s.red_start_s - hold_s) for s in held.signals),
                           held.zone_length_m - hold_m, held.speed_limit_mps, v0)  # fmt: skip
        try:
            rest = solve(shifted, params, grid, t_max_s=t_max_s - hold_s).trajectory
        except InfeasibleError:
            continue
        if hold_m <= 0:
            return rest
        return Trajectory(np.concatenate([[0.0], rest.t_s + hold_s]), np.concatenate([[0.0], rest.x_m + hold_m]), np.concatenate([[v0], rest.v_mps]))
    return None


def hindsight_optimum(truth: Scenario, params, grid, regular: Trajectory | None = None) -> Trajectory | None:
    """The DP that knows the truth (any :class:`~advisory.signals.Signal`), within the regular driver's trip time.

    The DP (:mod:`advisory.optimizer.dp`) takes fixed-time lights: each light is given, as one fixed cycle, the
    first red that ends after the earliest possible arrival (at the limit from entry) and the start of the red
    after it. The trajectory is then checked against the full truth; None where that fails (a later red the
    cycle does not repeat) or nothing is feasible."""
    from advisory.drivers.regular import regular_driver
    from advisory.optimizer.dp import InfeasibleError, solve, time_limit_s

    v_lim = truth.speed_limit_mps
    signals = []
    for light in truth.signals:
        earliest = light.position_m / v_lim
        reds = [(a, b) for a, b in light.red_intervals(earliest, earliest + 3600.0) if b > earliest]
        if not reds:
            signals.append(FixedTimeSignal(light.position_m, -1e6, 1.0, 1e7))
            continue
        a, b = max(reds[0][0], earliest - 1e4), reds[0][1]
        if not np.isfinite(b):
            return None
        after = reds[1][0] if len(reds) > 1 else b + 1e6
        signals.append(FixedTimeSignal(light.position_m, a, b - a, max(after - b, 1e-3)))
    fixed = Scenario(truth.name, tuple(signals), truth.zone_length_m, v_lim, truth.initial_speed_mps)
    regular = regular if regular is not None else regular_driver(truth)
    try:
        best = solve(fixed, params, grid, t_max_s=time_limit_s(regular, params, fixed, grid)).trajectory
    except InfeasibleError:
        return None
    return None if red_light_violations(best, truth) else best


def red_light_violations(traj: Trajectory, scenario: Scenario, tol_s: float = 1e-6) -> list[str]:
    """Stop lines reached while red (crossing instants inside a red interval)."""
    out = []
    for n, light in enumerate(scenario.signals):
        t_cross = traj.crossing_time_s(light.position_m)
        if np.isfinite(t_cross) and light.is_red(t_cross - tol_s) and light.is_red(t_cross + tol_s):
            out.append(f"light {n + 1} reached at {t_cross:.2f} s during red")
    return out
