r"""EV longitudinal power model: paper Eq. 1, with a physical treatment of braking.

All functions are pure and elementwise: they take floats or numpy arrays (broadcast together) and
use only arithmetic and numpy ufuncs, so ``numba.njit`` compiles them unchanged for the kernels.

References
----------
.. [1] Y. Wang, S. G. Advani, A. K. Prasad, "Effects of eco-driving on energy consumption and battery
   degradation for electric vehicles at signalized intersections," arXiv preprint, 2024 (Eq. 1, Table 1).
.. [2] L. Guzzella, A. Sciarretta, *Vehicle Propulsion Systems*, 3rd ed., Springer, 2013, ch. 2,
   doi:10.1007/978-3-642-35913-2.
"""

from __future__ import annotations

import numpy as np
from numba.extending import register_jitable

from advisory.physics.battery import interp_clamped
from advisory.physics.params import G_MPS2, MPH_TO_MPS


@register_jitable
def road_load_force_n(
    speed_mps,
    grade_frac,
    mass_kg,
    rolling_coef,
    rolling_speed_coef_s_per_m,
    drag_coef,
    frontal_area_m2,
    air_density_kg_per_m3,
):
    r"""
    Tractive force at the wheels needed to hold a speed: grade, rolling and aerodynamic drag.

    Parameters
    ----------
    speed_mps : numeric
        Speed over ground, >= 0. [m/s]
    grade_frac : numeric
        Road grade, rise over run, positive uphill. [-]
    mass_kg : float
        Vehicle mass including payload. [kg]
    rolling_coef, rolling_speed_coef_s_per_m : float
        Rolling resistance C_r1 [-] and its speed term C_r2. [s/m]
    drag_coef, frontal_area_m2, air_density_kg_per_m3 : float
        Aerodynamic drag coefficient C_d [-], frontal area A [m²], air density rho. [kg/m³]

    Returns
    -------
    numeric
        Road-load force; negative on descents steep enough to overcome the losses. [N]

    Notes
    -----
    .. math:: F = m g \sin\theta + (C_{r1} + C_{r2} v) m g \cos\theta + \tfrac12 \rho A C_d v^2,
              \quad \theta = \arctan(\text{grade})

    Examples
    --------
    Paper vehicle (Table 1) at the 55 mph limit on the flat:
    rolling (0.0065 + 4.92e-5 * 24.5872) * 1611 * 9.80665 = 121.81 N,
    aero 0.5 * 1.225 * 2.22 * 0.23 * 24.5872**2 = 189.06 N.

    >>> round(float(road_load_force_n(24.5872, 0.0, 1611.0, 0.0065, 4.92e-5, 0.23, 2.22, 1.225)), 2)
    310.86
    """
    # sin(arctan g) = g / sqrt(1 + g²), cos(arctan g) = 1 / sqrt(1 + g²): one sqrt instead of three trig calls.
    cos_theta = 1.0 / np.sqrt(1.0 + grade_frac * grade_frac)
    weight_n = mass_kg * G_MPS2
    slope_n = weight_n * grade_frac * cos_theta
    rolling_n = (rolling_coef + rolling_speed_coef_s_per_m * speed_mps) * weight_n * cos_theta
    aero_n = 0.5 * air_density_kg_per_m3 * frontal_area_m2 * drag_coef * speed_mps * speed_mps
    return slope_n + rolling_n + aero_n


@register_jitable
def wheel_power_w(
    speed_mps,
    accel_mps2,
    grade_frac,
    mass_kg,
    rolling_coef,
    rolling_speed_coef_s_per_m,
    drag_coef,
    frontal_area_m2,
    air_density_kg_per_m3,
):
    r"""
    Mechanical power at the wheels, the bracket of paper Eq. 1 times speed.

    Parameters
    ----------
    speed_mps, accel_mps2, grade_frac : numeric
        Speed [m/s], acceleration [m/s²] and road grade [-].
    mass_kg, rolling_coef, rolling_speed_coef_s_per_m, drag_coef, frontal_area_m2, air_density_kg_per_m3
        As in :func:`road_load_force_n`.

    Returns
    -------
    numeric
        Wheel power: positive when the motor drives, negative when the car must be braked. [W]

    Notes
    -----
    .. math:: P_{wheel} = (m a + F_{road}(v, \theta))\, v

    Examples
    --------
    Cruise at 24.5872 m/s on the flat: 310.86 N * 24.5872 m/s = 7643 W.

    >>> round(float(wheel_power_w(24.5872, 0.0, 0.0, 1611.0, 0.0065, 4.92e-5, 0.23, 2.22, 1.225)))
    7643
    """
    force_n = mass_kg * accel_mps2 + road_load_force_n(
        speed_mps,
        grade_frac,
        mass_kg,
        rolling_coef,
        rolling_speed_coef_s_per_m,
        drag_coef,
        frontal_area_m2,
        air_density_kg_per_m3,
    )
    return force_n * speed_mps


@register_jitable
def em_eff_frac(power_frac, map_power_frac, map_eff_frac):
    r"""
    Efficiency of the electric machine (motor + inverter) at a fraction of its peak power.

    Parameters
    ----------
    power_frac : numeric
        Machine power over its peak, either direction (shaft out when driving, shaft in when braking). [-]
    map_power_frac, map_eff_frac : 1-D arrays
        The efficiency curve: increasing power fractions and the efficiency at each. [-], [-]

    Returns
    -------
    numeric
        Efficiency, linear between the curve's points and held at its ends. [-]

    Notes
    -----
    FASTSim's convention (Brooker et al. 2015): one curve against power fraction, used for both directions.
    A curve against power is a torque-speed map collapsed along the road load: light load is
    where a permanent-magnet machine's fixed (iron, inverter switching) losses weigh most.

    Examples
    --------
    FASTSim's 2022 Model 3 curve at 5 % of 239 kW (12 kW): halfway between 0.88 (4 %) and 0.90 (6 %).

    >>> import numpy as np
    >>> x = np.array([0.0, 0.02, 0.04, 0.06, 0.08, 0.1, 0.2, 0.4, 0.6, 0.8, 1.0])
    >>> y = np.array([0.84, 0.86, 0.88, 0.90, 0.91, 0.92, 0.94, 0.95, 0.95, 0.94, 0.93])
    >>> round(float(em_eff_frac(0.05, x, y)), 4)
    0.89
    """
    return interp_clamped(np.abs(power_frac), map_power_frac, map_eff_frac)  # (numba's np.interp allocates per scalar call)


