import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from advisory.physics.battery import ah_throughput_eol_ah, soh_rate_per_s
from advisory.physics.model import pack, soh_loss_frac
from advisory.physics.params import GAS_CONSTANT_J_PER_MOL_K, DegradationParams

D = DegradationParams()
RATES, PREF = np.array(D.m_c_rates), np.array(D.m_prefactor)


def a_total(c):
    return ah_throughput_eol_ah(
        c, RATES, PREF, D.activation_j_per_mol, D.activation_slope_j_per_mol_c, D.power_law_z,
        D.capacity_loss_eol_pct, D.temperature_k, GAS_CONSTANT_J_PER_MOL_K, D.c_rate_min, D.c_rate_max,
    )


@pytest.mark.parametrize("c,m", [(0.5, 31630), (2.0, 21681), (6.0, 12934), (10.0, 15512)])
def test_measured_points_by_hand(c, m):
    ea = 31700 - 370.3 * c
    expected = (20 / (m * np.exp(-ea / (8.3144 * 298.15)))) ** (1 / 0.55)
    assert a_total(c) == pytest.approx(expected, rel=1e-12)


def test_m_is_linear_between_measured_rates():
    c = 1.25  # midway between 0.5 C and 2 C
    m = 0.5 * (31630 + 21681)
    ea = 31700 - 370.3 * c
    assert a_total(c) == pytest.approx((20 / (m * np.exp(-ea / (8.3144 * 298.15)))) ** (1 / 0.55), rel=1e-12)


def test_below_half_c_the_whole_model_is_clamped():
    # every Ah below 0.5 C wears like an Ah at 0.5 C: no extrapolation of the fit
    assert a_total(np.array([0.0, 0.1, 0.3])) == pytest.approx(np.full(3, a_total(0.5)))
    assert a_total(20.0) == pytest.approx(a_total(10.0))


def test_a_pack_cycled_n_times_reaches_end_of_life():
    q_pack_ah, c = 154.0, 2.0
    current = c * q_pack_ah
    n_cycles = a_total(c) / D.cell_capacity_ah
    hours = 2 * n_cycles / c  # N full cycles: N charges and N discharges at c
    assert soh_rate_per_s(current, q_pack_ah, a_total(c), D.cell_capacity_ah, 1.0) * hours * 3600 == pytest.approx(-1.0)


@given(i1=st.floats(0, 3000), i2=st.floats(0, 3000))
def test_soh_loss_grows_with_current(paper, i1, i2):
    vec, rates, pref = pack(paper)
    lo, hi = sorted((i1, i2))
    volt = paper.vehicle.pack_voltage_v
    assert soh_loss_frac(hi * volt, 1.0, vec, rates, pref) >= soh_loss_frac(lo * volt, 1.0, vec, rates, pref) * (1 - 1e-12)


def test_sign_of_current_does_not_matter_and_multiplier_scales(paper):
    vec, rates, pref = pack(paper)
    vec10, _, _ = pack(paper.with_decay_multiplier(10))
    assert soh_loss_frac(-40e3, 1.0, vec, rates, pref) == soh_loss_frac(40e3, 1.0, vec, rates, pref) > 0
    assert soh_loss_frac(40e3, 1.0, vec10, rates, pref) == pytest.approx(10 * soh_loss_frac(40e3, 1.0, vec, rates, pref))
    assert soh_loss_frac(0.0, 1.0, vec, rates, pref) == 0.0


def test_parameters_are_checked():
    with pytest.raises(ValueError):
        DegradationParams(m_c_rates=(2.0, 0.5), m_prefactor=(1.0, 2.0))
    with pytest.raises(ValueError):
        DegradationParams(decay_multiplier=0.0)
