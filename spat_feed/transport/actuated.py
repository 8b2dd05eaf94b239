"""Actuated lights for simulation: when phases really end, what the controller publishes each second.

Pure (no clock, no I/O except :func:`fit_switches`, which reads recordings). Three parts:

* **The fit** (:func:`fit_switches`, ``python -m spat_feed.transport.actuated [CSV ...]``): on recorded SPaT (the
  ``../shared/data/spat`` format) every phase's *first* published window ``[minEnd, maxEnd]`` against the
  instant it really ended (midway between the last snapshot in the phase and the first after it: the
  recordings are 1 Hz). Per phase class (red, and not red): the share that ends after ``maxEnd``, the
  quantiles of where inside the window the rest end, ``u = (end - minEnd) / (maxEnd - minEnd)``, and the mean
  overshoot of the late ones. A phase never ends before its ``minEnd`` (within the 1 s sampling).
* **The truth** (:func:`actuated_light`): a fixed-time light's changes become published windows of a given
  half-width around the nominal instant; the real switch is drawn inside the window and, in a share of
  cases, beyond it (uniform up to ``beyond_frac`` of the window past ``maxEnd``, or from a :class:`SwitchFit`).
  Never before ``minEnd``. :meth:`ActuatedLight.truth` is an :class:`advisory.signals.TimelineSignal`.
* **The feed** (:meth:`ActuatedLight.plan_at`, :class:`ActuatedFeed`): what an actuated controller publishes
  at each instant: the windows narrow as time passes (``minEnd`` never in the past), become exact
  ``decide_s`` before the switch (the controller has decided), and past ``maxEnd`` a late phase's
  ``maxEnd`` is pushed ``late_push_s`` ahead, as the recorded controller does. :class:`ActuatedFeed` turns
  that into J2735 events (:func:`spat_feed.timing.messages.movement_events`), reads them back as a receiver does
  (:func:`spat_feed.timing.messages.plan_from_movement`) and gives the advisor its
  :class:`~advisory.advice.views.Observation` through :func:`spat_feed.prediction.observe.light_view`, with dropouts
  (no message: the last one ages and goes stale), a skewed feed clock (the receiver is told only a bound,
  ``clock_uncertainty_s``) and what the receiver learnt of each intersection beforehand (``IntersectionHistory``:
  the light's phases, and with a :func:`conflicting_light` the changes of that stage its phases follow).
"""

from __future__ import annotations

import math
import sys
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from advisory.advice.views import LightView, Observation
from advisory.signals import FixedTimeSignal, Scenario, TimelineSignal
from advisory.trajectory import Trajectory
from spat_feed.road.corridors import IntersectionSpec, SignalGroupSpec
from spat_feed.timing.messages import MovementState, confidence_index, movement_events, plan_from_movement, to_unix_s
from spat_feed.prediction.history import IntersectionHistory
from spat_feed.prediction.observe import PlanReading, light_view
from spat_feed.timing.plans import AMBER, GREEN, RED, STOP_STATES, ChangeWindow, MovementPhaseState, UncertainPlan

SAMPLE_S = 1.0
"""The recordings' snapshot interval: a switch is known to within this. [s]"""
QUANTILE_LEVELS = tuple(np.linspace(0.0, 1.0, 11))
LIKELY_AHEAD_S = 1e-3
"""A change that has not come yet is published as likely at least this far after now. [s]"""


# --------------------------------------------------------------------------------------------------
# The fit


