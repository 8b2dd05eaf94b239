"""Score a speed trace: energy, regen, battery wear and cost, with an energy audit that closes.

``score_trace(t_s, speed_mps, params)`` runs one fused numba pass over the steps (mid-step form,
``advisory.physics.model``; a long trace in parallel chunks of :data:`CHUNK_STEPS`). In the same pass it keeps
an energy audit whose terms come from their own formulas, not from the battery power: kinetic + potential +
aerodynamic + rolling + drivetrain losses + regen losses + friction braking + accessories equals the net battery
energy to rounding.
"""

from __future__ import annotations

import os
import threading
from dataclasses import dataclass

import numba
import numpy as np
from numba import njit, prange

from advisory.physics.energy import battery_power_w, motor_braking_power_w
from advisory.physics.model import (
    I_AREA,
    I_AUX,
    I_CR1,
    I_CR2,
    I_DRAG,
    I_MASS,
    I_REGEN_MAX,
    I_RHO,
    J_PER_KWH,
    chain_effs,
    pack,
    soh_loss_frac,
    step_wheel_power_w,
)
from advisory.physics.params import G_MPS2, ModelParams


# Slots of the kernel's running totals.
T_OUT, T_IN, T_SOH, T_DIST, T_POT, T_AERO, T_ROLL, T_DRIVE, T_REGEN, T_FRICTION, T_AUX, N_TOTALS = range(12)


CHUNK_STEPS = 1 << 16
"""Steps per chunk of a long trace; the chunks are scored in parallel and their totals summed in order (the same
sums, to rounding, whatever the number of threads)."""

if "NUMBA_THREADING_LAYER" not in os.environ:
    numba.config.THREADING_LAYER = "workqueue"
_PARALLEL = threading.Lock()
"""The parallel chunks run on numba's ``workqueue`` threading layer (unless ``NUMBA_THREADING_LAYER`` says
otherwise), one kernel at a time per process. GNU OpenMP, which numba picks where it finds it, is not fork-safe: a
process forked after a parallel kernel ran aborts at its own ("fork() called from a process already using GNU
OpenMP"; the study, spat-eval and the benches fork worker pools). ``workqueue`` is fork-safe but aborts when two
threads launch parallel kernels at once (numba docs, "The Threading Layers"; the service scores trips on its thread
pool): hence the lock."""


# fastmath: the inputs are validated finite; reordering and FMA move the sums by ~1e-15 relative (5.9 -> 7.9 M
# samples/s on one thread)
@njit(cache=True, fastmath=True)
def _score_steps(t_s, speed_mps, grade_frac, p, m_c_rates, m_prefactor, totals, out_battery_w, out_soh_loss, first, stop):
    """
    One pass over steps ``first`` to ``stop - 1`` of a trace (step k joins samples k and k+1).

    Accumulates into ``totals`` (N_TOTALS,): battery out / regen in [J], SOH lost [-], distance [m], and
    the audit terms [J], each computed from its own formula (not from the battery power). When
    ``out_battery_w`` / ``out_soh_loss`` have length n - 1 they receive the per-step battery power [W]
    and SOH loss [-]; pass empty arrays to skip them.
    """
    keep = out_battery_w.shape[0] > 0
    weight = p[I_MASS] * G_MPS2
    for k in range(first, stop):
        dt = t_s[k + 1] - t_s[k]
        grade = 0.5 * (grade_frac[k] + grade_frac[k + 1])
        wheel = step_wheel_power_w(speed_mps[k], speed_mps[k + 1], dt, grade, p)
        v = 0.5 * (speed_mps[k] + speed_mps[k + 1])
        drive_eff, regen_eff, share = chain_effs(wheel, v, p)  # once: for the battery power and the audit
        battery = battery_power_w(wheel, drive_eff, regen_eff, share, p[I_REGEN_MAX], p[I_AUX])
        soh = soh_loss_frac(battery, dt, p, m_c_rates, m_prefactor)
        energy = battery * dt
        if energy >= 0.0:
            totals[T_OUT] += energy
        else:
            totals[T_IN] -= energy
        totals[T_SOH] += soh
        if keep:
            out_battery_w[k] = battery
            out_soh_loss[k] = soh
        # audit terms
        dist = v * dt
        cos_theta = 1.0 / np.sqrt(1.0 + grade * grade)
        totals[T_DIST] += dist
        totals[T_POT] += weight * grade * cos_theta * dist
        totals[T_AERO] += 0.5 * p[I_RHO] * p[I_AREA] * p[I_DRAG] * v * v * dist
        totals[T_ROLL] += (p[I_CR1] + p[I_CR2] * v) * weight * cos_theta * dist
        motor = motor_braking_power_w(wheel, regen_eff, share, p[I_REGEN_MAX])
        if wheel > 0.0:
            totals[T_DRIVE] += wheel * (1.0 / drive_eff - 1.0) * dt
        else:
            totals[T_REGEN] += motor * (1.0 - regen_eff) * dt
            totals[T_FRICTION] += (-wheel - motor) * dt
        totals[T_AUX] += p[I_AUX] * dt


