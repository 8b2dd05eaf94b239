"""The virtual driver of a connected car in SUMO: follows the service's advice, sees the lights, stays in traffic.

The same person as :func:`advisory.drivers.closed_loop.simulate`'s driver, stepped by SUMO instead of stepping
itself: it asks once a second (the caller posts the car's fix to the service and hands the advice back), acts on
it after a 1 s reaction, tracks an advised speed at comfortable rates (1.5 m/s² up and down, firm 3 m/s² for
"brake to", a lift-off at the car's own coast-down), drifts up 1 m/s below 25 mph, lifts off for "Red light ahead.",
prepares to stop and stops at the line for "stop". Its own eyes decide before each line where the advisor's firm
3 m/s² still stops the car (at the regular driver's decision point, or farther out when faster), on the light's real
colour (SUMO's) and the phone's display of the countdowns (:func:`advisory.drivers.closed_loop.belief` of the views
the advice came from): it brakes for a light that will be red on arrival at its speed or whose red can begin before
it is over the line, never slows down so much that a red catches it after deciding to go, waits at a line still red,
and stops for an amber where 3 m/s² suffice (else it clears it: ITE's yellow interval is timed for that rate). It
sees the car in front: it slows for a queue's standing or crawling tail itself (:func:`follow_mps` at 3 m/s²), stops
behind a car braking harder than it can follow at once at the rate that suffices (:func:`stop_behind_mps2`), and
behind a car that sets its pace it judges a green by when it gets to the line behind it. A driver never plans a
braking harder than 3 m/s² (the issue's hard brake: 3.5 m/s²); a car braking in front of it may ask more of it.

:meth:`AdvisedDriver.command` returns the speed the car should have one step later, or None where neither the advice
nor the driver's eyes ask anything (no speed advised, "drive normally", before the zone, past the last light): SUMO's
own driver then drives, the same person the unadvised run has. SUMO applies a commanded speed within the vehicle
type's acceleration and braking and below its car-following safe speed (SUMO's default speed mode, every check on,
but for its own stop at a red or amber while the driver clears an amber it chose to go through: ``clearing``): the
car never drives into the one ahead, whatever it was advised.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from advisory.advice.kinematics import coast_decel_mps2
from advisory.advice.views import Advice, AdvisorParams, LightView
from advisory.advice.queue import QueueModel
from advisory.drivers.closed_loop import DriverModel, _silent, _time_to_cover_s, amber_stops, belief
from advisory.drivers.regular import time_to_cover_s
from advisory.signals import TimelineSignal

TRAFFIC_DRIVER = replace(DriverModel(), amber="stop")
"""Follows advice as the closed loop's driver does; on amber it stops where it can stop at 4 m/s², as SUMO's drivers
of :data:`ecodrive.traffic.network.VTYPE` do (SUMO treats an amber as a red for a car that can stop with its decel)."""


@dataclass(frozen=True, slots=True)
class LightNow:
    """The next light as the driver's eyes see it: its stop line, red or amber now, and (amber) when red begins."""

    index: int  # which light of the corridor (0-based)
    station_m: float
    red: bool
    amber: bool = False
    red_at_s: float = np.inf  # amber: the instant its red begins (SUMO's program) [s]
    shows_amber: bool = True  # its program shows an amber before each red (False: some green goes straight to red)


