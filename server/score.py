"""A finished trip's score: the drive as recorded, and the paper's regular driver over the same SPaT.

Both are scored by ``advisory.evaluation.endstate.score_in_end_state`` (zone energy, wear and cost, plus the
re-acceleration to the speed limit at the zone end), with the trip's vehicle. The recorded drive is the
trip's on-route fixes inside the zone (speeds from the fixes; positions integrated from them, so the
trajectory is consistent). The regular driver (``advisory.drivers.regular``) enters the zone at the speed limit at
the instant the car entered it (the first fix, extrapolated back to station 0), facing the trip's plans.
"""

from __future__ import annotations

import numpy as np

from advisory.evaluation.endstate import EndStateScore, score_in_end_state
from advisory.physics.params import model_params
from advisory.drivers.regular import regular_driver
from advisory.signals import Scenario
from advisory.evaluation.track import entry_instant_s, trajectory_from_samples
from advisory.trajectory import Trajectory
from spat_feed.scenarios import FeedScenario, advisory_scenario_at

from server.schemas import DriverScoreOut, TripScoreOut

EDGE_M = 25.0
"""A drive counts as complete if its fixes start within this of the zone entry and end within it of the exit. [m]"""


def scenario_from(scenario: FeedScenario, entry_unix_s: float, speed_limit_mps: float) -> Scenario:
    """The trip's lights as an ``advisory.signals.Scenario`` whose time 0 is ``entry_unix_s``."""
    return advisory_scenario_at(scenario, entry_unix_s, speed_limit_mps)


def _out(score: EndStateScore, traj: Trajectory) -> DriverScoreOut:
    return DriverScoreOut(
        distance_m=float(traj.x_m[-1] - traj.x_m[0]),
        duration_s=traj.duration_s,
        exit_speed_mps=score.exit_speed_mps,
        energy_kwh=score.energy_kwh,
        soh_lost_frac=score.soh_lost_frac,
        electricity_usd=score.electricity_usd,
        wear_usd=score.wear_usd,
        cost_usd=score.cost_usd,
    )


def trip_score(
    trip_id: str, scenario: FeedScenario, vehicle: str, t_s: np.ndarray, v_mps: np.ndarray, x_m: np.ndarray, speed_limit_mps: float
) -> TripScoreOut:
    """Score a trip from its recorded fixes ``(t, v, x)`` (Unix s, m/s, station m; time-ordered)."""
    params = model_params(vehicle)
    length_m = scenario.corridor.length_m
    inside = (x_m >= 0.0) & (x_m <= length_m)
    t, v, x = t_s[inside], np.minimum(v_mps[inside], 70.0), x_m[inside]
    n = int(t.size)
    notes = []
    if n >= 1 and x[0] <= EDGE_M:
        entry_s = entry_instant_s(t[0], x[0], v[0])
    else:
        entry_s = scenario.entry_unix_s
        notes.append("no fix near the zone entry: the regular driver enters at the trip's entry instant")
    sc = scenario_from(scenario, entry_s, speed_limit_mps)
    speed_limit_mps = sc.speed_limit_mps  # the corridor's own limit where its file states one
    regular_traj = regular_driver(sc)
    regular = score_in_end_state(regular_traj, params, speed_limit_mps)
    driven_out = None
    savings = None
    coverage = float((x.max() - x.min()) / length_m) if n >= 2 else 0.0
    complete = n >= 2 and x[0] <= EDGE_M and x[-1] >= length_m - EDGE_M
    if n >= 2:
        traj = trajectory_from_samples(t, v, x0_m=x[0])
        driven = score_in_end_state(traj, params, speed_limit_mps)
        driven_out = _out(driven, traj)
        savings = {
            key: float(1.0 - a / b) if b > 0 else 0.0
            for key, a, b in (
                ("energy", driven.energy_kwh, regular.energy_kwh),
                ("wear", driven.soh_lost_frac, regular.soh_lost_frac),
                ("cost", driven.cost_usd, regular.cost_usd),
            )
        }
    else:
        notes.append("fewer than two on-route fixes with a speed: nothing to score for the drive")
    if n >= 2 and not complete:
        notes.append("the fixes do not cover the whole zone: the comparison is indicative")
    return TripScoreOut(
        trip_id=trip_id,
        complete=bool(complete),
        n_fixes=n,
        coverage_frac=min(coverage, 1.0),
        vehicle=vehicle,
        driven=driven_out,
        regular=_out(regular, regular_traj),
        savings_frac=savings,
        note="; ".join(notes),
    )