@dataclass(frozen=True, slots=True)
class SwitchFit:
    """When phases of one class really end, relative to their first published window. Units in names."""

    phase: str  # "red" or "green" (every state not red)
    n: int  # phases with a bounded window
    before_min_n: int  # phases that ended before minEnd (more than the sampling): 0 on the recordings
    late_frac: float  # share that ended after maxEnd
    inside_quantiles: tuple[float, ...]  # of u = (end - min) / (max - min) for the others, at QUANTILE_LEVELS
    late_mean_s: float  # mean of (end - maxEnd) over the late ones
    median_width_s: float

    def draw_s(self, min_s: float, max_s: float, rng: np.random.Generator) -> float:
        """A switch instant for a window ``[min_s, max_s]``: late with ``late_frac`` (exponential overshoot),
        else inside at a quantile drawn from ``inside_quantiles`` (linear between them). [s]"""
        if rng.random() < self.late_frac:
            return max_s + rng.exponential(self.late_mean_s)
        u = float(np.interp(rng.random(), QUANTILE_LEVELS, self.inside_quantiles))
        return min_s + u * (max_s - min_s)


def switch_observations(snapshots) -> list[tuple[bool, float, float, float]]:
    """``(red, minEnd, maxEnd, end)`` for every phase whose start and end the recording holds and whose first
    window is bounded (a ``maxEnd`` about an hour ahead means unknown). [s, Unix]"""
    from spat_feed.timing.messages import UNKNOWN_MAX_END_S

    series: dict[tuple[int, int], list[tuple[float, MovementPhaseState, float, float]]] = {}
    for ix in snapshots:
        t = to_unix_s(ix.timestamp)
        for m in ix.states:
            ev = m.state_time_speed[0]
            if ev.timing is None or ev.timing.max_end_time is None:
                continue
            series.setdefault((ix.id, m.signal_group), []).append((t, ev.event_state, to_unix_s(ev.timing.min_end_time), to_unix_s(ev.timing.max_end_time)))
    out = []
    for rows in series.values():
        starts = [i for i in range(1, len(rows)) if rows[i][1] != rows[i - 1][1]]
        for i, j in zip(starts, starts[1:]):  # a phase from its first snapshot i to its last j - 1
            t0, state, lo, hi = rows[i]
            if hi - t0 >= UNKNOWN_MAX_END_S or rows[j][0] - rows[j - 1][0] > 2 * SAMPLE_S:
                continue  # unknown bound, or a gap in the recording hides the switch
            out.append((state in STOP_STATES, lo, hi, 0.5 * (rows[j - 1][0] + rows[j][0])))
    return out


def fit_switches(paths: Iterable[str | Path]) -> dict[str, SwitchFit]:
    """Fit :class:`SwitchFit` for red and for green on the recorded SPaT CSVs at ``paths``."""
    from spat_feed.transport.recorded import read_spat_csv

    paths = list(paths)
    obs = [o for p in paths for o in switch_observations(read_spat_csv(p))]
    fits = {}
    for name, red in (("red", True), ("green", False)):
        rows = np.array([(lo, hi, end) for r, lo, hi, end in obs if r == red])
        if not len(rows):  # a controller that publishes its state only: nothing to fit
            raise ValueError(f"no phase with a bounded window ({name}) in {', '.join(map(str, paths))}: nothing to fit")
        lo, hi, end = rows.T
        late = end > hi + 0.5 * SAMPLE_S
        inside = ~late & (hi - lo > 0)
        u = np.clip((end[inside] - lo[inside]) / (hi[inside] - lo[inside]), 0.0, 1.0)
        fits[name] = SwitchFit(
            phase=name,
            n=len(rows),
            before_min_n=int(np.sum(end < lo - SAMPLE_S)),
            late_frac=float(late.mean()),
            inside_quantiles=tuple(float(q) for q in np.quantile(u, QUANTILE_LEVELS)),
            late_mean_s=float(np.mean(end[late] - hi[late])) if late.any() else 0.0,
            median_width_s=float(np.median(hi - lo)),
        )
    return fits


# --------------------------------------------------------------------------------------------------
# The truth and what the controller publishes


