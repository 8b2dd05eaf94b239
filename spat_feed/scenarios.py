"""A feed scenario: a corridor, a timing and a trip's entry instant, giving every light's plan in Unix time.

Pure: :func:`spat_message_at` builds the SPaT message of a scenario at an instant it is handed. The
service (``spat_feed.service``) and the in-process source (``spat_feed.source``) both call it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache

from advisory.physics.params import SPEED_LIMIT_MPS
from advisory.signals import Scenario
from spat_feed.corridors import TIMING_PRESETS, Corridor, Timing, load_corridor, timing_for_trip
from spat_feed.messages import IntersectionState, MovementState, SpatMessage, from_unix_s, movement_events
from spat_feed.plans import FixedTimePlan, Plan, to_fixed_time_signal, uncertain_from_fixed


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
    timing: Timing
    entry_unix_s: float
    uncertainty: Uncertainty = field(default_factory=Uncertainty)

    def __post_init__(self) -> None:
        if len(self.timing.red_starts_s) != len(self.corridor.intersections):
            raise ValueError(
                f"timing {self.timing.name!r} has {len(self.timing.red_starts_s)} lights, "
                f"corridor {self.corridor.name!r} has {len(self.corridor.intersections)}"
            )

    @property
    def key(self) -> tuple:
        """Identifies the scenario: subscribers with equal keys receive the same messages."""
        u = self.uncertainty
        return (self.corridor.name, self.timing.name, round(self.entry_unix_s, 3), u.early_s, u.late_s, u.confidence_frac)

    def fixed_plans(self) -> dict[tuple[int, int], FixedTimePlan]:
        """(intersection id, signal group) -> fixed-time plan on the Unix axis."""
        t = self.timing
        return {
            (ix.id, sg.id): FixedTimePlan(t.red_s, t.green_s, t.amber_s, self.entry_unix_s + red_start_s)
            for ix, red_start_s in zip(self.corridor.intersections, t.red_starts_s)
            for sg in ix.signal_groups
        }

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
    """
    plans = scenario.fixed_plans()
    signals = tuple(
        to_fixed_time_signal(plans[(ix.id, ix.signal_groups[0].id)], ix.stop_line_m, t0_s=entry_unix_s) for ix in scenario.corridor.intersections
    )
    return Scenario(f"{scenario.corridor.name} {scenario.timing.name}", signals, scenario.corridor.length_m, speed_limit_mps)


@lru_cache(maxsize=64)
def _cached_corridor(name_or_path: str) -> Corridor:
    return load_corridor(name_or_path)


def make_scenario(
    corridor: str | Corridor = "paper_s400",
    timing: str | Timing = "15_15",
    entry_unix_s: float = 0.0,
    uncertainty: Uncertainty | None = None,
) -> FeedScenario:
    """A scenario from preset names. ``timing="trip"`` picks one of the 16 from ``entry_unix_s``."""
    if isinstance(corridor, str):
        corridor = _cached_corridor(corridor)
    if isinstance(timing, str):
        timing = timing_for_trip(entry_unix_s) if timing == "trip" else TIMING_PRESETS[timing]
    return FeedScenario(corridor, timing, float(entry_unix_s), uncertainty or Uncertainty())


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
        ]
        intersections.append(IntersectionState(id=ix.id, name=ix.name, revision=revision, timestamp=stamp, states=states))
    return SpatMessage(timestamp=stamp, name=f"{scenario.corridor.name} {scenario.timing.name}", intersections=intersections)
