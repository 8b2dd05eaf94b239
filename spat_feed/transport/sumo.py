"""SUMO's traffic lights as SPaT: each light's state and when it can change, as J2735 intersection states.

A :class:`SumoSpatSource` reads a running SUMO simulation (``libsumo`` in process, or a ``traci`` connection: any
object with their ``simulation`` and ``trafficlight`` domains) and, when asked (once a simulated second), renders
every light it is told of as an :class:`~spat_feed.timing.messages.IntersectionState` stamped with the simulation's
instant on the Unix axis (``t0_unix_s`` + simulation time), to offer to a :class:`~spat_feed.transport.store.SpatStore`
exactly as an MQTT subscriber or a log player does: the store's time rules, its history of each group and every trip
then read SUMO as they read a real controller.

What SUMO knows and the message says, per signal group (one SUMO link: the corridor's through movement):

* the current state: SUMO's link character read by its meaning (:data:`LINK_STATES`: ``r`` red, ``y`` amber,
  ``G`` protected green, ``g`` permissive green, ``u`` red+amber, ``s`` a stop sign, ``o`` flashing amber, ``O`` off),
  consecutive phases that show the link the same J2735 state being one event (the corridor's red spans the cross
  street's green and amber);
* for a ``static`` program, every change exactly (``minEndTime = likelyTime = maxEndTime``, confidence 100 %): the
  current phase ends at SUMO's own next switch, the later ones after their programmed durations;
* for an ``actuated`` program, the current event alone, with the window SUMO's controller is held to: it ends no
  earlier than its phase's ``minDur`` and no later than its ``maxDur`` after the phase began (the phases after it
  showing the same state add their own ``minDur`` .. ``maxDur``); no ``likelyTime`` and no confidence. Where that
  event is due to end now (its ``maxDur`` reached: SUMO switches at the start of the coming step), the event after
  it follows, with its own window from now: a reading says what the light does from its stamp on, and one whose
  every event has ended says nothing of it (before, 2 % of the readings: the end of each amber and fixed-length red,
  read as "no data" for that second). SUMO does not
  predict them, and this is what a real actuated controller publishes (the Antwerp recordings: the current phase,
  ``minEndTime`` and ``maxEndTime``): the service's predictor bounds the phases after it from the group's history.
  (Later events with summed windows would overlap the current one's, and J2735 readers, ours included, cut such
  windows to follow each other: an amber "ending between 26 and 70 s" after a green "ending between 22 and 66 s"
  reads as a green ending between 22 and 26 s, :func:`~spat_feed.timing.messages.plan_from_movement`: safe, but
  narrower than SUMO's controller is held to.)
* ``startTime`` of the current event: when the source saw the state begin (:meth:`SumoSpatSource.observe` each
  step), or for a static program the programmed start.

For a static program the events follow the current one for a whole cycle, up to and including the next time the
current state begins (green, amber, red, green at a light with amber; green, red, green without): the controller
runs a fixed program and knows it, as SUMO's GLOSA device reads it (``MSDevice_GLOSA::getTimeToSwitch`` walks the
program's phases). Three events (the simulator's default) leave a green's red after its amber without an end, so the
advisor saw that red as lasting for good and could not plan for the green after it (traced: 7th Street, docs/history/TRAFFIC.md).
``n_events`` caps them where given.

The amber each group shows before its reds (:meth:`SumoSpatSource.amber_s`) is read from the program too, and
declared to the store with every publication (:meth:`~spat_feed.transport.store.SpatStore.declare_amber`): 0 where a
green goes straight to red (SUMO's lights built from a plan without amber, the paper's corridors), so the advisor
keeps its margin before such a red (``PlanReading.amber_s``); J2735 has no field for it, and the store does not guess
it from what it saw (recorded controllers also go from green to red where their amber is not published).

With ``queues=True`` each movement also carries what stop-line detectors on its approach would measure (J2735
``maneuverAssistList``, one ``ConnectionManeuverAssist`` per incoming lane of its SUMO link, ``connectionID`` the
link index: no MAP here): ``queueLength``, the jam standing back from the stop line (:func:`jam_length_m`, the
quantity of SUMO's own lane-area detectors' ``jamLengthMeters``: halting vehicles, under 0.1 m/s, no farther
apart than :data:`JAM_GAP_M`), whole metres. A controller with detectors can publish it; the queue-aware advisor
counts it before anything else (:mod:`advisory.advice.queue`).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

from spat_feed.timing.messages import ConnectionManeuverAssist, IntersectionState, MovementEvent, MovementState, TimeChangeDetails, from_unix_s
from spat_feed.timing.plans import MovementPhaseState as S, PhaseClass, phase_class

LINK_STATES: dict[str, S] = {
    "r": S.STOP_AND_REMAIN,
    "R": S.STOP_AND_REMAIN,
    "y": S.PROTECTED_CLEARANCE,
    "Y": S.PROTECTED_CLEARANCE,
    "G": S.PROTECTED_MOVEMENT_ALLOWED,
    "g": S.PERMISSIVE_MOVEMENT_ALLOWED,
    "u": S.PRE_MOVEMENT,
    "s": S.STOP_THEN_PROCEED,
    "o": S.CAUTION_CONFLICTING_TRAFFIC,
    "O": S.DARK,
}
"""SUMO's link state characters (sumo.dlr.de/docs/Simulation/Traffic_Lights.html, "signal state definitions") -> J2735."""