@dataclass(frozen=True, slots=True)
class ActuatedLight:
    """One actuated light on a zone's time axis: each change's published window and its real instant.

    ``states[i]`` holds until change ``i`` (window ``windows[i]``, real instant ``switches_s[i]``), then
    ``states[i + 1]``; the last state holds after the last change.
    """

    position_m: float
    states: tuple[MovementPhaseState, ...]
    windows: tuple[ChangeWindow, ...]
    switches_s: tuple[float, ...]
    decide_s: float = 3.0  # the controller publishes the exact instant this long before the switch [s]
    late_push_s: float = 5.0  # a phase past its maxEnd is published with maxEnd this far ahead [s]
    amber_s: float = 4.0  # the last seconds of each green show amber, published as J2735 protected-clearance (at 88.5 km/h a car that cannot stop clears in it); 0: none [s]

    def truth(self) -> TimelineSignal:
        """The light as it really switches (amber: the last ``amber_s`` of a green, green for the rules)."""
        bounds = (-math.inf, *self.switches_s, math.inf)
        reds = [(bounds[i], bounds[i + 1]) for i, s in enumerate(self.states) if s in STOP_STATES]
        ends = [-math.inf] + [b for _, b in reds]  # the green before each red began when the red before it ended
        ambers = [(max(a - self.amber_s, e), a) for (a, _), e in zip(reds, ends) if math.isfinite(a)]
        return TimelineSignal(self.position_m, tuple(reds), tuple(ambers))

    def amber_start_s(self, i: int) -> float | None:
        """When the amber before change ``i`` begins (a change from a go state into a stop state, with ``amber_s`` > 0:
        ``amber_s`` before it, or when the red before it ended if the green was shorter), else None. [s]"""
        if self.amber_s <= 0.0 or self.states[i] in STOP_STATES or self.states[i + 1] not in STOP_STATES:
            return None
        return max(self.switches_s[i] - self.amber_s, self.switches_s[i - 1] if i > 0 else -math.inf)

    def state_at(self, t_s: float) -> MovementPhaseState:
        """The state really showing at ``t_s`` (what its controller publishes as the current phase): amber
        (J2735 protected-clearance) in the last ``amber_s`` of a green."""
        k = int(np.searchsorted(self.switches_s, t_s, side="right"))
        if k < len(self.switches_s) and (a := self.amber_start_s(k)) is not None and t_s >= a:
            return AMBER
        return self.states[k]

    def plan_at(self, t_s: float) -> UncertainPlan:
        """What the controller publishes at ``t_s``: the state now and every change to come, windows narrowed.

        A green that ends in an amber (``amber_s`` > 0) is published as J2735 does: the green, the change into amber
        (protected-clearance), then the amber and its change into red, which comes ``amber_s`` after the amber begins
        (exact once the controller has decided when the green ends, ``decide_s`` before the amber). Windows of one
        plan may not overlap (:class:`~spat_feed.timing.plans.UncertainPlan`): where the green's window is wider than
        the amber, the amber's start is published no later than the red's earliest start (the green's ``maxEndTime`` is
        cut, never the red's ``minEndTime``, which stays hard)."""
        k = int(np.searchsorted(self.switches_s, t_s, side="right"))  # changes already made
        in_amber = k < len(self.switches_s) and (a_k := self.amber_start_s(k)) is not None and t_s >= a_k
        states, changes = [AMBER if in_amber else self.states[k]], []
        floor_s = t_s
        for i in range(k, len(self.windows)):
            w, real = self.windows[i], self.switches_s[i]
            amber = None if i == k and in_amber else self.amber_start_s(i)
            if amber is not None:  # the green ends in its amber: its window is the change's, ``length_s`` earlier
                length_s = real - amber
                if amber - t_s <= self.decide_s:
                    a_lo = a_hi = a_likely = max(amber, floor_s)
                    conf = 1.0
                else:
                    a_lo = max(w.min_end_s - length_s, floor_s)
                    a_hi = max(w.max_end_s - length_s if w.max_end_s - length_s > t_s else t_s + self.late_push_s, a_lo)
                    a_likely, conf = min(max(w.likely_s - length_s, a_lo, t_s + LIKELY_AHEAD_S), a_hi), w.confidence_frac
                lo, likely, hi = a_lo + length_s, a_likely + length_s, a_hi + length_s  # the red: the amber's length later
                a_hi = min(a_hi, lo)  # windows may not overlap: the green's latest end is cut, never the red's earliest
                changes.append(ChangeWindow(a_lo, min(a_likely, a_hi), a_hi, conf))
                states.append(AMBER)
            elif real - t_s <= self.decide_s or i == k and in_amber:
                lo = hi = likely = max(real, floor_s)
                conf = 1.0
            else:
                lo = max(w.min_end_s, floor_s)
                hi = max(w.max_end_s if w.max_end_s > t_s else t_s + self.late_push_s, lo)
                # a change still to come is likely after now (a likely time that has passed would publish the next
                # state as the current one: J2735 receivers read the current state off the likely times)
                likely, conf = min(max(w.likely_s, lo, t_s + LIKELY_AHEAD_S), hi), w.confidence_frac
            changes.append(ChangeWindow(lo, likely, hi, conf))
            states.append(self.states[i + 1])
            floor_s = hi
        return UncertainPlan(tuple(states), tuple(changes))


    def published_change(self, t_s: float, i: int) -> ChangeWindow | None:
        """The window :meth:`plan_at` publishes at ``t_s`` for change ``i`` (None: it has come)."""
        k = int(np.searchsorted(self.switches_s, t_s, side="right"))
        if i < k or i >= len(self.windows):
            return None
        position = -1
        for j in range(k, i + 1):  # each change, after its amber's start where it has one to come
            amber = self.amber_start_s(j)
            position += 2 if amber is not None and not (j == k and t_s >= amber) else 1
        return self.plan_at(t_s).changes[position]


