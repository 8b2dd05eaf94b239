"""One step of driving, priced: the mid-step form shared by scoring and the DP.

A step goes from speed ``v0`` to ``v1`` in ``dt`` seconds at constant acceleration. It is evaluated at
its average speed (``v = (v0 + v1) / 2``, ``a = (v1 - v0) / dt``, distance ``v dt``), so the inertia
work ``m a v dt`` equals ``m (v1² - v0²) / 2`` exactly and a drive's kinetic energy is conserved.

Kernels receive the model as one float64 vector (``pack``) plus the two M(c) arrays; the indices
below name its entries. Everything here is ``register_jitable``: plain numpy in Python, inlined by numba.
"""

from __future__ import annotations

import numpy as np
from numba.extending import register_jitable

from advisory.physics.battery import ah_throughput_eol_ah, soh_rate_per_s
from advisory.physics.energy import battery_power_w, em_eff_frac, regen_share_frac, wheel_power_w
from advisory.physics.params import EM_MAP_MAX_POINTS, GAS_CONSTANT_J_PER_MOL_K, ModelParams

(
    I_MASS,
    I_CR1,
    I_CR2,
    I_DRAG,
    I_AREA,
    I_RHO,
    I_TRANS,
    I_REGEN_SHARE,
    I_REGEN_MAX,
    I_AUX,
    I_VOLT,
    I_PACK_AH,
    I_EA,
    I_EA_SLOPE,
    I_Z,
    I_DQ,
    I_TEMP,
    I_CELL_AH,
    I_C_MIN,
    I_C_MAX,
    I_DECAY_MULT,
    I_USD_PER_J,
    I_WEAR_USD,
    I_EM_PMAX,
    I_FADE_A,
    I_FADE_B,
    I_MAP_N,
    I_MAP_X,
) = range(28)
I_MAP_Y = I_MAP_X + EM_MAP_MAX_POINTS
N_PACKED = I_MAP_Y + EM_MAP_MAX_POINTS

J_PER_KWH = 3.6e6


