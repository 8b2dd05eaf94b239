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
   than fit between the car and the line. That count is Poisson (arrivals are, to first order; SUMO's flows are):
   the mean where one count is needed (``QueueEstimate.cars``, the sure view), its law over the light's timings
   (:func:`count_law`, ``QueueEstimate.law``, :func:`apply`).

After a red has ended its queue goes on discharging (:func:`past_queue`: the jam last published in it, else the
cars not connected arriving over it), the connected cars ahead behind it: it is not forgotten at the green.

The queue's last car then crosses the line ``startup_s + (n - 1) x headway_s`` after the red ends, somewhere between
the fast and the slow end of the measured discharge (:class:`QueueModel`): :func:`apply` closes the line until then as
a distribution over the light's equally likely timings, which the advisor's choice prices (never a plan into a queue
surely standing, no waiting for the slowest discharge in every timing). A car that is
itself in a queue (slower than ``queued_mps`` and not first at the line: ``in_queue``) or right behind a slower
connected car (within ``follow_gap_s`` plus a jam spacing: ``follow_mps``) is given no speed by the service: it
follows the car in front (closing in on a slower connected car, it lifts off to that car's speed:
:func:`advisory.advice.queue_words.ease_to_car_ahead`), and the advice resumes, planned afresh, once it is free (never a target above what the
traffic ahead allows; and a plan made in a queue is a crawl: every faster speed reaches the line before the queue has
gone, and the advisor keeps a plan that still works, to the green after next).
The cars ahead bound when this car can cross (:func:`behind_s`: each drives as the service advised it at its last
fix, :func:`plan_of`, or, not advised, holds its speed now, and this car follows it as in Newell's car following, a
time gap and a jam spacing behind). Where that bound leaves a
car that could make a green alone no time to cross before a red that no amber announces (less ``no_amber_margin_s``
where they set its crossing), the line is closed to it until the red's end and it is not told to follow
(``stop_behind``): it prepares to stop. Decided within the distance the car needs to stop at the others' rate plus a
headway's travel. (Traced in SUMO, paper_s400 at 900 veh/h, every car connected: cars told to follow a platoon
slowing for the next light's queue entered a red no amber announced, 0.5 s in; a cap at the car ahead's speed
instead cost the advised cars +49-115 % of time.)


The cars behind count too (issue 28, item 2: the traffic behind is not to be slowed): :func:`followers` expects the
cars a slower plan holds up (the connected ones behind it, :func:`held_up`, the others from the flow,
:func:`unseen_behind`), and the estimate carries them (``QueueEstimate.followers``, ``.behind``) for the advisor, which
prices time ``1 + followers`` times (:func:`advisory.advice.views.time_price`), and for what a plan costs them
(:mod:`advisory.advice.behind`). The service's own advice and words in a queue: :mod:`advisory.advice.queue_words`.

