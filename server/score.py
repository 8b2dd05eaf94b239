"""A finished trip's score: the drive as recorded against the paper's regular driver, like with like.

What is compared (docs/SERVICE.md, "Score"):

* **The zone only.** The trip's on-route fixes, with their stations along the (extended) route, are cut to
  ``[0, length]`` by ``advisory.evaluation.track.cut_to_zone``: the entry and exit instants and speeds are
  interpolated between the fixes on either side of each edge; fixes outside are never moved onto the ends.
* **Speeds robust to GPS noise.** Both drivers' speeds go through the same pipeline: sampled at the trip's
  own fix instants, Gaussian-smoothed (``SMOOTH_S``, ``advisory.evaluation.track.smooth_speed_mps``, as
  ``replay`` smooths), standstill below 0.2 m/s, positions integrated from the speeds. Speed noise reads
  as kinetic-energy churn and 1 Hz sampling rounds off braking peaks; passing the regular driver through
  the same sampling cancels the second, the smoothing shrinks the first.
* **The regular driver starts where and as fast as the car entered** (``Scenario.initial_speed_mps``:
  the car's speed at the interpolated entry, at most the limit), at the same instant, and sees the same
  SPaT: the trip's fixed-time plans, or for a trip on live SPaT the phases the trip observed
  (:class:`ObservedSignal`, from ``server.trips.ObservedLights``).
* **Red lights.** A stop line crossed while red (``advisory.evaluation.track.red_light_crossings``, with
  GPS tolerance) is listed with its time, light and how far into red, and the drive is never reported as
  a saving (``savings_frac`` is null).
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from advisory.drivers.regular import regular_driver
from advisory.evaluation.endstate import EndStateScore, score_in_end_state
from advisory.evaluation.track import STANDSTILL_MPS, cut_to_zone, red_light_crossings, smooth_speed_mps, trajectory_from_samples
from advisory.physics.params import model_params
from advisory.signals import Scenario
from advisory.trajectory import Trajectory
from spat_feed.scenarios import FeedScenario, advisory_scenario_at

from server.schemas import DriverScoreOut, RedLightCrossingOut, TripScoreOut

EDGE_M = 25.0
"""A drive counts as complete if its fixes start within this of the zone entry and cross the exit. [m]"""
SMOOTH_S = 1.0
"""Gaussian smoothing (standard deviation) of both drivers' speeds. With 0.2 m/s of white speed noise at 1 Hz it
leaves ~0.1 m/s: on the 16 paper timings the regular driver's own noisy drive scores -0.1 % energy on average
(sd 0.9 %, worst 2.1 %; tests/server/test_score.py); unsmoothed -4.7 % (sd 5.9 %, worst 21 %). [s]"""


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


def _pipeline(t_s: np.ndarray, v_mps: np.ndarray) -> np.ndarray:
    """Smoothed speeds, the ends held constant beyond the samples (so the first and last are not pulled
    towards their inner neighbours), standstill set to 0."""
    if t_s.size < 2:
        return v_mps.copy()
    pad = np.arange(1.0, 3.0 * SMOOTH_S + 1.0)
    t = np.concatenate([t_s[0] - pad[::-1], t_s, t_s[-1] + pad])
    v = np.concatenate([np.full(pad.size, v_mps[0]), v_mps, np.full(pad.size, v_mps[-1])])
    v = smooth_speed_mps(t, v, SMOOTH_S)[pad.size : pad.size + t_s.size]
    v[v < STANDSTILL_MPS] = 0.0
    return v


def sampled_like(reference: Trajectory, fix_t_s: np.ndarray, length_m: float) -> Trajectory:
    """``reference`` (time 0 = zone entry) as the trip's fixes would have recorded it: sampled at the fixes'
    interval and sub-second phase, through the same smoothing, cut to the zone and integrated again."""
    dt = float(np.median(np.diff(fix_t_s))) if fix_t_s.size >= 2 else 1.0
    dt = min(max(dt, 0.1), 5.0)
    pad = 3.0 * SMOOTH_S + dt
    phase = float(np.mod(fix_t_s[0], dt)) if fix_t_s.size else 0.0
    t = np.arange(phase - pad - dt, reference.duration_s + pad, dt)
    t_end = reference.t_s[-1]
    inside = np.clip(t, 0.0, t_end)
    v0, v1 = float(reference.v_mps[0]), float(reference.v_mps[-1])
    v = reference.speed_at(inside)
    x = np.where(t < 0.0, v0 * t, np.where(t > t_end, length_m + v1 * (t - t_end), reference.position_at(inside)))
    zone = cut_to_zone(t, x, _pipeline(t, v), length_m)
    return trajectory_from_samples(zone.t_s, zone.v_mps, 0.0, t0_s=zone.t_in_s)


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
    t, x, raw_v = np.asarray(t_s, dtype=float), np.asarray(x_m, dtype=float), np.minimum(np.asarray(v_mps, dtype=float), 70.0)
    v = _pipeline(t, raw_v) if t.size else raw_v
    zone = cut_to_zone(t, x, v, length_m) if t.size >= 2 else None
    n = 0 if zone is None else int(np.count_nonzero((x >= 0.0) & (x <= length_m)))
    if zone is None:
        entry_s, v_in = scenario.entry_unix_s, speed_limit_mps
        notes.append("fewer than two on-route fixes reaching the zone: nothing to score for the drive; the regular driver enters at the trip's entry instant at the limit")
    else:
        entry_s = zone.t_in_s
        v_in = float(min(max(zone.v_mps[0], 0.0), speed_limit_mps))
    v_seen = v_in if zone is None else float(np.interp(entry_s, t, raw_v))  # as recorded: between the fixes around the entry
    try:
        lights = None if observed is not None else advisory_scenario_at(scenario, entry_s, speed_limit_mps)
    except ValueError:  # live lights: no plan to compare against, only what the trip saw
        observed, lights = {}, None
    if lights is None:
        signals = tuple(ObservedSignal(ix.stop_line_m, observed.get(ix.id, ()), entry_s) for ix in scenario.corridor.intersections)
        lights = Scenario(f"{scenario.corridor.name} observed", signals, length_m, speed_limit_mps, speed_limit_mps)
        notes.append("signal truth: the phases this trip observed on its live SPaT")
    lights = replace(lights, initial_speed_mps=v_in)
    exact_regular = regular_driver(lights)
    driven_out = savings = None
    crossings = []
    complete = False
    coverage = 0.0
    if zone is None:
        regular_traj = exact_regular
    else:
        fix_t = zone.t_s[1:-1] - entry_s if zone.t_s.size > 2 else zone.t_s - entry_s
        regular_traj = sampled_like(exact_regular, fix_t, length_m)
        # measured alike, the regular driver must enter exactly as fast as the trip was measured to: one
        # correction of its entry speed by the difference its own measurement makes (1 Hz across a kink)
        v_fix = float(min(max(v_in + (zone.v_mps[0] - regular_traj.v_mps[0]), 0.0), speed_limit_mps))
        if abs(v_fix - v_in) > 1e-6:
            lights = replace(lights, initial_speed_mps=v_fix)
            regular_traj = sampled_like(regular_driver(lights), fix_t, length_m)
        traj = trajectory_from_samples(zone.t_s, zone.v_mps, 0.0, t0_s=entry_s)
        driven = score_in_end_state(traj, params, speed_limit_mps)
        regular = score_in_end_state(regular_traj, params, speed_limit_mps)
        driven_out = _out(driven, traj)
        complete = zone.first_station_m <= EDGE_M and zone.exit_seen
        covered = (length_m if zone.exit_seen else zone.last_station_m) - (0.0 if zone.entry_seen else zone.first_station_m)
        coverage = max(0.0, covered) / length_m
        crossings = red_light_crossings(traj, lights.signals, t - entry_s, x)
        if crossings:
            notes.append("crossed a red light: this drive is not reported as a saving")
        else:
            savings = {
                key: round(float(1.0 - a / b), 4) if b > 0 else 0.0
                for key, a, b in (
                    ("energy", driven.energy_kwh, regular.energy_kwh),
                    ("wear", driven.soh_lost_frac, regular.soh_lost_frac),
                    ("cost", driven.cost_usd, regular.cost_usd),
                )
            }
        if not complete:
            notes.append("the fixes do not cover the whole zone: the comparison is indicative")
    regular_score = score_in_end_state(regular_traj, params, speed_limit_mps)
    return TripScoreOut(
        trip_id=trip_id,
        complete=bool(complete),
        n_fixes=n,
        coverage_frac=round(min(coverage, 1.0), 4),
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
        note="; ".join(notes),
    )
