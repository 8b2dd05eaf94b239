r"""Battery wear: the graphite/LiFePO4 cycle-life model of Wang et al. (2011), paper Eq. 2-3.

Pure, elementwise functions (floats or numpy arrays, ``numba.njit``-compatible).

SOH here follows Ebbesen et al. (2012): 1 for a new pack, 0 at end of life (``capacity_loss_eol_pct``
of capacity lost), so ``battery_usd_per_kwh * pack_kwh * SOH lost`` is the share of the pack used up.

Choices the paper leaves open (docs/MODEL.md discusses them):

* **M(c) between the measured C-rates** (0.5, 2, 6, 10 C) is interpolated linearly in c.
* **Outside 0.5-10 C the whole model is evaluated at the clamped C-rate** (M *and* Ea). Wang et al. fitted
  it on cells cycled at 0.5 C and above; taken literally below 0.5 C (the linear Ea(c) with M held at
  its 0.5 C value, or M extrapolated along the 0.5-2 C segment) it is extrapolated into a regime it
  never saw, and the extrapolated M makes small currents *more* damaging per Ah than 0.5 C. With the
  clamp, every Ah below 0.5 C costs the same as at 0.5 C (a plain Ah-throughput model), and the decay
  *rate* still grows with current (see tests). The non-monotone shape inside 0.5-10 C (per Ah, 2 C
  wears less than 0.5 C) is the fit's and is kept as published.

References
----------
.. [1] J. Wang, P. Liu, J. Hicks-Garner, E. Sherman, S. Soukiazian, M. Verbrugge, H. Tataria,
   J. Musser, P. Finamore, "Cycle-life model for graphite-LiFePO4 cells," J. Power Sources,
   vol. 196, no. 8, pp. 3942-3948, 2011, doi:10.1016/j.jpowsour.2010.11.134.
.. [2] S. Ebbesen, P. Elbert, L. Guzzella, "Battery state-of-health perceptive energy management for
   hybrid electric vehicles," IEEE Trans. Veh. Technol., vol. 61, no. 7, pp. 2893-2900, 2012,
   doi:10.1109/TVT.2012.2203836.
"""

from __future__ import annotations

import numpy as np
from numba import types
from numba.extending import overload, register_jitable

SECONDS_PER_HOUR = 3600.0


def interp_clamped(x, xp, fp):
    """Piecewise-linear interpolation, constant beyond the ends: ``np.interp`` in numpy."""
    return np.interp(x, xp, fp)


@overload(interp_clamped)
def _interp_clamped_scalar(x, xp, fp):
    # numba's own np.interp allocates on every scalar call; a short linear scan is ~20x faster here.
    if isinstance(x, types.Float):

        def impl(x, xp, fp):
            n = xp.shape[0]
            if x <= xp[0]:
                return fp[0]
            for i in range(1, n):
                if x <= xp[i]:
                    w = (x - xp[i - 1]) / (xp[i] - xp[i - 1])
                    return fp[i - 1] + w * (fp[i] - fp[i - 1])
            return fp[n - 1]

        return impl
    return lambda x, xp, fp: np.interp(x, xp, fp)


@register_jitable
def c_rate(current_a, capacity_ah):
    r"""
    C-rate of a current: ``|I| / Q``.

    Parameters
    ----------
    current_a : numeric
        Battery current, either sign. [A]
    capacity_ah : float
        Capacity of the same pack or cell. [Ah]

    Returns
    -------
    numeric
        C-rate, >= 0. [1/h]

    Examples
    --------
    >>> round(float(c_rate(-308.57, 154.2857)), 4)
    2.0
    """
    return np.abs(current_a) / capacity_ah