def actuated_light(
    light: FixedTimeSignal,
    half_width_s: float,
    rng: np.random.Generator,
    t0_s: float = -200.0,
    t1_s: float = 800.0,
    *,
    beyond_frac: float = 0.1,
    fits: dict[str, SwitchFit] | None = None,
    confidence_frac: float | None = None,
) -> ActuatedLight:
    """An actuated version of ``light`` over ``[t0_s, t1_s]``: each change at nominal ``T`` is published as
    ``[T - w, T + w]`` (``w`` = ``half_width_s``, cut to 0.4 of the shorter neighbouring phase) with
    ``likely = T``, and really happens uniformly in ``[T - w, T + w + beyond_frac * 2w]`` (or drawn from
    ``fits``). Phases last at least 1 s. ``confidence_frac`` defaults to the share inside the window."""
    reds = light.red_intervals(t0_s, t1_s)
    nominal = sorted({x for r in reds for x in r if t0_s < x < t1_s})
    states = [RED if light.is_red(t0_s) else GREEN]
    windows, switches = [], []
    conf = confidence_frac if confidence_frac is not None else (1.0 / (1.0 + beyond_frac) if half_width_s > 0 else 1.0)
    previous = -math.inf
    for i, t_nom in enumerate(nominal):
        to_red = not light.is_red(t_nom - 1e-6) and light.is_red(t_nom)
        phase_before = light.green_s if to_red else light.red_s
        phase_after = light.red_s if to_red else light.green_s
        w = min(half_width_s, 0.4 * phase_before, 0.4 * phase_after)
        lo, hi = max(t_nom - w, previous + 1.0), t_nom + w
        if fits is not None:
            real = fits["green" if to_red else "red"].draw_s(lo, hi, rng)
        else:
            real = rng.uniform(lo, hi + beyond_frac * (hi - lo))
        real = max(real, lo)
        if i + 1 < len(nominal):
            real = min(real, nominal[i + 1] - 0.4 * min(light.red_s, light.green_s) - 1.0)  # before the next window opens
        windows.append(ChangeWindow(lo, min(max(t_nom, lo), hi), max(hi, lo), conf if w > 0 else 1.0))
        switches.append(real)
        states.append(RED if to_red else GREEN)
        previous = real
    return ActuatedLight(light.position_m, tuple(states), tuple(windows), tuple(switches))