@dataclass
class AdvisedDriver:
    """One connected car's driver (see the module docstring). Times on one axis (the simulation's Unix seconds)."""

    stop_lines_m: tuple[float, ...]
    advisor: AdvisorParams = field(default_factory=AdvisorParams)
    vid: str = ""  # the car (SUMO's id)
    model: DriverModel = TRAFFIC_DRIVER
    pending: list = field(default_factory=list)  # (when acted on, advice, its stop line)
    active: Advice | None = None
    stop_line_m: float = np.inf
    shown: dict = field(default_factory=dict)  # light index -> TimelineSignal | None: the display
    green_since: dict = field(default_factory=dict)
    committed: set = field(default_factory=set)
    braking_for: int | None = None
    surprised: dict = field(default_factory=dict)
    amber_seen: dict = field(default_factory=dict)
    amber_stop: set = field(default_factory=set)
    amber_go: set = field(default_factory=set)
    overrides: int = 0
    surprises: int = 0
    controlling: bool = False
    last_v_mps: float = np.inf  # the speed at the previous step (a car going slower than it was is being held back)
    clearing: bool = False  # going on through an amber, or towards a red that ends first: the simulator must not stop it there

    def heard(self, t_s: float, x_m: float, advice: Advice, views: dict[int, LightView]) -> None:
        """The advice for the fix at ``t_s`` (station ``x_m``) and the views it came from: light index -> view."""
        for n, line in enumerate(self.stop_lines_m):
            d = belief(views.get(n), t_s, line) if line > x_m else None
            self.shown[n] = d
            if d is not None and (d.is_red(t_s) or self.green_since.get(n, np.inf) > t_s):
                self.green_since[n] = d.next_green_start_s(t_s) if d.is_red(t_s) else t_s
        line = min((s for s in self.stop_lines_m if s > x_m + 1e-9), default=np.inf)
        self.pending.append((t_s + self.model.reaction_s, advice, line))

    def command(self, t_s: float, x_m: float, v_mps: float, dt_s: float, v_lim_mps: float, light: LightNow | None,
                leader: tuple[float, ...] | None = None) -> float | None:  # fmt: skip
        """The speed one step (``dt_s``) later, or None: SUMO's own driver drives (see the module docstring).

        ``leader``: the car in front as the driver sees it, (gap beyond the standstill gap [m], speed [m/s][,
        acceleration [m/s²]]), or None. Where that car stands or crawls (a queue's tail, slower than
        :data:`QUEUED_MPS`) or is braking (its speed falling faster than :data:`BRAKING_MPS2`: its brake lights), and
        keeping behind it at the advisor's firm braking (3 m/s²; SUMO's car following brakes with the car's 4 m/s²,
        late) asks for less than the speed the driver would drive (:func:`follow_mps`), the driver slows down itself,
        at most at that rate, before SUMO's car following would brake hard (traced: a queue standing 60 m ahead of a
        car told to coast at 21 m/s, SUMO braked at 3.6 m/s²; a car 1.2 s behind one braking at 4 m/s² for a queue,
        SUMO braked at 3.55 m/s²; a car told to stop, 136 m behind one braking from 8.7 m/s into a standing queue,
        seen only once that one was under 2 m/s: 3.51 m/s²). Behind a car that holds or gains speed SUMO's car
        following alone keeps the gap (slowing for every slower car cost 5 points of saving at 600 veh/h, every car
        connected). Behind a car braking harder than that rate, where the driver's own stop at it after its reaction
        no longer ends behind where that car stops, it brakes at once at the constant rate that does
        (:func:`stop_behind_mps2`; traced: 0.95 s behind a car SUMO stopped for an amber at 4 m/s², the safe speed
        tracked at 3 m/s² fell behind, and SUMO braked the car at 3.56 m/s²). Where that car sets the pace
        (:data:`HELD_MPS`), the driver judges a green by when it reaches the line behind it (:func:`_led_arrival_s`).
        A driver that has decided to cross the next line before its red and can no longer stop for it at the firm rate
        does not slow for brake lights ahead (SUMO's car following keeps the gap): slowed so, it could neither stop
        nor make the green (traced: 0.3 s into a red that no amber announced, behind a car 74 m ahead slowing for the
        next light's queue)."""
        self.clearing = False
        firm = self.advisor.firm_decel_mps2
        v_follow = np.inf if leader is None else follow_mps(leader[0], leader[1], firm, self.model.reaction_s)
        cmd = self._command(t_s, x_m, v_mps, dt_s, v_lim_mps, light, leader[:2] if v_follow <= v_mps + HELD_MPS else None)
        braking = leader is not None and len(leader) > 2 and leader[2] < -BRAKING_MPS2
        if braking and self._past_stopping(x_m, v_mps, light):
            braking = False  # going for a green it can no longer stop for: not slowed into its red (above)
        due = stop_behind_mps2(leader[0], leader[1], -leader[2], v_mps, firm, self.model.reaction_s) if braking else 0.0
        if due > 0.0 and (cmd is None or cmd > v_mps - due * dt_s):  # behind a car braking: its stop behind that car's, at once
            self.controlling = True
            return max(v_mps - min(due, self.model.regular().brake_max_mps2) * dt_s, 0.0)
        if leader is None or (leader[1] >= QUEUED_MPS and not braking) or v_follow >= v_mps - FOLLOW_TOL_MPS or (cmd is not None and cmd <= v_follow):
            return cmd
        self.controlling = True
        return max(v_follow, v_mps - firm * dt_s, 0.0)

    def _past_stopping(self, x_m: float, v_mps: float, light: LightNow | None) -> bool:
        """Whether the car has decided to cross ``light`` before its red (committed, the light not red) and can no
        longer stop before its line at the firmest braking it plans a stop with."""
        if light is None or light.red or light.index not in self.committed:
            return False
        rules = self.model.regular()
        planned = min(self.advisor.firm_decel_mps2, rules.brake_max_mps2)  # as :meth:`_command` plans a stop
        return v_mps * v_mps > 2.0 * planned * max(light.station_m - x_m - rules.stop_gap_m, 1e-6)

    def _command(self, t_s: float, x_m: float, v_mps: float, dt_s: float, v_lim_mps: float, light: LightNow | None,
                 led: tuple[float, float] | None) -> float | None:  # fmt: skip
        """:meth:`command` before the car in front is looked at, but for ``led``: its (gap, speed) where it sets the pace."""
        adv, drv = self.advisor, self.model
        rules = drv.regular()
        planned = min(adv.firm_decel_mps2, rules.brake_max_mps2)  # the firmest braking the driver plans a stop with
        while self.pending and self.pending[0][0] <= t_s + 1e-9:
            _, new, line = self.pending.pop(0)
            if not _silent(new):
                self.active, self.stop_line_m = new, line
        active, x, v, t = self.active, x_m, v_mps, t_s
        slowing, self.last_v_mps = led is not None and v < self.last_v_mps - 1e-6, v  # held back by the car in front
        free = False  # nothing asked for: SUMO's driver drives unless the eyes below say otherwise
        if active is not None and active.action == "none" and active.reason == "red_ahead":
            v_cmd = min(max(v, adv.min_cruise_speed_mps), v_lim_mps)
        elif active is None or active.target_speed_mps is None or active.action in ("none", "resume"):
            v_cmd, free = v_lim_mps, True
        elif active.action == "stop":
            v_cmd = 0.0 if x < self.stop_line_m else v_lim_mps
            free = x >= self.stop_line_m
        else:
            v_cmd = active.target_speed_mps + (drv.drift_mps if active.target_speed_mps < drv.low_speed_mps else 0.0)
            v_cmd = min(max(v_cmd, 0.0), v_lim_mps)
        rate_up, rate_down = drv.accel_mps2, drv.decel_mps2
        if active is None or active.target_speed_mps is None or active.action in ("none", "resume", "stop"):
            rate_up = rules.accel_mps2
        if active is not None and active.action == "brake_to":
            rate_down = adv.firm_decel_mps2
        if active is not None and active.action == "stop" and x < self.stop_line_m:
            to_line_m = _stop_room_m(self.stop_line_m - x, v, rules.stop_gap_m, rules.brake_max_mps2)
            at_gap = to_line_m == self.stop_line_m - rules.stop_gap_m - x  # not already rolling into the gap
            # lift off while a comfortable stop at the line still fits after the step the lift-off takes (SUMO moves
            # the car v dt first: checked on the room now, a car lifting off at 2.0 m/s 1.5 m short of its stopping
            # point needed 3.7 m/s² a step later; 7th Street actuated 900 veh/h, every car connected, seed 1)
            if at_gap and v * v < 2.0 * drv.decel_mps2 * (to_line_m - v * dt_s):
                rate_down = coast_decel_mps2(v, adv.vehicle)
            else:
                rate_down = max(rate_down, min(v * v / (2.0 * max(to_line_m, 1e-6)), rules.brake_max_mps2))
        clearing = red_ends = False
        if light is not None:
            n = light.index
            dist = light.station_m - x
            room = dist - rules.stop_gap_m
            decision_m = max(rules.decision_distance_m(v_lim_mps), v * v / (2.0 * planned) + rules.stop_gap_m)
            red_now = light.red
            display: TimelineSignal | None = self.shown.get(n)
            if display is None:
                green_at, next_red = (np.inf, np.inf) if red_now else (t, np.inf)
            elif red_now and not display.is_red(t):
                green_at, next_red = np.inf, np.inf
            else:
                green_at = display.next_green_start_s(t) if red_now else t
                next_red = display.next_red_start_s(display.next_green_start_s(green_at)) if red_now or not display.is_red(t) else np.inf
            # when it reaches the line: at its speed, or, behind a car that sets the pace, behind that car and a
            # second later (the amber, the held-back rule and the decision judge alike: judged apart, a car held back
            # braked for one step and went on, to be stopped by SUMO at the line as the red began; a car clearing an
            # amber behind a slower one entered the red); the second only where that car sets the arrival, later than
            # its own drive (traced at 9a2b11c: behind a slow car past the line, an amber it cleared 0.93 s before the
            # red judged too short, braked at 3.48 m/s²; paper_s400 actuated 900 veh/h, 50 %, seed 5, ``main.124``)
            own = _arrival_s(dist, v, v_lim_mps, drv)
            behind = own if led is None else _led_arrival_s(dist, v, led[0], led[1], v_lim_mps, drv)
            arrival = t + behind + (drv.red_end_margin_s if behind > own + 1e-9 else 0.0)
            heeded_m = max(decision_m, v * v / (2.0 * drv.decel_mps2) + rules.stop_gap_m)
            amber = dist <= heeded_m and light.amber
            if amber and self.amber_seen.get(n) != light.red_at_s:
                self.amber_seen[n] = light.red_at_s
                short = arrival > light.red_at_s  # it would not clear the line before the red
                late = rules.amber == "stop" or short
                need = v * v / (2.0 * max(room, 1e-6))
                stopping = self.braking_for == n  # already stopping for this line by its own decision: it goes on
                # (at its hardest: an amber shorter than ITE's, or a stop begun, is braked hard, not run red)
                if amber_stops(late, False, need, planned) or amber_stops(short, stopping, need, rules.brake_max_mps2):
                    self.committed.discard(n)
                    self.amber_stop.add(n)
                    self.surprises += not stopping
                else:  # clears it: no braking until over the line
                    self.amber_stop.discard(n)
                    self.amber_go.add(n)
                    self.committed.add(n)
                    self.braking_for = None
            shown_green = display is not None and not display.is_red(t)
            waited = t - self.green_since.get(n, -np.inf) >= drv.reaction_s  # a reaction time since the display's green
            overdue = display is None or (shown_green and waited)
            # the last call (a red still red where a stop needs the firm rate) waits, as the surprise does, a reaction
            # time after the display's green began: SUMO shows a change at the step after its instant (traced: committed
            # at 98 m and 24.5 m/s to a red the display ended 0.5 s later, the last call came at once, the red still on
            # for that half step, and the driver braked at 3.54 m/s²; paper_s400 actuated 900 veh/h, 100 %, seed 2)
            overdue = overdue or (red_now and v_cmd > 0.0 and not (shown_green and not waited)
                                  and v * v >= 2.0 * drv.last_call_decel_mps2 * max(room - v * dt_s, 1e-6))  # fmt: skip
            if n in self.committed and red_now and self.surprised.get(n) is None and overdue:
                self.surprises += 1
                self.surprised[n] = t
                if v * v / (2.0 * max(room, 1e-6)) <= drv.emergency_decel_mps2:
                    self.committed.discard(n)
            if not red_now:
                self.surprised.pop(n, None)
            if amber and n in self.amber_stop and n not in self.committed:
                self.braking_for = n
            elif n in self.committed and red_now and v < drv.min_coast_mps and n not in self.amber_go:
                self.committed.discard(n)  # held to a crawl by the cars ahead on a red it meant to meet green: decide again
            elif (n in self.committed and n not in self.amber_go and not red_now and not light.amber and slowing
                  and next_red <= arrival and v * v / (2.0 * max(room, 1e-6)) <= planned):  # fmt: skip
                # held back by the car ahead after deciding to go, it no longer reaches the line a second before the red
                # it was shown: it stops while it still can (it drove on, and SUMO stopped it at the line at 22 m/s²,
                # paper_s400; or it crossed as the red began, 900 veh/h, seed 2)
                self.committed.discard(n)
                self.braking_for = n
                self.overrides += 1
            elif n not in self.committed and dist - v * dt_s <= decision_m:
                # at a light that shows no amber the eye cannot see a red coming: told to stop for it, the driver stops
                # where it can without braking hard (the closed loop's driver, the same person; traced: told "Prepare to
                # stop" 161 m out, its eye went on for a green it would have left 0.1 s before the red, and SUMO's car
                # following behind a slower car took it over the line 0.5 s into the red)
                # (a car at a crawl or standing decides by its eye: the "stop" it was told stays the active advice
                # while the next ones say nothing, and would hold it at the line through the green)
                told_stop = (active is not None and active.action == "stop" and self.stop_line_m == light.station_m and not light.shows_amber
                             and v > drv.min_coast_mps and v * v <= 2.0 * TOLD_STOP_MPS2 * max(room, 1e-6))  # fmt: skip
                if (red_now and (v <= 0.1 or green_at > arrival - drv.red_end_margin_s)) or next_red <= arrival or told_stop:
                    if self.braking_for != n and (active is None or active.action != "stop"):
                        self.overrides += 1
                    self.braking_for = n
                else:
                    self.committed.add(n)
                    self.braking_for = None
            if self.braking_for == n:
                hardest = drv.emergency_decel_mps2 if n in self.surprised else rules.brake_max_mps2
                self.controlling = True
                return _to_line_mps(v, room, dt_s, hardest, min(adv.min_cruise_speed_mps, v_lim_mps), drv.decel_mps2, rules.accel_mps2)
            elif n in self.committed:
                if red_now:
                    free = False
                    v_cmd = min(v_cmd, v)
                    if room <= v * dt_s:
                        v_cmd, rate_down = 0.0, min(v * v / (2.0 * max(dist - 0.05, 1e-3)), rules.brake_max_mps2)
                elif active is not None and active.action == "stop":
                    v_cmd, free = v_lim_mps, True
                if v_cmd < v and not free:
                    coasting = active is not None and active.action in ("coast", "ease_off", "cruise")
                    v_to = max(drv.coast_floor_frac * v_cmd, drv.min_coast_mps) if coasting else v_cmd
                    rate = coast_decel_mps2(v, adv.vehicle) if active is not None and active.action in ("ease_off", "cruise") else rate_down
                    if next_red <= t + _time_to_cover_s(dist, v, v_to, rate) + 1.0:
                        v_cmd = v
            clearing = n in self.amber_go and self.braking_for != n and not red_now
            # going on towards a red it has seen will end before it gets there: SUMO's own driver would brake for it at
            # 4 m/s² (it does not know the red ends; traced, paper_s400 fixed 300 / 0.5, seed 2); the driver's own last
            # call (a red still red where 3 m/s² are needed to stop) stays its guard
            red_ends = n in self.committed and self.braking_for != n and red_now
            if clearing:  # over the line before the red, whatever the advice (SUMO's own driver would stop here at 4 m/s²)
                v_cmd, free = max(v_lim_mps if free else v_cmd, v), False
        else:
            self.braking_for = None
        self.clearing = clearing or red_ends
        if self.braking_for is None and not free and active is not None and active.action in ("ease_off", "cruise") and v_cmd < v:
            rate_down = min(rate_down, coast_decel_mps2(v, adv.vehicle))
        if self.braking_for is None and not free and not clearing and active is not None and active.action == "coast" and v <= v_cmd + 0.05:
            if v > drv.min_coast_mps:
                v_cmd, rate_down = 0.0, coast_decel_mps2(v, adv.vehicle)
            elif light is not None and light.red:
                self.controlling = True
                room = light.station_m - x - rules.stop_gap_m
                return _to_line_mps(v, room, dt_s, rules.brake_max_mps2, min(adv.min_cruise_speed_mps, v_lim_mps), drv.decel_mps2, rules.accel_mps2)
            else:
                free = True
        self.controlling = not free
        if free:
            return None
        a = min(max((v_cmd - v) / dt_s, -rate_down), rate_up)
        return max(v + a * dt_s, 0.0)


