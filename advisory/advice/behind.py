"""What a plan costs the cars behind the car (issue 28, item 2: the traffic behind is not to be slowed).

The queue-aware estimate (:func:`advisory.advice.queue.estimate`) counts the cars a slower plan holds up
(``Observation.followers``, :func:`~advisory.advice.queue.followers`; the connected ones among them where they are,
``QueueEstimate.behind``), and the advisor prices time ``1 + followers`` times
(:func:`advisory.advice.views.time_price`). The service's check prices what that misses, each drive crossing the
lines behind the queues in front of the car (:func:`behind_queues_s`): :func:`gives_up_green` weighs the green a plan
gives up at each light a normal drive makes by the cars that lose it, and the red each follower it pushes past the
end of that green waits out (:func:`pushed_past` for the connected ones, :func:`cut_off` for the others). Past a
green line the car sets the pace of the platoon behind it (:func:`platoon_through`): :func:`cut_behind` prices the
cars a slow plan cuts off there before the red, at the line just passed and the next one, each one cut off delaying
the next queue too (:func:`knock_on_s`), at this light and at the light after it (:func:`spill_s`), and
:func:`paced_for_behind` raises such a plan to the slowest speed that does not.

Pure: no clock, no I/O. The service gathers the probes (:mod:`server.queue`).
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from advisory.advice.choice import WAIT_CAP_S
from advisory.advice.kinematics import KEEP_MODES, crossing_time_s, line_speed_mps
from advisory.advice.queue import PastRed, Probe, Probes, QueueEstimate, QueueModel, cleared_s, normal_drive_s, normal_drives_s, past_queue, unseen_behind
from advisory.advice.views import Advice, AdvisorParams, LightView, Observation
from advisory.advice.wording import phrase, published_speed_mps


PACED_REASON = "traffic_behind"
"""``Advice.reason`` of a plan raised for the cars behind (:func:`paced_for_behind`): the service's, not the advisor's."""

GIVE_UP_SLACK_S = 5.0
"""A plan reaching the last light ahead this much later than a normal drive that makes every green gives one up. [s]"""


def behind_queues_s(crossings_s: Sequence[float], obs: Observation, queue: QueueEstimate | None, accel_mps2: float, model: QueueModel) -> list[float]:
    """A drive's crossing of each line ahead of ``obs`` (``crossings_s``, as it would cross on an empty road, from now)
    behind the queues in front of the car (``queue``, its :class:`~advisory.advice.queue.QueueEstimate`: per line the cars in front and when the
    last of them crosses it, :func:`~advisory.advice.queue.cleared_s`; None: no queue): no earlier than a headway after the queue's last car at the fast end of the discharge (``fast_headway_s``
    after its fast clearing: the earliest a driver following it crosses; the check it serves guards the traffic behind,
    so the normal drive it weighs a plan against is not taken later than it may be), then at that car's speed there (speeding up at ``accel_mps2`` from its place in the queue, ``n`` jam spacings back), and on from that
    line as a normal drive (speeding up to the limit at ``accel_mps2``): two drives the queue holds at a line leave it
    alike, whatever each would have done alone. A queue whose clearing is unknown holds the car for ever (inf). [s]

    Examples
    --------
    A normal drive at the limit (24.6 m/s) reaching a line 113 m ahead in 4.6 s, two cars clearing it 3.4-5 s from now,
    the next line 400 m further on: it crosses the first 1.4 s after the queue's last car at the fast end, at 4.8 s, at
    7.7 m/s (two jam spacings at 2 m/s²), and the next one 19.1 s later (8.4 s and 136 m to the limit, 264 m at it); no
    queue: its own times.

    >>> obs = Observation(23.1, 24.6, (LightView(1, 113.0), LightView(2, 513.0)))
    >>> two = QueueEstimate((2.0, 0.0), (0, 0), (7.0, 0.0), clear_s=((3.4, 5.0), (0.0, 0.0)))
    >>> [round(t, 1) for t in behind_queues_s([4.6, 20.9], obs, two, 2.0, QueueModel())]
    [4.8, 23.9]
    >>> behind_queues_s([4.6, 20.9], obs, None, 2.0, QueueModel()), behind_queues_s([9.0, 25.0], obs, two, 2.0, QueueModel())
    ([4.6, 20.9], [9.0, 25.0])
    """
    out: list[float] = []
    held = None  # (time, speed, distance) where a queue last held the drive: it drives on normally from there
    for j, t_s in enumerate(crossings_s):
        line_m = obs.lights[j].distance_m
        if held is not None:
            t_s = held[0] + normal_drive_s(line_m - held[2], held[1], obs.speed_limit_mps, accel_mps2)
        fast, slow = cleared_s(obs.lights[j], queue, j)
        if slow > 0.0:
            held_s = fast + model.fast_headway_s if math.isfinite(slow) else math.inf
            if held_s > t_s:
                n = queue.cars[j] if queue is not None and j < len(queue.cars) else 0.0
                t_s, held = held_s, (held_s, min(math.sqrt(2.0 * accel_mps2 * n * model.jam_spacing_m), obs.speed_limit_mps), line_m)
        out.append(t_s)
    return out


def keeps_green(light: LightView, arrive_s: float, fast_clear_s: float, model: QueueModel) -> bool:
    """An actuated green (the light's timing uncertain: its latest changes known, ``late_red_windows_s``) on now, with
    a queue in front discharging over its line until ``fast_clear_s`` (its last car's crossing at the fast end of the
    discharge, from now), is held for a car reaching the line at ``arrive_s`` (its drive on an empty road) no later
    than the controller's passage time after that car (``model.passage_s``): its detector never sees a gap long enough
    to end the green, which then lasts for this car until its latest end (the late view). A car arriving later leaves
    the gap after the queue, and the green may end in it as the light's timings have it.

    Traced in SUMO (paper_s400 actuated 900 veh/h, 50 %, seed 5, ``main.11``, docs/history/TRAFFIC.md): 218 m before a
    green that had just begun, five cars discharging in front of it, the sure view red from the green's minimum on
    (12 s) and the queue's fast clearing past it, so a normal drive "made" no green and the check weighed nothing; the
    car crawled on at 4.5 m/s, the green ended 16 s after its start (no car at the detector), and it and the five cars
    behind it waited 26 s for the next one: unadvised, the same cars crossed in that green, which lasted until the
    last of them was over.

    Examples
    --------
    >>> lv = LightView(1, 218.0, red_windows_s=((12.0, math.inf),), likely_red_windows_s=((24.5, math.inf),),
    ...                late_red_windows_s=((37.0, math.inf),))
    >>> keeps_green(lv, 13.0, 11.5, QueueModel()), keeps_green(lv, 14.0, 11.5, QueueModel()), keeps_green(lv, 13.0, 0.0, QueueModel())
    (True, False, False)
    >>> keeps_green(LightView(1, 218.0, red_windows_s=((12.0, 40.0),)), 13.0, 11.5, QueueModel())  # exact timing: as published
    False
    """
    return light.late_red_windows_s is not None and not light.red_now and 0.0 < fast_clear_s < math.inf and arrive_s <= fast_clear_s + model.passage_s


def gives_up_green(obs: Observation, advice: Advice, params: AdvisorParams, slack_s: float = GIVE_UP_SLACK_S, model: QueueModel | None = None,
                   behind: Sequence[Probe] = (), queue: QueueEstimate | None = None, real: Observation | None = None) -> bool:  # fmt: skip
    """The advised plan gives up green time that a normal drive (speeding up to the limit at the regular driver's
    ``normal_accel_mps2``, no advice to react to) uses: at a light that the normal drive crosses outside its reds (the
    queue's included, :func:`~advisory.advice.queue.apply`), as every light before it, the plan arrives ``late`` after it, and the time lost
    is more than ``slack_s``:

    * ``late`` for the car itself, at the last light ahead where the normal drive makes every light (before that, a red
      further on takes the time back: the car waits there either way);
    * ``late`` for each follower it holds up (``Observation.followers``), at every such light, and the red each one
      pushed past the end of that light's green waits out: the connected ones among them (``behind``, nearest first,
      :attr:`~advisory.advice.queue.QueueEstimate.behind`) where they are (:func:`pushed_past`), the others as expected from the flow
      (:func:`cut_off`); where a red further on stops the normal drive, only while the plan has still to slow the car
      (its target below the car's speed): a car already slowed is not sent back up to the limit towards that red
      (traced in SUMO: such cars met it or a queue's tail braking harder than 3.5 m/s², or entered it), and the
      followers' time is already lost.

    Both drives cross each line behind the queue in front of the car (``queue``, the car's :class:`~advisory.advice.queue.QueueEstimate`;
    :func:`behind_queues_s`): a normal drive into a queue still discharging is held by it, not as on an empty road
    (one that would reach it while it surely stands, before its fast clearing, does not make the light: it stops there)
    (traced in SUMO, paper_s400 fixed 300 veh/h, 50 %, seed 2, ``main.6``: 113 m out at 23 m/s with two cars clearing
    3.4-5 s from now, a plan slowing to 69 km/h was turned back because its normal drive at the limit crossed at 4.6 s;
    told to drive normally the car slowed at 3.0-3.2 m/s² behind the queue).

    The plan is not credited with a stop it avoids at a red further on: a car that drives normally through this light
    is advised again after it, with the distance to the next one to slow down in. Alike, past the light the plan is for
    (``advice.light_ahead``) the car is advised again: it drives on from that line as a normal drive from the plan's
    speed, not at the plan's speed to the last light (a plan slowing for the first light's queue was counted 4.5 s
    late at the second light, 400 m on at 69 km/h). Traced in SUMO (docs/history/TRAFFIC.md): a car
    launching from a queue at the first light, told to crawl 400 m to the second light's green after next (the advisor
    plans with comfortable accelerations, and its own ``tight_green`` rule looks at the next light); seven connected
    cars told to crawl through the first light towards the second one's queue having cleared, the cars behind them cut
    off at the first light (35 s each); a car told to slow down for the second light's green 124 m before a first light
    that turned red without amber 8 s later, over that line 0.7 s later than a normal drive, a connected car 2.5 s
    behind it (over the line 0.4 s before the red at its speed) pushed into that red (counted as half a car arriving
    at random, 2 s behind, it was not pushed). On an empty road (no followers) only the first case is checked, as
    before.

    At the next light, where its timing is uncertain and it is green now (``real``: the lights as they are, before the
    queue closed them), a normal drive that reaches the line within the passage time after the queue in front holds the
    green (:func:`keeps_green`): it makes the light unless its latest red comes first, where the sure view, red from
    the green's minimum on, had it stop."""
    if advice.target_speed_mps is None or advice.action not in KEEP_MODES or not obs.lights:
        return False
    model = model or QueueModel()
    v, limit, mode = obs.speed_mps, obs.speed_limit_mps, KEEP_MODES[advice.action]
    alone = [normal_drive_s(lv.distance_m, v, limit, params.normal_accel_mps2) for lv in obs.lights]
    normal = behind_queues_s(alone, obs, queue, params.normal_accel_mps2, model)
    plan_alone = [crossing_time_s(lv.distance_m, v, advice.target_speed_mps, params, mode) for lv in obs.lights]
    aim = min(max(advice.light_ahead - 1, 0), len(obs.lights) - 1)  # the light the plan is for: past it, the car is advised again
    for j in range(aim + 1, len(obs.lights)):
        gap_m = obs.lights[j].distance_m - obs.lights[aim].distance_m
        plan_alone[j] = plan_alone[aim] + normal_drive_s(gap_m, advice.target_speed_mps, limit, params.normal_accel_mps2)
    planned = behind_queues_s(plan_alone, obs, queue, params.normal_accel_mps2, model)
    # made: crossed outside the light's reds by the normal drive on its own, so not into a queue surely standing (before its
    # fast clearing: the sure view of :func:`~advisory.advice.queue.apply`), where it would stop too; its time there is the one behind the queue
    made = next((j for j, (lv, t) in enumerate(zip(obs.lights, alone)) if not _makes(lv, t, normal[j], j, real or obs, queue, model)), len(obs.lights))
    known = Probes.of(behind)
    for j in range(made):
        line_m = obs.lights[j].distance_m
        late = planned[j] - normal[j]
        if late <= 0.0:
            continue
        own = 1.0 if made == len(obs.lights) and j == made - 1 else 0.0
        held = made == len(obs.lights) or advice.target_speed_mps < v - params.hysteresis_mps
        n_behind = max(obs.followers, 0.0) if held else 0.0
        lost = (own + n_behind) * late + cut_off(obs.lights[j], normal[j], normal[j] + late, n_behind - len(known), model.headway_s)
        if held and known:  # the car's front a jam spacing past the line (Newell's shift: the one behind follows it from there)
            past_m = line_m + model.jam_spacing_m
            normal_past = normal_drive_s(past_m, v, limit, params.normal_accel_mps2) + normal[j] - alone[j]  # (held as at the line)
            planned_past = crossing_time_s(past_m, v, advice.target_speed_mps, params, mode) + planned[j] - plan_alone[j]
            lost += pushed_past(obs.lights[j], normal_past, planned_past, known, max(limit, 1.0), model)
        if lost > slack_s:
            return True
    return False


def _makes(light: LightView, alone_s: float, normal_s: float, j: int, real: Observation, queue: QueueEstimate | None, model: QueueModel) -> bool:
    """:func:`gives_up_green`'s test of line ``j``: the normal drive (``alone_s`` on its own, ``normal_s`` behind the
    queue) crosses outside its reds, the green held by the queue for it at the next light (:func:`keeps_green`)."""
    now = real.lights[j]
    if j == 0 and keeps_green(now, alone_s, cleared_s(now, queue, j)[0], model):
        return not any(a <= normal_s < b for a, b in now.late_red_windows_s)
    return not (light.is_red_at(alone_s) or light.is_red_at(normal_s))


def pushed_past(light: LightView, normal_s: float, planned_s: float, behind: Sequence[Probe], limit_mps: float, model: QueueModel | None = None) -> float:
    """The wait [s] that the connected cars ``behind`` this one (nearest first, each where it is now) lose at ``light``
    when this car's front is a jam spacing past its line at ``planned_s`` instead of ``normal_s``: each crosses the
    line at its own normal drive (speeding up to the limit at ``drive_accel_mps2``) or, where the car in front of it
    holds it, as it follows now (Newell's shift, as in :func:`~advisory.advice.queue.behind_s`, with the driver's own lag: its gap less the
    jam spacing over its speed, after that car is a jam spacing past the line; these cars are the ones :func:`~advisory.advice.queue.held_up`
    finds within ``follow_gap_s``, which a slower car ahead slows with it: a driver 2.5 s behind kept its 2.5 s in
    SUMO, where :func:`~advisory.advice.queue.behind_s`'s ``headway_s`` would have it close up to 2 s); one pushed from before the red it meets
    to after that red's start waits it out (:data:`advisory.advice.choice.WAIT_CAP_S` where its end is unknown).

    Examples
    --------
    A car 61.4 m (2.5 s at 24.6 m/s) behind one over the line of a light turning red in 8 s, itself there 0.44 s before
    that red: 53.9 m beyond the jam spacing, 2.19 s, it crosses at 7.56 s (its own drive) behind a car 7.5 m past the
    line at 5.37 s; behind the same car slowed to be there at 6.2 s, at 8.39 s: the red's 30 s lost.

    >>> lv = LightView(1, 124.5, red_windows_s=((8.0, 38.0),))
    >>> pushed_past(lv, 5.37, 6.2, [Probe(-61.4, 24.6)], 24.6), pushed_past(lv, 5.37, 5.5, [Probe(-61.4, 24.6)], 24.6)
    (30.0, 0.0)
    """
    model = model or QueueModel()
    lost, line_m = 0.0, light.distance_m
    normal_at, planned_at, ahead_m = normal_s, planned_s, 0.0
    behind = Probes.of(behind)
    for p_ahead_m, p_speed_mps in zip(behind.ahead_m.tolist(), behind.speed_mps.tolist()):
        v = max(p_speed_mps, model.queued_mps)
        own = normal_drive_s(line_m - p_ahead_m, p_speed_mps, limit_mps, model.drive_accel_mps2)
        lag = max(ahead_m - p_ahead_m - model.jam_spacing_m, 0.0) / v
        normal_x, planned_x = max(own, normal_at + lag), max(own, planned_at + lag)
        start, end = next(((a, b) for a, b in light.red_windows_s if b > normal_x), (math.inf, math.inf))  # the red it meets, or the next
        if normal_x < start <= planned_x:
            lost += min(end - start, WAIT_CAP_S)
        normal_at, planned_at, ahead_m = normal_x + model.jam_spacing_m / v, planned_x + model.jam_spacing_m / v, p_ahead_m
    return lost


def cut_off(light: LightView, normal_s: float, planned_s: float, followers: float, headway_s: float) -> float:
    """The wait [s] that the followers lose at ``light`` when the car crosses it at ``planned_s`` instead of
    ``normal_s``, where the green then ends at the next red's start ``R``: the ``k``-th follower crosses a headway after
    the one before, so it is pushed past ``R`` when ``normal_s + k h < R <= planned_s + k h``, and then waits the whole
    red (:data:`advisory.advice.choice.WAIT_CAP_S` where its end is unknown). ``followers`` is a mean: the ``k``-th is
    there with probability ``P(K >= k)``, ``K`` Poisson (cars arriving at random).

    Examples
    --------
    >>> lv = LightView(1, 100.0, red_windows_s=((10.0, 40.0),))
    >>> round(cut_off(lv, 5.0, 7.0, 1.0, 2.0), 2)  # the 2nd follower (normal 9 s, pushed to 11 s) is there with P = 0.26
    7.93
    >>> cut_off(lv, 5.0, 7.0, 0.0, 2.0), cut_off(lv, 1.0, 2.0, 5.0, 3.0)  # none behind; followers 3 s apart, none pushed
    (0.0, 0.0)
    >>> round(cut_off(LightView(1, 100.0, red_windows_s=((10.0, math.inf),)), 5.0, 7.0, 1.0, 2.0), 1)  # its end unknown: 150 s
    39.6
    """
    start, end = next(((a, b) for a, b in light.red_windows_s if a > normal_s), (math.inf, math.inf))
    if not math.isfinite(start) or followers <= 0.0 or planned_s <= normal_s:
        return 0.0
    lost, p_at_least, p_k, k = 0.0, 1.0, math.exp(-followers), 0  # P(K >= k), P(K = k)
    while True:
        p_at_least -= p_k  # P(K >= k + 1)
        k += 1
        p_k *= followers / k
        if normal_s + k * headway_s >= start or p_at_least < 1e-4:
            return lost
        if planned_s + k * headway_s >= start:
            lost += p_at_least * min(end - start, WAIT_CAP_S)


def platoon_through(line_m: float, red_s: float, lead_s, gap_s: float, jam_m: float, first: int = 1, n_max: int = 60) -> int:
    r"""How many cars following a leader, one lane, can cross a line ``line_m`` ahead of the leader (negative: behind
    it) before a red begins at ``red_s`` (from now) [-]: the ``k``-th car behind the leader (``k`` from ``first``)
    follows it as in Newell's car following (G. F. Newell, 2002: the reference of :func:`~advisory.advice.queue.behind_s`), its trajectory the leader's shifted by ``k`` jam spacings and ``k``
    time gaps, so it is at the line when the leader is ``k`` jam spacings past it, ``k`` gaps later:

    .. math:: T_k = t_L(d + k \delta) + k \tau

    with :math:`t_L(x)` when the leader's front is :math:`x` ahead of where it is now (``lead_s``, negative for a
    place it has passed), :math:`d` the line's distance, :math:`\delta` the jam spacing ``jam_m`` and :math:`\tau`
    the gap ``gap_s``. A leader driving slowly past a line thins the platoon crossing it behind it: at the limit
    (24.6 m/s) a jam spacing of 7.5 m and a 1.1 s gap let a car over every 1.4 s, at 8 m/s every 2 s. Counted
    until a car misses the red, at most ``n_max``.

    Examples
    --------
    A line 7 m behind a leader, red in 15 s, a 1.1 s gap: behind a leader holding 8 m/s the ``k``-th car is at the line
    at ``(7.5 k - 7) / 8 + 1.1 k``, 7 cars before the red; behind one at 24.6 m/s, 10.

    >>> platoon_through(-7.0, 15.0, lambda x: x / 8.0, 1.1, 7.5), platoon_through(-7.0, 15.0, lambda x: x / 24.6, 1.1, 7.5)
    (7, 10)
    """
    k = first - 1
    while k - first + 1 < n_max and lead_s(line_m + (k + 1) * jam_m) + (k + 1) * gap_s < red_s:
        k += 1
    return k - first + 1


DISCHARGE_LEVELS = 5
"""How many levels of the discharge, evenly spaced from its fast end to its slow end (:class:`~advisory.advice.queue.QueueModel`),
:func:`spill_s` averages over: the expectation's quadrature, as :data:`PRICED_TIMINGS` over a light's timings. [-]"""


def _platoon_gaps_s(model: QueueModel, limit_mps: float, levels: int = DISCHARGE_LEVELS) -> list[float]:
    """The gaps [s] of :func:`platoon_through` at ``levels`` evenly spaced levels of the discharge, from its fast end to
    its slow end (:class:`~advisory.advice.queue.QueueModel`: a car over the line every ``fast_headway_s`` to every
    ``headway_s`` behind a leader at the limit ``limit_mps``), as :func:`spill_s` averages over them.

    One level: the fast end alone (a light of uncertain timing, whose timings spread the red over the platoon's places
    already: :func:`cut_behind`). The headways behind a leader at 25 m/s, each gap plus the jam spacing's 0.3 s:

    >>> [round(g + 7.5 / 25.0, 2) for g in _platoon_gaps_s(QueueModel(), 25.0)]
    [1.46, 1.58, 1.7, 1.82, 1.94]
    >>> [round(g + 7.5 / 25.0, 2) for g in _platoon_gaps_s(QueueModel(), 25.0, 1)]
    [1.4]
    """
    fast, slow = model.fast_headway_s, model.headway_s
    at = [(j + 0.5) / levels for j in range(levels)] if levels > 1 else [0.0]  # one level: the fast end
    return [max(fast + level * (slow - fast) - model.jam_spacing_m / limit_mps, 0.0) for level in at]


def _platoon_counts(line_m: float, red_s: float, margin_s: float, normal, planned, gap_s: float, jam_m: float, first: int) -> tuple[int, int, int, int]:
    """:func:`platoon_through` behind a normal drive and behind the plan, before the red and ``margin_s`` before it. [-]"""
    n_normal, n_plan = (platoon_through(line_m, red_s, lead, gap_s, jam_m, first) for lead in (normal, planned))
    if not margin_s:
        return n_normal, n_plan, n_normal, n_plan
    return n_normal, n_plan, *(platoon_through(line_m, red_s - margin_s, lead, gap_s, jam_m, first) for lead in (normal, planned))


PRICED_TIMINGS = 5
"""Of a light's equally likely timings (its forecast's quantiles, in order), how many :func:`cut_behind` prices the
wait behind a plan on, evenly spaced in level: the expectation's quadrature (a light green now, turning red 1-39 s from
now, a car coasting 387 m before it, two cars behind: 20 timings 1.06 ms a call, 5 timings 0.24 ms and 299 s against
272 s; the pacing's bisection calls it about six times a light). [-]"""


def priced_timings(timings: Sequence, n: int = PRICED_TIMINGS) -> tuple:
    """``n`` of ``timings`` (equally likely, in the order of their levels) at the levels ``(j + 0.5) / n``: all of
    them where there are no more.

    Examples
    --------
    >>> priced_timings(tuple(range(20))), priced_timings((7, 8))
    ((2, 6, 10, 14, 18), (7, 8))
    """
    k = len(timings)
    return tuple(timings) if k <= n else tuple(timings[int((j + 0.5) * k / n)] for j in range(n))


def cut_behind(light: LightView, obs: Observation, advice: Advice, params: AdvisorParams, behind: Sequence[Probe] = (),
               arrivals_vps: float | None = None, connected_share: float = 1.0, past: PastRed | None = None,
               model: QueueModel | None = None, queue: QueueEstimate | None = None, view_m: float = math.inf, levels: int = DISCHARGE_LEVELS) -> float:  # fmt: skip
    """The wait [s] that the cars behind lose at ``light``'s line when the car follows ``advice`` instead of driving
    normally: the line the car has just passed (``light.distance_m <= 0``: behind it) or the next one ahead (its
    queue estimate ``queue``), in the green the car crosses it in (issue 28, the traffic behind).

    A car driving slowly over a green line holds the platoon behind it to its pace (:func:`platoon_through`: Newell's
    shift), so fewer of them cross before the red than behind the same car driving normally (speeding
    up to the limit at ``normal_accel_mps2``; both held by the queue in front of the car, :func:`behind_queues_s`, and
    at the line ahead by its own red, which a drive reaching it then waits out standing; the plan never faster than
    that drive, and a lift-off for the line ahead not coasting on past it), and each one cut off waits the red out (its likely timing; at most
    :data:`advisory.advice.choice.WAIT_CAP_S`). How many cross is uncertain as the discharge is: while the light is
    green, the count is the mean over its levels from the fast end to the slow end (:func:`_platoon_gaps_s`, a car over
    the line every 1.46-1.94 s behind a leader at the limit, as :func:`spill_s` has them), so a plan that delays the
    platoon's tail by a fraction of a headway cuts a car off in about that fraction of the levels. Before, at the fast
    end alone (a car every 1.4 s, to guard the traffic behind), the counts behind both drives were equal or one apart: a
    plan delaying the tail by 0.3-0.6 s cut nobody off wherever the red fell later in the last gap (traced in SUMO,
    paper_s400 fixed 900 veh/h, 50 %, seed 2, docs/history/TRAFFIC.md: connected cars slowing in light 1's stream
    0.5-1 s late, the stream's last cars cut off by the red, their places carried over from cycle to cycle at the
    saturated light). The fast end alone, as before, where the light is red now (the plan then prices the end of the
    green after it, its car holding its speed at the line over the whole of it: with the levels, a glide to the green
    156 m out with twelve cars behind it was priced 60 s and told to drive normally, the traced 7th Street case of
    item 5 in docs/TRAFFIC.md, fixed 900 veh/h, every car connected, seed 1, ``main.12``) and at
    a light of uncertain timing (``levels`` 1: the expectation over its timings spreads the red over the platoon's
    places already; with the levels on top of it paper_s400 actuated 900 veh/h, 50 %, five seeds, saving 17.45 -> 15.98 %
    and others' time +2.9 -> +5.7 %). The cars there: the connected ones (``behind``, each where it is now,
    negative ``ahead_m``) still before the line that reach it before the red by their own normal drive, the ones
    already past it (they take the first places behind the car), and the cars that are not connected: a Poisson count
    whose mean is the larger of the flow's, ``(1 - connected_share) x arrivals_vps x`` the time from the car's own
    crossing to the red, with the connected cars not yet on the route (``view_m`` behind this car the service's view
    of it begins: :func:`~advisory.advice.queue.unseen_behind`), plus, at the line passed, its last red's queue still to cross (``past``,
    :func:`~advisory.advice.queue.past_queue`), and the connected cars' own, ``(1 - share) / share`` for each connected car counted (a saturated approach's
    residual queue is not in the flow's count). The advisor itself prices the time the followers lose at the lights
    ahead, not the green they lose behind it (:func:`advisory.advice.views.time_price`).

    At a light of uncertain timing (an actuated one: ``light.scenario_red_windows_s``, its equally likely timings) the
    wait is the mean over :func:`priced_timings` of them, each priced as an exact light: a plan slow towards a green
    that may end any second cuts off the cars behind in the timings in which a normal drive still makes it. Traced in
    SUMO (paper_s400 actuated 900 veh/h, 50 %, seed 2, ``main.15``): priced on the likely timing alone (its red
    beginning before a normal drive's arrival: nothing lost), a car 387 m before the second light, green then, was
    told to coast and crawled on at 10 -> 5 m/s through the rest of that green, the red and the next green, which the
    controller ended before the car reached its loop; the cars behind lost the cycle with it.

    Traced in SUMO (paper_s400 fixed 900 veh/h, 50 %, seed 1, docs/history/TRAFFIC.md): cars in the first light's
    discharging queue, told to hold 26-31 km/h for the second light's queue 400 m on, crossed the first at 8-9 m/s
    instead of 14-18 m/s; the platoon behind them crossed at their pace and the last two to five cars of the green were
    cut off (a 30 s red each, and the cycle's 30 s green), others' travel time +14 %. Each one cut off also stands first
    in the next queue (:func:`knock_on_s`), which it sends on to the light after this one a headway later, where a red
    may meet a car of it that made that light without it (:func:`spill_s`).

    Examples
    --------
    A car 7 m past a line turning red in 15 s (for 30 s), at 9.2 m/s, told to hold 29 km/h; four connected cars
    standing behind the line (7.5-30 m back), 900 veh/h, half of them connected: over the discharge's five levels a
    normal drive lets 9, 8, 7, 7, 6 cars through before the red, the plan 7, 7, 7, 6, 6; a place ``k`` past the fourth
    is taken with probability P(K >= k - 4) (K Poisson, mean 4: a car not connected for each connected one), 0.45 cars
    cut off on average, each waiting the red's 30 s and delaying the 11.5 cars that queue behind it by a headway each
    (:func:`knock_on_s`, 16.2 s): 20.9 s lost; a tenth of the cars connected, every place surely taken (0.8 cars):
    36.9 s. Nobody behind, every car connected: nothing lost.

    >>> from advisory.advice.views import Advice, AdvisorParams
    >>> passed = LightView(1, -7.0, red_windows_s=((15.0, 45.0),))
    >>> obs = Observation(9.2, 24.6, (LightView(2, 393.0, red_windows_s=((0.0, 40.0),)),))
    >>> four, hold = [Probe(-7.0 - 7.5 * k, 0.0) for k in (1, 2, 3, 4)], Advice("cruise", "green_wave", 8.04)
    >>> [round(cut_behind(passed, obs, hold, AdvisorParams(), four, 900 / 3600, share), 1) for share in (0.5, 0.1)]
    [20.9, 36.9]
    >>> cut_behind(passed, obs, hold, AdvisorParams())
    0.0
    """
    target = advice.target_speed_mps
    if target is None or advice.action not in KEEP_MODES:
        return 0.0
    if light.scenario_red_windows_s:  # uncertain timing: the expected wait over the light's timings
        timings = Counter(priced_timings(light.scenario_red_windows_s))
        return sum(n * cut_behind(replace(light, red_windows_s=w, likely_red_windows_s=None, late_red_windows_s=None, scenario_red_windows_s=None),
                                  obs, advice, params, behind, arrivals_vps, connected_share, past, model, queue, view_m, levels=1)
                   for w, n in timings.items()) / sum(timings.values())  # fmt: skip
    model = model or QueueModel()
    v, limit, line_m = obs.speed_mps, max(obs.speed_limit_mps, 1.0), light.distance_m
    mode, pace = KEEP_MODES[advice.action], max(obs.speed_mps, model.queued_mps)
    windows = light.red_windows_s if light.likely_red_windows_s is None else light.likely_red_windows_s
    held_s, v_held = -math.inf, limit  # the queue in front holds both drives at the line ahead until then, at that speed
    if line_m > 0.0:
        fast, slow = cleared_s(light, queue, 0)
        if slow > 0.0:
            held_s = fast + model.fast_headway_s if math.isfinite(slow) else math.inf
            n = queue.cars[0] if queue is not None and queue.cars else 0.0
            v_held = min(math.sqrt(2.0 * params.normal_accel_mps2 * n * model.jam_spacing_m), limit)
        # and the light's own red: a drive that reaches the line in it stands there until it ends (before, the normal
        # drive crossed a red line, and a car gliding to the green was paced into the red for the platoon behind it)
        arrive_s = max(normal_drive_s(line_m, v, limit, params.normal_accel_mps2), held_s)
        red_end_s = next((b for a, b in windows if a <= arrive_s < b), None)
        if red_end_s is not None:
            held_s, v_held = red_end_s, 0.0

    @_once  # (each place's time is asked once per level of the discharge: :func:`_platoon_counts`)
    def normal(x):
        if x <= 0.0:
            return x / pace
        if line_m > 0.0 and x >= line_m and held_s > normal_drive_s(line_m, v, limit, params.normal_accel_mps2):
            return held_s + normal_drive_s(x - line_m, v_held, limit, params.normal_accel_mps2)
        return normal_drive_s(x, v, limit, params.normal_accel_mps2)

    # a lift-off is to the light it is for (the next one, this line): past it the car does not coast on, slower and
    # slower, but holds at least its speed there (before: a car coasting to the green after a red was priced as
    # crawling on past the line, the platoon behind it with it, 600 s cut off, and told to drive normally into the
    # red). A plan that holds a speed is priced holding it: past the line the car is advised again, for the next light,
    # often as slowly (tried: a normal drive from the line for every plan; 7th Street fixed 900 veh/h saved 1-1.5 points
    # more, but paper_s400 fixed 900 veh/h 100 % cost +4.4 points of advised time and 7th Street actuated 900 veh/h
    # +1.4 to +4.4; docs/history/TRAFFIC.md, ninth session)
    coast_to = mode == "brake_coast" and line_m > 0.0 and advice.light_ahead == 1 and advice.light_id in (None, light.intersection_id)
    if coast_to:  # (held at the line by the queue or the red, it leaves it as a normal drive does)
        at_line_s = float(crossing_time_s(line_m, v, target, params, mode))
        v_line = max(line_speed_mps(line_m, v, target, params, mode), model.queued_mps) if at_line_s >= normal(line_m) else None

    @_once
    def planned(x):
        if x <= 0.0:
            return x / pace
        if coast_to and x > line_m:
            return max(at_line_s + (x - line_m) / v_line, normal(x)) if v_line is not None else normal(x)
        return max(float(crossing_time_s(x, v, target, params, mode)), normal(x))

    crossed_s = normal(line_m)
    start, end = next(((a, b) for a, b in windows if a > max(crossed_s, 0.0)), (math.inf, math.inf))
    if not math.isfinite(start):
        return 0.0  # no red known: nobody is cut off by this green's end
    behind = Probes.of(behind)
    ahead_m = behind.ahead_m
    over = int(np.count_nonzero((line_m < ahead_m) & (ahead_m < 0.0)))  # connected, already over the line: the first places
    # a connected car behind, at a light that shows no amber, is to be over the line ``no_amber_margin_s`` before the red
    # where the car in front sets its crossing, or it is told to stop (:func:`~advisory.advice.queue.estimate`, ``stop_behind``): its place is
    # cut off that much earlier (traced: a connected car 4.5 s behind a platoon held to 11.5 m/s, over the line 2 s
    # before a red that no amber announces at its own pace, was told to stop; it and the car behind it lost 33-35 s)
    margin_s = model.no_amber_margin_s if light.amber_s == 0.0 else 0.0
    spread = levels if not light.is_red_at(0.0) else 1  # (red now: the fast end alone, as the docstring says)
    counts = [_platoon_counts(line_m, start, margin_s, normal, planned, gap_s, model.jam_spacing_m, over + 1) for gap_s in _platoon_gaps_s(model, limit, spread)]
    if all(n_plan >= n_normal and n_plan_c >= n_normal_c for n_normal, n_plan, n_normal_c, n_plan_c in counts):
        return 0.0
    before = behind.where(ahead_m <= min(line_m, 0.0))  # the connected cars still before the line that make it in the green
    there = int(np.count_nonzero(normal_drives_s(line_m - before.ahead_m, before.speed_mps, limit, model.drive_accel_mps2) < start))
    share = min(max(connected_share, 0.0), 1.0)
    not_connected, connected = unseen_behind(arrivals_vps, share, crossed_s, start, (line_m + view_m) / limit)
    flow = not_connected + connected
    if flow and past is not None and line_m <= 0.0:
        flow += past_queue(past, model, arrivals_vps, share, math.inf, 0)[1]
    unseen = max(flow, (there + over) * (1.0 - share) / share if share > 0.0 else 0.0)
    p_connected = connected / unseen if unseen > 0.0 else 0.0  # an unseen car in a place is a connected one not yet on the route
    # the k-th place behind the line is taken with probability P(there + K >= k), K Poisson with mean ``unseen``; the
    # first ``there`` by the connected cars known; the cut the mean over the discharge's levels (``counts``)
    cut, p_k, p_at_least = 0.0, math.exp(-unseen), 1.0
    for k in range(1, max(c[0] for c in counts) + 1):
        if k > there:
            p_at_least -= p_k  # P(K >= j + 1) from P(K >= j), j = k - there - 1
            p_k *= unseen / (k - there)
            if p_at_least < 1e-4:
                break
        for n_normal, n_plan, n_normal_c, n_plan_c in counts:
            cut_c, cut_u = float(n_plan_c < k <= n_normal_c), float(n_plan < k <= n_normal)
            cut += (cut_c if k <= there else p_at_least * (p_connected * cut_c + (1.0 - p_connected) * cut_u)) / len(counts)
    if cut == 0.0:
        return 0.0
    after = next((lv for lv in obs.lights if lv.distance_m > line_m), None)  # the light after this one
    queued = queued_behind(light, start, end, arrivals_vps, model.fast_headway_s)  # (knock_on_s: a headway each)
    return cut * (min(end - start, WAIT_CAP_S) + model.fast_headway_s * queued + spill_s(light, after, end, queued, limit, model))


def _once(f):
    """``f`` of one argument, each value worked out once (:func:`functools.cache`, without the cost of making its
    wrapper: :func:`cut_behind` makes two a call)."""
    made: dict = {}

    def once(x):
        y = made.get(x)
        if y is None:
            y = made[x] = f(x)
        return y

    return once


def knock_on_s(light: LightView, start_s: float, end_s: float, arrivals_vps: float | None, headway_s: float) -> float:
    """The time [s] that one car cut off at the red from ``start_s`` to ``end_s`` costs the cars behind it: it stands
    first in that red's queue, so every car that queues behind it crosses a headway later. Those cars: the red's
    arrivals and the ones joining while the queue discharges, ``flow x red / (1 - flow x headway)`` (a deterministic
    queue at a signal, D/D/1: it clears when the discharge has caught up with the arrivals), no more than the next
    green lets over the line (``green / headway``, an oversaturated approach; the green to the light's next red,
    none known: the red's length). ``arrivals_vps`` None: not known, 0.

    Traced in SUMO (paper_s400 fixed 600 veh/h, 50 %, seed 3, docs/history/TRAFFIC.md): four cars cut off at light 1's end of
    green each stood first in the next queue; that whole green crossed 1-2 s later, and its last cars lost light 2's
    green (227 of the others' 309 s).

    Examples
    --------
    600 veh/h, a 30 s red, the fast headway 1.4 s: 5 cars arrive over the red, 6.5 in all queue before it clears, each
    1.4 s later: 9.1 s.

    >>> lv = LightView(1, 100.0, red_windows_s=((10.0, 40.0), (70.0, 100.0)))
    >>> round(knock_on_s(lv, 10.0, 40.0, 600 / 3600, 1.4), 2), knock_on_s(lv, 10.0, 40.0, None, 1.4)
    (9.13, 0.0)
    """
    return headway_s * queued_behind(light, start_s, end_s, arrivals_vps, headway_s)


def queued_behind(light: LightView, start_s: float, end_s: float, arrivals_vps: float | None, headway_s: float) -> float:
    """How many cars queue behind one standing first in the red from ``start_s`` to ``end_s`` [-]: the count of
    :func:`knock_on_s` (D/D/1, no more than the next green lets over; ``arrivals_vps`` None or no end known: 0)."""
    if not arrivals_vps or not math.isfinite(end_s):
        return 0.0
    windows = light.red_windows_s if light.likely_red_windows_s is None else light.likely_red_windows_s
    green_s = next((a for a, _ in windows if a >= end_s), end_s + (end_s - start_s)) - end_s
    load = arrivals_vps * headway_s
    queued = arrivals_vps * (end_s - start_s) / (1.0 - load) if load < 1.0 else math.inf
    return min(queued, green_s / headway_s)


def spill_s(light: LightView, after: LightView | None, end_s: float, queued: float, limit_mps: float, model: QueueModel,
            levels: int = DISCHARGE_LEVELS) -> float:  # fmt: skip
    r"""The wait [s] that one car cut off at ``light`` (its red ending at ``end_s``, from now) costs at the light
    ``after`` it: standing first in that red's queue, it puts each of the ``queued`` cars behind it (a mean,
    :func:`knock_on_s`'s count; Poisson, ``N``) a place further back in the platoon that the queue sends on to
    ``after``, a headway later; where a red of ``after`` begins between a car's place without the cut car and its
    place with it, that car meets the red and waits it out (at most :data:`advisory.advice.choice.WAIT_CAP_S`). The
    platoon's places at ``after``'s line: the queue's ``i``-th car (the cut one ``0``) crosses ``light`` a start-up
    and ``i`` headways after ``end_s`` at ``sqrt(2 a i \delta)`` (``i`` jam spacings to speed up in, at
    ``drive_accel_mps2``, to the limit), drives on normally, and is never less than a headway behind the car before it
    (Newell's car following: a car starting farther back cannot close in further). The discharge is the field's range,
    uncertain as the queue's clearing is (:class:`~advisory.advice.queue.QueueEstimate`): the wait is the mean over
    ``levels`` evenly spaced from its fast end (2 s start-up, 1.4 s a car) to its slow end (3 s, 2.0 s). ``after`` of
    uncertain timing: its likely timing. None (no light after), or no red end known: 0.

    Traced in SUMO (paper_s400 fixed 600 veh/h, 50 %, seed 3, docs/history/TRAFFIC.md): light 2 is 16.3 s at the limit
    after light 1, both turning together; a car cut off at light 1's end of green stood first in the next queue, the
    platoon of the next green crossed light 1 1-2 s later, and its last car met light 2's red: 227 of the others' 309 s
    (the tenth session), the knock-on that :func:`knock_on_s` prices at light 1 alone.

    Examples
    --------
    One level (the fast end and the slow end alike: 2 s start-up, 1.4 s a car), a red ending at 40 s, light 2 400 m
    on at a 24.6 m/s limit: the cut car is there at 40 + 2 + 22.4 = 64.4 s (from rest), the next one at 65.8 s (alone,
    from 7.5 m back, it would be there at 63.4 s: a headway behind the cut car instead), the one after at 67.2 s. A
    red at light 2 from 65 s (for 30 s) meets the first car behind the cut one (its place 64.4 s without the cut car,
    65.8 s with it), there with P(N >= 1) = 1 - exp(-6.5) (6.5 cars queued on average): 29.95 s; a red from 100 s
    meets none of the places the queue moves: 0.

    >>> one = QueueModel(startup_s=2.0, headway_s=1.4)
    >>> light, step = LightView(1, 100.0, red_windows_s=((10.0, 40.0),)), LightView(2, 500.0, red_windows_s=((65.0, 95.0),))
    >>> round(spill_s(light, step, 40.0, 6.5, 24.6, one), 2), spill_s(light, replace(step, red_windows_s=((100.0, 130.0),)), 40.0, 6.5, 24.6, one)
    (29.95, 0.0)
    """
    if after is None or queued <= 0.0 or not math.isfinite(end_s):
        return 0.0
    windows = after.red_windows_s if after.likely_red_windows_s is None else after.likely_red_windows_s
    gap_m, accel = after.distance_m - light.distance_m, model.drive_accel_mps2
    lost = 0.0
    for level in ((j + 0.5) / levels for j in range(levels)):
        startup_s = model.fast_startup_s + level * (model.startup_s - model.fast_startup_s)
        headway_s = model.fast_headway_s + level * (model.headway_s - model.fast_headway_s)
        place_s = end_s + startup_s + normal_drive_s(gap_m, 0.0, limit_mps, accel)  # the cut car's
        last_s = max((a for a, _ in windows if a > place_s), default=-math.inf)  # no place moves past a later red's start
        p_at_least, p_k = 1.0, math.exp(-queued)  # P(N >= i - 1), P(N = i - 1)
        for i in range(1, 200):
            p_at_least -= p_k  # P(N >= i): the i-th car behind the cut one is there
            p_k *= queued / i
            if p_at_least < 1e-4 or place_s >= last_s:
                break
            v_mps = min(math.sqrt(2.0 * accel * i * model.jam_spacing_m), limit_mps)
            own_s = end_s + startup_s + i * headway_s + normal_drive_s(gap_m, v_mps, limit_mps, accel)
            before_s, place_s = place_s, max(own_s, place_s + headway_s)  # its place without the cut car, and with it
            red = next(((a, b) for a, b in windows if before_s < a <= place_s), None)
            if red is not None and not any(a <= before_s < b for a, b in windows):
                lost += p_at_least * min(red[1] - red[0], WAIT_CAP_S)
    return lost / levels


def paced_for_behind(lost_s, obs: Observation, advice: Advice, params: AdvisorParams, slack_s: float = GIVE_UP_SLACK_S) -> Advice | None:
    """``advice`` where the wait it makes the cars behind lose (``lost_s(advice)``, e.g. :func:`cut_behind` summed over
    the lines they still have to cross) is within ``slack_s``; else the same plan at the slowest speed that keeps it
    so (the advisor's speed steps, ``speed_step_mps``, above the plan's, up to the limit; the wait shrinks as the speed rises: the slower the car over a
    line, the fewer behind it cross): "Hold" it, "Speed up to" it or "Ease off to" it; None where only the limit
    does (drive normally). The car is advised again at its next fix: once the cars behind are over the line, or
    its green is over, the advisor's own plan comes back. Before (a plain "drive normally" in its place), the car
    sped up towards the limit, was told to brake for the plan at its next fix, and so on (traced in SUMO:
    paper_s400 fixed 900 veh/h, 50 %, the advised cars costlier than unadvised).

    The paced plan has its own reason, :data:`PACED_REASON` (``traffic_behind``), and words that say why and promise
    no green ("Keep up with the traffic. Speed up to 40 kilometers per hour.", :func:`advisory.advice.wording.phrase`):
    it is not a speed for the light ahead. Before, it kept the plan's countdown: "Green in 40 seconds. Speed up to 40
    kilometers per hour." for a red of 40 s 393 m away, where 40 km/h is at the line in 35 s, in the red. The
    countdown fields (``light_red``, ``seconds_to_change_s``) stay the light's own, as the display shows them.

    Examples
    --------
    >>> from advisory.advice.views import Advice, AdvisorParams
    >>> obs = Observation(9.0, 24.6, (LightView(2, 393.0, red_windows_s=((0.0, 40.0),)),))
    >>> slow = Advice("ease_off", "green_wave", 6.7, light_red=True, seconds_to_change_s=40.0, light_id=2)
    >>> out = paced_for_behind(lambda a: 30.0 if a.target_speed_mps < 11.0 else 0.0, obs, slow, AdvisorParams(units="kmh"))
    >>> out.action, out.reason, out.target_speed_mps, out.message
    ('accelerate', 'traffic_behind', 11.17, 'Keep up with the traffic. Speed up to 40 kilometers per hour.')
    >>> out.light_red, out.seconds_to_change_s
    (True, 40.0)
    >>> paced_for_behind(lambda a: 0.0, obs, slow, AdvisorParams()) is slow, paced_for_behind(lambda a: 9.0, obs, slow, AdvisorParams())
    (True, None)
    """
    if advice.target_speed_mps is None or advice.action not in KEEP_MODES or lost_s(advice) <= slack_s:
        return advice
    v, limit = obs.speed_mps, obs.speed_limit_mps

    def at(target: float) -> Advice:
        action = "accelerate" if target > v + params.hysteresis_mps else ("ease_off" if target < v - params.hysteresis_mps else "cruise")
        out = replace(advice, action=action, reason=PACED_REASON, target_speed_mps=published_speed_mps(target), current_speed_mps=v)
        return replace(out, message=phrase(out, params.units))

    step = params.speed_step_mps  # the advisor's candidates' step (whole mph: the spoken number is the advised one)
    speeds = [k * step for k in range(math.floor(advice.target_speed_mps / step) + 1, math.ceil(limit / step))]
    lo, hi = 0, len(speeds)  # the first speed whose wait is within the slack (bisection: it shrinks as the speed rises)
    while lo < hi:
        mid = (lo + hi) // 2
        if lost_s(at(speeds[mid])) <= slack_s:
            hi = mid
        else:
            lo = mid + 1
    return at(speeds[lo]) if lo < len(speeds) and speeds[lo] < limit - params.hysteresis_mps else None