STATIC, ACTUATED = 0, 3
"""``Logic.type`` of SUMO's static and actuated programs (libsumo/TraCI constants TRAFFICLIGHT_TYPE_*)."""

HALTING_MPS = 0.1
"""A vehicle slower than this is halting (SUMO's own threshold, ``--tls.actuated.jam-threshold`` aside). [m/s]"""

JAM_GAP_M = 10.0
"""Halting vehicles this close (bumper to bumper) belong to one jam (SUMO's lane-area detectors: ``jamDistThreshold``
default 10 m). [m]"""

HORIZON_S = 3000.0
"""Events are listed no further than this after now (a program with a very long phase). [s]"""


def link_state(char: str) -> S:
    """The J2735 state of one SUMO link character (``ValueError`` for an unknown one).

    Examples
    --------
    >>> link_state("G").value, link_state("r").value, link_state("y").value
    ('protected-Movement-Allowed', 'stop-And-Remain', 'protected-clearance')
    """
    try:
        return LINK_STATES[char]
    except KeyError:
        raise ValueError(f"unknown SUMO link state {char!r}") from None


@dataclass(frozen=True, slots=True)
class SumoLight:
    """One signal group in SUMO: J2735 intersection id and signal group, SUMO's traffic light and link index."""

    intersection_id: int
    signal_group: int
    tls_id: str
    link_index: int
    name: str | None = None
    movement_name: str | None = None


@dataclass(frozen=True, slots=True)
class _Phase:
    state: S
    duration_s: float
    min_s: float
    max_s: float


