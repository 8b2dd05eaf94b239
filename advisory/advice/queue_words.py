"""What the service says in traffic, over the advisor's answer or in its place (queue-aware advice, issue 28).

The advisor plans on the lights as the queue holds them (:func:`advisory.advice.queue.apply`: a green held by the
queue is a red to it); the service then says it truly: the countdown of the light as it really is and a queue's
clearing said as such (:func:`said_truly`, :func:`queue_phrase`). Where the queue in front, not the light, decides,
the service gives its own advice: a lift-off to a slower connected car's speed (:func:`ease_to_car_ahead`), the glide
that meets the queue's tail and follows it through (:func:`tail_glide`), and "drive normally" (:func:`drive_normally`)
in place of a plan that gives up a green or that only the limit keeps from cutting off the cars behind
(:mod:`advisory.advice.behind`), or one made for the queue that the driver's eye, at the line, makes needless
(:func:`seen_at_line`).

Pure: no clock, no I/O. The service decides when each applies (:meth:`server.queue.QueueBoard.check`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import replace

from advisory.advice.behind import PACED_REASON
from advisory.advice.kinematics import crossing_time_s
from advisory.advice.queue import QueueEstimate, QueueModel, normal_drive_s
from advisory.advice.views import Advice, AdvisorParams, LightView, Observation, light_timing
from advisory.advice.wording import phrase, published_speed_mps, say_seconds


def drive_normally(advice: Advice, units: str, light: LightView | None = None) -> Advice:
    """``advice`` turned into "drive normally" (reason ``tight_green``) through ``light``, the next one: the countdown
    to its red where it is green now (the countdown of the plan given up can be another light's: "Red in 50 seconds.
    Drive normally." was said 124 m before a light turning red in 8 s, its 50 s the second light's green), none where it
    is red or not known; without ``light``, the advice's countdown kept.

    Examples
    --------
    >>> plan = Advice("coast", "green_wave", 9.4, light_red=True, seconds_to_change_s=50.0, light_id=2)
    >>> drive_normally(plan, "metric", LightView(1, 124.5, red_windows_s=((8.0, 38.0),))).message
    'Red in 8 seconds. Drive normally.'
    """
    out = replace(advice, action="none", reason="tight_green", target_speed_mps=None)
    if light is not None:
        to_red = light.seconds_to_red()
        counted = to_red is not None and not light.red_now
        out = replace(out, light_red=False if counted else None, seconds_to_change_s=to_red if counted else None, light_ahead=1,
                      light_id=light.intersection_id if counted else None)
    return replace(out, message=phrase(out, units), speak=True)


def seen_at_line(real: LightView, advice: Advice, for_queue: bool, speed_mps: float, limit_mps: float, params: AdvisorParams,
                 model: QueueModel | None = None) -> bool:  # fmt: skip
    """True where the advisor fell silent at the line (``too_close``: the driver goes on with the plan it follows) while
    that plan was made for the queue in front (``for_queue``: given on lights the queue held, or the glide to its tail),
    the light itself (``real``) is green and a normal drive (:func:`~advisory.advice.queue.normal_drive_s`) is over its line before its red
    (less the advisor's ``green_margin_s`` where no amber announces that red): there the car is told to drive normally.

    The queue estimate counts cars the service cannot see (the red's unconnected arrivals, the last red's cars still
    discharging, between the field's fast and slow ends): it keeps a car out of a queue it cannot see yet. At the line
    (the advisor's ``too_close``, 15 m or 3 s) the driver sees the queue itself, and its car following keeps it behind a
    car standing there; the slow plan made for the estimate only loses time there. Silent, the driver went on with it
    across an empty line on green (traced in SUMO, paper_s400 fixed 300 veh/h 50 %, seed 1, ``main.16``: told "Queue
    ahead clears in 18 seconds. Lift off and coast." 77 m out, silent from 14 m, it crossed the green at 3.7 m/s and
    sped up past the line only, 4.5 s later than at 293a7fe, where it had been told to prepare to stop and its eye took
    the green; the three connected cars behind it lost the next light's green, 40 s each).

    Examples
    --------
    >>> green = LightView(1, 14.0, red_windows_s=((30.0, 60.0),), amber_s=0.0)
    >>> seen_at_line(green, Advice("none", "too_close"), True, 4.0, 24.6, AdvisorParams())
    True
    >>> seen_at_line(green, Advice("none", "too_close"), False, 4.0, 24.6, AdvisorParams())  # a plan for the light
    False
    >>> seen_at_line(green, Advice("none", "short_wait"), True, 4.0, 24.6, AdvisorParams())  # not at the line
    False
    >>> red = LightView(1, 14.0, red_windows_s=((-10.0, 2.5),))
    >>> seen_at_line(red, Advice("none", "too_close"), True, 4.0, 24.6, AdvisorParams())  # the light itself red
    False

    14 m at 4 m/s, speeding up at 2 m/s²: over the line in 2.3 s; with the 2 s margin before a red no amber announces,
    a red 4 s away is too close:

    >>> seen_at_line(LightView(1, 14.0, red_windows_s=((4.0, 60.0),), amber_s=0.0), Advice("none", "too_close"), True, 4.0, 24.6, AdvisorParams())
    False
    """
    model = model or QueueModel()
    if advice.action != "none" or advice.reason != "too_close" or real.red_now or not for_queue:
        return False
    to_red = real.seconds_to_red()
    margin = params.green_margin_s if real.amber_s == 0.0 else 0.0
    return to_red is None or normal_drive_s(real.distance_m, speed_mps, limit_mps, model.drive_accel_mps2) + margin < to_red


def queue_phrase(advice: Advice, queue_s: float | None, units: str) -> str:
    """The words for ``advice`` where the queue in front, not the light, holds the car: the queue's clearing said
    ("Queue ahead clears in 4 seconds."), then what to do, with no countdown of the light's (the display shows the
    light's own: ``light_red``, ``seconds_to_change_s``). A countdown to a green that already came would be untrue.

    Examples
    --------
    >>> queue_phrase(Advice("brake_to", "green_wave", 19.2), 4.2, "kmh")
    'Queue ahead clears in 4 seconds. Brake to 69 kilometers per hour.'
    >>> queue_phrase(Advice("stop", "red_ahead", 0.0, light_ahead=2), 12.0, "mph"), queue_phrase(Advice("none", "red_ahead"), None, "mph")
    ('Second light: queue ahead clears in 12 seconds. Prepare to stop.', 'Queue ahead.')
    """
    when = say_seconds(queue_s)
    head = f"Queue ahead clears in {when}." if when else "Queue ahead."
    if advice.light_ahead == 2:
        head = f"Second light: q{head[1:]}"
    if advice.action == "stop":
        rest = "Prepare to stop."
    elif advice.action == "coast" and advice.reason == "red_ahead":
        rest = "Lift off and coast."
    elif advice.action == "none":
        rest = ""
    else:  # the action's own words, without a countdown
        rest = phrase(replace(advice, seconds_to_change_s=None, light_ahead=1), units)
    return f"{head} {rest}".strip()


def said_truly(advice: Advice, real: Sequence[LightView], held: Sequence[LightView], units: str) -> Advice:
    """``advice``, planned on the lights as the queue holds them (``held``, :func:`~advisory.advice.queue.apply`: a green held by the queue is
    a red to the advisor), with the countdown of the light it names as that light really is (``real``: the
    observation before :func:`~advisory.advice.queue.apply`): ``light_red`` its state now and ``seconds_to_change_s`` its next change, as the
    service's schema says; where the advisor's countdown was to a green later than the light's (the queue's
    clearing), the words say the queue (:func:`queue_phrase`), not "Green in 3 seconds" under a green light (traced in
    SUMO, paper_s400 fixed 300 veh/h: "Green in 9 seconds. Brake to 69 km/h." with the red ending in 6 s, and "Green in 3
    seconds" on a green held by the queue, ``light_red`` true). Unchanged where the queue holds no light it names.

    Examples
    --------
    >>> real = (LightView(1, 113.0, red_windows_s=((30.0, 60.0),)),)
    >>> held = (LightView(1, 113.0, red_windows_s=((0.0, 3.4), (30.0, 60.0))),)
    >>> plan = Advice("brake_to", "green_wave", 19.2, light_red=True, seconds_to_change_s=3.4, message="Green in 3 seconds. Brake to 69 kilometers per hour.", light_id=1)
    >>> out = said_truly(plan, real, held, "kmh")
    >>> out.light_red, out.seconds_to_change_s, out.message
    (False, 30.0, 'Queue ahead clears in 3 seconds. Brake to 69 kilometers per hour.')
    """
    if advice.light_red is None or advice.light_id is None:
        return advice
    i = next((k for k, light in enumerate(held) if light.intersection_id == advice.light_id), None)
    if i is None or i >= len(real) or real[i] == held[i]:
        return advice
    red, to_change = light_timing(real[i])
    counted = advice.seconds_to_change_s
    queue_s = counted if advice.light_red and counted is not None and (not red or to_change is None or counted > to_change + 0.5) else None
    out = replace(advice, light_red=red, seconds_to_change_s=to_change)
    if queue_s is None and (red, to_change) == (advice.light_red, counted):
        return advice
    keep_words = (advice.action == "none" and advice.reason != "red_ahead") or advice.reason == PACED_REASON  # (a paced plan names no countdown)
    return replace(out, message=phrase(out, units) if queue_s is None or keep_words else queue_phrase(out, queue_s, units))


def ease_to_car_ahead(follow: Advice, speed_mps: float, ahead_mps: float, params: AdvisorParams) -> Advice:
    """``follow`` ("Queue ahead. Follow the car in front.", no speed) for a car closing in on a slower connected car
    (at ``ahead_mps``), as a lift-off to that car's speed: "Queue ahead. Ease off to 22 miles per hour." (action
    ``ease_off``, reason ``queue``; the advisor's whole-mph step at or below that car's speed, never above what the
    traffic ahead allows); ``follow`` itself where that speed is below the slowest ever advised (``min_cruise_speed_mps``:
    a car standing or crawling ahead, the driver stops behind it by car following) or not below this car's.

    Told only to follow, a driver closes in at its speed and brakes where the gap runs out (car following: SUMO's
    Krauss, and a person alike), shedding as heat what a lift-off a few seconds earlier would have kept; every car of a
    connected platoon behind a gliding leader did so and passed the braking on down the platoon. Traced in SUMO (7th
    Street fixed time, 900 veh/h, every car connected, seed 1, docs/TRAFFIC.md): the 170 of its 219 cars told to follow
    at some fix cost together 0.043 $ more than with GLOSA's device, whose cars glide on their own (the run's whole gap:
    0.034 $); lifting off to the car ahead's speed, the run's saving 5.0 -> 6.1 % (GLOSA 6.1 %), time unchanged.

    Examples
    --------
    >>> follow = Advice("none", "queue", message="Queue ahead. Follow the car in front.")
    >>> eased = ease_to_car_ahead(follow, 13.4, 10.0, AdvisorParams())
    >>> eased.action, eased.target_speed_mps, eased.message
    ('ease_off', 9.83, 'Queue ahead. Ease off to 22 miles per hour.')
    >>> ease_to_car_ahead(follow, 13.4, 3.0, AdvisorParams()) is follow  # crawling ahead: follow it
    True
    """
    step = params.speed_step_mps
    target = math.floor(ahead_mps / step + 1e-9) * step
    if target < params.min_cruise_speed_mps - 1e-9 or target >= speed_mps - params.hysteresis_mps:
        return follow
    out = replace(follow, action="ease_off", target_speed_mps=published_speed_mps(target), current_speed_mps=speed_mps)
    return replace(out, message=queue_phrase(out, None, params.units))


def tail_glide(obs: Observation, est: QueueEstimate, advice: Advice, params: AdvisorParams, model: QueueModel | None = None) -> Advice | None:
    r"""The glide that meets the queue's tail and follows it through, where the advisor's answer (``advice``, on the
    lights as the queue holds them) is a stop at the next light, a lift-off for one, or no advice for a stop to wait a
    moment at the line (``short_wait``: the line is held by the queue, and the car meets its tail before the line; traced
    in SUMO, paper_s400 fixed 600 veh/h, every car connected, seed 1, ``main.8``: silent at the limit from 272 m out
    towards four cars standing, then told to follow 81 m out, braking at 3.5 m/s²), that only the queue in front
    asks for: the light itself (``obs``, as it is: before :func:`~advisory.advice.queue.apply`) is green from the queue's fast clearing until
    this car is over the line behind its slow one. None where it is not such a stop, or where no glide meets the tail
    moving.

    The queue's ``n`` cars (``est.cars``) stand back from the line, one jam spacing each; this car's place behind them is
    ``n`` jam spacings back. A car standing there would cross the line a headway after the queue's last car
    (``est.clear_s``, between the fast and the slow discharge), having started ``\sqrt{2 n \delta / a}`` earlier
    (speeding up at ``drive_accel_mps2`` over the ``n`` jam spacings): this car, slowing gently (``comfort_decel_mps2``)
    to a speed ``v`` and holding it, reaches that place no earlier than such a standing car would have reached ``v``
    there (``v / a`` after its start), so it never closes in on a tail still standing, and crosses the line as the
    stop would have, behind the queue, without stopping: of the same crossing, the glide brakes less, and costs less
    than the stop. The fastest such speed at the middle of the discharge range, else the slowest advised speed where
    it meets the tail moving at the fast end (the hard constraint of :func:`~advisory.advice.queue.apply`: the queue surely stands until then).
    At a light of exact timing only: under uncertain timing (an actuated light) when the queue starts to move is as
    uncertain as the green, which the advisor's choice prices over the light's timings (:func:`~advisory.advice.queue.apply`); the glide, one
    instant, cost the one-seed matrix's actuated 900 veh/h 50 % +12.4 -> +20.5 % of advised time, counted from the
    sure view's red end as from its likely one (cars slowed on a green approach leave gaps at the controller's loops).

    (The advisor plans a glide to the line, not to the tail: where the queue holds the line longer than its slowest
    advised speed, 10 mph, can wait, every glide crossed it before the queue had gone and the car was told to stop
    behind it; traced in SUMO, paper_s400 fixed 300 veh/h, 50 %: advised time +8.4 -> +17.5 % when that stop
    replaced the slowest glide, which the car had followed until its car following held it behind the queue.)

    Examples
    --------
    A car at 13 m/s 120 m from a green light, four cars in front clearing 8-11 s from now: its place is 90 m ahead; a
    car standing there would cross the line 9.4-13 s from now, having started 5.5 s earlier (30 m at 2 m/s²): at
    3.9-7.5 s, 5.7 s at the middle. Slowing to 7.6 m/s (27 km/h) the car gets there at 9.9 s, after such a car had
    reached that speed (5.7 + 3.8 = 9.5 s); at 8.0 m/s it would be there at 9.6 s, before 9.7 s.

    >>> obs = Observation(13.0, 13.4, (LightView(1, 120.0, red_windows_s=((40.0, 70.0),)),))
    >>> est = QueueEstimate((4.0,), (0,), (13.0,), clear_s=((8.0, 11.0),))
    >>> glide = tail_glide(obs, est, Advice("coast", "red_ahead", 13.0), AdvisorParams(units="kmh"))
    >>> glide.action, glide.reason, round(glide.target_speed_mps, 2), glide.light_red, glide.message
    ('slow_down', 'queue', 7.6, False, 'Queue ahead clears in 10 seconds. Slow down to 27 kilometers per hour.')
    >>> tail_glide(obs, est, Advice("cruise", "green_wave", 13.0), AdvisorParams()) is None  # not a stop
    True
    """
    model = model or QueueModel()
    stop = (advice.action in ("stop", "coast") and advice.reason == "red_ahead") or (advice.action == "none" and advice.reason == "short_wait")
    if not stop or not obs.lights or est.stop_behind or not est.clear_s:
        return None
    light, (fast, slow), v = obs.lights[0], est.clear_s[0], obs.speed_mps
    exact = light.likely_red_windows_s is None and light.scenario_red_windows_s is None
    if not exact or advice.light_id not in (None, light.intersection_id) or not (0.0 < fast <= slow < math.inf) or not est.cars:
        return None
    over_s = slow + model.headway_s + (params.green_margin_s if light.amber_s == 0.0 else 0.0)
    if any(a < over_s and b > fast for a, b in light.red_windows_s):  # the light's own red, not the queue, stops it
        return None
    place_m = light.distance_m - est.cars[0] * model.jam_spacing_m
    if place_m <= model.jam_spacing_m or v < params.min_cruise_speed_mps:
        return None
    start_s = math.sqrt(2.0 * est.cars[0] * model.jam_spacing_m / model.drive_accel_mps2)
    go_fast = fast + model.fast_headway_s - start_s
    go_mid = 0.5 * (fast + slow) + 0.5 * (model.fast_headway_s + model.headway_s) - start_s
    best = None
    target = params.min_cruise_speed_mps
    while target <= v + 1e-9:
        reach_s = crossing_time_s(place_m, v, target, params, "brake")
        if reach_s >= go_mid + target / model.drive_accel_mps2:
            best = target
        elif best is None and target == params.min_cruise_speed_mps and reach_s >= go_fast + target / model.drive_accel_mps2:
            best = target
        target += params.speed_step_mps
    if best is None or light.is_red_at(crossing_time_s(light.distance_m, v, best, params, "brake")):  # never planned into a red
        return None
    red, to_change = light_timing(light)
    action = "slow_down" if best < v - params.hysteresis_mps else "cruise"
    out = Advice(action, "queue", best, light_red=red, seconds_to_change_s=to_change, light_id=light.intersection_id, current_speed_mps=v)
    return replace(out, message=queue_phrase(out, 0.5 * (fast + slow), params.units), speak=True)