BRAKING_MPS2 = 0.5
"""The car in front is braking where its speed falls faster than this (its brake lights; a lift-off slows an EV by
0.07-0.19 m/s² at 5-25 m/s): the driver keeps behind it at its own firm rate (:func:`follow_mps`), as behind a queue's
tail. (At 0.1 m/s², every coasting car in front counted: paper_s400 actuated 900 veh/h, 50 %, seed 4, advised time
+16.1 -> +36.5 %.) [m/s²]"""
LINE_GAP_M = 0.05
"""Where a driver past the point it meant to stop at (the regular driver's ``stop_gap_m`` before the line) stops:
this far before the line (SUMO's front on the line has not crossed it). [m]"""


def _stop_room_m(dist_m: float, v_mps: float, stop_gap_m: float, brake_max_mps2: float) -> float:
    """The room a driver stopping for a line ``dist_m`` ahead stops in: up to ``stop_gap_m`` before it, or, where that
    takes more than ``brake_max_mps2`` (the car already rolls into that gap), up to the line itself (:data:`LINE_GAP_M`)
    rather than braking harder (traced: a car rolling at 2 m/s 1.4 m before a red line, 7th Street actuated, was
    braked at 4 m/s² to a standstill). [m]

    Examples
    --------
    >>> _stop_room_m(50.0, 10.0, 1.0, 4.0), round(_stop_room_m(1.4, 1.97, 1.0, 4.0), 2)
    (49.0, 1.35)
    """
    room = dist_m - stop_gap_m
    return room if v_mps * v_mps <= 2.0 * brake_max_mps2 * max(room, 0.0) else max(dist_m - LINE_GAP_M, room)


