"""Queue-aware advice: the lights ahead as a car in traffic meets them, not as an empty road shows them.

A car arriving at the start of green behind six queued cars does not glide through: it stops. For the car that
asks, :func:`estimate` counts the cars that will stand in front of it at each light ahead when the red it faces ends,
and :func:`apply` moves that red's end, in the advisor's view, to the moment those cars have crossed the line: the
advisor then aims at the queue having cleared, not at the start of green, with every rule of the advisor unchanged
(its 2 s margin after the red, "stop" where no speed makes it, the plan kept while it works).

Where the count comes from, in order of trust (issue 28):

1. ``queueLength`` of the SPaT message (J2735 ``maneuverAssistList`` of the light's movement, the longest of its
   lane connections, :attr:`LightView.queue_m`, fresh readings only): the cars standing in it (one per jam spacing,
   no more than fit between the car and the line) wait at the line; a connected car standing inside it is one of
   them, not one more, and the arrival-rate estimate below is not made for that light (the detectors counted).
2. The connected cars ahead on the approach (:class:`Probe`: the service knows where every trip on the corridor is,
   to the second): between this car and the line, each one that will reach the line during the red (or stands
   before it) is in the queue.
3. An arrival-rate estimate for the cars that are not connected: ``(1 - share) x flow x`` the time from the red's
   start to this car's own unimpeded arrival at the line (every car arriving at the line in that time is ahead of it
   and stands), only at the next light (at the one after it, arrivals are platoons released by the first), never more
   than fit between the car and the line.

After a red has ended its queue goes on discharging (:func:`past_queue`: the jam last published in it, else the
cars not connected arriving over it), the connected cars ahead behind it: it is not forgotten at the green.

The queue's last car then crosses the line ``startup_s + (n - 1) x headway_s`` after the red ends, somewhere between
the fast and the slow end of the measured discharge (:class:`QueueModel`): :func:`apply` closes the line until then as
a distribution over the light's equally likely timings, which the advisor's choice prices (never a plan into a queue
surely standing, no waiting for the slowest discharge in every timing). A car that is
itself in a queue (slower than ``queued_mps`` and not first at the line: ``in_queue``) or right behind a slower
connected car (within ``follow_gap_s`` plus a jam spacing: ``follow_mps``) is given no speed by the service: it
follows the car in front (closing in on a slower connected car, it lifts off to that car's speed:
:func:`ease_to_car_ahead`), and the advice resumes, planned afresh, once it is free (never a target above what the
traffic ahead allows; and a plan made in a queue is a crawl: every faster speed reaches the line before the queue has
gone, and the advisor keeps a plan that still works, to the green after next).

The cars ahead bound when this car can cross (:func:`behind_s`: each holds its speed now, its plan not known here,
and this car follows it as in Newell's car following, a time gap and a jam spacing behind). Where that bound leaves a
car that could make a green alone no time to cross before a red that no amber announces (less ``no_amber_margin_s``
where they set its crossing), the line is closed to it until the red's end and it is not told to follow
(``stop_behind``): it prepares to stop. Decided within the distance the car needs to stop at the others' rate plus a
headway's travel. (Traced in SUMO, paper_s400 at 900 veh/h, every car connected: cars told to follow a platoon
slowing for the next light's queue entered a red no amber announced, 0.5 s in; a cap at the car ahead's speed
instead cost the advised cars +49-115 % of time.)

The cars behind count too (issue 28, item 2: the traffic behind is not to be slowed): :func:`followers` expects the
cars a slower plan holds up (the connected ones behind it, the others from the flow), the advisor prices time ``1 +
followers`` times (:func:`advisory.advice.views.time_price`), and :func:`gives_up_green` weighs the green a plan gives
up at each light a normal drive makes by the cars that lose it, and the red each follower it pushes past the end of that
green waits out (:func:`cut_off`). Past a green line the car sets the pace of the platoon behind it (:func:`platoon_through`):
:func:`cut_behind` prices the cars a slow plan cuts off there before the red, at the line just passed and the next one,
and :func:`paced_for_behind` raises such a plan to the slowest speed that does not.

Pure: no clock, no I/O. The service gathers the probes (:mod:`server.queue`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

from advisory.advice.choice import WAIT_CAP_S
from advisory.advice.kinematics import KEEP_MODES, crossing_time_s, line_speed_mps
from advisory.advice.mixture import implied_timings
from advisory.advice.views import Advice, AdvisorParams, LightView, Observation, light_timing
from advisory.advice.wording import phrase, published_speed_mps, say_seconds


PACED_REASON = "traffic_behind"
"""``Advice.reason`` of a plan raised for the cars behind (:func:`paced_for_behind`): the service's, not the advisor's."""


@dataclass(frozen=True, slots=True)
class QueueModel:
    """How a queue discharges and what a queued car is. Units in names.

    Sources: start-up lost time 2 s and a saturation headway of 1.9 s (1,900 veh/h per lane) are the Highway Capacity
    Manual's (6th ed., ch. 19) base values (its first car over the line ~3.9 s after the green); field measurements
    cited in issue 28 give about 2.0 s between cars at the stop line falling to about 1.4 s further back, after a 2-3 s
    start-up. The discharge is a range, not one instant: slow (``startup_s`` 3 s, ``headway_s`` 2.0 s a car: the
    field's longest start-up and its headway at the line, HCM's 1.9-2 s) to fast (``fast_startup_s`` 2 s,
    ``fast_headway_s`` 1.4 s a car); the jam spacing is a passenger car's 5 m plus a 2.5 m gap (SUMO's passenger type;
    7-8 m in field counts of stopped queues). Field values, not the simulator's: SUMO's queue of this project's cars
    lets the next car go about 1 s + 1.72 s a car after the green (docs/TRAFFIC.md), about the fast end's
    ``fast_startup_s + (n - 1) x fast_headway_s`` plus the advisor's 2 s margin (1.3 s earlier for one car, 1.6 s later
    for ten)."""

    startup_s: float = 3.0
    headway_s: float = 2.0
    fast_startup_s: float = 2.0
    fast_headway_s: float = 1.4
    """The fast end of the measured discharge (``startup_s``, ``headway_s``: the slow end): the queue's first car over
    the line 2 s after the red ends, each next one 1.4 s after the one before (the field's shortest headway, reached
    further back in a queue). The queue clears somewhere between the two (:attr:`QueueEstimate.clear_s`, priced as a
    distribution: :func:`apply`). [s]"""
    jam_spacing_m: float = 7.5
    queued_mps: float = 2.0  # a car slower than this short of a line stands in a queue
    drive_accel_mps2: float = 2.0  # another car (ahead or behind) speeds up to the limit at this, as the regular driver does (paper Sec. 2)
    follow_gap_s: float = 3.0  # a connected car ahead within this time gap (plus one jam spacing) sets the pace
    no_amber_margin_s: float = 2.0
    """Where the cars ahead set its crossing (:func:`behind_s` later than its own drive, or closing in on a slower car),
    at a light that shows no amber (``LightView.amber_s`` = 0), this car is to be over the line this long before the
    red, or it stops there: the advisor's ``green_margin_s`` before such a red, for a car whose crossing a car ahead
    sets. [s]"""


@dataclass(frozen=True, slots=True)
class Probe:
    """Another connected car on the route: how far ahead of the one asking (negative: behind) [m] and its speed [m/s]."""

    ahead_m: float
    speed_mps: float


@dataclass(frozen=True, slots=True)
class QueueEstimate:
    """Per light ahead (as in the observation): the cars that cross its line before this car and hold it up (known +
    estimated), the connected ones among them, and the earliest instant this car can cross that line for them
    (seconds from now; 0: nothing holds it up)."""

    cars: tuple[float, ...]
    known: tuple[int, ...]
    free_at_s: tuple[float, ...]
    in_queue: bool = False
    follow_mps: float | None = None
    followers: float = 0.0
    """Cars expected behind this one that a slower plan holds up (:func:`followers`). [-]"""
    behind: tuple[Probe, ...] = ()
    """The connected ones among them, nearest first (:func:`held_up`): where each is, for :func:`gives_up_green`."""
    stop_behind: bool = False
    """At the next light, whose red no amber announces, the connected cars ahead let this car cross no sooner than that
    red (less the margin where they set its crossing, :func:`behind_s`): it is to stop there, not to follow them."""
    clear_s: tuple[tuple[float, float], ...] = ()
    """Per light: until when the line is closed to this car (from now; 0: it is not) if the queue discharges fast, and
    if it discharges slowly (:class:`QueueModel`): until the queue's last car has crossed (this car crosses a headway
    later: the advisor's margin after a window's end, ``green_margin_s``), or until :func:`behind_s` lets it cross.
    :func:`apply` closes the line between the two as a distribution. [s]"""
    after_red_s: tuple[tuple[float, float] | None, ...] = ()
    """Per light, where the queue waits for the red's end: the same two instants counted from that end (fast, slow), so
    that a timing whose red ends earlier clears earlier (and one whose end only the timings know, not the sure view,
    clears at all); None where the queue does not wait for it (cars discharging on a green, the cars ahead's bound). [s]"""


def _first_red(light: LightView) -> tuple[float, float] | None:
    """The red the car faces: the first window still to end."""
    return _first_red_of(light.red_windows_s)


def estimate(
    obs: Observation,
    probes: Sequence[Probe],
    model: QueueModel | None = None,
    arrivals_vps: float | None = None,
    connected_share: float = 1.0,
    red_elapsed_s: float | None = None,
    past_red: PastRed | None = None,
) -> QueueEstimate:
    """The cars in front of the car of ``obs`` at each light and when it can cross behind them (module docstring).

    The cars ahead cross each line in their order (one lane): one standing (slower than ``queued_mps``) or arriving
    during the red waits for its end; the queue's first car crosses ``startup_s`` after it, each next one ``headway_s``
    after the one before; a car arriving later (speeding up to the limit at ``drive_accel_mps2``, 2 m/s², from its speed now, as the regular
    driver does) joins the queue if it comes before the queue has gone, else it holds nobody up (car following keeps
    the gap); this car can cross ``headway_s`` after the queue's last car. On a green the standing cars are a queue already
    discharging (one a headway from now). ``arrivals_vps``: the flow arriving at the next light, per
    lane [veh/s] (None: the connected cars alone); ``connected_share``: the share of those cars that are connected;
    ``red_elapsed_s``: how long the next light's current red has been on (None: unknown, counted from now);
    ``past_red``: the next light's last red, where it is not red now: the queue that formed in it goes on
    discharging after its end (:func:`past_queue`), and the cars ahead join it."""
    model = model or QueueModel()
    v_free = max(obs.speed_limit_mps, 1.0)
    cars, known, free_at, clears, after_reds = [], [], [], [], []
    before, stop_behind = 0.0, False
    for i, light in enumerate(obs.lights):
        red = _first_red(light)
        start, end = red if red is not None else (math.inf, math.inf)
        ahead = sorted((light.distance_m - p.ahead_m, p.speed_mps) for p in probes if before < p.ahead_m < light.distance_m)
        queue_m = light.queue_m if light.fresh else None
        past = past_red if i == 0 and past_red is not None and start > 0.0 and past_red.end_s <= 0.0 else None
        if past is not None and past.queue_m is not None:  # the jam published in the red: the cars in it (connected
            ahead = [(to_line, v) for to_line, v in ahead if to_line > max(past.queue_m, queue_m or 0.0)]  # ones too) discharge
            queue_m = None  # from its end; the one published now is its tail, still standing
        if queue_m is not None:  # the detectors' count: connected cars standing inside the published queue are in it
            ahead = [(to_line, v) for to_line, v in ahead if to_line > queue_m or v >= model.queued_mps]
        arrivals = [0.0 if v < model.queued_mps else normal_drive_s(to_line, v, obs.speed_limit_mps, model.drive_accel_mps2) for to_line, v in ahead]
        if queue_m is not None:  # standing: one car per jam spacing, as many as fit between the line and this car
            arrivals = [0.0] * int(round(max(min(queue_m, light.distance_m - model.jam_spacing_m), 0.0) / model.jam_spacing_m)) + arrivals
        n_unseen = 0.0
        if i == 0 and queue_m is None and arrivals_vps is not None and arrivals_vps > 0.0 and connected_share < 1.0 and red is not None:
            began = -(red_elapsed_s or 0.0) if start <= 0.0 else start
            mine = light.distance_m / v_free  # this car's unimpeded arrival at the line
            n_unseen = (1.0 - connected_share) * arrivals_vps * max(0.0, min(end, mine) - began)
            n_unseen = min(n_unseen, max(light.distance_m / model.jam_spacing_m - 1.0 - len(ahead), 0.0))
            arrivals = [max(start, 0.0)] * int(round(n_unseen)) + arrivals  # they arrived first: ahead in the queue
        # the past red's queue still discharging (fast, slow: its last car's crossing), the cars ahead behind it
        (prev_fast, prev), n_prev = past_queue(past, model, arrivals_vps, connected_share, light.distance_m, len(ahead)) if past else ((-math.inf,) * 2, 0)
        # the discharge, slow and fast, counted from the red's end (one whose end is unknown: from after every arrival)
        ref = end if math.isfinite(end) else max([max(start, 0.0), *arrivals]) + 1.0
        crossed, holding = _discharge(arrivals, start, ref, model.startup_s, model.headway_s, prev)
        crossed_fast, holding_fast = _discharge(arrivals, start, ref, model.fast_startup_s, model.fast_headway_s, prev_fast)
        waits = holding > 0 and any(start <= a < ref for a in arrivals)  # the queue waits for the red's end
        after_red = (crossed_fast - ref, crossed - ref) if waits else None
        if waits:
            crossed, crossed_fast = crossed - ref + end, crossed_fast - ref + end
        holding += n_prev
        free = max(crossed + model.headway_s, 0.0) if holding else 0.0
        clear = (max(crossed_fast, 0.0) if holding_fast or prev_fast > 0.0 else 0.0, max(crossed, 0.0) if holding else 0.0)
        # behind the cars ahead (:func:`behind_s`): where they leave this car no time to cross before a red that no
        # amber announces, one it could make alone, the line is closed to it until that red's end (an amber warns the
        # driver behind a car as any other). Decided within the distance the car needs to stop at the others' rate plus a headway's travel: farther out
        # the cars ahead may yet leave it time, and it can still stop when it gets there.
        v = obs.speed_mps
        deciding = light.distance_m <= v * v / (2.0 * model.drive_accel_mps2) + v * model.headway_s
        if light.amber_s == 0.0 and 0.0 < start and free < start and light.distance_m / v_free < start and deciding:
            lead_cars = [(p.ahead_m, p.speed_mps) for p in probes if before < p.ahead_m]
            lead = behind_s(light.distance_m, lead_cars, model)
            nearest = min(lead_cars, default=None)
            # the margin where the cars ahead set its crossing (later than its own drive, or closing in on a slower car):
            # their plans, not known here, make it uncertain (traced: platoons slowing for the next light's queue)
            held = lead > normal_drive_s(light.distance_m, v, obs.speed_limit_mps, model.drive_accel_mps2)
            margin = model.no_amber_margin_s if held or (nearest is not None and _close(obs, nearest[0], model) and _closing(obs, nearest[1])) else 0.0
            if lead + margin > start:
                free = max(free, lead, start)
                clear, after_red = (max(clear[0], lead, start), max(clear[1], lead, start)), None
                stop_behind = stop_behind or i == 0
        cars.append(float(holding))
        clears.append(clear)
        after_reds.append(after_red)
        known.append(len(ahead))
        free_at.append(free)
        before = light.distance_m
    in_queue = bool(obs.lights) and obs.speed_mps < model.queued_mps and obs.lights[0].distance_m > model.jam_spacing_m + 1.0
    follow = None
    ahead_cars = [p for p in probes if p.ahead_m > 0.0]
    if ahead_cars:
        nearest = min(ahead_cars, key=lambda p: p.ahead_m)
        if _close(obs, nearest.ahead_m, model) and _closing(obs, nearest.speed_mps):  # closing in on a slower car
            follow = nearest.speed_mps
    free0 = free_at[0] if free_at else 0.0
    n_behind = followers(obs, probes, free0, model, arrivals_vps, connected_share)
    return QueueEstimate(tuple(cars), tuple(known), tuple(free_at), in_queue, follow, n_behind, held_up(obs, probes, free0, model), stop_behind and not in_queue,
                         tuple(clears), tuple(after_reds))  # fmt: skip


def _discharge(arrivals: Sequence[float], start: float, end: float, startup_s: float, headway_s: float,
               crossed: float = -math.inf) -> tuple[float, int]:  # fmt: skip
    """When the last of the cars arriving at a line at ``arrivals`` (from now, in their order) that form a queue there
    crosses it [s], and how many they are, for a red from ``start`` to ``end``: one arriving during the red waits for
    its end, the first crossing ``startup_s`` after it and each next one ``headway_s`` after the one before; one
    standing on a green (arrival 0) is a queue already discharging, one car a headway; one arriving while the queue
    discharges joins it; one arriving after it has gone holds nobody up (car following keeps the gap). ``crossed``:
    when the last car of a queue already there (an earlier red's, :func:`past_queue`) crosses, the cars behind it.

    Examples
    --------
    >>> _discharge([0.0, 0.0, 0.0], 0.0, 20.0, 3.0, 2.0), _discharge([0.0, 0.0, 0.0], 0.0, 20.0, 2.0, 1.5)
    ((27.0, 3), (25.0, 3))
    >>> _discharge([30.0], 0.0, 20.0, 3.0, 2.0)  # after the red, nobody in front: no queue
    (-inf, 0)
    >>> _discharge([0.0, 3.0, 12.0], 40.0, 70.0, 3.0, 2.0, 5.0)  # behind an earlier red's queue crossing until 5 s
    (9.0, 2)
    """
    holding = 0
    for a in arrivals:
        if start <= a < end:  # waits for the red's end
            crossed = max(end + (startup_s if holding == 0 else 0.0), crossed + headway_s)
        elif a == 0.0 and start > 0.0:  # standing on a green: a queue already discharging, one car a headway
            crossed = max(0.0, crossed + headway_s)
        elif a < crossed + headway_s:  # arrives while the queue discharges: joins it
            crossed += headway_s
        else:  # arrives after the queue has gone: holds nobody up
            continue
        holding += 1
    return crossed, holding


@dataclass(frozen=True, slots=True)
class PastRed:
    """A light's last red, where it is not red now (the service keeps it: ``server.queue.QueueBoard``): its start and
    end from now (both <= 0) [s], and the queue standing back from the stop line that the controller last published
    during it (None: none published) [m]."""

    start_s: float
    end_s: float
    queue_m: float | None = None


def past_queue(past: PastRed, model: QueueModel, arrivals_vps: float | None, connected_share: float, line_m: float,
               n_ahead: int) -> tuple[tuple[float, float], int]:  # fmt: skip
    """The queue that formed in the last red of a light green now, discharging since its end: when its last car
    crosses the line (fast, slow: :class:`QueueModel`, from now) [s], and how many of its cars are still to cross [-].

    Its cars: the jam the controller last published in the red (one car per jam spacing; the connected cars in it are
    among them), else the cars that are not connected arriving over the red, ``(1 - connected_share) x arrivals_vps x``
    its length (the connected ones are probes: :func:`estimate` has them join it where they are). The first crosses
    ``startup_s`` after the red's end, each next one ``headway_s`` later; no more are still to cross than fit between
    this car (``line_m`` from the line, ``n_ahead`` connected cars in front of it) and the line. Before, the queue was
    forgotten at the green (the red's start dropped, the published jam gone when its first car moves): a car at the
    limit was told to drive normally into it (traced in SUMO, paper_s400, docs/TRAFFIC.md).

    Examples
    --------
    A 30 s red that ended 4 s ago, 300 veh/h of which half connected: 1.25 cars (one), over the line 2-3 s after the
    end: gone. At 720 veh/h, 3 cars: the last crosses 0.8 s from now at the fast end (2 s + 2 x 1.4 s after the end),
    3 s at the slow end (3 s + 2 x 2 s), two still to cross. A 40 m jam published in the red: 5 cars, 3.6 s and 7 s.

    >>> past_queue(PastRed(-34.0, -4.0), QueueModel(), 300 / 3600, 0.5, 200.0, 0)
    ((-2.0, -1.0), 0)
    >>> [(round(fast, 2), slow, n) for (fast, slow), n in (past_queue(PastRed(-34.0, -4.0, q), QueueModel(), 720 / 3600, 0.5, 200.0, 0)
    ...                                                   for q in (None, 40.0))]
    [(0.8, 3.0, 2), (3.6, 7.0, 4)]
    """
    if past.queue_m is not None:
        n = round(max(min(past.queue_m, line_m - model.jam_spacing_m), 0.0) / model.jam_spacing_m)
    elif arrivals_vps and connected_share < 1.0:
        n = round((1.0 - connected_share) * arrivals_vps * max(past.end_s - past.start_s, 0.0))
    else:
        n = 0
    if n == 0:
        return (-math.inf, -math.inf), 0
    fit = max(line_m / model.jam_spacing_m - 1.0 - n_ahead, 0.0)  # cars still to cross: between this car and the line
    fast = min(past.end_s + model.fast_startup_s + (n - 1) * model.fast_headway_s, fit * model.fast_headway_s)
    slow = min(past.end_s + model.startup_s + (n - 1) * model.headway_s, fit * model.headway_s)
    return (fast, slow), max(math.ceil(slow / model.headway_s - 1e-9), 0) if slow > 0.0 else 0


def _close(obs: Observation, ahead_m: float, model: QueueModel) -> bool:
    """A car ``ahead_m`` ahead is within ``follow_gap_s`` of this one (plus a jam spacing): it may set the pace."""
    return ahead_m <= obs.speed_mps * model.follow_gap_s + model.jam_spacing_m


def _closing(obs: Observation, ahead_mps: float) -> bool:
    """A car ahead at ``ahead_mps`` is slower than this one (by more than 1 m/s): this car is closing in on it."""
    return ahead_mps < min(obs.speed_mps, obs.speed_limit_mps) - 1.0


def behind_s(line_m: float, ahead: Sequence[tuple[float, float]], model: QueueModel | None = None) -> float:
    r"""The earliest instant this car can cross a line ``line_m`` ahead behind the cars ahead of it (``ahead``: how far
    ahead of this car [m] and speed [m/s], each), 0 where none holds it. [s]

    Each car ahead holds its speed now (the service does not know its plan: the connected cars traced ahead of those
    that entered a red were slowing for the next light's queue, not speeding up to the limit as :func:`estimate` has
    cars arriving at a queue do), and this car follows it as in Newell's simplified car following [1]_: its
    trajectory is the one ahead shifted by a space ``jam_spacing_m`` and a time, the headway ``headway_s`` or the
    shorter one it keeps now (its gap less the jam spacing over the speed of the car ahead: a platoon at the limit 1.2 s
    apart stays so), so its front reaches the line that time after the car ahead is ``jam_spacing_m`` past it (or was:
    a car ahead already past the line holds it for less than that time). Cars standing (slower than ``queued_mps``) do
    not count here (a queue: :func:`estimate`).

    .. math:: t = \max\big(0, \max_k \; (d - a_k + \delta) / v_k + \min(\tau, (a_k - \delta) / v_k)\big)

    with :math:`d` the line's distance,
    :math:`a_k` how far ahead car :math:`k` is and :math:`v_k` its speed, :math:`\delta` the jam spacing and
    :math:`\tau` the headway.

    References
    ----------
    .. [1] G. F. Newell, "A simplified car-following theory: a lower order model," *Transp. Res. Part B*, vol. 36,
       no. 3, pp. 195-205, 2002, doi:10.1016/S0191-2615(00)00044-8.

    Examples
    --------
    A car 52.5 m before a line 100 m ahead of this one, at 20 m/s: it is 7.5 m past the line in 3 s, this car can cross
    2 s after that; 0.6 s after it where it is 19.5 m ahead (12 m, 0.6 s at 20 m/s, more than the jam spacing); one
    10 m past the line at 10 m/s was 7.5 m past it 0.25 s ago, this car crosses 2 - 0.25 s from now; none ahead, or one
    far past the line: nothing holds it.

    >>> behind_s(100.0, [(47.5, 20.0)]), behind_s(100.0, [(19.5, 20.0)]), behind_s(40.0, [(50.0, 10.0)])
    (5.0, 5.0, 1.75)
    >>> behind_s(20.0, []), behind_s(20.0, [(80.0, 20.0)])
    (0.0, 0.0)
    """
    model = model or QueueModel()
    out = 0.0
    for ahead_m, v_mps in ahead:
        if ahead_m > 0.0 and v_mps >= model.queued_mps:
            lag_s = min(model.headway_s, max(ahead_m - model.jam_spacing_m, 0.0) / v_mps)
            out = max(out, (line_m - ahead_m + model.jam_spacing_m) / v_mps + lag_s)
    return out


def unseen_behind(arrivals_vps: float | None, connected_share: float, from_s: float, to_s: float,
                  view_s: float = math.inf) -> tuple[float, float]:  # fmt: skip
    """The cars expected to reach a line behind this car between ``from_s`` and ``to_s`` from now that the service does
    not know as probes [-], two counts: the ones not connected, ``(1 - connected_share) x arrivals_vps x (to_s -
    from_s)``, and the connected ones not on the route yet (Poisson arrivals at the flow's rate, each share of them alike): the service
    sees a trip only from where it advises it on (the approach's start), and a connected car that reaches the line later
    than ``view_s`` from now (the time a car at the limit takes from that start to the line) is still upstream of it now,
    ``connected_share x arrivals_vps x (to_s - max(from_s, view_s))``. ``view_s`` inf: every connected car behind is seen.

    Traced in SUMO (paper_s400 fixed 600 veh/h, 50 %, seed 3, docs/TRAFFIC.md): a car told to slow 224 m before a light
    green for 16 s more was priced as cutting off no one (0.54 cars expected behind it, all of them not connected); the
    connected car 4.5 s behind it was still 70 m before the approach's start, seen four fixes later, once the car had
    slowed, and it and the car behind it were cut off by the red, 33-35 s each.

    Examples
    --------
    600 veh/h, half of them connected, over 12 s: 1 car not connected; the approach's start 6 s before the line at the
    limit, the connected cars arriving in the last 6 s are not on the route yet: 0.5 more.

    >>> unseen_behind(600 / 3600, 0.5, 0.0, 12.0), unseen_behind(600 / 3600, 0.5, 0.0, 12.0, 6.0), unseen_behind(None, 0.5, 0.0, 12.0, 6.0)
    ((1.0, 0.0), (1.0, 0.5), (0.0, 0.0))
    """
    if not arrivals_vps or to_s <= from_s:
        return 0.0, 0.0
    share = min(max(connected_share, 0.0), 1.0)
    return arrivals_vps * (1.0 - share) * (to_s - from_s), arrivals_vps * share * max(to_s - max(from_s, view_s), 0.0)


def followers(
    obs: Observation, probes: Sequence[Probe], free_at_s: float = 0.0, model: QueueModel | None = None, arrivals_vps: float | None = None,
    connected_share: float = 1.0, view_m: float = math.inf,
) -> float:
    """The cars expected behind the car of ``obs`` that a slower plan holds up: the ones that reach the next light's
    line behind it before it can cross there (``free_at_s`` from now, where the queue in front holds it) plus
    ``follow_gap_s`` (a car closer than that behind a slower one is slowed with it; one lane, no overtaking).

    The connected cars are known (``probes`` behind it: ``ahead_m < 0``, :func:`held_up`): each counts whose unimpeded
    arrival at the line (speeding up to the limit at ``drive_accel_mps2`` from its speed now, as the regular driver)
    falls within that window after this car's own. The others are expected from the flow: ``(1 - connected_share) x
    arrivals_vps x`` the window (Poisson arrivals; at 600 veh/h and half of them connected, 0.25 cars within 3 s: one or
    more with probability 1 - exp(-0.25) = 22 %), and the connected ones not yet on the route (``view_m``: how far
    behind this car the service's view of the route begins; :func:`unseen_behind`). The advisor prices the time a plan
    gives up ``1 + followers`` times (:func:`advisory.advice.views.time_price`). [-]

    Examples
    --------
    >>> from advisory.advice.views import LightView
    >>> obs = Observation(20.0, 20.0, (LightView(1, 200.0),))
    >>> round(followers(obs, [], arrivals_vps=600 / 3600, connected_share=0.5), 2)
    0.25
    >>> followers(obs, [Probe(-30.0, 20.0), Probe(-100.0, 20.0)])  # 1.5 s and 5 s behind
    1.0
    >>> round(followers(obs, [], arrivals_vps=600 / 3600, connected_share=0.5, view_m=0.0), 2)  # the route begins here
    0.5
    """
    model = model or QueueModel()
    if not obs.lights:
        return 0.0
    known, window = _held_up(obs, probes, free_at_s, model)
    d, lim = obs.lights[0].distance_m, max(obs.speed_limit_mps, 1.0)
    mine = normal_drive_s(d, obs.speed_mps, lim, model.drive_accel_mps2)
    return float(len(known) + sum(unseen_behind(arrivals_vps, connected_share, mine, mine + window, (d + view_m) / lim)))


def held_up(obs: Observation, probes: Sequence[Probe], free_at_s: float = 0.0, model: QueueModel | None = None) -> tuple[Probe, ...]:
    """The connected cars among ``probes`` that :func:`followers` counts, nearest first.

    Examples
    --------
    >>> from advisory.advice.views import LightView
    >>> held_up(Observation(20.0, 20.0, (LightView(1, 200.0),)), [Probe(-100.0, 20.0), Probe(-30.0, 20.0), Probe(10.0, 20.0)])
    (Probe(ahead_m=-30.0, speed_mps=20.0),)
    """
    return _held_up(obs, probes, free_at_s, model or QueueModel())[0] if obs.lights else ()


def _held_up(obs: Observation, probes: Sequence[Probe], free_at_s: float, model: QueueModel) -> tuple[tuple[Probe, ...], float]:
    """:func:`held_up`, and the window [s] after this car's normal arrival at the next line that it counts them in."""
    d, lim = obs.lights[0].distance_m, max(obs.speed_limit_mps, 1.0)
    mine = normal_drive_s(d, obs.speed_mps, lim, model.drive_accel_mps2)
    window = max(free_at_s - mine, 0.0) + model.follow_gap_s
    known = (p for p in probes if p.ahead_m < 0.0 and normal_drive_s(d - p.ahead_m, p.speed_mps, lim, model.drive_accel_mps2) - mine < window)
    return tuple(sorted(known, key=lambda p: (-p.ahead_m, p.speed_mps))), window


def _held_until(windows, until_s: float):
    """``windows`` (relative, sorted, disjoint) with the line also closed from now until ``until_s``: their union.

    Examples
    --------
    >>> _held_until(((0.0, 10.0), (40.0, 70.0)), 15.0), _held_until(((5.0, 10.0),), 3.0), _held_until(((0.0, 10.0),), 5.0)
    (((0.0, 15.0), (40.0, 70.0)), ((0.0, 3.0), (5.0, 10.0)), ((0.0, 10.0),))
    """
    if windows is None or until_s <= 0.0:
        return windows
    merged: list[tuple[float, float]] = []
    for a, b in sorted([(0.0, until_s), *((max(a, 0.0), b) for a, b in windows if b > 0.0)]):
        if merged and a <= merged[-1][1]:
            merged[-1] = (merged[-1][0], max(merged[-1][1], b))
        else:
            merged.append((a, b))
    return tuple(merged)


def apply(obs: Observation, est: QueueEstimate) -> Observation:
    """``obs`` as the car meets the lights in traffic: each line closed to this car until the queue in front of it has
    crossed, a distribution between the fast and the slow discharge (``est.clear_s``), not one instant:

    * each of the light's equally likely timings (``LightView.scenario_red_windows_s``; an exact light's windows in
      each, :data:`~advisory.advice.mixture.IMPLIED_TIMINGS` of them) is closed until the clearing at its own level,
      uniform from fast to slow, in the timings' order (a timing whose red ends early meets the fast discharge too),
      counted from that timing's own red end where the queue waits for the red (``est.after_red_s``): the choice
      under uncertain timing (:mod:`advisory.advice.choice`) prices a plan on each, so it neither plans into a queue
      still standing nor hangs back for one already gone (traced in SUMO: one conservative instant, the latest red end
      plus the slow discharge, in every timing, held advised cars and the lane behind them seconds after the line was
      free);
    * the sure view (``red_windows_s``) until the fast clearing: before it the queue surely stands, and no plan reaches
      it there (the hard constraint, in every timing); the likely view until the middle one, the late view until the
      slow one.

    The advisor adds its margin after each window's end (``green_margin_s``): this car's own headway behind the queue's
    last car. An exact light with a queue ahead is thus planned by the choice (its timings are the queue's)."""
    lights = tuple(_held(lv, clear, after) for lv, clear, after in zip(obs.lights, est.clear_s or ((0.0, 0.0),) * len(obs.lights),
                                                                       est.after_red_s or (None,) * len(obs.lights)))  # fmt: skip
    return replace(obs, lights=lights, followers=est.followers)


def _held(light: LightView, clear_s: tuple[float, float], after_red_s: tuple[float, float] | None) -> LightView:
    """``light`` closed until the queue has crossed, at each level of its discharge (:func:`apply`)."""
    fast, slow = clear_s
    if slow <= 0.0 and fast <= 0.0:
        return light

    def until(windows, level):
        red = _first_red_of(windows)
        if after_red_s is not None and red is not None and math.isfinite(red[1]):  # counted from this view's own red end
            return _held_until(windows, red[1] + after_red_s[0] + (after_red_s[1] - after_red_s[0]) * level)
        return _held_until(windows, fast + (slow - fast) * level if math.isfinite(slow) else (fast if level == 0.0 else slow))

    timings = light.scenario_red_windows_s or implied_timings(light)
    n = len(timings)
    return replace(light, red_windows_s=until(light.red_windows_s, 0.0), likely_red_windows_s=until(light.likely_red_windows_s, 0.5),
                   late_red_windows_s=until(light.late_red_windows_s, 1.0),
                   scenario_red_windows_s=tuple(until(w, (k + 0.5) / n) for k, w in enumerate(timings)))  # fmt: skip


def _first_red_of(windows) -> tuple[float, float] | None:
    """The red of ``windows`` (relative, sorted; None: no view) still to end first."""
    return None if windows is None else next(((a, b) for a, b in windows if b > 0.0), None)


GIVE_UP_SLACK_S = 5.0
"""A plan reaching the last light ahead this much later than a normal drive that makes every green gives one up. [s]"""


def normal_drive_s(distance_m: float, v_mps: float, limit_mps: float, accel_mps2: float) -> float:
    """Time to a line ``distance_m`` ahead speeding up at once at ``accel_mps2`` to the limit, then holding it. [s]

    Examples
    --------
    >>> round(normal_drive_s(100.0, 0.0, 20.0, 2.0), 2), round(normal_drive_s(100.0, 20.0, 20.0, 2.0), 2)
    (10.0, 5.0)
    """
    v, lim = max(v_mps, 0.0), max(limit_mps, 0.1)
    if v >= lim:
        return distance_m / v
    d_acc = (lim * lim - v * v) / (2.0 * accel_mps2)
    if distance_m <= d_acc:
        return (math.sqrt(v * v + 2.0 * accel_mps2 * distance_m) - v) / accel_mps2
    return (lim - v) / accel_mps2 + (distance_m - d_acc) / lim


def behind_queues_s(crossings_s: Sequence[float], obs: Observation, queue: QueueEstimate | None, accel_mps2: float, model: QueueModel) -> list[float]:
    """A drive's crossing of each line ahead of ``obs`` (``crossings_s``, as it would cross on an empty road, from now)
    behind the queues in front of the car (``queue``, its :class:`QueueEstimate`: per line the cars in front and when the
    last of them crosses it, :func:`cleared_s`; None: no queue): no earlier than a headway after the queue's last car at the fast end of the discharge (``fast_headway_s``
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


def cleared_s(light: LightView, queue: QueueEstimate | None, j: int) -> tuple[float, float]:
    """When the last car of the queue in front crosses line ``j`` (``light``, as the observation has it, before
    :func:`apply`), at the fast and at the slow end of the discharge, from now (0, 0: no queue) [s]: the estimate's
    ``clear_s``, counted from the red's likely end where the queue waits for it (``after_red_s``): the sure view's end
    is the latest an actuated red may end, and counted from it a queue held every drive for a green that came earlier
    (traced in SUMO, paper_s400 actuated 600 veh/h, 50 %: the check let slow plans stand, advised time +12.5 -> +15.3 %).

    Examples
    --------
    >>> lv = LightView(1, 200.0, red_windows_s=((0.0, 30.0),), likely_red_windows_s=((0.0, 20.0),))
    >>> cleared_s(lv, QueueEstimate((3.0,), (0,), (37.0,), clear_s=((34.8, 37.0),), after_red_s=((4.8, 7.0),)), 0), cleared_s(lv, None, 0)
    ((24.8, 27.0), (0.0, 0.0))
    """
    if queue is None or j >= len(queue.clear_s):
        return 0.0, 0.0
    fast, slow = queue.clear_s[j]
    after = queue.after_red_s[j] if j < len(queue.after_red_s) else None
    red = _first_red_of(light.red_windows_s if light.likely_red_windows_s is None else light.likely_red_windows_s)
    if after is not None and red is not None and math.isfinite(red[1]):
        return red[1] + after[0], red[1] + after[1]
    return fast, slow


def gives_up_green(obs: Observation, advice: Advice, params: AdvisorParams, slack_s: float = GIVE_UP_SLACK_S, model: QueueModel | None = None,
                   behind: Sequence[Probe] = (), queue: QueueEstimate | None = None) -> bool:  # fmt: skip
    """The advised plan gives up green time that a normal drive (speeding up to the limit at the regular driver's
    ``normal_accel_mps2``, no advice to react to) uses: at a light that the normal drive crosses outside its reds (the
    queue's included, :func:`apply`), as every light before it, the plan arrives ``late`` after it, and the time lost
    is more than ``slack_s``:

    * ``late`` for the car itself, at the last light ahead where the normal drive makes every light (before that, a red
      further on takes the time back: the car waits there either way);
    * ``late`` for each follower it holds up (``Observation.followers``), at every such light, and the red each one
      pushed past the end of that light's green waits out: the connected ones among them (``behind``, nearest first,
      :attr:`QueueEstimate.behind`) where they are (:func:`pushed_past`), the others as expected from the flow
      (:func:`cut_off`); where a red further on stops the normal drive, only while the plan has still to slow the car
      (its target below the car's speed): a car already slowed is not sent back up to the limit towards that red
      (traced in SUMO: such cars met it or a queue's tail braking harder than 3.5 m/s², or entered it), and the
      followers' time is already lost.

    Both drives cross each line behind the queue in front of the car (``queue``, the car's :class:`QueueEstimate`;
    :func:`behind_queues_s`): a normal drive into a queue still discharging is held by it, not as on an empty road
    (one that would reach it while it surely stands, before its fast clearing, does not make the light: it stops there)
    (traced in SUMO, paper_s400 fixed 300 veh/h, 50 %, seed 2, ``main.6``: 113 m out at 23 m/s with two cars clearing
    3.4-5 s from now, a plan slowing to 69 km/h was turned back because its normal drive at the limit crossed at 4.6 s;
    told to drive normally the car slowed at 3.0-3.2 m/s² behind the queue).

    The plan is not credited with a stop it avoids at a red further on: a car that drives normally through this light
    is advised again after it, with the distance to the next one to slow down in. Alike, past the light the plan is for
    (``advice.light_ahead``) the car is advised again: it drives on from that line as a normal drive from the plan's
    speed, not at the plan's speed to the last light (a plan slowing for the first light's queue was counted 4.5 s
    late at the second light, 400 m on at 69 km/h). Traced in SUMO (docs/TRAFFIC.md): a car
    launching from a queue at the first light, told to crawl 400 m to the second light's green after next (the advisor
    plans with comfortable accelerations, and its own ``tight_green`` rule looks at the next light); seven connected
    cars told to crawl through the first light towards the second one's queue having cleared, the cars behind them cut
    off at the first light (35 s each); a car told to slow down for the second light's green 124 m before a first light
    that turned red without amber 8 s later, over that line 0.7 s later than a normal drive, a connected car 2.5 s
    behind it (over the line 0.4 s before the red at its speed) pushed into that red (counted as half a car arriving
    at random, 2 s behind, it was not pushed). On an empty road (no followers) only the first case is checked, as
    before."""
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
    # fast clearing: the sure view of :func:`apply`), where it would stop too; its time there is the one behind the queue
    made = next((j for j, (lv, t) in enumerate(zip(obs.lights, alone)) if lv.is_red_at(t) or lv.is_red_at(normal[j])), len(obs.lights))
    known = tuple(behind)
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


def pushed_past(light: LightView, normal_s: float, planned_s: float, behind: Sequence[Probe], limit_mps: float, model: QueueModel | None = None) -> float:
    """The wait [s] that the connected cars ``behind`` this one (nearest first, each where it is now) lose at ``light``
    when this car's front is a jam spacing past its line at ``planned_s`` instead of ``normal_s``: each crosses the
    line at its own normal drive (speeding up to the limit at ``drive_accel_mps2``) or, where the car in front of it
    holds it, as it follows now (Newell's shift, as in :func:`behind_s`, with the driver's own lag: its gap less the
    jam spacing over its speed, after that car is a jam spacing past the line; these cars are the ones :func:`held_up`
    finds within ``follow_gap_s``, which a slower car ahead slows with it: a driver 2.5 s behind kept its 2.5 s in
    SUMO, where :func:`behind_s`'s ``headway_s`` would have it close up to 2 s); one pushed from before the red it meets
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
    for p in behind:
        v = max(p.speed_mps, model.queued_mps)
        own = normal_drive_s(line_m - p.ahead_m, p.speed_mps, limit_mps, model.drive_accel_mps2)
        lag = max(ahead_m - p.ahead_m - model.jam_spacing_m, 0.0) / v
        normal_x, planned_x = max(own, normal_at + lag), max(own, planned_at + lag)
        start, end = next(((a, b) for a, b in light.red_windows_s if b > normal_x), (math.inf, math.inf))  # the red it meets, or the next
        if normal_x < start <= planned_x:
            lost += min(end - start, WAIT_CAP_S)
        normal_at, planned_at, ahead_m = normal_x + model.jam_spacing_m / v, planned_x + model.jam_spacing_m / v, p.ahead_m
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
    follows it as in Newell's car following (G. F. Newell, 2002: the reference of :func:`behind_s`), its trajectory the leader's shifted by ``k`` jam spacings and ``k``
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


def cut_behind(light: LightView, obs: Observation, advice: Advice, params: AdvisorParams, behind: Sequence[Probe] = (),
               arrivals_vps: float | None = None, connected_share: float = 1.0, past: PastRed | None = None,
               model: QueueModel | None = None, queue: QueueEstimate | None = None, view_m: float = math.inf) -> float:  # fmt: skip
    """The wait [s] that the cars behind lose at ``light``'s line when the car follows ``advice`` instead of driving
    normally: the line the car has just passed (``light.distance_m <= 0``: behind it) or the next one ahead (its
    queue estimate ``queue``), in the green the car crosses it in (issue 28, the traffic behind).

    A car driving slowly over a green line holds the platoon behind it to its pace (:func:`platoon_through`: Newell's
    shift, the gap that lets a car over every ``fast_headway_s`` behind a leader at the limit, the fast end of the
    measured discharge: this guards the traffic behind, so the normal drive it is weighed against is not taken
    slower than it may be), so fewer of them cross before the red than behind the same car driving normally (speeding
    up to the limit at ``normal_accel_mps2``; both held by the queue in front of the car, :func:`behind_queues_s`, and
    at the line ahead by its own red, which a drive reaching it then waits out standing; the plan never faster than
    that drive, and a lift-off for the line ahead not coasting on past it), and each one cut off waits the red out (its likely timing; at most
    :data:`advisory.advice.choice.WAIT_CAP_S`). The cars there: the connected ones (``behind``, each where it is now,
    negative ``ahead_m``) still before the line that reach it before the red by their own normal drive, the ones
    already past it (they take the first places behind the car), and the cars that are not connected: a Poisson count
    whose mean is the larger of the flow's, ``(1 - connected_share) x arrivals_vps x`` the time from the car's own
    crossing to the red, with the connected cars not yet on the route (``view_m`` behind this car the service's view
    of it begins: :func:`unseen_behind`), plus, at the line passed, its last red's queue still to cross (``past``,
    :func:`past_queue`), and the connected cars' own, ``(1 - share) / share`` for each connected car counted (a saturated approach's
    residual queue is not in the flow's count). The advisor itself prices the time the followers lose at the lights
    ahead, not the green they lose behind it (:func:`advisory.advice.views.time_price`).

    Traced in SUMO (paper_s400 fixed 900 veh/h, 50 %, seed 1, docs/TRAFFIC.md): cars in the first light's discharging
    queue, told to hold 26-31 km/h for the second light's queue 400 m on, crossed the first at 8-9 m/s instead of
    14-18 m/s; the platoon behind them crossed at their pace and the last two to five cars of the green were cut off
    (a 30 s red each, and the cycle's 30 s green), others' travel time +14 %. Each one cut off also stands first in the
    next queue (:func:`knock_on_s`).

    Examples
    --------
    A car 7 m past a line turning red in 15 s (for 30 s), at 9.2 m/s, told to hold 29 km/h; four connected cars
    standing behind the line (7.5-30 m back), 900 veh/h, half of them connected: the plan lets 8 cars through before
    the red, a normal drive 9; the ninth place is taken with probability P(K >= 5) = 0.37 (K Poisson, mean 4: a car
    not connected for each connected one), and the car cut off there waits the red's 30 s and delays the 11.5 cars
    that queue behind it by a headway each (:func:`knock_on_s`, 16.2 s): 17.1 s lost; a tenth of the cars connected,
    surely taken: 46.2 s. Nobody behind, every car connected: nothing lost.

    >>> from advisory.advice.views import Advice, AdvisorParams
    >>> passed = LightView(1, -7.0, red_windows_s=((15.0, 45.0),))
    >>> obs = Observation(9.2, 24.6, (LightView(2, 393.0, red_windows_s=((0.0, 40.0),)),))
    >>> four, hold = [Probe(-7.0 - 7.5 * k, 0.0) for k in (1, 2, 3, 4)], Advice("cruise", "green_wave", 8.04)
    >>> [round(cut_behind(passed, obs, hold, AdvisorParams(), four, 900 / 3600, share), 1) for share in (0.5, 0.1)]
    [17.1, 46.2]
    >>> cut_behind(passed, obs, hold, AdvisorParams())
    0.0
    """
    target = advice.target_speed_mps
    if target is None or advice.action not in KEEP_MODES:
        return 0.0
    model = model or QueueModel()
    v, limit, line_m = obs.speed_mps, max(obs.speed_limit_mps, 1.0), light.distance_m
    mode, pace = KEEP_MODES[advice.action], max(obs.speed_mps, model.queued_mps)
    gap_s = max(model.fast_headway_s - model.jam_spacing_m / limit, 0.0)
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
    # +1.4 to +4.4; docs/TRAFFIC.md, ninth session)
    coast_to = mode == "brake_coast" and line_m > 0.0 and advice.light_ahead == 1 and advice.light_id in (None, light.intersection_id)
    if coast_to:  # (held at the line by the queue or the red, it leaves it as a normal drive does)
        at_line_s = float(crossing_time_s(line_m, v, target, params, mode))
        v_line = max(line_speed_mps(line_m, v, target, params, mode), model.queued_mps) if at_line_s >= normal(line_m) else None

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
    over = sum(1 for p in behind if line_m < p.ahead_m < 0.0)  # connected, already over the line: the first places
    there = sum(1 for p in behind if p.ahead_m <= min(line_m, 0.0) and normal_drive_s(line_m - p.ahead_m, p.speed_mps, limit, model.drive_accel_mps2) < start)
    n_normal = platoon_through(line_m, start, normal, gap_s, model.jam_spacing_m, over + 1)
    n_plan = platoon_through(line_m, start, planned, gap_s, model.jam_spacing_m, over + 1)
    # a connected car behind, at a light that shows no amber, is to be over the line ``no_amber_margin_s`` before the red
    # where the car in front sets its crossing, or it is told to stop (:func:`estimate`, ``stop_behind``): its place is
    # cut off that much earlier (traced: a connected car 4.5 s behind a platoon held to 11.5 m/s, over the line 2 s
    # before a red that no amber announces at its own pace, was told to stop; it and the car behind it lost 33-35 s)
    margin_s = model.no_amber_margin_s if light.amber_s == 0.0 else 0.0
    n_normal_c = platoon_through(line_m, start - margin_s, normal, gap_s, model.jam_spacing_m, over + 1) if margin_s else n_normal
    n_plan_c = platoon_through(line_m, start - margin_s, planned, gap_s, model.jam_spacing_m, over + 1) if margin_s else n_plan
    if n_plan >= n_normal and n_plan_c >= n_normal_c:
        return 0.0
    share = min(max(connected_share, 0.0), 1.0)
    not_connected, connected = unseen_behind(arrivals_vps, share, crossed_s, start, (line_m + view_m) / limit)
    flow = not_connected + connected
    if flow and past is not None and line_m <= 0.0:
        flow += past_queue(past, model, arrivals_vps, share, math.inf, 0)[1]
    unseen = max(flow, (there + over) * (1.0 - share) / share if share > 0.0 else 0.0)
    p_connected = connected / unseen if unseen > 0.0 else 0.0  # an unseen car in a place is a connected one not yet on the route
    # the k-th place behind the line is taken with probability P(there + K >= k), K Poisson with mean ``unseen``; the
    # first ``there`` by the connected cars known
    cut, p_k, p_at_least = 0.0, math.exp(-unseen), 1.0
    for k in range(1, n_normal + 1):
        if k > there:
            p_at_least -= p_k  # P(K >= j + 1) from P(K >= j), j = k - there - 1
            p_k *= unseen / (k - there)
            if p_at_least < 1e-4:
                break
        cut_c, cut_u = float(n_plan_c < k <= n_normal_c), float(n_plan < k <= n_normal)
        cut += cut_c if k <= there else p_at_least * (p_connected * cut_c + (1.0 - p_connected) * cut_u)
    return cut * (min(end - start, WAIT_CAP_S) + knock_on_s(light, start, end, arrivals_vps, model.fast_headway_s))


def knock_on_s(light: LightView, start_s: float, end_s: float, arrivals_vps: float | None, headway_s: float) -> float:
    """The time [s] that one car cut off at the red from ``start_s`` to ``end_s`` costs the cars behind it: it stands
    first in that red's queue, so every car that queues behind it crosses a headway later. Those cars: the red's
    arrivals and the ones joining while the queue discharges, ``flow x red / (1 - flow x headway)`` (a deterministic
    queue at a signal, D/D/1: it clears when the discharge has caught up with the arrivals), no more than the next
    green lets over the line (``green / headway``, an oversaturated approach; the green to the light's next red,
    none known: the red's length). ``arrivals_vps`` None: not known, 0.

    Traced in SUMO (paper_s400 fixed 600 veh/h, 50 %, seed 3, docs/TRAFFIC.md): four cars cut off at light 1's end of
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
    if not arrivals_vps or not math.isfinite(end_s):
        return 0.0
    windows = light.red_windows_s if light.likely_red_windows_s is None else light.likely_red_windows_s
    green_s = next((a for a, _ in windows if a >= end_s), end_s + (end_s - start_s)) - end_s
    load = arrivals_vps * headway_s
    queued = arrivals_vps * (end_s - start_s) / (1.0 - load) if load < 1.0 else math.inf
    return headway_s * min(queued, green_s / headway_s)


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
    the light itself (``real``) is green and a normal drive (:func:`normal_drive_s`) is over its line before its red
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
    """``advice``, planned on the lights as the queue holds them (``held``, :func:`apply`: a green held by the queue is
    a red to the advisor), with the countdown of the light it names as that light really is (``real``: the
    observation before :func:`apply`): ``light_red`` its state now and ``seconds_to_change_s`` its next change, as the
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
    asks for: the light itself (``obs``, as it is: before :func:`apply`) is green from the queue's fast clearing until
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
    it meets the tail moving at the fast end (the hard constraint of :func:`apply`: the queue surely stands until then).
    At a light of exact timing only: under uncertain timing (an actuated light) when the queue starts to move is as
    uncertain as the green, which the advisor's choice prices over the light's timings (:func:`apply`); the glide, one
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