def conflicting_light(light: ActuatedLight, rng: np.random.Generator, *, after_start_s: tuple[float, float] = (2.0, 6.0),
                      before_end_s: tuple[float, float] = (3.0, 20.0), misfire_frac: float = 0.1,
                      misfire_s: tuple[float, float] = (5.0, 20.0)) -> ActuatedLight:  # fmt: skip
    """A conflicting stage of ``light``: another signal group of its intersection, green while ``light`` is red, from
    an intergreen after each of its reds begins to a fixed lead before it ends (an intergreen and any fixed stage
    between them; each drawn once, in ``after_start_s`` and ``before_end_s``: a controller's are fixed). In
    ``misfire_frac`` of its greens another stage comes in between: the green ends ``misfire_s`` earlier, so a
    receiver that learnt "``light``'s red ends the lead after this green" (:class:`~spat_feed.prediction.history.ChangeLinks`)
    is told too early an end, or, with too many such, learns no link. Its windows are exact; its greens end in an amber
    as ``light``'s do (``amber_s``)."""
    after_start, before_end = float(rng.uniform(*after_start_s)), float(rng.uniform(*before_end_s))
    states, switches = [RED], []
    for a, b in light.truth().reds_s:
        if not (math.isfinite(a) and math.isfinite(b)):
            continue
        g0 = a + after_start
        g1 = b - before_end - (rng.uniform(*misfire_s) if rng.uniform() < misfire_frac else 0.0)
        if g1 - g0 >= 2.0:
            switches += [g0, g1]
            states += [GREEN, RED]
    windows = tuple(ChangeWindow(x, x, x) for x in switches)
    return ActuatedLight(light.position_m, tuple(states), windows, tuple(switches), amber_s=light.amber_s)


@dataclass
class ActuatedFeed:
    """The closed loop's SPaT source for actuated lights: ``feed(t, x, v) -> Observation`` (see the module).

    ``epoch_unix_s`` places the zone's time 0 on the Unix axis. ``dropouts_s``: intervals ``[a, b)`` with no
    message; the last one received ages and is stale after ``stale_after_s``. ``skew_s``: the feed's clock is
    this far ahead of the car's. ``n_events``: events per movement (1 = the current phase only, as Antwerp; the
    default 4 carries the current phase and the cycle after it, green, amber, red and green: before the amber was
    published, 3 did).
    """

    lights: Sequence[ActuatedLight]
    speed_limit_mps: float
    skew_s: float = 0.0
    dropouts_s: Sequence[tuple[float, float]] = ()
    n_events: int = 4
    stale_after_s: float = 3.0
    epoch_unix_s: float = 1.7e9
    clock_uncertainty_s: float = 0.0  # what the receiver is told of the skew: a bound, not the offset [s]
    warm_up_s: float = 600.0  # the receiver has watched each light this long before the car enters (IntersectionHistory) [s]
    conflicting: Sequence[ActuatedLight | None] = ()  # each light's conflicting stage (signal group 2 of its intersection)
    _last: dict[int, tuple[float, object]] = field(default_factory=dict, repr=False)
    _history: dict[int, IntersectionHistory] = field(default_factory=dict, repr=False)

    def _others(self, n: int, t_s: float) -> dict[int, MovementPhaseState]:
        """The other signal groups of light ``n``'s intersection at ``t_s``: their states (group 2: the conflicting stage)."""
        other = self.conflicting[n] if n < len(self.conflicting) else None
        return {} if other is None else {2: other.state_at(t_s)}

    def movement_at(self, n: int, t_s: float) -> MovementState:
        """Light ``n``'s J2735 movement as published at ``t_s`` (on the feed's skewed clock)."""
        plan = self.lights[n].plan_at(t_s)
        shift = self.epoch_unix_s + self.skew_s
        unix = UncertainPlan(plan.states, tuple(ChangeWindow(c.min_end_s + shift, c.likely_s + shift, c.max_end_s + shift, c.confidence_frac) for c in plan.changes))
        return MovementState(signal_group=1, state_time_speed=movement_events(unix, t_s + shift, self.n_events))

    def __call__(self, t_s: float, x_m: float, v_mps: float) -> Observation:
        down = any(a <= t_s < b for a, b in self.dropouts_s)
        views: list[LightView] = []
        for n, light in enumerate(self.lights):
            if light.position_m <= x_m or len(views) == 2:
                continue
            history = self._history.get(n)
            if history is None:  # what the receiver learnt of the intersection before the car came
                history = self._history[n] = IntersectionHistory()
                for t in np.arange(t_s - self.warm_up_s, t_s, 1.0):
                    history.record(float(t) + self.epoch_unix_s + self.skew_s, {1: light.state_at(float(t)), **self._others(n, float(t))})
            if not down:
                movement = self.movement_at(n, t_s)
                stamp = t_s + self.epoch_unix_s + self.skew_s
                plan = plan_from_movement(movement, stamp)
                history.record(stamp, {1: plan, **self._others(n, t_s)})
                self._last[n] = (t_s, plan, history.stats(1))
            received = self._last.get(n)
            reading = None
            if received is not None:
                age = t_s - received[0]
                reading = PlanReading(received[1], fresh=age <= self.stale_after_s, age_s=age, cycle=received[2],
                                      clock_uncertainty_s=self.clock_uncertainty_s, amber_s=light.amber_s)  # fmt: skip
            spec = IntersectionSpec(id=n + 1, name=f"light {n + 1}", stop_line_m=light.position_m, lat_deg=0.0, lon_deg=0.0,
                                    approach_heading_deg=0.0, signal_groups=(SignalGroupSpec(id=1),))  # fmt: skip
            views.append(light_view(spec, reading, x_m, t_s + self.epoch_unix_s, speed_mps=v_mps))
        return Observation(v_mps, self.speed_limit_mps, tuple(views), position_m=x_m)