TOLD_STOP_MPS2 = 3.5
"""Told to stop at a light that shows no amber, the driver stops where this braking suffices (the issue's hard brake:
braking harder is one). [m/s²]"""
FOLLOW_TOL_MPS = 0.1
"""The driver brakes for the car in front when it is this much faster than :func:`follow_mps` allows. [m/s]"""
QUEUED_MPS = QueueModel().queued_mps
"""A car in front slower than this stands or crawls in a queue: the driver slows for it itself. [m/s]"""
HELD_MPS = 0.5
"""The car in front sets the pace where :func:`follow_mps` allows at most this much more than the speed now. [m/s]"""


def follow_mps(gap_m: float, leader_mps: float, decel_mps2: float, reaction_s: float) -> float:
    r"""The fastest speed from which a driver reacting in ``reaction_s`` and braking at ``decel_mps2`` stops behind
    the car in front if that one brakes at the same rate: Krauss's safe speed [1]_ with the driver's comfortable
    braking instead of the vehicle's maximum. A driver at it never needs more than ``decel_mps2`` to stay behind a car
    whose speed does not drop faster than that; two cars at the same speed keep ``reaction_s`` between them. [m/s]

    .. math:: v = -b\tau + \sqrt{(b\tau)^2 + v_l^2 + 2 b g}

    ``gap_m``: beyond the standstill gap (SUMO's ``minGap``) [m]; ``leader_mps`` [m/s].

    References
    ----------
    .. [1] S. Krauss, "Microscopic modeling of traffic flow: investigation of collision free vehicle dynamics,"
       DLR, Köln, Rep. 98-08, 1998.

    Examples
    --------
    >>> round(follow_mps(100.0, 0.0, 1.5, 1.0), 2), round(follow_mps(24.6, 24.6, 1.5, 1.0), 2)
    (15.89, 24.6)
    """
    b = decel_mps2
    return float(-b * reaction_s + np.sqrt((b * reaction_s) ** 2 + leader_mps * leader_mps + 2.0 * b * max(gap_m, 0.0)))


