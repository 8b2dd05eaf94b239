import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from advisory.physics.energy import (
    battery_power_w,
    em_eff_frac,
    motor_braking_power_w,
    regen_share_frac,
    road_load_force_n,
    wheel_power_w,
)
from advisory.physics.model import battery_power_for_wheel_w, pack
from advisory.physics.params import CALIBRATED, G_MPS2, PAPER_54KWH, SPEED_LIMIT_MPS, ModelParams

V = PAPER_54KWH
ARGS = (V.mass_kg, V.rolling_coef, V.rolling_speed_coef_s_per_m, V.drag_coef, V.frontal_area_m2, V.air_density_kg_per_m3)
ETA = V.drivetrain_eff_frac


def test_cruise_power_at_the_limit_by_hand():
    v = 24.58  # m/s, the paper's 88.5 km/h
    rolling = (0.0065 + 4.92e-5 * v) * 1611 * 9.80665  # 121.79 N
    aero = 0.5 * 1.225 * 2.22 * 0.23 * v**2  # 188.95 N
    assert rolling == pytest.approx(121.79, abs=0.01) and aero == pytest.approx(188.95, abs=0.01)
    wheel = (rolling + aero) * v  # 7638.0 W
    battery = wheel / (0.8536 * 0.90 * 0.95)  # 10465.7 W
    assert wheel_power_w(v, 0.0, 0.0, *ARGS) == pytest.approx(wheel, rel=1e-12)
    assert battery_power_w(wheel, ETA, ETA, 1.0, np.inf, 0.0) == pytest.approx(battery, rel=1e-12)
    assert battery == pytest.approx(10465.7, abs=0.1)


def test_grade_adds_weight_component():
    v, grade = 20.0, 0.05
    theta = np.arctan(grade)
    expected = 1611 * G_MPS2 * (np.sin(theta) + (0.0065 + 4.92e-5 * v) * np.cos(theta)) + 0.5 * 1.225 * 2.22 * 0.23 * v**2
    assert road_load_force_n(v, grade, *ARGS) == pytest.approx(expected, rel=1e-12)


@pytest.mark.parametrize("speed", [0.0, 20.0, np.array([0.0, 10.0, 20.0])])
def test_scalar_and_array_inputs(speed):
    out = wheel_power_w(speed, 1.0, 0.0, *ARGS)
    assert np.shape(out) == np.shape(speed)


def test_regen_respects_power_limit():
    # Hard braking: 100 kW at the wheels, limit 60 kW at the battery -> motor takes 60/eta at the wheels.
    assert motor_braking_power_w(-100e3, 0.73, 1.0, 60e3) == pytest.approx(60e3 / 0.73)
    assert battery_power_w(-100e3, 0.73, 0.73, 1.0, 60e3, 0.0) == pytest.approx(-60e3)
    assert battery_power_w(-100e3, 0.73, 0.73, 0.0, 60e3, 0.0) == 0.0  # no regen: all friction
    assert battery_power_w(-100e3, 0.73, 0.73, 1.0, np.inf, 0.0) == pytest.approx(-73e3)  # the paper: no limit


@given(
    v0=st.floats(0, 35),
    v1=st.floats(0, 35),
    dt=st.floats(0.1, 5),
    grade=st.floats(-0.08, 0.08),
    share=st.floats(0, 1),
)
def test_regen_never_returns_more_than_mechanical_energy_lost(v0, v1, dt, grade, share):
    v, a = 0.5 * (v0 + v1), (v1 - v0) / dt
    wheel = wheel_power_w(v, a, grade, *ARGS)
    battery = battery_power_w(wheel, ETA, ETA, share, 60e3, 0.0)
    if wheel < 0:
        # recovered power is at most the braking power at the wheels, times the chain efficiency
        assert -battery <= -wheel * ETA * (1 + 1e-12)
        assert battery <= 0
    else:
        assert battery >= wheel  # driving always costs more than the wheel work