Pure: no clock, no I/O. The service gathers the probes (:mod:`server.queue`).
"""

from __future__ import annotations

import math
from bisect import bisect_left
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, replace

import numpy as np
from numba import njit

from advisory.advice.kinematics import KEEP_MODES, MODE_CODES, MODE_NAMES, crossing_time_s
from advisory.advice.mixture import IMPLIED_TIMINGS, implied_timings
from advisory.advice.views import Advice, AdvisorParams, LightView, Observation


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
    passage_s: float = 2.0
    """An actuated green, once past its minimum, ends when no car has reached its detector for this long (the
    controller's passage time, unit extension or gap: 2-4 s in the field, the short end the snappiest and the one
    assumed here; SUMO's ``max-gap`` 3 s): the queue in front discharging over its line holds it, and a car reaching
    the line within this long after the queue's last car holds it too (:func:`~advisory.advice.behind.keeps_green`). [s]"""


@dataclass(frozen=True, slots=True)
class Probe:
    """Another connected car on the route: how far ahead of the one asking (negative: behind) [m] and its speed [m/s]."""

    ahead_m: float
    speed_mps: float


class Probes(Sequence[Probe]):
    """Many connected cars at once, as two arrays of equal length (the service makes a lane's run of them in one go:
    ``server.queue.Lane``): how far ahead of the one asking (negative: behind) [m] and their speeds [m/s]. A sequence of
    :class:`Probe` to code that reads them one at a time; the functions here that look at every car read the arrays
    (:meth:`of`: any sequence of probes as arrays). ``plan_mps`` and ``plan_mode``: each car's advised motion where the
    service advised it at that fix (:func:`plan_of`; NaN: none, the car holds its speed now), or None for all."""

    __slots__ = ("ahead_m", "speed_mps", "plan_mps", "plan_mode")

    def __init__(self, ahead_m: np.ndarray, speed_mps: np.ndarray, plan_mps: np.ndarray | None = None, plan_mode: np.ndarray | None = None) -> None:
        self.ahead_m = ahead_m
        self.speed_mps = speed_mps
        self.plan_mps = plan_mps
        self.plan_mode = plan_mode

    @staticmethod
    def of(probes: Sequence[Probe]) -> Probes:
        """``probes`` as arrays (itself where it is :class:`Probes` already)."""
        if isinstance(probes, Probes):
            return probes
        return Probes(np.array([p.ahead_m for p in probes], dtype=float), np.array([p.speed_mps for p in probes], dtype=float))

    def where(self, keep: np.ndarray) -> Probes:
        """The cars where ``keep`` (a mask or indices) says, in its order."""
        if self.plan_mps is None:
            return Probes(self.ahead_m[keep], self.speed_mps[keep])
        return Probes(self.ahead_m[keep], self.speed_mps[keep], self.plan_mps[keep], self.plan_mode[keep])

    def cars(self, keep: np.ndarray) -> list[tuple[float, ...]]:
        """The cars where ``keep`` says as :func:`behind_s` takes them: ``(ahead_m, speed_mps)``, with
        ``(plan_mps, plan_mode)`` where the service advised them (:func:`plan_of`)."""
        ahead_m, speed_mps = self.ahead_m[keep].tolist(), self.speed_mps[keep].tolist()
        if self.plan_mps is None:
            return list(zip(ahead_m, speed_mps))
        return list(zip(ahead_m, speed_mps, self.plan_mps[keep].tolist(), self.plan_mode[keep].tolist()))

    def __len__(self) -> int:
        return len(self.ahead_m)

    def __getitem__(self, k):
        if isinstance(k, slice):
            return self.where(k)
        return Probe(float(self.ahead_m[k]), float(self.speed_mps[k]))

    def __iter__(self) -> Iterator[Probe]:
        return map(Probe, self.ahead_m.tolist(), self.speed_mps.tolist())

    def __repr__(self) -> str:
        return f"Probes({list(self)!r})"

    def __eq__(self, other: object) -> bool:  # the same cars in the same order, as a tuple of them is
        if not isinstance(other, (Probes, tuple, list)):
            return NotImplemented
        return len(self) == len(other) and all(a == b for a, b in zip(self, other))

    def __hash__(self) -> int:
        return hash(tuple(self))


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
    behind: Sequence[Probe] = ()
    """The connected ones among them, nearest first (:func:`held_up`): where each is, for :func:`~advisory.advice.behind.gives_up_green`."""
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
    law: tuple[tuple[tuple[float, tuple[float, float], tuple[float, float] | None], ...], ...] = ()
    """Per light, where the count of the cars in front is uncertain (the cars not connected arriving over the next
    light's red, a Poisson count: :func:`count_law`): for the count at each level of the light's timings, fewest
    first, the probability that the count is at most that, and ``clear_s`` and ``after_red_s`` for
    that count (:func:`apply` takes each level's); ``clear_s``, ``after_red_s`` and ``cars`` are the mean's, rounded.
    () where the count is sure. [-, s, s]"""


def _first_red(light: LightView) -> tuple[float, float] | None:
    """The red the car faces: the first window still to end."""
    return _first_red_of(light.red_windows_s)


def _held_red(light: LightView) -> tuple[float, float] | None:
    """The red that the queue in front meets at the next light: the first one (:func:`_first_red`), but at a light of
    uncertain timing green now (an actuated one: its latest changes known, ``late_red_windows_s``) the latest one
    (maxEnd): a queue discharging over the line, and each car that joins it, keeps the controller's detector busy
    (their headways shorter than any passage time, :attr:`QueueModel.passage_s`), so its green does not end under them
    before its maximum. The sure view ends it at its minimum, and a queue that had not crossed by then waited for the
    red after it: traced in SUMO (paper_s400 actuated 900 veh/h, 50 %, seed 5, ``main.11``), five cars discharging
    on a green just begun, the red after it of unknown end, were taken to clear never, the line closed to the car
    behind them in every timing, which crawled on at 4.5 m/s and lost the green with the cars behind it."""
    if light.late_red_windows_s is not None and not light.red_now:
        return _first_red_of(light.late_red_windows_s)
    return _first_red(light)


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
    cars, known, free_at, clears, after_reds, laws = [], [], [], [], [], []
    before, stop_behind = 0.0, False
    probes = Probes.of(probes)
    ahead_m, speed_mps = probes.ahead_m, probes.speed_mps
    for i, light in enumerate(obs.lights):
        red = _held_red(light) if i == 0 else _first_red(light)
        start, end = red if red is not None else (math.inf, math.inf)
        between = (before < ahead_m) & (ahead_m < light.distance_m)  # the cars ahead before this line, by distance to it
        to_line, v = light.distance_m - ahead_m[between], speed_mps[between]
        by_line = np.lexsort((v, to_line))
        to_line, v = to_line[by_line], v[by_line]
        queue_m = light.queue_m if light.fresh else None
        past = past_red if i == 0 and past_red is not None and start > 0.0 and past_red.end_s <= 0.0 else None
        if past is not None and past.queue_m is not None:  # the jam published in the red: the cars in it (connected
            keep = to_line > max(past.queue_m, queue_m or 0.0)  # ones too) discharge from its end; the one published
            to_line, v, queue_m = to_line[keep], v[keep], None  # now is its tail, still standing
        if queue_m is not None:  # the detectors' count: connected cars standing inside the published queue are in it
            keep = (to_line > queue_m) | (v >= model.queued_mps)
            to_line, v = to_line[keep], v[keep]
        arrivals = np.where(v < model.queued_mps, 0.0, normal_drives_s(to_line, v, obs.speed_limit_mps, model.drive_accel_mps2))
        if queue_m is not None:  # standing: one car per jam spacing, as many as fit between the line and this car
            standing = int(round(max(min(queue_m, light.distance_m - model.jam_spacing_m), 0.0) / model.jam_spacing_m))
            arrivals = np.concatenate((np.zeros(standing), arrivals))
        unseen, cap = 0.0, 0  # the cars not connected: their count's mean and the most that fit
        if i == 0 and queue_m is None and arrivals_vps is not None and arrivals_vps > 0.0 and connected_share < 1.0 and red is not None:
            began = -(red_elapsed_s or 0.0) if start <= 0.0 else start
            mine = light.distance_m / v_free  # this car's unimpeded arrival at the line
            unseen = (1.0 - connected_share) * arrivals_vps * max(0.0, min(end, mine) - began)
            cap = round(max(light.distance_m / model.jam_spacing_m - 1.0 - len(to_line), 0.0))
        # the past red's queue still discharging (fast, slow: its last car's crossing), the cars ahead behind it
        prev, n_prev = past_queue(past, model, arrivals_vps, connected_share, light.distance_m, len(to_line)) if past else ((-math.inf,) * 2, 0)
        holding, free, clear, after_red = _clearing(round(min(unseen, cap)), arrivals, start, end, prev, n_prev, model)
        law = tuple((p, *_clearing(k, arrivals, start, end, prev, n_prev, model)[2:]) for k, p in count_law(unseen, cap, _levels(light)))
        # behind the cars ahead (:func:`behind_s`): where they leave this car no time to cross before a red that no
        # amber announces, one it could make alone, the line is closed to it until that red's end (an amber warns the
        # driver behind a car as any other). Decided within the distance the car needs to stop at the others' rate plus a headway's travel: farther out
        # the cars ahead may yet leave it time, and it can still stop when it gets there.
        sure = _first_red(light)
        start = sure[0] if sure is not None else math.inf  # (that red as early as it may come, not held by the queue)
        v = obs.speed_mps
        deciding = light.distance_m <= v * v / (2.0 * model.drive_accel_mps2) + v * model.headway_s
        if light.amber_s == 0.0 and 0.0 < start and free < start and light.distance_m / v_free < start and deciding:
            lead_cars = probes.cars(before < ahead_m)
            lead = behind_s(light.distance_m, lead_cars, model)
            lead = lead if math.isfinite(lead) else end  # a car ahead told to stop at the line: until the red's end, at least
            nearest = min(lead_cars, default=None)
            # the margin where the cars ahead set its crossing (later than its own drive, or closing in on a slower car):
            # how they drive their plans (advised ones: :func:`plan_of`; the others' not known) makes it uncertain (traced:
            # platoons slowing for the next light's queue)
            held = lead > normal_drive_s(light.distance_m, v, obs.speed_limit_mps, model.drive_accel_mps2)
            margin = model.no_amber_margin_s if held or (nearest is not None and _close(obs, nearest[0], model) and _closing(obs, nearest[1])) else 0.0
            if lead + margin > start:
                free = max(free, lead, start)
                clear, after_red = (max(clear[0], lead, start), max(clear[1], lead, start)), None
                law = tuple((p, (max(c[0], lead, start), max(c[1], lead, start)), None) for p, c, _ in law)
                stop_behind = stop_behind or i == 0
        cars.append(float(holding))
        clears.append(clear)
        after_reds.append(after_red)
        laws.append(law)
        known.append(len(to_line))
        free_at.append(free)
        before = light.distance_m
    in_queue = bool(obs.lights) and obs.speed_mps < model.queued_mps and obs.lights[0].distance_m > model.jam_spacing_m + 1.0
    follow = None
    ahead_cars = np.flatnonzero(ahead_m > 0.0)
    if len(ahead_cars):
        nearest = probes[int(ahead_cars[np.argmin(ahead_m[ahead_cars])])]  # (the first of the nearest, as min() finds it)
        if _close(obs, nearest.ahead_m, model) and _closing(obs, nearest.speed_mps):  # closing in on a slower car
            follow = nearest.speed_mps
    n_behind, behind = followers_held_up(obs, probes, free_at[0] if free_at else 0.0, model, arrivals_vps, connected_share)
    return QueueEstimate(tuple(cars), tuple(known), tuple(free_at), in_queue, follow, n_behind, behind, stop_behind and not in_queue,
                         tuple(clears), tuple(after_reds), tuple(laws))  # fmt: skip


def _clearing(unseen: int, arrivals: np.ndarray, start: float, end: float, prev: tuple[float, float], n_prev: int,
              model: QueueModel) -> tuple[int, float, tuple[float, float], tuple[float, float] | None]:  # fmt: skip
    """The queue in front at one line, for a red from ``start`` to ``end``, with ``unseen`` cars not connected arriving
    first (at the red's start) and then the connected ones at ``arrivals``, behind the past red's queue (``prev``:
    its last car's crossing, fast and slow; ``n_prev`` of its cars still to cross, :func:`past_queue`): how many cars
    hold this car up, when it can cross behind them, when the last of them crosses at the fast and at the slow end of
    the discharge (:attr:`QueueEstimate.clear_s`) and, where they wait for the red's end, the same counted from it
    (:attr:`QueueEstimate.after_red_s`)."""
    if unseen:
        arrivals = np.concatenate((np.full(unseen, max(start, 0.0)), arrivals))
    # the discharge, slow and fast, counted from the red's end (one whose end is unknown: from after every arrival)
    ref = end if math.isfinite(end) else max(max(start, 0.0), float(arrivals.max(initial=-math.inf))) + 1.0
    crossed, holding = _discharged(arrivals, start, ref, model.startup_s, model.headway_s, prev[1])
    crossed_fast, holding_fast = _discharged(arrivals, start, ref, model.fast_startup_s, model.fast_headway_s, prev[0])
    waits = holding > 0 and bool(np.any((start <= arrivals) & (arrivals < ref)))  # the queue waits for the red's end
    after_red = (crossed_fast - ref, crossed - ref) if waits else None
    if waits:
        crossed, crossed_fast = crossed - ref + end, crossed_fast - ref + end
    holding += n_prev
    free = max(crossed + model.headway_s, 0.0) if holding else 0.0
    clear = (max(crossed_fast, 0.0) if holding_fast or prev[0] > 0.0 else 0.0, max(crossed, 0.0) if holding else 0.0)
    return holding, free, clear, after_red


def count_law(mean: float, cap: int, levels: Sequence[float]) -> tuple[tuple[int, float], ...]:
    """A Poisson count of mean ``mean``, never more than ``cap``, at ``levels``: the count at each (the fewest ``k``
    with :math:`P(N \\le k) \\ge q` at level ``q``: 0 at level 0), each with the probability that the count is at
    or below it (1 at ``cap``), fewest first. Arrivals at a line are Poisson to first order (and SUMO's flows are):
    the cars not connected arriving over a red are not their mean, rounded, but this many with this chance (issue 28:
    14 cars traced standing where 7.5 were expected). () where ``mean`` is 0: no such cars.

    Examples
    --------
    Mean 2 at the levels of 4 equally likely timings (1/8, 3/8, 5/8, 7/8): P(N <= k) = e^-2 (1, 3, 5, 19/3, 7) =
    0.135, 0.406, 0.677, 0.857, 0.947 for k = 0-4: counts 0, 1, 2, 4 (3 cars, 0.857, fall short of 7/8); at most 2
    cars fit: 0, 1, 2 (P 1). Mean 7.5 at 1/40 (the lowest of 20 timings): P(N <= 2) = e^-7.5 (1 + 7.5 + 28.125) = 0.020,
    P(N <= 3) = 0.059: 3 cars.

    >>> [(k, round(p, 3)) for k, p in count_law(2.0, 10, (0.125, 0.375, 0.625, 0.875))]
    [(0, 0.135), (1, 0.406), (2, 0.677), (4, 0.947)]
    >>> [count_law(2.0, 10, (q,))[0][0] for q in (0.0, 0.1, 0.135, 0.14, 0.5, 0.9, 0.975)]
    [0, 0, 0, 1, 2, 4, 5]
    >>> [(k, round(p, 3)) for k, p in count_law(2.0, 2, (0.125, 0.375, 0.625, 0.875))], count_law(7.5, 20, (0.025,))[0][0]
    ([(0, 0.135), (1, 0.406), (2, 1.0)], 3)
    """
    if mean <= 0.0:
        return ()
    k, p = 0, math.exp(-mean)
    cdf, out = p, []
    for q in sorted(levels):  # the fewest k with P(N <= k) >= q, k <= cap
        while cdf < q and k < cap:
            k += 1
            p *= mean / k
            cdf += p
        if not out or out[-1][0] != k:
            out.append((k, 1.0 if k == cap else cdf))
    return tuple(out)


def _levels(light: LightView) -> tuple[float, ...]:
    """The levels of ``light``'s equally likely timings (its own, or :func:`~advisory.advice.mixture.implied_timings`'
    :data:`~advisory.advice.mixture.IMPLIED_TIMINGS`): ``(k + 1/2) / n`` for the k-th of n (:func:`count_law`,
    :func:`apply`). [-]"""
    n = len(light.scenario_red_windows_s) if light.scenario_red_windows_s else IMPLIED_TIMINGS
    return tuple((k + 0.5) / n for k in range(n))


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
    return _discharged(np.asarray(arrivals, dtype=float), start, end, startup_s, headway_s, crossed)


@njit(cache=True)
def _discharged(arrivals: np.ndarray, start: float, end: float, startup_s: float, headway_s: float, crossed: float) -> tuple[float, int]:
    """:func:`_discharge` compiled, ``arrivals`` an array (a fix runs it over every car ahead, twice a light)."""
    holding = 0
    for a in arrivals:  # (max() spelled out: max(x, y) is y where y > x, else x)
        if start <= a < end:  # waits for the red's end
            at_end, behind = end + (startup_s if holding == 0 else 0.0), crossed + headway_s
            crossed = behind if behind > at_end else at_end
        elif a == 0.0 and start > 0.0:  # standing on a green: a queue already discharging, one car a headway
            behind = crossed + headway_s
            crossed = behind if behind > 0.0 else 0.0
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


_ADVISOR_DEFAULTS = AdvisorParams()  # (frozen: one for every call of :func:`plan_drive_s` given none)
NORMAL_MODE, STOP_MODE = -1, -2
"""Advised motions besides the kinematics' speed changes (:data:`~advisory.advice.kinematics.MODE_CODES`), for
:func:`plan_of`: "drive normally" (speeding up to the limit as the regular driver does) and "prepare to stop"."""


def plan_of(advice: Advice, limit_mps: float) -> tuple[float, int]:
    """The motion ``advice`` asks of the car it is given to, as :func:`behind_s` takes it for a car ahead: the target
    speed [m/s] and how the car gets there (a code of :data:`~advisory.advice.kinematics.MODE_CODES`, the mode the
    advisor plans that action in, :data:`~advisory.advice.kinematics.KEEP_MODES`; :data:`NORMAL_MODE`: "drive
    normally", to ``limit_mps``; :data:`STOP_MODE`: a stop at its next line); ``(nan, 0)`` where the advice asks no
    motion (follow the car in front, no data, "red light ahead": the car holds its speed now, as before).

    Examples
    --------
    >>> plan_of(Advice("slow_down", "green_wave", 8.0), 24.6), plan_of(Advice("none", "tight_green"), 24.6)
    ((8.0, 2), (24.6, -1))
    >>> plan_of(Advice("stop", "red"), 24.6), plan_of(Advice("none", "queue"), 24.6)
    ((0.0, -2), (nan, 0))
    """
    if advice.action == "stop":
        return 0.0, STOP_MODE
    if advice.action in KEEP_MODES and advice.target_speed_mps is not None:
        return min(advice.target_speed_mps, limit_mps), MODE_CODES[KEEP_MODES[advice.action]]
    if advice.action == "resume" or (advice.action == "none" and advice.reason == "tight_green"):
        return limit_mps, NORMAL_MODE
    return math.nan, 0


def plan_drive_s(distance_m: float, v_mps: float, plan_mps: float = math.nan, plan_mode: int = 0, params: AdvisorParams | None = None,
                 accel_mps2: float = 2.0) -> float:  # fmt: skip
    """Time for a car at ``v_mps`` to cover ``distance_m`` in its advised motion (:func:`plan_of`): the speed change
    of the advisor's own model of that action (:func:`~advisory.advice.kinematics.crossing_time_s`, no reaction: the
    advice is the car's latest, which it follows already), then the target held; "drive normally" speeding up to the
    limit at ``accel_mps2`` (:func:`normal_drive_s`); a stop never covers it (inf); with no plan (NaN) or backwards (a
    distance already covered) at its speed now. [s]

    Examples
    --------
    At 15 m/s, told to slow to 8 m/s (gently, 1.5 m/s², then hold it): 53.67 m in 4.67 s, the 46.33 m left of 100 m
    at 8 m/s in 5.79 s: 10.46 s, where holding 15 m/s takes 6.67 s.

    >>> round(plan_drive_s(100.0, 15.0, 8.0, MODE_CODES["brake"]), 2), round(plan_drive_s(100.0, 15.0), 2)
    (10.46, 6.67)
    >>> round(plan_drive_s(100.0, 10.0, 20.0, NORMAL_MODE), 2), plan_drive_s(100.0, 10.0, 0.0, STOP_MODE), plan_drive_s(-5.0, 10.0, 0.0, STOP_MODE)
    (6.25, inf, -0.5)
    """
    if distance_m <= 0.0 or plan_mps != plan_mps:
        return distance_m / v_mps
    if plan_mode == STOP_MODE:
        return math.inf
    if plan_mode == NORMAL_MODE:
        return normal_drive_s(distance_m, v_mps, plan_mps, accel_mps2)
    return float(crossing_time_s(distance_m, v_mps, float(plan_mps), params or _ADVISOR_DEFAULTS, MODE_NAMES[int(plan_mode)], 0.0))


def behind_s(line_m: float, ahead: Sequence[tuple[float, ...]], model: QueueModel | None = None, params: AdvisorParams | None = None) -> float:
    r"""The earliest instant this car can cross a line ``line_m`` ahead behind the cars ahead of it (``ahead``: how far
    ahead of this car [m] and speed [m/s], each, and where the service advised it its advised motion, ``(plan_mps,
    plan_mode)`` of :func:`plan_of`), 0 where none holds it. [s]

    Each car ahead drives as it was advised (:func:`plan_drive_s`: its target reached as the advisor plans that
    action, "drive normally" at the regular driver's rate, a stop at its line never crossing it) or, not advised
    (not connected to this service, following the car in front, no fresh advice), holds its speed now (the connected
    cars traced ahead of those that entered a red were slowing for the next light's queue, not speeding up to the limit
    as :func:`estimate` has cars arriving at a queue do), and this car follows it as in Newell's simplified car
    following [1]_: its trajectory is the one ahead shifted by a space ``jam_spacing_m`` and a time, the headway
    ``headway_s`` or the shorter one it keeps now (its gap less the jam spacing over the speed of the car ahead: a
    platoon at the limit 1.2 s apart stays so), so its front reaches the line that time after the car ahead is
    ``jam_spacing_m`` past it (or was: a car ahead already past the line holds it for less than that time). Cars
    standing (slower than ``queued_mps``) do not count here (a queue: :func:`estimate`). ``params``: the advisor's
    rates of those motions (default :class:`~advisory.advice.views.AdvisorParams`).

    .. math:: t = \max\big(0, \max_k \; T_k(d - a_k + \delta) + \min(\tau, (a_k - \delta) / v_k)\big)

    with :math:`d` the line's distance, :math:`a_k` how far ahead car :math:`k` is, :math:`v_k` its speed and
    :math:`T_k(x)` the time it takes to drive :math:`x` (:math:`x / v_k` holding its speed), :math:`\delta` the jam
    spacing and :math:`\tau` the headway.

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

    A car 37.5 m ahead at 15 m/s (2 s), told to slow to 8 m/s (:func:`plan_drive_s`: 53.67 m in 4.67 s, then 16.33 m at
    8 m/s in 2.04 s) is 7.5 m past a line 100 m ahead in 6.71 s, and this car crosses 2 s after it, 8.71 s from now;
    holding 15 m/s, the 70 m in 4.67 s, 6.67 s.

    >>> round(behind_s(100.0, [(37.5, 15.0, 8.0, MODE_CODES["brake"])]), 2), round(behind_s(100.0, [(37.5, 15.0)]), 2)
    (8.71, 6.67)
    """
    model = model or QueueModel()
    out = 0.0
    for car in ahead:
        ahead_m, v_mps = car[0], car[1]
        if ahead_m > 0.0 and v_mps >= model.queued_mps:
            lag_s = min(model.headway_s, max(ahead_m - model.jam_spacing_m, 0.0) / v_mps)
            to_go_m = line_m - ahead_m + model.jam_spacing_m
            plan_mps, plan_mode = (car[2], car[3]) if len(car) > 2 else (math.nan, 0)
            if plan_mode == STOP_MODE and ahead_m >= line_m:  # told to stop at a line past this one
                plan_mps = math.nan
            out = max(out, plan_drive_s(to_go_m, v_mps, plan_mps, plan_mode, params, model.drive_accel_mps2) + lag_s)
    return out


def unseen_behind(arrivals_vps: float | None, connected_share: float, from_s: float, to_s: float,
                  view_s: float = math.inf) -> tuple[float, float]:  # fmt: skip
    """The cars expected to reach a line behind this car between ``from_s`` and ``to_s`` from now that the service does
    not know as probes [-], two counts: the ones not connected, ``(1 - connected_share) x arrivals_vps x (to_s -
    from_s)``, and the connected ones not on the route yet (Poisson arrivals at the flow's rate, each share of them alike): the service
    sees a trip only from where it advises it on (the approach's start), and a connected car that reaches the line later
    than ``view_s`` from now (the time a car at the limit takes from that start to the line) is still upstream of it now,
    ``connected_share x arrivals_vps x (to_s - max(from_s, view_s))``. ``view_s`` inf: every connected car behind is seen.

    Traced in SUMO (paper_s400 fixed 600 veh/h, 50 %, seed 3, docs/history/TRAFFIC.md): a car told to slow 224 m before a light
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
    return followers_held_up(obs, probes, free_at_s, model, arrivals_vps, connected_share, view_m)[0]


def followers_held_up(
    obs: Observation, probes: Sequence[Probe], free_at_s: float = 0.0, model: QueueModel | None = None, arrivals_vps: float | None = None,
    connected_share: float = 1.0, view_m: float = math.inf,
) -> tuple[float, Sequence[Probe]]:
    """:func:`followers` and :func:`held_up` (as :class:`Probes`) together, of one pass over ``probes`` (a fix's estimate
    needs both)."""
    model = model or QueueModel()
    if not obs.lights:
        return 0.0, ()
    known, window, mine = _held_up(obs, probes, free_at_s, model)
    d, lim = obs.lights[0].distance_m, max(obs.speed_limit_mps, 1.0)
    return float(len(known) + sum(unseen_behind(arrivals_vps, connected_share, mine, mine + window, (d + view_m) / lim))), known


def held_up(obs: Observation, probes: Sequence[Probe], free_at_s: float = 0.0, model: QueueModel | None = None) -> tuple[Probe, ...]:
    """The connected cars among ``probes`` that :func:`followers` counts, nearest first.

    Examples
    --------
    >>> from advisory.advice.views import LightView
    >>> held_up(Observation(20.0, 20.0, (LightView(1, 200.0),)), [Probe(-100.0, 20.0), Probe(-30.0, 20.0), Probe(10.0, 20.0)])
    (Probe(ahead_m=-30.0, speed_mps=20.0),)
    """
    return tuple(followers_held_up(obs, probes, free_at_s, model)[1])


def _held_up(obs: Observation, probes: Sequence[Probe], free_at_s: float, model: QueueModel) -> tuple[Probes, float, float]:
    """:func:`held_up`, the window [s] after this car's normal arrival at the next line that it counts them in, and
    that arrival [s]."""
    d, lim = obs.lights[0].distance_m, max(obs.speed_limit_mps, 1.0)
    mine = normal_drive_s(d, obs.speed_mps, lim, model.drive_accel_mps2)
    window = max(free_at_s - mine, 0.0) + model.follow_gap_s
    probes = Probes.of(probes)
    behind = probes.where(probes.ahead_m < 0.0)
    known = behind.where(normal_drives_s(d - behind.ahead_m, behind.speed_mps, lim, model.drive_accel_mps2) - mine < window)
    return known.where(np.lexsort((known.speed_mps, -known.ahead_m))), window, mine


def _held_until(windows, until_s: float):
    """``windows`` (relative, sorted, disjoint) with the line also closed from now until ``until_s``: their union.

    Examples
    --------
    >>> _held_until(((0.0, 10.0), (40.0, 70.0)), 15.0), _held_until(((5.0, 10.0),), 3.0), _held_until(((0.0, 10.0),), 5.0)
    (((0.0, 15.0), (40.0, 70.0)), ((0.0, 3.0), (5.0, 10.0)), ((0.0, 10.0),))
    """
    if windows is None or until_s <= 0.0:
        return windows
    spans = sorted([(0.0, until_s)] + [(0.0 if 0.0 > a else a, b) for a, b in windows if b > 0.0])  # (a fix makes dozens:
    merged: list[tuple[float, float]] = []  # max() and the last span's indexing spelled out)
    start, end = spans[0]
    for a, b in spans[1:]:
        if a <= end:
            if b > end:
                end = b
        else:
            merged.append((start, end))
            start, end = a, b
    merged.append((start, end))
    return tuple(merged)


def _held_untils(windows):
    """:func:`_held_until` of ``windows`` as a function of ``until_s``, the same tuples, for a light's views and
    timings that share windows (an exact light's 20 timings: one): the spans from now are clamped and swept once, and
    each instant merges the first of them into its span from now and takes the sweep of the rest as it was.

    Examples
    --------
    >>> held = _held_untils(((-3.0, 27.0), (57.0, 87.0)))
    >>> [held(u) for u in (0.0, 10.0, 30.0, 60.0)] == [_held_until(((-3.0, 27.0), (57.0, 87.0)), u) for u in (0.0, 10.0, 30.0, 60.0)]
    True
    """
    if windows is None:
        return lambda until_s: None
    spans = [(0.0 if 0.0 > a else a, b) for a, b in windows if b > 0.0]
    if spans != sorted(spans) or any(a != a or b != b for a, b in spans):  # (not as a light's windows are: as it was)
        return lambda until_s: _held_until(windows, until_s)
    rest: list[tuple] = [()] * (len(spans) + 1)  # rest[j]: the sweep of spans[j:] on its own
    for j in range(len(spans) - 1, -1, -1):
        (start, end), after = spans[j], rest[j + 1]
        while after and after[0][0] <= end:  # the runs after it that it reaches
            if after[0][1] > end:
                end = after[0][1]
            after = after[1:]
        rest[j] = ((start, end), *after)

    def held(until_s: float):
        if until_s <= 0.0:
            return windows
        first = bisect_left(spans, (0.0, until_s))  # the spans before (0, until_s) as sorted() puts it (from 0, ending sooner)
        start, end, j = spans[0][0] if first else 0.0, until_s, first
        while j < len(spans) and spans[j][0] <= end:
            if spans[j][1] > end:
                end = spans[j][1]
            j += 1
        return ((start, end), *rest[j])

    return held


def apply(obs: Observation, est: QueueEstimate) -> Observation:
    """``obs`` as the car meets the lights in traffic: each line closed to this car until the queue in front of it has
    crossed, a distribution between the fast and the slow discharge (``est.clear_s``), not one instant:

    * each of the light's equally likely timings (``LightView.scenario_red_windows_s``; an exact light's windows in
      each, :data:`~advisory.advice.mixture.IMPLIED_TIMINGS` of them) is closed until the clearing at its own level,
      uniform from fast to slow, in the timings' order (a timing whose red ends early meets the fast discharge too),
      for the count of cars not connected at that level (``est.law``: the k-th of n timings the fewest cars a Poisson
      count of the estimate's mean stays at or below with probability (k + 1/2) / n; comonotone, a long queue with a
      slow discharge: with 20 timings the clearing is one variable's quantiles, and both lengthen it), counted from
      that timing's own red end where the queue waits for the red (``est.after_red_s``): the choice
      under uncertain timing (:mod:`advisory.advice.choice`) prices a plan on each, so it neither plans into a queue
      still standing nor hangs back for one already gone (traced in SUMO: one conservative instant, the latest red end
      plus the slow discharge, in every timing, held advised cars and the lane behind them seconds after the line was
      free);
    * the sure view (``red_windows_s``) until the fast clearing of the mean count (rounded): before it the queue
      stands, and no plan reaches it there (the hard constraint, in every timing; at the law's fewest instead, 7th
      Street fixed 600 veh/h lost 0.1-0.7 points of saving and its advised cars stopped twice as often, docs/TRAFFIC.md);
      the likely view until the middle one, the late view until the slow one of the slowest timing's count.

    The advisor adds its margin after each window's end (``green_margin_s``): this car's own headway behind the queue's
    last car. An exact light with a queue ahead is thus planned by the choice (its timings are the queue's)."""
    n = len(obs.lights)
    lights = tuple(_held(lv, clear, after, law) for lv, clear, after, law in zip(obs.lights, est.clear_s or ((0.0, 0.0),) * n,
                                                                              est.after_red_s or (None,) * n, est.law or ((),) * n))  # fmt: skip
    return replace(obs, lights=lights, followers=est.followers)


def _held(light: LightView, clear_s: tuple[float, float], after_red_s: tuple[float, float] | None, law=()) -> LightView:
    """``light`` closed until the queue has crossed, at each level of its discharge and of its count (:func:`apply`)."""
    mean = (1.0, clear_s, after_red_s)  # the mean count, rounded: the sure view's
    law = law or (mean,)
    if all(slow <= 0.0 and fast <= 0.0 for _, (fast, slow), _ in (*law, mean)):
        return light

    made: dict = {}  # windows -> (_held_untils, first red): the views and timings share windows (an exact light's: all)

    def until(windows, level, rows=law):  # the count at this level (the law's tail past the slowest timing's: no view's)
        _, (fast, slow), after = rows[0] if len(rows) == 1 else next((row for row in rows if row[0] >= level), rows[-1])
        known = made.get(id(windows))
        if known is None:
            known = made[id(windows)] = (_held_untils(windows), _first_red_of(windows))
        held, red = known
        if after is not None and red is not None and math.isfinite(red[1]):  # counted from this view's own red end
            return held(red[1] + after[0] + (after[1] - after[0]) * level)
        return held(fast + (slow - fast) * level if math.isfinite(slow) else (fast if level == 0.0 else slow))

    timings = light.scenario_red_windows_s or implied_timings(light)
    return replace(light, red_windows_s=until(light.red_windows_s, 0.0, (mean,)), likely_red_windows_s=until(light.likely_red_windows_s, 0.5),
                   late_red_windows_s=until(light.late_red_windows_s, 1.0),
                   scenario_red_windows_s=tuple(until(w, q) for w, q in zip(timings, _levels(light))))  # fmt: skip


def _first_red_of(windows) -> tuple[float, float] | None:
    """The red of ``windows`` (relative, sorted; None: no view) still to end first."""
    if windows is None:
        return None
    for a, b in windows:  # a loop, not next() over a generator: a fix makes dozens
        if b > 0.0:
            return a, b
    return None


def normal_drive_s(distance_m: float, v_mps: float, limit_mps: float, accel_mps2: float) -> float:
    """Time to a line ``distance_m`` ahead speeding up at once at ``accel_mps2`` to the limit, then holding it. [s]

    Examples
    --------
    >>> round(normal_drive_s(100.0, 0.0, 20.0, 2.0), 2), round(normal_drive_s(100.0, 20.0, 20.0, 2.0), 2)
    (10.0, 5.0)
    """
    v = 0.0 if 0.0 > v_mps else v_mps  # max(v_mps, 0.0) and max(limit_mps, 0.1), without the calls (a fix makes hundreds)
    lim = 0.1 if 0.1 > limit_mps else limit_mps
    if v >= lim:
        return distance_m / v
    d_acc = (lim * lim - v * v) / (2.0 * accel_mps2)
    if distance_m <= d_acc:
        return (math.sqrt(v * v + 2.0 * accel_mps2 * distance_m) - v) / accel_mps2
    return (lim - v) / accel_mps2 + (distance_m - d_acc) / lim


_normal_drive_compiled = njit(cache=True)(normal_drive_s)  # (the same function compiled, for the loop over many cars)


@njit(cache=True)
def normal_drives_s(distance_m: np.ndarray, v_mps: np.ndarray, limit_mps: float, accel_mps2: float) -> np.ndarray:
    """:func:`normal_drive_s` of many cars at once (their distances and speeds as arrays), compiled: the same operations
    in the same order, so the same floats (``tests/test_queue.py``), in a few microseconds for hundreds of cars. [s]"""
    out = np.empty(len(distance_m))
    for k in range(len(distance_m)):
        out[k] = _normal_drive_compiled(distance_m[k], v_mps[k], limit_mps, accel_mps2)
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