@register_jitable
def ah_throughput_eol_ah(
    c_rate_per_h,
    m_c_rates,
    m_prefactor,
    activation_j_per_mol,
    activation_slope_j_per_mol_c,
    power_law_z,
    capacity_loss_eol_pct,
    temperature_k,
    gas_constant_j_per_mol_k,
    c_rate_min,
    c_rate_max,
):
    r"""
    Discharged Ah throughput of one cell until end of life at a C-rate, paper Eq. 2.

    Parameters
    ----------
    c_rate_per_h : numeric
        C-rate, clamped to [c_rate_min, c_rate_max] before use. [1/h]
    m_c_rates, m_prefactor : 1-D arrays
        Measured C-rates [1/h] and pre-exponential factors M [-], interpolated linearly.
    activation_j_per_mol, activation_slope_j_per_mol_c : float
        Ea(c) = activation_j_per_mol - activation_slope_j_per_mol_c * c. [J/mol], [J/(mol C)]
    power_law_z : float
        Power-law exponent z. [-]
    capacity_loss_eol_pct : float
        Capacity loss that ends life, Delta Q_b. [%]
    temperature_k, gas_constant_j_per_mol_k : float
        Cell temperature T [K] and R. [J/(mol K)]
    c_rate_min, c_rate_max : float
        Range of C-rates the fit was measured on. [1/h]

    Returns
    -------
    numeric
        A_total, discharged Ah throughput of a cell to end of life. [Ah]

    Notes
    -----
    .. math:: A_{total}(c, T) = \left[\frac{\Delta Q_b}{M(c)\, e^{-E_a(c)/(R T)}}\right]^{1/z}

    Examples
    --------
    At 2 C: Ea = 31700 - 740.6 = 30959.4 J/mol, exp(-30959.4 / (8.3144 * 298.15)) = exp(-12.48898) = 3.76797e-6,
    M * exp = 21681 * 3.76797e-6 = 0.081693, (20 / 0.081693) ** (1 / 0.55) = 22,047 Ah.

    >>> rates, m = np.array([0.5, 2, 6, 10.0]), np.array([31630, 21681, 12934, 15512.0])
    >>> round(float(ah_throughput_eol_ah(2.0, rates, m, 31700, 370.3, 0.55, 20, 298.15, 8.3144, 0.5, 10)), -1)
    22050.0
    """
    c = np.minimum(np.maximum(c_rate_per_h, c_rate_min), c_rate_max)
    prefactor = interp_clamped(c, m_c_rates, m_prefactor)
    activation = activation_j_per_mol - activation_slope_j_per_mol_c * c
    # [dQ / (M e^(-Ea/RT))]^(1/z) as one log and one exp (a pow is a log and an exp of its own)
    return np.exp((np.log(capacity_loss_eol_pct / prefactor) + activation / (gas_constant_j_per_mol_k * temperature_k)) / power_law_z)


@register_jitable
def soh_rate_per_s(current_a, pack_capacity_ah, ah_throughput_eol_cell_ah, cell_capacity_ah, decay_multiplier):
    r"""
    State-of-health decay rate, paper Eq. 3, per second.

    Parameters
    ----------
    current_a : numeric
        Battery current, either sign. [A]
    pack_capacity_ah : float
        Pack capacity Q. [Ah]
    ah_throughput_eol_cell_ah : numeric
        A_total of one cell at this current's C-rate (:func:`ah_throughput_eol_ah`). [Ah]
    cell_capacity_ah : float
        Capacity of the cell the model was fitted on (2.2 Ah in Wang et al.). [Ah]
    decay_multiplier : float
        Scales the rate (10 for the paper's NCA case). [-]

    Returns
    -------
    numeric
        dSOH/dt, <= 0. [1/s]

    Notes
    -----
    With N(c) = A_total / Q_cell the cycles to end of life,

    .. math:: \dot{SOH} = -k \frac{|I|}{2 N(c) Q}

    so a pack cycled N(c) times at C-rate c (2 N Q of |I| throughput, charge and discharge)
    loses exactly 1 of SOH.

    Examples
    --------
    154.29 A (1 C) on a 154.29 Ah pack, N = 22047 / 2.2 = 10021 cycles: -1 / (2 * 10021 * 3600) per s.

    >>> round(float(soh_rate_per_s(154.29, 154.29, 22047.0, 2.2, 1.0)) * 2 * 22047 / 2.2 * 3600, 12)
    -1.0
    """
    cycles = ah_throughput_eol_cell_ah / cell_capacity_ah
    return -decay_multiplier * np.abs(current_a) / (2.0 * cycles * pack_capacity_ah * SECONDS_PER_HOUR)
