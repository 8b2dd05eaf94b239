"""A feed scenario: a corridor, a timing and a trip's entry instant, giving every light's plan in Unix time.

The timing is a paper-style :class:`~spat_feed.timing.paper.Timing` (relative to the entry) or a signal-plan
file (:class:`~spat_feed.timing.signal_plans.SignalPlan`: the pattern in force at the entry, on the Unix axis);
lights a plan marks ``live`` have no simulated plan (their SPaT comes from a live source).
:func:`resolve_timing` turns a timing name into one of these for a corridor.

Pure: :func:`spat_message_at` builds the SPaT message of a scenario at an instant it is handed. The
service (``spat_feed.transport.service``) and the in-process source (``spat_feed.transport.store``) both call it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache

from advisory.physics.params import SPEED_LIMIT_MPS
from advisory.signals import Scenario
from spat_feed.road.corridors import Corridor, load_corridor, load_plan
from spat_feed.timing.messages import IntersectionState, MovementState, SpatMessage, from_unix_s, movement_events
from spat_feed.timing.plans import FixedTimePlan, Plan, to_fixed_time_signal, uncertain_from_fixed
from spat_feed.timing.paper import TIMING_PRESETS, Timing, timing_for_trip
from spat_feed.timing.signal_plans import SignalPlan, TimingLike


@dataclass(frozen=True, slots=True)
class Uncertainty:
    """How an actuated controller's change windows spread around the fixed plan's instants. [s, s, -]

    Each change is published as ``[t - early_s, t + late_s]`` with ``likelyTime = t``; the simulated
    controller really changes at ``t``.
    """

    early_s: float = 0.0
    late_s: float = 0.0
    confidence_frac: float = 1.0

    def __post_init__(self) -> None:
        if self.early_s < 0 or self.late_s < 0 or not 0 <= self.confidence_frac <= 1:
            raise ValueError(f"bad uncertainty {self}")

    @property
    def is_fixed(self) -> bool:
        return self.early_s == 0 and self.late_s == 0


@dataclass(frozen=True, slots=True)
class FeedScenario:
    """Lights of ``corridor`` timed by ``timing`` for a car entering the zone at ``entry_unix_s``."""

    corridor: Corridor
    timing: TimingLike
    entry_unix_s: float
    uncertainty: Uncertainty = field(default_factory=Uncertainty)

    def __post_init__(self) -> None:
        self.timing.check(self.corridor)

    @property
    def key(self) -> tuple:
        """Identifies the scenario: subscribers with equal keys receive the same messages."""
        u = self.uncertainty
        return (self.corridor.name, self.timing.name, round(self.entry_unix_s, 3), u.early_s, u.late_s, u.confidence_frac)

    def fixed_plans(self) -> dict[tuple[int, int], FixedTimePlan]:
        """(intersection id, signal group) -> fixed-time plan on the Unix axis (``live`` lights absent)."""
        return self.timing.fixed_plans(self.corridor, self.entry_unix_s)

    def plans_at(self, now_unix_s: float) -> dict[tuple[int, int], Plan]:
        """The plans as published at ``now_unix_s``: fixed, or uncertain windows around now.

        An uncertain plan covers one cycle before to four cycles after ``now_unix_s``; windows inside
        that span do not depend on ``now_unix_s``, so successive messages agree.
        """
        fixed = self.fixed_plans()
        if self.uncertainty.is_fixed:
            return dict(fixed)
        u = self.uncertainty
        return {
            key: uncertain_from_fixed(
                p, now_unix_s - p.cycle_s, now_unix_s + 4 * p.cycle_s, early_s=u.early_s, late_s=u.late_s, confidence_frac=u.confidence_frac
            )
            for key, p in fixed.items()
        }

    def advisory_scenario(self) -> Scenario:
        """The :class:`advisory.signals.Scenario` the DP advisor plans against (time 0 = zone entry)."""
        return advisory_scenario_at(self, self.entry_unix_s)


def advisory_scenario_at(scenario: FeedScenario, entry_unix_s: float, speed_limit_mps: float = SPEED_LIMIT_MPS) -> Scenario:
    """The lights of ``scenario`` as an :class:`advisory.signals.Scenario` whose time 0 is ``entry_unix_s``.

    The plans stay anchored at ``scenario.entry_unix_s``; ``entry_unix_s`` is when a car really crossed
    station 0 (a recorded drive rarely enters at the planned instant to the millisecond). With
    ``entry_unix_s == scenario.entry_unix_s`` this is :meth:`FeedScenario.advisory_scenario`.

    The speed limit is the corridor's lowest over the zone when its file states limits, else
    ``speed_limit_mps`` (the DP and the regular driver take one limit; never above any segment's).
    ``ValueError`` if a light is ``live`` (no fixed plan to plan against).
    """
    plans = scenario.fixed_plans()
    missing = [ix.id for ix in scenario.corridor.intersections if (ix.id, ix.signal_groups[0].id) not in plans]
    if missing:
        raise ValueError(f"intersection(s) {missing} of {scenario.corridor.name!r} are live in timing {scenario.timing.name!r}: no fixed plan to compare against")
    signals = tuple(
        to_fixed_time_signal(plans[(ix.id, ix.signal_groups[0].id)], ix.stop_line_m, t0_s=entry_unix_s) for ix in scenario.corridor.intersections
    )
    limit = scenario.corridor.zone_speed_limit_mps(speed_limit_mps)
    return Scenario(f"{scenario.corridor.name} {scenario.timing.name}", signals, scenario.corridor.length_m, limit, limit)


@lru_cache(maxsize=64)
def _cached_corridor(name_or_path: str) -> Corridor:
    return load_corridor(name_or_path)


def resolve_timing(corridor: Corridor, timing: str | TimingLike | None, entry_unix_s: float = 0.0, *, allow_files: bool = True) -> TimingLike:
    """The timing a trip on ``corridor`` runs under.

    ``timing``: a plan of the corridor by name, a paper preset by name (``"15_15"``, ``"field_test"``), a
    plan file by path (``.json``/``.toml``), or ``None`` / ``"trip"``: the corridor's default plan if it has
    one, else one of the paper's 16 picked from ``entry_unix_s`` (:func:`timing_for_trip`). ``KeyError``
    for an unknown name; ``ValueError`` (naming the file) for a plan that does not fit the corridor.
    ``allow_files=False`` (names from a network request): paths are unknown names.
    """
    if isinstance(timing, (Timing, SignalPlan)):
        out = timing
    elif timing is None or timing == "trip":
        out = corridor.plan() or timing_for_trip(entry_unix_s)
    elif any(p.name == timing for p in corridor.plans):
        out = corridor.plan(timing)
    elif timing in TIMING_PRESETS:
        out = TIMING_PRESETS[timing]
    elif allow_files and timing.lower().endswith((".json", ".toml")):
        out = load_plan(timing)
        try:
            out.check(corridor)
        except ValueError as exc:
            raise ValueError(f"{timing}: {exc}") from None
    else:
        plans = [p.name for p in corridor.plans]
        files = ", or a plan file (.json/.toml)" if allow_files else ""
        raise KeyError(f"unknown timing {timing!r}; choose from {plans + sorted(TIMING_PRESETS)} or 'trip'{files}")
    out.check(corridor)
    return out


def make_scenario(
    corridor: str | Corridor = "paper_s400",
    timing: str | TimingLike | None = "15_15",
    entry_unix_s: float = 0.0,
    uncertainty: Uncertainty | None = None,
) -> FeedScenario:
    """A scenario from names (see :func:`resolve_timing`); ``timing="trip"``: the corridor's default plan,
    or one of the paper's 16 picked from ``entry_unix_s``."""
    if isinstance(corridor, str):
        corridor = _cached_corridor(corridor)
    return FeedScenario(corridor, resolve_timing(corridor, timing, entry_unix_s), float(entry_unix_s), uncertainty or Uncertainty())


def spat_message_at(scenario: FeedScenario, now_unix_s: float, n_events: int = 3, *, revision: int = 0) -> SpatMessage:
    """The SPaT message of every light in ``scenario`` at ``now_unix_s``.

    Each signal group reports its current state and the next ``n_events - 1``, with their windows.
    """
    plans = scenario.plans_at(now_unix_s)
    stamp = from_unix_s(now_unix_s)
    intersections = []
    for ix in scenario.corridor.intersections:
        states = [
            MovementState(
                signal_group=sg.id,
                movement_name=sg.name or None,
                state_time_speed=movement_events(plans[(ix.id, sg.id)], now_unix_s, n_events),
            )
            for sg in ix.signal_groups
            if (ix.id, sg.id) in plans  # a live light: no simulated state
        ]
        if not states:
            continue
        intersections.append(IntersectionState(id=ix.id, name=ix.name, revision=revision, timestamp=stamp, states=states))
    return SpatMessage(timestamp=stamp, name=f"{scenario.corridor.name} {scenario.timing.name}", intersections=intersections)