@dataclass(frozen=True, slots=True)
class EnergyAudit:
    """Where the net battery energy went [J]. ``residual_j`` is net battery minus the sum of the rest."""

    kinetic_j: float
    potential_j: float
    aero_j: float
    rolling_j: float
    drivetrain_loss_j: float
    regen_loss_j: float
    friction_brake_j: float
    aux_j: float
    residual_j: float


@dataclass(frozen=True, slots=True)
class TraceSeries:
    """Per-sample cumulative series, for plots (length n, starting at 0)."""

    t_s: np.ndarray
    position_m: np.ndarray
    speed_mps: np.ndarray
    battery_power_w: np.ndarray  # per step, length n - 1
    energy_kwh: np.ndarray
    soh_lost_frac: np.ndarray


@dataclass(frozen=True, slots=True)
class DriveScore:
    distance_m: float
    duration_s: float
    battery_out_kwh: float
    regen_in_kwh: float
    net_kwh: float
    wh_per_km: float
    soh_lost_frac: float
    capacity_loss_pct: float
    electricity_usd: float
    wear_usd: float
    audit: EnergyAudit
    series: TraceSeries | None = None

    @property
    def total_usd(self) -> float:
        return self.electricity_usd + self.wear_usd

    def as_dict(self) -> dict:
        keys = (
            "distance_m duration_s battery_out_kwh regen_in_kwh net_kwh wh_per_km soh_lost_frac "
            "capacity_loss_pct electricity_usd wear_usd"
        ).split()
        out = {k: getattr(self, k) for k in keys}
        out["total_usd"] = self.total_usd
        out["audit_j"] = {k: getattr(self.audit, k) for k in EnergyAudit.__slots__}
        return out


@njit(cache=True, parallel=True)
def _score_chunks(t_s, speed_mps, grade_frac, p, m_c_rates, m_prefactor, out_battery_w, out_soh_loss):
    """:func:`_score_steps` over chunks of :data:`CHUNK_STEPS` steps in parallel; the totals (N_TOTALS,)."""
    n_steps = t_s.shape[0] - 1
    n_chunks = (n_steps + CHUNK_STEPS - 1) // CHUNK_STEPS
    totals = np.zeros((n_chunks, N_TOTALS))
    for c in prange(n_chunks):
        stop = min((c + 1) * CHUNK_STEPS, n_steps)
        _score_steps(t_s, speed_mps, grade_frac, p, m_c_rates, m_prefactor, totals[c], out_battery_w, out_soh_loss, c * CHUNK_STEPS, stop)
    out = np.zeros(N_TOTALS)
    for c in range(n_chunks):  # in chunk order
        out += totals[c]
    return out