class SumoSpatSource:
    """SPaT of SUMO's lights (see the module docstring). ``conn``: ``libsumo`` or a ``traci`` connection."""

    def __init__(self, conn, lights: Sequence[SumoLight], t0_unix_s: float, n_events: int | None = None, queues: bool = False) -> None:
        if n_events is not None and n_events < 1:
            raise ValueError("n_events must be >= 1")
        self.conn = conn
        self.lights = tuple(lights)
        self.t0_unix_s = float(t0_unix_s)
        self.n_events = n_events
        self.queues = queues
        self._programs: dict[str, tuple[str, int, list[list[str]], list[tuple[float, float, float]]]] = {}
        self._seen: dict[tuple[str, int], tuple[S, float]] = {}  # (tls, link) -> (state, since) [Unix s]
        self.published = 0
        self.verdicts: dict[str, int] = {}

    # -- SUMO's program --------------------------------------------------------------------------------
    def _program(self, tls_id: str):
        """(program id, logic type, phase states, (duration, minDur, maxDur) per phase) of the running program."""
        tl = self.conn.trafficlight
        pid = tl.getProgram(tls_id)
        cached = self._programs.get(tls_id)
        if cached is not None and cached[0] == pid:
            return cached
        logic = next(lg for lg in tl.getAllProgramLogics(tls_id) if lg.programID == pid)
        states = [list(p.state) for p in logic.phases]
        times = [(float(p.duration), float(p.minDur), float(p.maxDur)) for p in logic.phases]
        self._programs[tls_id] = cached = (pid, int(logic.type), states, times)
        return cached

    def amber_s(self, light: SumoLight) -> float | None:
        """The shortest amber the light's program shows between a green and the red after it: 0 where some green goes
        straight to red (no amber warns of that red), None where no green of the program ends in amber or red (a link
        that is never green): :func:`program_amber_s` of the running program. An actuated program's amber is its
        phase's ``minDur`` where that is shorter. [s]"""
        _, kind, states, times = self._program(light.tls_id)
        return program_amber_s([link_state(p[light.link_index]) for p in states],
                               [min(d, mn) if kind == ACTUATED and mn > 0.0 else d for d, mn, _ in times])  # fmt: skip

    def now_unix_s(self) -> float:
        return self.t0_unix_s + float(self.conn.simulation.getTime())

    def observe(self) -> None:
        """Note each light's state now (call every simulation step: a state's ``startTime`` is when it was seen first)."""
        now = self.now_unix_s()
        tl = self.conn.trafficlight
        for light in self.lights:
            state = link_state(tl.getRedYellowGreenState(light.tls_id)[light.link_index])
            key = (light.tls_id, light.link_index)
            seen = self._seen.get(key)
            if seen is None or seen[0] is not state:
                self._seen[key] = (state, now if seen is not None else -math.inf)

    def current_state(self, light: SumoLight) -> S:
        """The light's state as SUMO reports it now: the state it showed during the step that just ended."""
        return link_state(self.conn.trafficlight.getRedYellowGreenState(light.tls_id)[light.link_index])

    def coming_state(self, light: SumoLight) -> tuple[S, float]:
        """The state SUMO applies during the coming step (a static program's switch due now happens at its start) and
        when that phase is due to end [Unix s]: what a driver at the line sees now. (SUMO switches a light at the start
        of a step; the state read after a step is the one the step used. An actuated controller decides at a due
        switch whether to extend the phase: there the state read is the one given.)"""
        tl = self.conn.trafficlight
        _, kind, states, times = self._program(light.tls_id)
        t = float(self.conn.simulation.getTime())
        cur = tl.getPhase(light.tls_id)
        switch = float(tl.getNextSwitch(light.tls_id))
        if switch <= t + 1e-9 and kind != ACTUATED:  # (an actuated controller decides then whether to extend: unknown now)
            cur = (cur + 1) % len(states)
            switch = t + times[cur][0]
        return link_state(states[cur][light.link_index]), self.t0_unix_s + max(switch, t)

    def events(self, light: SumoLight) -> list[MovementEvent]:
        """The light's current event and those after it, with their windows: a static program's whole cycle, to the
        next time the current state begins (at most ``n_events`` in all where given), an actuated one's current event
        alone, and the next one where the current is due to end now (see the module docstring)."""
        tl = self.conn.trafficlight
        now = self.now_unix_s()
        _, kind, states, times = self._program(light.tls_id)
        n = len(states)
        cur = tl.getPhase(light.tls_id)
        current = link_state(tl.getRedYellowGreenState(light.tls_id)[light.link_index])
        spent = float(tl.getSpentDuration(light.tls_id))
        exact = kind != ACTUATED
        if exact:
            lo = hi = max(float(tl.getNextSwitch(light.tls_id)) - float(self.conn.simulation.getTime()), 0.0)
        else:
            lo = max(times[cur][1] - spent, 0.0)
            hi = max(times[cur][2] - spent, lo)
        start = self._start(light, current, cur, spent, states, times, exact, now)
        events: list[MovementEvent] = []
        state, j = current, cur
        guard = 0
        wanted = (self.n_events or 4 * n + 8) if exact else 1
        while len(events) < wanted and lo <= HORIZON_S and guard < 4 * n + 8:
            # phases after j showing the same state belong to this event
            k = (j + 1) % n
            while link_state(states[k][light.link_index]) is state and guard < 4 * n + 8:
                d, mn, mx = times[k]
                lo, hi = lo + (d if exact else mn), hi + (d if exact else mx)
                k = (k + 1) % n
                guard += 1
            nxt = link_state(states[k][light.link_index])
            if nxt is state:  # the light never changes in this program
                events.append(MovementEvent(event_state=state))
                break
            timing = TimeChangeDetails(
                start_time=from_unix_s(start) if math.isfinite(start) else None,
                min_end_time=from_unix_s(now + lo),
                max_end_time=from_unix_s(now + hi),
                likely_time=from_unix_s(now + lo) if exact else None,
                confidence=15 if exact else None,
            )
            events.append(MovementEvent(event_state=state, timing=timing))
            if len(events) > 1 and state is current:  # the cycle is round: the current state begins again
                break
            if not exact and len(events) == 1 and hi <= 0.0:  # due to switch now: what the controller does next
                wanted = 2
            start = now + lo if lo == hi else math.nan
            state, j = nxt, k
            d, mn, mx = times[k]
            lo, hi = lo + (d if exact else mn), hi + (d if exact else mx)
            guard += 1
        if events and events[-1].timing is not None and len(events) > 1:
            events = _with_next_times(events)
        return events

    def _start(self, light, state, cur, spent, states, times, exact, now) -> float:
        seen = self._seen.get((light.tls_id, light.link_index))
        if seen is not None and seen[0] is state and math.isfinite(seen[1]):
            return seen[1]
        if not exact:
            return -math.inf
        back, k = spent, (cur - 1) % len(states)  # a static program: the state began where its phases began
        for _ in range(len(states) - 1):
            if link_state(states[k][light.link_index]) is not state:
                break
            back += times[k][0]
            k = (k - 1) % len(states)
        return now - back

    def states(self, lights: Iterable[SumoLight] | None = None) -> list[IntersectionState]:
        """Every light's intersection state now, one per intersection (its lights' signal groups together)."""
        now = self.now_unix_s()
        stamp = from_unix_s(now)
        by_ix: dict[int, list[MovementState]] = {}
        names: dict[int, str | None] = {}
        for light in self.lights if lights is None else lights:
            by_ix.setdefault(light.intersection_id, []).append(
                MovementState(signal_group=light.signal_group, movement_name=light.movement_name, state_time_speed=self.events(light),
                              maneuver_assist_list=self.assists(light) if self.queues else None)  # fmt: skip
            )
            names.setdefault(light.intersection_id, light.name)
        return [IntersectionState(id=i, name=names[i], timestamp=stamp, states=ms) for i, ms in by_ix.items()]

    def assists(self, light: SumoLight) -> list[ConnectionManeuverAssist]:
        """What stop-line detectors see on each incoming lane of the light's link: its jam's length (module docstring)."""
        lanes = dict.fromkeys(link[0] for link in self.conn.trafficlight.getControlledLinks(light.tls_id)[light.link_index])
        return [ConnectionManeuverAssist(connection_id=light.link_index, queue_length=min(round(self.jam_m(lane)), 10_000)) for lane in lanes]

    def jam_m(self, lane: str) -> float:
        """The jam standing back from the end of ``lane`` now (:func:`jam_length_m` of its vehicles). [m]"""
        veh = self.conn.vehicle
        cars = [(veh.getLanePosition(v), veh.getLength(v), veh.getSpeed(v)) for v in self.conn.lane.getLastStepVehicleIDs(lane)]
        return jam_length_m(float(self.conn.lane.getLength(lane)), cars)

    def publish(self, store) -> list[str]:
        """Offer every intersection's state now to ``store`` (a :class:`~spat_feed.transport.store.SpatStore`); the
        verdicts, counted in ``verdicts``."""
        for light in self.lights:
            store.declare_amber(light.intersection_id, light.signal_group, self.amber_s(light))
        out = []
        for state in self.states():
            verdict = store.offer(state)
            self.verdicts[verdict] = self.verdicts.get(verdict, 0) + 1
            out.append(verdict)
        self.published += 1
        return out