@register_jitable
def regen_share_frac(speed_mps, share_max_frac, fade_a, fade_b_per_mph):
    r"""
    Share of the braking demand the motor takes at a speed: full above walking pace, fading to zero at rest.

    Parameters
    ----------
    speed_mps : numeric
        Speed over ground. [m/s]
    share_max_frac : float
        Share at speed. [-]
    fade_a, fade_b_per_mph : float
        Fade constants (FASTSim 2: 500 and 0.99 1/mph); ``fade_a = 0`` turns the fade off. [-], [1/mph]

    Returns
    -------
    numeric
        Share of the wheels' braking power routed to the motor (before its power limit). [-]

    Notes
    -----
    .. math:: s(v) = \frac{s_{max}}{1 + a\, e^{-b (v_{mph} + 1)}}

    FASTSim 2's ``regen_contrl_lim_kw_perc`` (``simdrive.py``, constants ``regen_a``, ``regen_b`` in
    ``parameters.py``): motors cannot brake to a standstill, so the friction brakes take over below
    ~5 mph (2.2 m/s).

    Examples
    --------
    >>> round(float(regen_share_frac(0.0, 0.98, 500.0, 0.99)), 4)
    0.0052
    >>> round(float(regen_share_frac(5 * 0.44704, 0.98, 500.0, 0.99)), 3)
    0.423
    >>> float(regen_share_frac(3.0, 1.0, 0.0, 0.0))
    1.0
    """
    return share_max_frac / (1.0 + fade_a * np.exp(-fade_b_per_mph * (speed_mps / MPH_TO_MPS + 1.0)))


@register_jitable
def motor_braking_power_w(wheel_power_w, regen_eff_frac, regen_share_frac, regen_power_max_w):
    r"""
    Part of the braking power at the wheels that the motor absorbs (the rest goes to the friction brakes).

    Parameters
    ----------
    wheel_power_w : numeric
        Wheel power; only its negative part (braking) matters. [W]
    regen_eff_frac : numeric
        Efficiency of the chain from the wheels back to the battery (gear times machine). [-]
    regen_share_frac : numeric
        Share of the braking demand routed to the motor while under the power limit. [-]
    regen_power_max_w : float
        Largest charging power the drive delivers to the battery (``inf``: no limit). [W]

    Returns
    -------
    numeric
        Wheel-side braking power taken by the motor, >= 0. [W]

    Notes
    -----
    .. math:: B_m = \min\left(s\,\max(-P_{wheel}, 0),\ P_{regen,max}/\eta_r\right)

    Examples
    --------
    Braking at 50 kW with a 0.73 chain and a 60 kW battery-side limit: the motor can take
    60/0.73 = 82.2 kW at the wheels, so it takes all 50 kW.

    >>> float(motor_braking_power_w(-50e3, 0.73, 1.0, 60e3))
    50000.0
    """
    braking_w = np.maximum(-wheel_power_w, 0.0)
    return np.minimum(regen_share_frac * braking_w, regen_power_max_w / regen_eff_frac)


@register_jitable
def battery_power_w(wheel_power_w, drive_eff_frac, regen_eff_frac, regen_share_frac, regen_power_max_w, aux_power_w):
    r"""
    Battery terminal power for a wheel power: paper Eq. 1 when driving, physical regen when braking.

    Parameters
    ----------
    wheel_power_w : numeric
        Mechanical power at the wheels. [W]
    drive_eff_frac, regen_eff_frac : numeric
        Chain efficiency battery -> wheels when driving, wheels -> battery when braking; the paper's
        eta_trans * eta_motor * eta_invert for both. [-]
    regen_share_frac, regen_power_max_w : numeric
        As in :func:`motor_braking_power_w`. [-], [W]
    aux_power_w : float
        Constant accessory load (0 in the paper). [W]

    Returns
    -------
    numeric
        Power out of the battery; negative while regenerative braking charges it. [W]

    Notes
    -----
    .. math:: P_{batt} = \frac{\max(P_{wheel},0)}{\eta_d} - \eta_r\, B_m + P_{aux}

    Paper Eq. 1 divides by eta for every sign of P. Applied to braking that would return *more*
    energy than the wheels give up; here the loss chain multiplies on the way back, so the battery
    never recovers more than the kinetic and potential energy lost.

    Examples
    --------
    Cruise of the paper vehicle: 7643.28 W / (0.8536 * 0.90 * 0.95) = 10473 W.

    >>> eta = 0.8536 * 0.90 * 0.95
    >>> round(float(battery_power_w(7643.28, eta, eta, 1.0, float("inf"), 0.0)))
    10473
    >>> round(float(battery_power_w(-10e3, 0.73, 0.73, 1.0, 60e3, 0.0)))
    -7300
    """
    motor_w = motor_braking_power_w(wheel_power_w, regen_eff_frac, regen_share_frac, regen_power_max_w)
    return np.maximum(wheel_power_w, 0.0) / drive_eff_frac - regen_eff_frac * motor_w + aux_power_w