def actuated_scenario(scenario: Scenario, half_width_s: float, rng: np.random.Generator, **kwargs) -> tuple[Scenario, list[ActuatedLight]]:
    """``scenario`` with every fixed-time light made actuated (:func:`actuated_light`): the truth scenario and its lights."""
    lights = [actuated_light(s, half_width_s, rng, **kwargs) for s in scenario.signals]
    truth = Scenario(scenario.name + f" ±{half_width_s:g} s", tuple(a.truth() for a in lights), scenario.zone_length_m,
                     scenario.speed_limit_mps, scenario.initial_speed_mps)  # fmt: skip
    return truth, lights


CURRENT_ONLY_FRAC = 0.5
"""Share of :func:`random_case` cases whose controller publishes the current phase only, as Antwerp's. [-]"""


def random_case(seed: int, max_half_width_s: float = 15.0, max_skew_s: float = 3.0, dropouts: bool = True, amber_s: float | None = None):
    """One randomized closed-loop case (the tests' and the bench's): two lights 150-1000 m apart, cycle 40-120 s,
    red 30-70 %, actuated with windows up to ``±max_half_width_s`` (the real switch anywhere inside and up to
    10 % beyond), up to two dropouts of 2-10 s in the first minute, a feed clock off by up to ``±max_skew_s``,
    tracking noise up to 1 m/s. In :data:`CURRENT_ONLY_FRAC` of the cases (drawn apart, so the others are the
    cases they always were) each controller publishes its current phase only, as Antwerp's: what comes after it
    is what the receiver learnt over the 25 minutes before the car (the light's phases, and the changes of its
    conflicting stage, :func:`conflicting_light`, with 10 % of misfires, that its reds follow). ``amber_s``: the
    amber the lights really show before each red (default :attr:`ActuatedLight.amber_s`; 0: none, the stress case of
    a green that turns red at once, which no driver can see coming). Returns ``(truth scenario, feed, tracking noise
    [m/s])``."""
    from advisory.signals import paper_scenario

    rng = np.random.default_rng(seed)
    current_only = np.random.default_rng([seed, 1]).uniform() < CURRENT_ONLY_FRAC
    cycle = rng.uniform(40, 120)
    share = rng.uniform(0.3, 0.7)
    fixed = paper_scenario(rng.uniform(-cycle, cycle), rng.uniform(-cycle, cycle), rng.uniform(150, 1000),
                           red_s=cycle * share, green_s=cycle * (1 - share))  # fmt: skip
    truth, lights = actuated_scenario(fixed, rng.uniform(0, max_half_width_s), rng, **({"t0_s": -1600.0} if current_only else {}))
    if amber_s is not None:
        lights = [replace(light, amber_s=amber_s) for light in lights]
        truth = replace(truth, signals=tuple(light.truth() for light in lights))
    gaps = []
    for _ in range(rng.integers(0, 3) if dropouts else 0):
        start = rng.uniform(0, 60)
        gaps.append((start, start + rng.uniform(2, 10)))
    feed = ActuatedFeed(lights, fixed.speed_limit_mps, skew_s=rng.uniform(-max_skew_s, max_skew_s), dropouts_s=gaps,
                        clock_uncertainty_s=max_skew_s)  # fmt: skip
    noise = float(rng.uniform(0, 1.0))
    if current_only:
        conflicting = [conflicting_light(light, rng) for light in lights]
        feed = replace(feed, n_events=1, warm_up_s=1500.0, conflicting=conflicting)
    return truth, feed, noise