def _with_next_times(events: list[MovementEvent]) -> list[MovementEvent]:
    """Each event's ``nextTime``: when the same state is next expected (J2735), here the following event's likely end
    where it is known (static programs)."""
    out = []
    for i, ev in enumerate(events):
        nxt = events[i + 1].timing.likely_time if i + 1 < len(events) and events[i + 1].timing is not None else None
        out.append(ev if nxt is None else ev.model_copy(update={"timing": ev.timing.model_copy(update={"next_time": nxt})}))
    return out


def program_amber_s(states: Sequence[S], durations_s: Sequence[float]) -> float | None:
    """The shortest amber between a green and the red after it in a cyclic program of one link: its phases' states
    and durations; 0 where a green is followed at once by a red, None where no green ends in amber or red. [s]

    Examples
    --------
    >>> G, Y, R = S.PROTECTED_MOVEMENT_ALLOWED, S.PROTECTED_CLEARANCE, S.STOP_AND_REMAIN
    >>> program_amber_s([R, R, G], [27.0, 3.0, 30.0]), program_amber_s([R, G, Y], [30.0, 26.0, 4.0])
    (0.0, 4.0)
    >>> program_amber_s([R, G, Y, Y], [30.0, 25.0, 3.0, 2.0]), program_amber_s([R, R], [30.0, 3.0]) is None
    (5.0, True)
    """
    classes = [phase_class(s) for s in states]
    n, out = len(classes), None
    for k in range(n):
        if classes[k] is not PhaseClass.GREEN or classes[(k + 1) % n] is PhaseClass.GREEN:
            continue  # not the end of a green
        amber_s, j = 0.0, (k + 1) % n
        while classes[j] is PhaseClass.AMBER and j != k:
            amber_s, j = amber_s + float(durations_s[j]), (j + 1) % n
        if classes[j] is PhaseClass.RED:
            out = amber_s if out is None else min(out, amber_s)
    return out


def jam_length_m(lane_length_m: float, cars: Sequence[tuple[float, float, float]]) -> float:
    """How far back from the end of a lane (the stop line) its jam reaches: the halting vehicles (slower than
    :data:`HALTING_MPS`) from the line back, each no farther than :data:`JAM_GAP_M` behind the one before (the first
    no farther from the line); ``cars``: (front position along the lane, length, speed) in m, m, m/s. [m]

    Examples
    --------
    >>> jam_length_m(100.0, [(98.0, 5.0, 0.0), (90.5, 5.0, 0.0), (60.0, 5.0, 0.0), (40.0, 5.0, 8.0)])
    14.5
    >>> jam_length_m(100.0, [(98.0, 5.0, 3.0)]), jam_length_m(100.0, [(80.0, 5.0, 0.0)])
    (0.0, 0.0)
    """
    back_m, jam_m = lane_length_m, 0.0
    for front, length, speed in sorted(cars, reverse=True):
        if speed >= HALTING_MPS or back_m - front > JAM_GAP_M:
            break
        back_m = front - length
        jam_m = lane_length_m - back_m
    return jam_m