def stop_behind_mps2(gap_m: float, leader_mps: float, leader_decel_mps2: float, v_mps: float, firm_mps2: float, reaction_s: float) -> float:
    r"""The braking due now behind a car that brakes harder than the driver's ``firm_mps2`` (a car braking no harder
    is :func:`follow_mps`'s, which assumes that rate: none due here): none (0) while a stop at ``firm_mps2`` after the
    driver's ``reaction_s`` still ends behind where that car stops if it goes on braking at ``leader_decel_mps2``
    (Gipps's safe condition [1]_ with that car's own braking, not the driver's), else the constant braking that stops
    the car there from now, at least ``firm_mps2``. Braking at once at that rate is the gentlest stop behind it; a
    driver that tracks Krauss's safe speed at ``firm_mps2`` instead (:func:`follow_mps`, which assumes the car in
    front brakes no harder) falls behind that speed as it falls behind a car braking at 4 m/s², and SUMO's car
    following then brakes it harder (traced at 3.56 m/s²). [m/s²]

    .. math:: b = \max\left(b_f, \frac{v^2}{2 (g + v_l^2 / 2 b_l)}\right) \text{ where }
              v \tau + \frac{v^2}{2 b_f} > g + \frac{v_l^2}{2 b_l}, \text{ else } 0

    ``gap_m``: beyond the standstill gap [m]; ``leader_mps`` [m/s]; ``leader_decel_mps2`` > 0 [m/s²]; ``v_mps`` [m/s].

    References
    ----------
    .. [1] P. G. Gipps, "A behavioural car-following model for computer simulation," Transp. Res. B, vol. 15, no. 2,
       pp. 105-111, 1981, doi:10.1016/0191-2615(81)90037-0.

    Examples
    --------
    >>> round(stop_behind_mps2(23.29, 24.59, 4.0, 24.39, 3.0, 1.0), 2)  # 0.95 s behind a car braking at 4 m/s²
    3.01
    >>> stop_behind_mps2(100.0, 24.59, 4.0, 24.39, 3.0, 1.0), round(stop_behind_mps2(45.0, 24.59, 4.0, 24.59, 3.0, 1.0), 2)
    (0.0, 3.0)
    >>> stop_behind_mps2(20.0, 15.0, 2.0, 20.0, 3.0, 1.0)  # a car slowing at 2 m/s²: Krauss's safe speed's
    0.0
    """
    room_m = gap_m + leader_mps * leader_mps / (2.0 * leader_decel_mps2)
    if leader_decel_mps2 <= firm_mps2 or v_mps * reaction_s + v_mps * v_mps / (2.0 * firm_mps2) <= room_m:
        return 0.0
    return max(firm_mps2, v_mps * v_mps / (2.0 * max(room_m, 1e-6)))


