"""The data the advice is made on and gives: a light ahead as the advisor sees it (:class:`LightView`, its equally likely
:class:`Timings`), what the advisor knows at one instant (:class:`Observation`), the advisory (:class:`Advice`), the
advisor's settings and memory (:class:`AdvisorParams`, :class:`AdvisorMemory`), and the few readings of them that
several modules share (the countdown as likely: :func:`light_timing`; the price on time lost: :func:`time_price`).

Pure data; the advisor (:mod:`advisory.advice.advisor`) decides on it. Times are relative to *now*. [m], [s]
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from advisory.frozen import quick_init
from advisory.physics.params import PAPER_54KWH, VehicleParams


class Timings(tuple):
    """A light's equally likely timings (``LightView.scenario_red_windows_s``: one tuple of red windows ``(start, end)``
    per timing) that also carries them packed, ``array_s``: shape ``(timings, k, 2)``, each timing's windows in order,
    padded with +inf (``k`` the most windows of a timing). The observation makes them so
    (:func:`spat_feed.prediction.observe.light_view`), and :func:`advisory.advice.mixture.mixture_timings` takes the array as it is instead of packing
    the tuples again (20 timings' windows: ~25 us a view). As a tuple it is the plain tuple of its timings. [s]

    Examples
    --------
    >>> t = Timings.packed((((0.0, 10.0),), ((0.0, 12.0), (50.0, 60.0))))
    >>> t == (((0.0, 10.0),), ((0.0, 12.0), (50.0, 60.0))), t.array_s.shape, t.array_s[0, 1].tolist()
    (True, (2, 2, 2), [inf, inf])
    """

    array_s: np.ndarray

    @classmethod
    def packed(cls, timings) -> Timings:
        """The timings (tuples of windows), packed."""
        out = cls(timings)
        out.array_s = packed_windows_s(out, max((len(w) for w in out), default=0))
        return out


def packed_windows_s(timings, k: int) -> np.ndarray:
    """Timings (tuples of windows) as an array ``(len(timings), k, 2)`` padded with +inf: one flat list, one np.array
    call (a slice assignment per timing cost 30 us a fix). [s]"""
    flat: list[float] = []
    for windows in timings:
        for window in windows:
            flat += window
        flat += (np.inf,) * (2 * (k - len(windows)))
    return np.array(flat, dtype=float).reshape(len(timings), k, 2)


@quick_init
@dataclass(frozen=True, slots=True)
class LightView:
    """One light ahead, as the advisor sees it. Times are relative to now. [m], [s]

    ``red_windows_s``: upcoming red intervals ``(start, end)`` relative to now, conservative: an uncertain
    change to red counts from its earliest possible time, a change to green from its latest. A window with
    ``start <= 0`` means red now. At least the windows of the next ~2 minutes.

    Under uncertainty (an actuated light) two more views. ``likely_red_windows_s``: each change at its likely
    instant (the countdown; whether a stop is likely; what a plan aims between when the conservative windows leave
    no speed; it contains every red that minEnd guarantees). ``late_red_windows_s``: each change at its latest
    instant: a car reaching the line inside a likely red but before such a red begins may still beat it as it is,
    and is not slowed for the green after it; a driver's display may rely on a red lasting until then.
    """

    intersection_id: int
    distance_m: float
    fresh: bool = True
    confidence_frac: float = 1.0
    red_windows_s: tuple[tuple[float, float], ...] = ()
    likely_red_windows_s: tuple[tuple[float, float], ...] | None = None  # every change at its likely time; None: as red_windows_s
    late_red_windows_s: tuple[tuple[float, float], ...] | None = None  # every change at its latest; None: not known
    age_s: float = 0.0  # how old the SPaT behind this view is (a dropout: not fresh, windows of the last reading) [s]
    unknown_windows_s: tuple[tuple[float, float], ...] = ()  # phases whose state nothing reads, at their likely times [s]
    """Within the windows above, the phases whose state is unknown (J2735 ``unavailable`` or ``dark`` that the
    group's history cannot read, where they end: not the open tail past what it can bound), as each change is
    likely: no plan crosses in them, but they are not a red: no stop is asked for them (the driver is told there is
    no data)."""

    scenario_red_windows_s: tuple[tuple[tuple[float, float], ...], ...] | None = None
    """Under uncertainty, the red windows of each of the light's equally likely timings (every change at one quantile
    of its forecast, :mod:`advisory.advice.choice`); None: the timing is exact (``red_windows_s``). A window begins
    with the amber before its red, where the light shows one."""
    amber_s: float | None = None
    """The amber the light shows before each red, where its source knows it: None (unknown) is some amber, as traffic
    law requires; 0: none (a green may turn red at once). [s]"""

    queue_m: float | None = None
    """The queue standing back from the stop line that the controller published with a fresh reading (J2735
    ``queueLength``; queue-aware advice counts its cars first, :func:`advisory.advice.queue.estimate`); None: not said. [m]"""

    def likely_red_at(self, t_s: float) -> bool:
        """Red at ``t_s`` seconds from now if every change comes at its likely time (exact plans: :meth:`is_red_at`);
        a phase of unknown state is not a red."""
        windows = self.red_windows_s if self.likely_red_windows_s is None else self.likely_red_windows_s
        return any(start <= t_s < end for start, end in windows) and not self.unknown_at(t_s)

    def unknown_at(self, t_s: float) -> bool:
        """The state at ``t_s`` seconds from now is unknown (as each change is likely)."""
        return any(start <= t_s < end for start, end in self.unknown_windows_s)

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


@quick_init
@dataclass(frozen=True, slots=True)
class Observation:
    """What the advisor knows at one instant. ``lights``: the lights ahead, nearest first."""

    speed_mps: float
    speed_limit_mps: float
    lights: tuple[LightView, ...] = ()
    position_m: float | None = None  # along the corridor, for the DP tables
    on_route: bool = True
    zone_exit: bool = False  # left the route past its last light: the advice ends, nothing is wrong
    followers: float = 0.0
    """Cars expected behind this one that a slower plan holds up (the service's estimate in traffic:
    :func:`advisory.advice.queue.estimate`; 0 on an empty road). Each loses what the car loses, so every price the
    advisor puts on time lost is ``1 + followers`` times its own (:func:`time_price`). [-]"""


ACTIONS = ("cruise", "ease_off", "coast", "slow_down", "brake_to", "accelerate", "stop", "resume", "none")
"""Every ``Advice.action`` the advisor gives (the service's API enumerates these: keep them in step)."""
REASONS = ("green_wave", "red_ahead", "past_lights", "off_route", "no_spat", "stale_spat", "low_confidence", "too_close", "short_wait", "tight_green",
           "far_ahead")
"""Every ``Advice.reason`` the advisor gives (the service's API enumerates these: keep them in step)."""


@quick_init
@dataclass(frozen=True, slots=True)
class Advice:
    """One advisory. ``action``: cruise, ease_off (lift off and coast down to the target, then hold it),
    coast (brake gently to the target, then keep coasting to the light), slow_down (brake gently to the
    target, then hold it), brake_to (brake firmly to it, then hold), accelerate, stop, resume, or none (no
    speed advice; ``reason`` says why)."""

    action: str
    reason: str
    target_speed_mps: float | None = None
    light_red: bool | None = None
    seconds_to_change_s: float | None = None
    message: str = ""
    speak: bool = False
    source: str = "rules"  # "dp_table" when the target came from the lookup tables
    current_speed_mps: float | None = None  # the car's speed when advised ("Slow to X, then coast" vs "Lift off")
    light_ahead: int = 1  # which light the countdown (light_red, seconds_to_change_s) is about: 1 next, 2 the one after
    light_id: int | None = None  # that light's intersection id (None: no countdown)

    @property
    def counts_down_to(self) -> str | None:
        """What ``seconds_to_change_s`` counts down to: "green" while the light is red now, "red" while it is not;
        None without a countdown (unknown or never). Always the light's next change (``light_id``), never a later one."""
        if self.light_red is None or self.seconds_to_change_s is None or not math.isfinite(self.seconds_to_change_s):
            return None
        return "green" if self.light_red else "red"

    def as_dict(self) -> dict:
        return {k: getattr(self, k) for k in self.__slots__}


def time_price(obs: Observation) -> float:
    """How many cars lose the time a plan gives up: this one and the followers it holds up (``1 + obs.followers``).
    The price on time (``time_value_usd_per_s``, the choice under uncertainty) is multiplied by it, and the time a plan
    may give up for its energy (``table_slack_s``, the tables' target) divided by it (issue 28: the traffic behind; the
    service's own check counts it alike, :func:`advisory.advice.behind.gives_up_green`). [-]

    Examples
    --------
    >>> time_price(Observation(10.0, 20.0)), time_price(Observation(10.0, 20.0, followers=1.5))
    (1.0, 2.5)
    """
    return 1.0 + max(obs.followers, 0.0)


@dataclass(frozen=True, slots=True)
class AdvisorParams:
    """Advisor settings. Units in names."""

    min_cruise_speed_mps: float = 10 * 0.44704  # slowest speed ever advised (a creep towards a red)
    reaction_s: float = 1.0
    green_margin_s: float = 2.0  # advised crossings at least this long after a red ends (driver reaction, tracking error) [s]
    comfort_decel_mps2: float = 1.5
    firm_decel_mps2: float = 3.0  # "brake to X" when gentle braking cannot make the green (regular driver: 4)
    comfort_accel_mps2: float = 1.5
    normal_accel_mps2: float = 2.0  # how a driver speeds up with no advice (the regular driver's rate, paper Sec. 2)
    too_close_s: float = 3.0  # closer than this many seconds to the line at current speed: no advice
    too_close_m: float = 15.0
    short_wait_s: float = 3.0
    table_slack_s: float = 3.0  # the tables' target reaches the lines at most this much later than the fastest feasible one [s]
    min_confidence_frac: float = 0.5
    stop_lead_s: float = 2.0  # "prepare to stop" this long before a comfortable stop must begin (earlier: "Red light ahead.") [s]
    hold_stale_s: float = 30.0  # through a dropout this short the last advice is held (re-checked on the last SPaT) [s]
    hysteresis_mps: float = 1.0
    stop_risk_frac: float = 0.1  # uncertain timing: a plan may make a stop likelier than driving normally by at most this [-]
    time_value_usd_per_s: float | None = None  # uncertain timing: the price on time; None: the road's (choice.steady_time_value_usd_per_s) [$/s]
    speak_change_mps: float = 5 * 0.44704
    speed_step_mps: float = 0.44704  # candidates in whole mph: the spoken number is the advised one
    units: str = "mph"
    vehicle: VehicleParams = PAPER_54KWH  # for the coast-down profile

    def __post_init__(self) -> None:
        if self.units not in ("mph", "kmh"):
            raise ValueError("units must be 'mph' or 'kmh'")


@quick_init
@dataclass(frozen=True, slots=True)
class AdvisorMemory:
    """What the advisor remembers between fixes of one trip (for hysteresis and the speak flag)."""

    last: Advice | None = None
    spoken: Advice | None = None


def light_timing(light: LightView) -> tuple[bool, float | None]:
    """Red now, and the seconds to the next change, as likely (an actuated green past its minEnd is still green)."""
    light = countdown_view(light)
    if light.red_now:
        return True, light.seconds_to_green()
    return False, light.seconds_to_red()


def countdown_view(light: LightView) -> LightView:
    """The light with each change at its likely instant (what is said: "Green in 12 seconds")."""
    if light.likely_red_windows_s is None:
        return light
    return LightView(light.intersection_id, light.distance_m, light.fresh, light.confidence_frac, light.likely_red_windows_s)