# --------------------------------------------------------------------------------------------------
# Red entries and hard brakes of a closed-loop run: avoidable or not


@dataclass(frozen=True, slots=True)
class SafetyEvent:
    """A red entry or a hard brake in a closed-loop run fed by an :class:`ActuatedFeed`, and whether the feed had told
    of its red in time for a car to stop. Times on the zone's axis [s]; ``inf`` where the feed never told."""

    kind: str  # "red_entry" (a line crossed on red) or "hard_brake" (braking harder than the rate given)
    light: int  # the light's index in the feed
    at_s: float  # the crossing, or the hardest braking
    red_start_s: float  # the red it is about
    brake_mps2: float  # the hardest braking of the run (a hard brake), nan for a red entry
    known_s: float  # the first reading received that put a possible red at ``max(at_s, red_start_s)`` (its window, widened by the clock bound)
    decided_s: float  # the first reading received that published the red's start exactly
    distance_m: float  # from the car to the line at ``known_s``
    speed_mps: float  # the car's speed at ``known_s``
    stop_decel_mps2: float  # braking from ``known_s`` that stops the car at the line: v² / 2d
    avoidable: bool  # ``stop_decel_mps2`` within the rate given to :func:`safety_events`


def _told_s(light: ActuatedLight, feed: ActuatedFeed, red_start_s: float, at_s: float, before_s: float) -> tuple[float, float]:
    """The first reading received before ``before_s`` (one a second from entry, none in a dropout) whose published
    window for the start of the red that begins at ``red_start_s`` admits a red at ``at_s``, and the first that
    publishes that start exactly: ``(known_s, decided_s)``, ``inf`` where none did. A red already begun is known."""
    known = decided = math.inf
    for t in np.arange(0.0, math.ceil(before_s)):
        t = float(t)
        if t >= before_s or (known < math.inf and decided < math.inf):
            break
        if any(a <= t < b for a, b in feed.dropouts_s):
            continue
        if t >= red_start_s:
            known, decided = min(known, t), min(decided, t)
            continue
        c = light.published_change(t, int(np.searchsorted(light.switches_s, red_start_s)))
        if c is None:
            continue
        if c.min_end_s + feed.skew_s - feed.clock_uncertainty_s <= at_s:
            known = min(known, t)
        if c.max_end_s - c.min_end_s < 1e-9:
            decided = min(decided, t)
    return known, decided