def _arrival_s(dist_m: float, v_mps: float, v_lim_mps: float, drv: DriverModel) -> float:
    """When a driver deciding at the decision point reaches a line ``dist_m`` ahead: at its speed; a car slower than
    ``drv.min_coast_mps`` (pulling away in a queue, or standing) drives on to it at ``drv.accel_mps2`` up to the limit
    (standing: after its reaction), as nobody crawls 70 m to a light. [s]

    Examples
    --------
    >>> round(_arrival_s(100.0, 10.0, 13.4, DriverModel()), 1), round(_arrival_s(75.0, 0.9, 13.4, DriverModel()), 1)
    (10.0, 9.5)
    """
    if v_mps >= drv.min_coast_mps:
        return dist_m / v_mps
    return float(time_to_cover_s(dist_m, v_mps, drv.accel_mps2, v_lim_mps)) + (drv.reaction_s if v_mps <= 0.1 else 0.0)


def _led_arrival_s(dist_m: float, v_mps: float, gap_m: float, leader_mps: float, v_lim_mps: float, drv: DriverModel) -> float:
    r"""When a car held back by the car in front reaches a line ``dist_m`` ahead: no sooner than its own drive
    (:func:`_arrival_s`) nor than Newell's follower [1]_ of that car at its speed now (the follower is at the line a
    reaction time after the leader's front is a jam spacing past it, i.e. after the leader has covered
    ``dist_m - gap_m``: the gap is beyond the standstill gap, and the leader's length plus that gap is the jam spacing),
    and no later than the whole way at the slower pace of the two (the rule before: a leader already over the line, or
    about to be, still held the car to its speed for all of it; traced, an advised car 59 m before an amber at
    21 m/s, its leader 3 m before the line speeding up from 14.6 m/s, judged it would not clear and braked at
    3.8 m/s²). [s]

    .. math:: t = \min\left(\frac{d}{\min(v, v_l)},\ \max\left(t_{own}, \frac{d - g}{v_l} + \tau\right)\right)

    References
    ----------
    .. [1] G. F. Newell, "A simplified car-following theory: a lower order model," Transp. Res. B, vol. 36, no. 3,
       pp. 195-205, 2002, doi:10.1016/S0191-2615(00)00044-8.

    Examples
    --------
    >>> round(_led_arrival_s(58.7, 21.0, 48.0, 14.6, 24.6, DriverModel()), 2)  # the leader 3 m before the line
    2.8
    >>> round(_led_arrival_s(100.0, 20.0, 15.0, 15.0, 24.6, DriverModel()), 2)  # following 1 s behind: the pace
    6.67
    """
    paced = _arrival_s(dist_m, min(v_mps, leader_mps), v_lim_mps, drv)
    if leader_mps <= 0.1:
        return paced
    return min(paced, max(_arrival_s(dist_m, v_mps, v_lim_mps, drv), (dist_m - gap_m) / leader_mps + drv.reaction_s))