def test_speed_limit_constant():
    assert SPEED_LIMIT_MPS * 3.6 == pytest.approx(88.51, abs=0.01)


def test_paper_presets_have_no_regen_limit():
    """The paper states no regen power limit: hard braking from 88.5 km/h returns eta x the braking power."""
    p, _, _ = pack(ModelParams(PAPER_54KWH))
    assert battery_power_for_wheel_w(-150e3, 20.0, p) == pytest.approx(-150e3 * ETA, rel=1e-12)


X_FS = np.array([0.0, 0.02, 0.04, 0.06, 0.08, 0.1, 0.2, 0.4, 0.6, 0.8, 1.0])
Y_FS = np.array([0.84, 0.86, 0.88, 0.90, 0.91, 0.92, 0.94, 0.95, 0.95, 0.94, 0.93])


def test_machine_efficiency_curve_by_hand():
    assert em_eff_frac(0.0, X_FS, Y_FS) == pytest.approx(0.84)
    assert em_eff_frac(0.03, X_FS, Y_FS) == pytest.approx(0.87)  # halfway between 0.86 and 0.88
    assert em_eff_frac(0.3, X_FS, Y_FS) == pytest.approx(0.945)
    assert em_eff_frac(-0.3, X_FS, Y_FS) == pytest.approx(0.945)  # both directions
    assert em_eff_frac(1.2, X_FS, Y_FS) == pytest.approx(0.93)  # held at the end


def test_regen_share_fades_at_low_speed_by_hand():
    # FASTSim 2: 0.98 / (1 + 500 exp(-0.99 (mph + 1)))
    for mph in (0.0, 3.0, 5.0, 10.0, 30.0):
        expected = 0.98 / (1 + 500 * np.exp(-0.99 * (mph + 1)))
        assert regen_share_frac(mph * 0.44704, 0.98, 500.0, 0.99) == pytest.approx(expected, rel=1e-12)
    assert regen_share_frac(0.0, 0.98, 500.0, 0.99) < 0.01
    assert regen_share_frac(15 * 0.44704, 0.98, 500.0, 0.99) == pytest.approx(0.98, abs=1e-3)


def test_calibrated_chain_by_hand():
    p, _, _ = pack(ModelParams(CALIBRATED))
    # cruise needing 10 kW at the wheels: the machine delivers 10/0.98 = 10.204 kW = 4.27 % of 239 kW,
    # efficiency 0.88 + (0.0427 - 0.04) / 0.02 * 0.02 = 0.8827; battery 10.204 / 0.8827 + 0.25 kW
    out_w = 10e3 / 0.98
    eff = 0.88 + (out_w / 239e3 - 0.04)
    assert battery_power_for_wheel_w(10e3, 20.0, p) == pytest.approx(out_w / eff + 250.0, rel=1e-9)
    # braking 30 kW at the wheels at 20 m/s: share 0.98 (no fade at 45 mph); the machine takes
    # 30 * 0.98 * 0.98 = 28.81 kW = 12.06 % of 239 kW: efficiency 0.92 + 0.0206 * 0.2 = 0.9241
    share = 0.98 / (1 + 500 * np.exp(-0.99 * (20 / 0.44704 + 1)))
    in_w = 30e3 * share * 0.98
    eff = 0.92 + (in_w / 239e3 - 0.1) * 0.2
    assert battery_power_for_wheel_w(-30e3, 20.0, p) == pytest.approx(-in_w * eff + 250.0, rel=1e-9)
    # 150 kW of braking: the battery gets its 60 kW limit
    assert battery_power_for_wheel_w(-150e3, 20.0, p) == pytest.approx(-60e3 + 250.0, rel=1e-12)
    # at 1 m/s nearly everything goes to the friction brakes
    assert battery_power_for_wheel_w(-10e3, 1.0, p) > -0.1 * 10e3