def safety_events(traj: Trajectory, feed: ActuatedFeed, decel_mps2: float, hard_brake_mps2: float = 4.0) -> list[SafetyEvent]:
    """The red entries of ``traj`` against ``feed``'s truth, and its hardest braking if harder than ``hard_brake_mps2``
    (about the light ahead then: its red showing, or the next), each with the instant its red became knowable in the
    feed: the first reading received whose published window for that red's start, shifted by the feed's clock skew and
    widened by the bound the receiver is told (``clock_uncertainty_s``), admits a red at the crossing (at the braking
    or the red's start, the later); a red already begun is known. The window is the controller's own (every change it
    publishes, whatever ``n_events`` carries). An event is *avoidable* when a car braking at ``decel_mps2`` from that
    reading, with no reaction time, stops before the line: the advice's failure, not the feed's."""
    events = []  # (kind, light, at, red start, braking)
    for n, light in enumerate(feed.lights):
        t_c = traj.crossing_time_s(light.position_m)
        if math.isfinite(t_c) and light.truth().is_red(t_c):
            i = int(np.searchsorted(light.switches_s, t_c, side="right")) - 1  # the change into this red
            events.append(("red_entry", n, float(t_c), light.switches_s[i] if i >= 0 else -math.inf, math.nan))
    accel = traj.accel_mps2
    if len(accel) and -accel.min() > hard_brake_mps2 + 1e-6:  # (braking at exactly the rate is not harder)
        k = int(np.argmin(accel))
        t_b, x_b = float(traj.t_s[k]), float(traj.x_m[k])
        n = min((n for n, light in enumerate(feed.lights) if light.position_m > x_b), key=lambda n: feed.lights[n].position_m, default=None)
        if n is not None:
            light, truth = feed.lights[n], feed.lights[n].truth()
            i = int(np.searchsorted(light.switches_s, t_b, side="right")) - 1
            start = (light.switches_s[i] if i >= 0 else -math.inf) if truth.is_red(t_b) else truth.next_red_start_s(t_b)
            events.append(("hard_brake", n, t_b, float(start), float(-accel[k])))
    out = []
    for kind, n, at, red_start, brake in events:
        light = feed.lights[n]
        known, decided = _told_s(light, feed, red_start, max(at, red_start), at)
        d = v = need = math.inf
        if math.isfinite(known):
            d, v = light.position_m - float(traj.position_at(known)), float(traj.speed_at(known))
            need = v * v / (2.0 * d) if d > 0 else math.inf
        out.append(SafetyEvent(kind, n, at, red_start, brake, known, decided, d, v, need, need <= decel_mps2))
    return out


def recordings() -> list[str]:
    """The shared recordings (``../shared/data/spat``, or ``../../shared/data/spat`` from a worktree)."""
    repo = Path(__file__).resolve().parents[2]
    folder = next((p for p in (repo.parent / "shared", repo.parents[1] / "shared") if p.is_dir()), repo.parent / "shared")
    return sorted(str(p) for p in (folder / "data" / "spat").glob("*.csv.gz"))


def main(argv: Sequence[str] | None = None) -> int:
    """Print the fit on the given recordings (default: the shared Antwerp ones)."""
    argv = list(sys.argv[1:] if argv is None else argv)
    paths = argv or recordings()
    try:
        fits = fit_switches(paths)
    except ValueError as exc:
        print(f"spat_feed.transport.actuated: {exc}", file=sys.stderr)
        return 2
    for fit in fits.values():
        q = ", ".join(f"{x:.2f}" for x in fit.inside_quantiles)
        print(f"{fit.phase}: {fit.n} phases with a bounded first window (median width {fit.median_width_s:.0f} s); "
              f"ended before minEnd: {fit.before_min_n}; after maxEnd: {100 * fit.late_frac:.1f} % (mean overshoot "
              f"{fit.late_mean_s:.1f} s); inside, u = (end - minEnd) / (maxEnd - minEnd) at deciles 0..1: {q}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