def _to_line_mps(v_mps: float, room_m: float, dt_s: float, hardest_mps2: float, roll_mps: float, decel_mps2: float, accel_mps2: float) -> float:
    """The next step's speed of a driver stopping ``room_m`` before it: slowing at ``v²/(2 room)`` (at most
    ``hardest_mps2``), as the regular driver brakes for a red; a car slower than that rolls up to the line at up to
    ``roll_mps`` (the advisor's slowest advised speed), speeding up at ``accel_mps2``, from where ``decel_mps2`` still
    stops it at the line (Euler steps: it moves at the new speed). Without the roll a car crawling in a queue at
    0.7 m/s "stopped" for a light 70 m ahead at 0.003 m/s² for a whole cycle, and the lane behind it with it (SUMO,
    7th Street at 900 veh/h, docs/history/TRAFFIC.md). [m/s]

    Examples
    --------
    >>> round(_to_line_mps(0.9, 70.0, 0.5, 4.0, 4.47, 1.5, 2.0), 2), round(_to_line_mps(10.0, 50.0, 0.5, 4.0, 4.47, 1.5, 2.0), 2)
    (1.9, 9.5)
    >>> _to_line_mps(0.5, 0.0, 0.5, 4.0, 4.47, 1.5, 2.0)
    0.0
    """
    need = min(v_mps * v_mps / (2.0 * room_m), hardest_mps2) if room_m > 1e-6 else hardest_mps2
    down = max(v_mps - need * dt_s, 0.0)
    b = decel_mps2
    stoppable = -b * dt_s + np.sqrt(b * b * dt_s * dt_s + 2.0 * b * max(room_m, 0.0))
    roll = min(roll_mps, stoppable, v_mps + accel_mps2 * dt_s)
    return float(max(down, roll))
