"""A recorded drive against the paper's regular driver, like with like: the one comparison behind the
service's trip score (``server.score``) and ``replay`` (``replay.drive``).

Given a drive's on-route fixes ``(t, station, speed)`` (stations along the route extended beyond its ends),
:func:`drive_in_zone` (steps 1-2, and the drive's score) and :func:`compare_drive` (steps 3-4):

1. **Speeds**: Gaussian-smoothed (``smooth_s``, default :data:`SMOOTH_S`; the ends held constant beyond the
   fixes), standstill below ``STANDSTILL_MPS`` (:func:`smoothed_speeds`).
2. **Distance**: the zone ``[0, length]``, cut at its edges (``advisory.evaluation.track.cut_to_zone``). A drive
   whose fixes stop before the zone's end (a trip ended early) is compared over the distance it drove: cut
   where its fixes stop, and the regular driver cut at the same distance.
3. **The regular driver** enters at the same instant and as fast as the drive (at most the limit), sees the
   same lights (``lights_at(entry)``), and is measured as the drive was (:func:`measured_like`: sampled at
   the fixes' interval and sub-second phase, through the same smoothing, cut at the same distance): 1 Hz
   sampling rounds off braking peaks, so the regular driver is rounded off alike. One correction of its
   entry speed makes it enter exactly as fast as the drive was measured to.
4. **Scores** in the paper's common end state (``advisory.evaluation.endstate.score_in_end_state``: the
   distance + re-acceleration to the limit) and :func:`savings_frac`, ``1 - drive / regular`` (positive =
   less than the regular driver), none when a stop line was crossed while red. A line crossed inside a gap
   in the fixes while its light changed is neither (``red_unknown``): the drive is compared, with a note.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np

from advisory.drivers.regular import regular_driver
from advisory.evaluation.endstate import EndStateScore, score_in_end_state
from advisory.evaluation.track import (
    STANDSTILL_MPS,
    RedCrossing,
    RedLightCheck,
    UnjudgedCrossing,
    ZoneCut,
    cut_to_zone,
    red_light_check,
    smooth_speed_mps,
    trajectory_from_samples,
)
from advisory.physics.params import ModelParams
from advisory.signals import Scenario
from advisory.trajectory import Trajectory

SMOOTH_S = 1.0
"""Gaussian smoothing (standard deviation) of both drivers' speeds. With 0.2 m/s of white speed noise at 1 Hz it
leaves ~0.1 m/s: on the 16 paper timings the regular driver's own noisy drive scores -0.1 % energy on average
(sd 0.9 %, worst 2.1 %; tests/server/test_score.py); unsmoothed -4.7 % (sd 5.9 %, worst 21 %). [s]"""
EDGE_M = 25.0
"""A drive is complete if its fixes start within this of the zone entry and cross the exit. [m]"""
MAX_SPEED_MPS = 70.0
"""Recorded speeds are clipped here (a receiver's glitch). [m/s]"""


def smoothed_speeds(t_s: np.ndarray, v_mps: np.ndarray, smooth_s: float = SMOOTH_S) -> np.ndarray:
    """Smoothed speeds, the ends held constant beyond the samples (so the first and last are not pulled
    towards their inner neighbours), standstill set to 0."""
    v_mps = np.minimum(np.asarray(v_mps, dtype=float), MAX_SPEED_MPS)
    if t_s.size < 2 or smooth_s <= 0:
        v = v_mps.copy()
    else:
        pad = np.arange(1.0, 3.0 * smooth_s + 1.0)
        t = np.concatenate([t_s[0] - pad[::-1], t_s, t_s[-1] + pad])
        v = np.concatenate([np.full(pad.size, v_mps[0]), v_mps, np.full(pad.size, v_mps[-1])])
        v = smooth_speed_mps(t, v, smooth_s)[pad.size : pad.size + t_s.size]
    v[v < STANDSTILL_MPS] = 0.0
    return v


def measured_like(reference: Trajectory, fix_t_s: np.ndarray, distance_m: float, smooth_s: float = SMOOTH_S) -> Trajectory:
    """``reference`` (time 0 = zone entry, from station 0) as the drive's fixes would have recorded it: sampled
    at the fixes' interval and sub-second phase (``fix_t_s`` on the same axis), through the same smoothing,
    cut at ``distance_m`` and integrated again."""
    dt = float(np.median(np.diff(fix_t_s))) if fix_t_s.size >= 2 else 1.0
    dt = min(max(dt, 0.1), 5.0)
    pad = 3.0 * smooth_s + dt
    phase = float(np.mod(fix_t_s[0], dt)) if fix_t_s.size else 0.0
    t = np.arange(phase - pad - dt, reference.duration_s + pad, dt)
    t_end = reference.t_s[-1]
    inside = np.clip(t, 0.0, t_end)
    v0, v1 = float(reference.v_mps[0]), float(reference.v_mps[-1])
    v = reference.speed_at(inside)
    x = np.where(t < 0.0, v0 * t, np.where(t > t_end, float(reference.x_m[-1]) + v1 * (t - t_end), reference.position_at(inside)))
    zone = cut_to_zone(t, x, smoothed_speeds(t, v, smooth_s), distance_m)
    return trajectory_from_samples(zone.t_s, zone.v_mps, 0.0, t0_s=zone.t_in_s)


def savings_frac(a: EndStateScore, b: EndStateScore) -> dict[str, float]:
    """``1 - a / b`` for energy, wear (SOH lost) and cost: positive = ``a`` used less than ``b``."""
    return {key: float(1.0 - x / y) if y > 0 else 0.0
            for key, x, y in (("energy", a.energy_kwh, b.energy_kwh), ("wear", a.soh_lost_frac, b.soh_lost_frac), ("cost", a.cost_usd, b.cost_usd))}  # fmt: skip


@dataclass(frozen=True, slots=True)
class DriverResult:
    """One driver over the compared distance: its trajectory and its end-state score."""

    trajectory: Trajectory
    score: EndStateScore

    def as_dict(self) -> dict:
        s = self.score
        return {
            "distance_m": s.zone.distance_m,
            "duration_s": self.trajectory.duration_s,
            "exit_speed_mps": s.exit_speed_mps,
            "zone_net_kwh": s.zone.net_kwh,
            "energy_kwh": s.energy_kwh,
            "soh_lost_frac": s.soh_lost_frac,
            "electricity_usd": s.electricity_usd,
            "wear_usd": s.wear_usd,
            "cost_usd": s.cost_usd,
            "time_to_end_state_s": s.time_s,
        }


@dataclass(frozen=True)
class ZoneDrive:
    """A recorded drive over the distance it is compared on (times on the fixes' clock)."""

    t_s: np.ndarray
    station_m: np.ndarray
    """The on-route fixes as given: times and stations (extended beyond the zone's ends)."""
    zone: ZoneCut
    """The drive's smoothed samples over the compared distance."""
    length_m: float
    """The zone's length. [m]"""
    distance_m: float
    """The compared distance: the zone's length, or where the fixes of a partial drive stop. [m]"""
    complete: bool
    coverage_frac: float
    driven: DriverResult
    smooth_s: float
    notes: list[str] = field(default_factory=list)

    @property
    def entry_s(self) -> float:
        return self.zone.t_in_s

    @property
    def partial(self) -> bool:
        """The fixes stop before the zone's end: both drivers are scored over :attr:`distance_m` only."""
        return self.distance_m < self.length_m

    def red_crossings(self, signals) -> list[RedCrossing]:
        """Stop lines this drive crossed while red (``signals`` on a time axis whose 0 is the entry)."""
        return self.red_check(signals).crossings

    def red_check(self, signals) -> RedLightCheck:
        """The red-light verdicts (``advisory.evaluation.track.red_light_check``): the crossings judged red, and
        those inside a gap in the fixes that cannot be judged."""
        return red_light_check(self.driven.trajectory, signals, self.t_s - self.entry_s, self.station_m)

    def measured(self, reference: Trajectory, params: ModelParams, speed_limit_mps: float, keep_series: bool = False) -> DriverResult:
        """Another driver (time 0 = the entry, from station 0: the regular driver, the DP optimum) measured as
        this drive was and scored over the same distance."""
        fix_t = self.zone.t_s[1:-1] - self.entry_s if self.zone.t_s.size > 2 else self.zone.t_s - self.entry_s
        traj = measured_like(reference, fix_t, self.distance_m, self.smooth_s)
        return DriverResult(traj, score_in_end_state(traj, params, speed_limit_mps, keep_series=keep_series))


def drive_in_zone(
    t_s: np.ndarray,
    station_m: np.ndarray,
    v_mps: np.ndarray,
    length_m: float,
    params: ModelParams,
    speed_limit_mps: float,
    *,
    smooth_s: float = SMOOTH_S,
    keep_series: bool = False,
) -> ZoneDrive | None:
    """Steps 1-2 and the drive's score: its on-route fixes (time-ordered) smoothed and cut to the zone, or to
    the distance it drove; None when the fixes never reach the zone."""
    t, x = np.asarray(t_s, dtype=float), np.asarray(station_m, dtype=float)
    if t.size < 2:
        return None
    v = smoothed_speeds(t, v_mps, smooth_s)
    zone = cut_to_zone(t, x, v, length_m)
    if zone is None:
        return None
    notes: list[str] = []
    complete = bool(zone.first_station_m <= EDGE_M and zone.exit_seen)
    distance_m = float(length_m)
    if not zone.exit_seen:
        distance_m = zone.last_station_m
        cut = cut_to_zone(t, x, v, distance_m) if distance_m > 0.0 else None
        if cut is None or cut.t_s.size < 2:
            return None
        zone = replace(cut, exit_seen=False)
        notes.append(f"the fixes stop at {distance_m:.1f} m of the zone's {length_m:.0f} m: compared over those {distance_m:.1f} m, "
                     "the regular driver over the same distance")  # fmt: skip
    covered = distance_m - (0.0 if zone.entry_seen else zone.first_station_m)
    traj = trajectory_from_samples(zone.t_s, zone.v_mps, 0.0, t0_s=zone.t_in_s)
    driven = DriverResult(traj, score_in_end_state(traj, params, speed_limit_mps, keep_series=keep_series))
    return ZoneDrive(t, x, zone, float(length_m), distance_m, complete, max(0.0, min(covered / length_m, 1.0)), driven, float(smooth_s), notes)


@dataclass(frozen=True)
class Comparison:
    """A drive and the regular driver over the same distance, measured alike."""

    drive: ZoneDrive
    lights: Scenario
    """The lights as the regular driver saw them (time 0 = the entry; its entry speed set)."""
    regular: DriverResult
    red_crossings: list[RedCrossing]
    red_unknown: list[UnjudgedCrossing] = field(default_factory=list)
    """Stop lines crossed inside a gap in the fixes while the light changed: red or not is unknown."""

    @property
    def driven(self) -> DriverResult:
        return self.drive.driven

    def savings(self, against: DriverResult | None = None) -> dict[str, float] | None:
        """:func:`savings_frac` of the drive against the regular driver (or ``against``); None after a red."""
        return None if self.red_crossings else savings_frac(self.driven.score, (against or self.regular).score)


def compare_drive(
    drive: ZoneDrive, lights_at: Callable[[float], Scenario], params: ModelParams, speed_limit_mps: float, *, keep_series: bool = False
) -> Comparison:
    """Steps 3-4: ``drive`` against the regular driver. ``lights_at(entry_s)``: the lights on a time axis
    whose 0 is the drive's zone entry ``entry_s`` (on the fixes' clock)."""
    zone = drive.zone
    v_in = float(min(max(zone.v_mps[0], 0.0), speed_limit_mps))
    lights = replace(lights_at(drive.entry_s), initial_speed_mps=v_in)
    regular = drive.measured(regular_driver(lights), params, speed_limit_mps, keep_series)
    # measured alike, the regular driver must enter exactly as fast as the drive was measured to: one
    # correction of its entry speed by the difference its own measurement makes (1 Hz across a kink)
    v_fix = float(min(max(v_in + (zone.v_mps[0] - regular.trajectory.v_mps[0]), 0.0), speed_limit_mps))
    if abs(v_fix - v_in) > 1e-6:
        lights = replace(lights, initial_speed_mps=v_fix)
        regular = drive.measured(regular_driver(lights), params, speed_limit_mps, keep_series)
    check = drive.red_check(lights.signals)
    return Comparison(drive, lights, regular, check.crossings, check.unknown)
