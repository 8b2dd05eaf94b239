"""A finished trip's score: the drive as recorded against the paper's regular driver, like with like.

What is compared (docs/SERVICE.md, "Score"):

* **The zone only.** The trip's on-route fixes, with their stations along the (extended) route, are cut to
  ``[0, length]`` by ``advisory.evaluation.track.cut_to_zone``: the entry and exit instants and speeds are
  interpolated between the fixes on either side of each edge; fixes outside are never moved onto the ends.
* **Like with like** (``advisory.evaluation.compare.compare_drive``, the same code as ``replay``): both
  drivers' speeds smoothed alike (``SMOOTH_S``), the regular driver sampled at the trip's own fix
  instants, entering where and as fast as the car entered (``Scenario.initial_speed_mps``), at the same
  instant, through the same SPaT: the trip's fixed-time plans, or for a trip on live SPaT the phases the
  trip observed (:class:`ObservedSignal`, from ``server.trips.ObservedLights``).
* **A trip ended early** is compared over the distance it drove: both drivers cut where its fixes stop
  (``compared_m``), never the drive's part against the regular driver's whole zone.
* **Red lights.** A stop line crossed while red (``advisory.evaluation.track.red_light_crossings``, with
  GPS tolerance) is listed with its time, light and how far into red, and the drive is never reported as
  a saving (``savings_frac`` is null). A line passed inside a gap between fixes longer than a few seconds
  (an outage) while its light changed is not judged: it is listed under ``red_light_unknown``.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from advisory.drivers.regular import regular_driver
from advisory.evaluation.compare import compare_drive, drive_in_zone
from advisory.evaluation.endstate import EndStateScore, score_in_end_state
from advisory.physics.params import model_params
from advisory.signals import Scenario
from advisory.trajectory import Trajectory
from spat_feed.transport.scenarios import FeedScenario, advisory_scenario_at

from server.schemas import DriverScoreOut, RedLightCrossingOut, RedLightUnknownOut, TripScoreOut


class ObservedSignal:
    """A light as a trip observed it: phase runs ``(start, end, class)`` on the scenario's time axis.

    Duck-types :class:`advisory.signals.FixedTimeSignal` (``position_m``, ``is_red``, ``next_green_start_s``,
    ``next_red_start_s``, ``red_intervals``) so the regular driver and the red-light check run on it.
    Outside the observed span, and in unknown phases, the light is taken as not red.
    """

    __slots__ = ("position_m", "reds")

    def __init__(self, position_m: float, runs, t0_unix_s: float) -> None:
        self.position_m = float(position_m)
        self.reds = [(float(a) - t0_unix_s, float(b) - t0_unix_s) for a, b, cls in runs if cls == "red"]

    def is_red(self, t_s):
        t = np.asarray(t_s, dtype=float)
        out = np.zeros(t.shape, dtype=bool)
        for a, b in self.reds:
            out |= (t >= a) & (t < b)
        return out if out.ndim else bool(out)

    def next_green_start_s(self, t_s: float) -> float:
        return next((b for a, b in self.reds if a <= t_s < b), t_s)

    def next_red_start_s(self, t_s: float) -> float:
        if self.is_red(t_s):
            return t_s
        return next((a for a, _ in self.reds if a > t_s), math.inf)

    def red_intervals(self, t0_s: float, t1_s: float) -> list[tuple[float, float]]:
        return [(a, b) for a, b in self.reds if b > t0_s and a <= t1_s]


def _out(score: EndStateScore, traj: Trajectory) -> DriverScoreOut:
    return DriverScoreOut(
        distance_m=round(float(traj.x_m[-1] - traj.x_m[0]), 1),
        duration_s=round(traj.duration_s, 2),
        exit_speed_mps=round(score.exit_speed_mps, 2),
        energy_kwh=round(score.energy_kwh, 6),
        soh_lost_frac=float(f"{score.soh_lost_frac:.4g}"),
        electricity_usd=round(score.electricity_usd, 6),
        wear_usd=round(score.wear_usd, 6),
        cost_usd=round(score.cost_usd, 6),
    )


def trip_score(
    trip_id: str,
    scenario: FeedScenario,
    vehicle: str,
    t_s: np.ndarray,
    v_mps: np.ndarray,
    x_m: np.ndarray,
    speed_limit_mps: float,
    *,
    observed: dict[int, list] | None = None,
    notes: list[str] | None = None,
) -> TripScoreOut:
    """Score a trip from its recorded on-route fixes ``(t, v, x)`` (Unix s, m/s, station m along the route
    extended beyond its ends; time-ordered). ``observed``: intersection id -> phase runs the trip saw
    (live SPaT); None: the scenario's plans are the truth."""
    params = model_params(vehicle)
    length_m = scenario.corridor.length_m
    speed_limit_mps = scenario.corridor.zone_speed_limit_mps(speed_limit_mps)  # the corridor's own limit where its file states one
    notes = list(notes or ())
    t, x, raw_v = np.asarray(t_s, dtype=float), np.asarray(x_m, dtype=float), np.asarray(v_mps, dtype=float)

    def lights_at(entry_s: float) -> Scenario:
        nonlocal observed
        if observed is None:
            try:
                return advisory_scenario_at(scenario, entry_s, speed_limit_mps)
            except ValueError:  # live lights: no plan to compare against, only what the trip saw
                observed = {}
        signals = tuple(ObservedSignal(ix.stop_line_m, observed.get(ix.id, ()), entry_s) for ix in scenario.corridor.intersections)
        notes.append("signal truth: the phases this trip observed on its live SPaT")
        return Scenario(f"{scenario.corridor.name} observed", signals, length_m, speed_limit_mps, speed_limit_mps)

    drive = drive_in_zone(t, x, raw_v, length_m, params, speed_limit_mps)
    if drive is None:
        entry_s = scenario.entry_unix_s
        notes.append("fewer than two on-route fixes reaching the zone: nothing to score for the drive; the regular driver enters at the trip's entry instant at the limit")
        regular_traj = regular_driver(replace(lights_at(entry_s), initial_speed_mps=speed_limit_mps))
        regular_score = score_in_end_state(regular_traj, params, speed_limit_mps)
        driven_out, savings, crossings, complete, coverage, compared_m, n, v_seen = None, None, [], False, 0.0, None, 0, speed_limit_mps
        unknown = []
    else:
        comp = compare_drive(drive, lights_at, params, speed_limit_mps)
        entry_s = drive.entry_s
        v_seen = float(np.interp(entry_s, t, np.minimum(raw_v, 70.0)))  # as recorded: between the fixes around the entry
        n = int(np.count_nonzero((x >= 0.0) & (x <= length_m)))
        notes += drive.notes
        regular_traj, regular_score = comp.regular.trajectory, comp.regular.score
        driven_out = _out(comp.driven.score, comp.driven.trajectory)
        crossings, complete, coverage, compared_m = comp.red_crossings, drive.complete, drive.coverage_frac, drive.distance_m
        savings = comp.savings()
        unknown = comp.red_unknown
        for u in unknown:
            notes.append(f"light {u.light} ({u.position_m:.0f} m) was passed during a {u.gap_to_s - u.gap_from_s:.0f} s gap in the fixes while it changed: "
                         "whether it was red is unknown")  # fmt: skip
        if crossings:
            notes.append("crossed a red light: this drive is not reported as a saving")
        else:
            savings = {key: round(value, 4) for key, value in savings.items()}
        if not complete and not drive.partial:
            notes.append("the fixes do not start at the zone's entry: the comparison is indicative")
    return TripScoreOut(
        trip_id=trip_id,
        complete=bool(complete),
        n_fixes=n,
        coverage_frac=round(min(coverage, 1.0), 4),
        compared_m=None if compared_m is None else round(compared_m, 1),
        vehicle=vehicle,
        entry_unix_s=round(entry_s, 3),
        entry_speed_mps=round(v_seen, 2),
        driven=driven_out,
        regular=_out(regular_score, regular_traj),
        savings_frac=savings,
        red_light_crossings=[
            RedLightCrossingOut(light=c.light, intersection_id=scenario.corridor.intersections[c.light - 1].id, t_unix_s=round(entry_s + c.t_s, 3),
                                into_red_s=round(c.into_red_s, 1), speed_mps=round(c.speed_mps, 2))
            for c in crossings
        ],  # fmt: skip
        red_light_unknown=[
            RedLightUnknownOut(light=u.light, intersection_id=scenario.corridor.intersections[u.light - 1].id,
                               gap_from_unix_s=round(entry_s + u.gap_from_s, 3), gap_to_unix_s=round(entry_s + u.gap_to_s, 3))
            for u in unknown
        ],  # fmt: skip
        note="; ".join(notes),
    )
