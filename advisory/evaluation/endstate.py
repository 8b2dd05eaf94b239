"""Compare drivers in the same end state: back at the speed limit.

The paper ends its zone 100 m after light 2 (it also mentions 200 m), but a car leaving a standstill at
light 2 needs ``v_lim² / (2 · 2 m/s²) = 151 m`` to regain 88.5 km/h, so drivers can leave the zone at
different speeds. A slower exit has saved kinetic energy the car will still have to spend. We therefore
charge each driver, at the zone end, the **re-acceleration penalty** of the regular driver's own rule:
accelerate at 2 m/s² from the exit speed to the limit, *minus* cruising the same distance at the limit
(a car already at the limit). The penalty has an energy, a wear, a cost and a time part (time lost against
a car at the limit); it is zero at the limit. The DP uses the same function as its terminal cost and adds
the time part to its trip-time constraint, so both drivers are scored over the same end state.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from advisory.physics.model import J_PER_KWH, pack, soh_loss_frac, step_battery_power_w
from advisory.physics.params import ModelParams
from advisory.evaluation.scoring import DriveScore, score_trace
from advisory.trajectory import Trajectory


@dataclass(frozen=True, slots=True)
class Penalty:
    """Re-acceleration penalty (arrays or floats): energy [kWh], SOH [-], cost [$], time [s]."""

    energy_kwh: np.ndarray
    soh_lost_frac: np.ndarray
    cost_usd: np.ndarray
    time_s: np.ndarray


def reacceleration_penalty(
    exit_speed_mps, params: ModelParams, speed_limit_mps: float, accel_mps2: float = 2.0, n_sub: int = 32
) -> Penalty:
    """Penalty of leaving the zone at ``exit_speed_mps`` (array or float) instead of at the limit."""
    v0 = np.minimum(np.atleast_1d(np.asarray(exit_speed_mps, dtype=float)), speed_limit_mps)
    p, rates, pref = pack(params)
    frac = np.linspace(0.0, 1.0, n_sub + 1)
    v = v0[:, None] + (speed_limit_mps - v0[:, None]) * frac[None, :]  # (n, n_sub + 1)
    t_acc = (speed_limit_mps - v0) / accel_mps2
    dt = np.maximum(t_acc / n_sub, 1e-12)[:, None]
    battery_w = step_battery_power_w(v[:, :-1], v[:, 1:], dt, 0.0, p)
    energy_j = (battery_w * dt).sum(axis=1)
    soh = soh_loss_frac(battery_w, dt, p, rates, pref).sum(axis=1)
    d_acc = (speed_limit_mps**2 - v0**2) / (2.0 * accel_mps2)
    t_cruise = d_acc / speed_limit_mps
    cruise_w = step_battery_power_w(speed_limit_mps, speed_limit_mps, 1.0, 0.0, p)
    energy_j = energy_j - cruise_w * t_cruise
    soh = soh - soh_loss_frac(cruise_w, t_cruise, p, rates, pref)
    energy_kwh = energy_j / J_PER_KWH
    wear_usd = soh * params.cost.battery_usd_per_kwh * params.vehicle.pack_energy_kwh
    return Penalty(energy_kwh, soh, energy_kwh * params.cost.electricity_usd_per_kwh + wear_usd, t_acc - t_cruise)


@dataclass(frozen=True, slots=True)
class EndStateScore:
    """A drive through the zone plus the re-acceleration penalty to the common end state (at the limit)."""

    zone: DriveScore
    exit_speed_mps: float
    energy_kwh: float
    soh_lost_frac: float
    electricity_usd: float
    wear_usd: float
    time_s: float

    @property
    def cost_usd(self) -> float:
        return self.electricity_usd + self.wear_usd


def score_in_end_state(
    traj: Trajectory, params: ModelParams, speed_limit_mps: float, max_dt_s: float = 0.1, keep_series: bool = False
) -> EndStateScore:
    """Score a trajectory over its zone (sampled every <= ``max_dt_s``) plus the penalty to the limit."""
    t, _, v = traj.sample(max_dt_s)
    zone = score_trace(t, v, params, keep_series=keep_series)
    pen = reacceleration_penalty(v[-1], params, speed_limit_mps)
    energy = zone.net_kwh + float(pen.energy_kwh[0])
    soh = zone.soh_lost_frac + float(pen.soh_lost_frac[0])
    return EndStateScore(
        zone=zone,
        exit_speed_mps=float(v[-1]),
        energy_kwh=energy,
        soh_lost_frac=soh,
        electricity_usd=energy * params.cost.electricity_usd_per_kwh,
        wear_usd=soh * params.cost.battery_usd_per_kwh * params.vehicle.pack_energy_kwh,
        time_s=traj.duration_s + float(pen.time_s[0]),
    )
