"""The simulated controllers of a city: one SPaT stream per intersection, shared by every trip.

A real intersection publishes one state whatever the number of cars approaching it. The simulator does the
same: each intersection of the served corridors runs the corridor's own signal plan (its default plan file,
the pattern of the hour, cycles anchored on the local midnight), or, for a corridor without plans, the
paper's ``15_15`` timing anchored on the Unix epoch (every light turns red 15 s past each minute). Lights a
plan marks ``live`` are not simulated: their SPaT comes from a real source (a log, MQTT).

:func:`shared_scenario` is the :class:`~spat_feed.transport.scenarios.FeedScenario` a trip entering at an instant runs
under (its fixed plans are what the simulator publishes); :class:`IntersectionSimulator` renders every
intersection's J2735 state at an instant, the same text for every subscriber.

Pure: the instant is handed in; no clock, no I/O.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import replace

from spat_feed.road.corridors import Corridor
from spat_feed.timing.paper import TIMING_PRESETS
from spat_feed.timing.messages import IntersectionState, MovementState, from_unix_s, movement_events
from spat_feed.timing.plans import FixedTimePlan, next_changes
from spat_feed.transport.scenarios import FeedScenario
from spat_feed.timing.signal_plans import light_plans_at

SHARED_TIMING = "15_15"
"""The timing of a corridor without plans, anchored on the Unix epoch (a paper timing: red 30 s, green 30 s)."""


def shared_scenario(corridor: Corridor, entry_unix_s: float) -> FeedScenario:
    """The plans a trip entering ``corridor`` at ``entry_unix_s`` sees on the shared (per-intersection) SPaT.

    The corridor's default plan with its own reference (local midnight: the pattern in force at entry), or
    the paper's ``15_15`` anchored at Unix 0 (the same for every trip, unlike the per-trip ``timing=``).

    Examples
    --------
    >>> from spat_feed.road.corridors import paper_corridor
    >>> sc = shared_scenario(paper_corridor(400.0), 1_000_000.0)
    >>> plan = sc.fixed_plans()[(1, 2)]
    >>> plan.offset_s % 60.0, plan.red_s
    (15.0, 30.0)
    """
    plan = corridor.plan()
    if plan is not None and plan.reference == "local_midnight":
        return FeedScenario(corridor, plan, float(entry_unix_s))
    if plan is not None:
        return FeedScenario(corridor, plan, 0.0)
    timing = TIMING_PRESETS[SHARED_TIMING]  # every light of any number turns red at 15 s past each minute
    return FeedScenario(corridor, replace(timing, red_starts_s=(timing.red_starts_s[0],) * len(corridor.intersections)), 0.0)


def next_change_s(plan: FixedTimePlan, t_unix_s: float) -> float:
    """The first state change of ``plan`` after ``t_unix_s``. [s]"""
    return next_changes(plan, t_unix_s, 1)[0].likely_s


def simulated_plans(corridors: Iterable[Corridor], t_unix_s: float) -> dict[tuple[int, int], FixedTimePlan]:
    """(intersection id, signal group) -> plan of every simulated light at ``t_unix_s`` (live lights left out).

    Two corridors naming the same intersection must agree on its plans (one controller, one timing);
    ``ValueError`` naming both otherwise.
    """
    out: dict[tuple[int, int], FixedTimePlan] = {}
    owner: dict[int, str] = {}
    for corridor in corridors:
        for key, plan in light_plans_at(corridor, None, t_unix_s, 0.0).items():
            if plan is None:
                continue
            if key in out and out[key] != plan:
                raise ValueError(
                    f"intersection {key[0]} signal group {key[1]} has one plan in corridor {owner[key[0]]!r} and another in {corridor.name!r}: "
                    "one intersection id is one controller; give distinct intersections distinct ids"
                )
            out[key] = plan
            owner.setdefault(key[0], corridor.name)
    return out


class IntersectionSimulator:
    """Every simulated intersection's J2735 state at an instant (see the module docstring).

    Parameters
    ----------
    corridors : iterable of Corridor
        The served corridors; intersections shared by several corridors are published once.
    n_events : int
        Events per signal group: the current state and the next ``n_events - 1``.
    """

    def __init__(self, corridors: Iterable[Corridor], n_events: int = 3) -> None:
        self.corridors = tuple(corridors)
        self.n_events = n_events
        self.names = {ix.id: ix.name for c in self.corridors for ix in c.intersections}
        self._plans: dict[tuple[int, int], FixedTimePlan] = {}
        self._valid_until_s = -math.inf
        self._movements: dict[int, tuple[float, float, list[MovementState]]] = {}  # id -> (from, until, states)
        self.plans_at(0.0)  # a clash between corridors fails at start-up

    def plans_at(self, t_unix_s: float) -> dict[tuple[int, int], FixedTimePlan]:
        """The plans in force at ``t_unix_s``, re-read only when a plan's pattern may change."""
        if not self._valid_until_s > t_unix_s >= self._valid_until_s - 86_400.0:
            self._plans = simulated_plans(self.corridors, t_unix_s)
            switches = [p.next_switch_unix_s(t_unix_s) for c in self.corridors if (p := c.plan()) is not None]
            self._valid_until_s = min([s for s in switches if s > t_unix_s], default=t_unix_s + 86_400.0)
        return self._plans

    @property
    def intersection_ids(self) -> tuple[int, ...]:
        return tuple(sorted({i for i, _ in self._plans}))

    def states_at(self, t_unix_s: float) -> list[IntersectionState]:
        """One :class:`IntersectionState` per simulated intersection, stamped ``t_unix_s``.

        A fixed plan's events change only when its state does: they are rendered then and reused (with the
        new timestamp) until the next change, so a tick costs a few microseconds per intersection."""
        plans = self.plans_at(t_unix_s)
        cached = self._movements
        if any(not (c[0] <= t_unix_s < c[1]) for c in cached.values()) or not cached:
            by_ix: dict[int, list[tuple[int, FixedTimePlan]]] = {}
            for (ix, sg), plan in sorted(plans.items()):
                by_ix.setdefault(ix, []).append((sg, plan))
            for ix, groups in by_ix.items():
                c = cached.get(ix)
                if c is not None and c[0] <= t_unix_s < c[1]:
                    continue
                until = min(min(next_change_s(p, t_unix_s) for _, p in groups), self._valid_until_s)
                movements = [MovementState(signal_group=sg, state_time_speed=movement_events(p, t_unix_s, self.n_events)) for sg, p in groups]
                cached[ix] = (t_unix_s, until, movements)
        stamp = from_unix_s(t_unix_s)
        return [IntersectionState.model_construct(id=ix, name=self.names.get(ix), revision=0, timestamp=stamp, states=c[2]) for ix, c in cached.items()]