def pack(params: ModelParams) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Flatten ``params`` for kernels: (vector of N_PACKED floats, M(c) C-rates, M(c) values)."""
    v, d, c = params.vehicle, params.degradation, params.cost
    vec = np.zeros(N_PACKED)
    vec[I_MASS] = v.mass_kg
    vec[I_CR1] = v.rolling_coef
    vec[I_CR2] = v.rolling_speed_coef_s_per_m
    vec[I_DRAG] = v.drag_coef
    vec[I_AREA] = v.frontal_area_m2
    vec[I_RHO] = v.air_density_kg_per_m3
    vec[I_TRANS] = v.trans_eff_frac
    vec[I_REGEN_SHARE] = v.regen_share_frac
    vec[I_REGEN_MAX] = v.regen_power_max_w
    vec[I_AUX] = v.aux_power_w
    vec[I_VOLT] = v.pack_voltage_v
    vec[I_PACK_AH] = v.pack_capacity_ah
    vec[I_EA] = d.activation_j_per_mol
    vec[I_EA_SLOPE] = d.activation_slope_j_per_mol_c
    vec[I_Z] = d.power_law_z
    vec[I_DQ] = d.capacity_loss_eol_pct
    vec[I_TEMP] = d.temperature_k
    vec[I_CELL_AH] = d.cell_capacity_ah
    vec[I_C_MIN] = d.c_rate_min
    vec[I_C_MAX] = d.c_rate_max
    vec[I_DECAY_MULT] = d.decay_multiplier
    vec[I_USD_PER_J] = c.electricity_usd_per_kwh / J_PER_KWH
    vec[I_WEAR_USD] = c.battery_usd_per_kwh * v.pack_energy_kwh
    vec[I_EM_PMAX] = v.em_power_max_w
    vec[I_FADE_A] = v.regen_fade_a
    vec[I_FADE_B] = v.regen_fade_b_per_mph
    xs, ys = v.em_map
    vec[I_MAP_N] = len(xs)
    vec[I_MAP_X : I_MAP_X + len(xs)] = xs
    vec[I_MAP_Y : I_MAP_Y + len(ys)] = ys
    return vec, np.asarray(d.m_c_rates, dtype=np.float64), np.asarray(d.m_prefactor, dtype=np.float64)


@register_jitable
def step_wheel_power_w(v0_mps, v1_mps, dt_s, grade_frac, p):
    """Wheel power [W] of a constant-acceleration step, evaluated at its mid-step speed."""
    return wheel_power_w(
        0.5 * (v0_mps + v1_mps),
        (v1_mps - v0_mps) / dt_s,
        grade_frac,
        p[I_MASS],
        p[I_CR1],
        p[I_CR2],
        p[I_DRAG],
        p[I_AREA],
        p[I_RHO],
    )


@register_jitable
def chain_effs(wheel_w, speed_mps, p):
    """(drive efficiency, regen efficiency, regen share) [-] of the chain at a wheel power [W] and speed [m/s].

    Driving, the machine delivers ``P_wheel / eta_trans``; braking, it takes ``share |P_wheel| eta_trans``; each
    is read off the machine's efficiency curve at that power over its peak. Constant-chain presets have a flat
    curve, so both efficiencies are ``eta_trans eta_motor eta_invert``.
    """
    trans = p[I_TRANS]
    n = int(p[I_MAP_N])
    xs, ys = p[I_MAP_X : I_MAP_X + n], p[I_MAP_Y : I_MAP_Y + n]
    share = regen_share_frac(speed_mps, p[I_REGEN_SHARE], p[I_FADE_A], p[I_FADE_B])
    drive_eff = trans * em_eff_frac(np.maximum(wheel_w, 0.0) / (trans * p[I_EM_PMAX]), xs, ys)
    regen_eff = trans * em_eff_frac(share * np.maximum(-wheel_w, 0.0) * trans / p[I_EM_PMAX], xs, ys)
    return drive_eff, regen_eff, share


@register_jitable
def battery_power_for_wheel_w(wheel_w, speed_mps, p):
    """Battery power [W] for a wheel power [W] at a speed [m/s] (paper Eq. 1 with physical regen and aux)."""
    drive_eff, regen_eff, share = chain_effs(wheel_w, speed_mps, p)
    return battery_power_w(wheel_w, drive_eff, regen_eff, share, p[I_REGEN_MAX], p[I_AUX])


@register_jitable
def step_battery_power_w(v0_mps, v1_mps, dt_s, grade_frac, p):
    """Battery power [W] of a constant-acceleration step, at its mid-step speed."""
    wheel_w = step_wheel_power_w(v0_mps, v1_mps, dt_s, grade_frac, p)
    return battery_power_for_wheel_w(wheel_w, 0.5 * (v0_mps + v1_mps), p)


@register_jitable
def soh_loss_frac(battery_w, dt_s, p, m_c_rates, m_prefactor):
    """SOH lost [-] (0..1 scale, 1 = whole life) while the battery delivers ``battery_w`` [W] for ``dt_s`` [s]."""
    current_a = battery_w / p[I_VOLT]
    c = np.abs(current_a) / p[I_PACK_AH]
    a_total = ah_throughput_eol_ah(
        c,
        m_c_rates,
        m_prefactor,
        p[I_EA],
        p[I_EA_SLOPE],
        p[I_Z],
        p[I_DQ],
        p[I_TEMP],
        GAS_CONSTANT_J_PER_MOL_K,
        p[I_C_MIN],
        p[I_C_MAX],
    )
    return -soh_rate_per_s(current_a, p[I_PACK_AH], a_total, p[I_CELL_AH], p[I_DECAY_MULT]) * dt_s


@register_jitable
def step_cost_usd(battery_w, dt_s, p, m_c_rates, m_prefactor):
    """Paper Eq. 4 over one step: electricity on net battery energy plus pack wear [$]."""
    wear = soh_loss_frac(battery_w, dt_s, p, m_c_rates, m_prefactor)
    return battery_w * dt_s * p[I_USD_PER_J] + wear * p[I_WEAR_USD]


@register_jitable
def arc_cost_usd(v0_mps, v1_mps, dt_s, grade_frac, n_steps, p, m_c_rates, m_prefactor):
    """Cost [$] of a constant-acceleration arc from ``v0`` to ``v1`` in ``dt_s``, in ``n_steps`` equal time steps.

    Each step is priced in the mid-step form, so the arc's kinetic energy is exact and its aerodynamic and
    battery-wear terms converge as ``n_steps`` grows (the scoring uses steps of 0.1 s).
    """
    total = 0.0 * v0_mps
    dv = (v1_mps - v0_mps) / n_steps
    step_s = dt_s / n_steps
    for s in range(n_steps):
        va = v0_mps + dv * s
        battery_w = step_battery_power_w(va, va + dv, step_s, grade_frac, p)
        total = total + step_cost_usd(battery_w, step_s, p, m_c_rates, m_prefactor)
    return total