def _validate(t_s, speed_mps, grade_frac):
    t = np.ascontiguousarray(t_s, dtype=np.float64)
    v = np.ascontiguousarray(speed_mps, dtype=np.float64)
    if t.ndim != 1 or v.shape != t.shape:
        raise ValueError(f"t_s and speed_mps must be 1-D of the same length, got {t.shape} and {v.shape}")
    if t.size < 2:
        raise ValueError("a trace needs at least two samples")
    g = np.zeros_like(t) if grade_frac is None else np.ascontiguousarray(np.broadcast_to(grade_frac, t.shape), np.float64)
    for name, arr in (("t_s", t), ("speed_mps", v), ("grade_frac", g)):
        bad = np.flatnonzero(~np.isfinite(arr))
        if bad.size:
            raise ValueError(f"{name} is not finite at sample {bad[0]}")
    steps = np.diff(t)
    if (steps <= 0).any():
        raise ValueError(f"t_s must increase strictly; sample {int(np.argmax(steps <= 0)) + 1} does not")
    if (v < 0).any():
        raise ValueError(f"speed_mps must be >= 0; sample {int(np.argmax(v < 0))} is negative")
    return t, v, g


def score_trace(
    t_s,
    speed_mps,
    params: ModelParams,
    grade_frac=None,
    *,
    keep_series: bool = False,
) -> DriveScore:
    """
    Score a drive given as samples of time and speed (optionally grade).

    Parameters
    ----------
    t_s : array (n,)
        Sample times, strictly increasing. [s]
    speed_mps : array (n,)
        Speed at each sample, >= 0; constant acceleration between samples. [m/s]
    params : ModelParams
        Vehicle, degradation model and prices.
    grade_frac : array (n,) or float, optional
        Road grade at each sample, rise over run (default flat). [-]
    keep_series : bool
        Also return cumulative energy and SOH per sample (for plots).

    Returns
    -------
    DriveScore
        Totals in kWh, Wh/km, SOH fraction, $, and the energy audit in J.
    """
    t, v, g = _validate(t_s, speed_mps, grade_frac)
    vec, rates, pref = pack(params)
    n_keep = t.size - 1 if keep_series else 0
    battery_w, soh_loss = np.empty(n_keep), np.empty(n_keep)
    if t.size - 1 > CHUNK_STEPS:  # long traces in parallel chunks; a closed-loop run's few hundred steps in one
        with _PARALLEL:
            tot = _score_chunks(t, v, g, vec, rates, pref, battery_w, soh_loss)
    else:
        tot = np.zeros(N_TOTALS)
        _score_steps(t, v, g, vec, rates, pref, tot, battery_w, soh_loss, 0, t.size - 1)
    net_j = tot[T_OUT] - tot[T_IN]
    net_kwh = net_j / J_PER_KWH
    kinetic_j = 0.5 * params.vehicle.mass_kg * (v[-1] ** 2 - v[0] ** 2)
    parts = [kinetic_j] + [float(tot[i]) for i in (T_POT, T_AERO, T_ROLL, T_DRIVE, T_REGEN, T_FRICTION, T_AUX)]
    audit = EnergyAudit(*parts, residual_j=float(net_j - sum(parts)))
    distance_m = float(tot[T_DIST])
    soh = float(tot[T_SOH])
    series = None
    if keep_series:
        dt = np.diff(t)
        zero = np.zeros(1)
        series = TraceSeries(
            t_s=t,
            position_m=np.concatenate([zero, np.cumsum(0.5 * (v[1:] + v[:-1]) * dt)]),
            speed_mps=v,
            battery_power_w=battery_w,
            energy_kwh=np.concatenate([zero, np.cumsum(battery_w * dt) / J_PER_KWH]),
            soh_lost_frac=np.concatenate([zero, np.cumsum(soh_loss)]),
        )
    return DriveScore(
        distance_m=distance_m,
        duration_s=float(t[-1] - t[0]),
        battery_out_kwh=tot[T_OUT] / J_PER_KWH,
        regen_in_kwh=tot[T_IN] / J_PER_KWH,
        net_kwh=net_kwh,
        wh_per_km=net_kwh * 1e6 / distance_m if distance_m > 0 else float("nan"),
        soh_lost_frac=soh,
        capacity_loss_pct=soh * params.degradation.capacity_loss_eol_pct,
        electricity_usd=net_kwh * params.cost.electricity_usd_per_kwh,
        wear_usd=soh * params.cost.battery_usd_per_kwh * params.vehicle.pack_energy_kwh,
        audit=audit,
        series=series,
    )
