import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from advisory.physics.energy import battery_power_w, motor_braking_power_w, road_load_force_n, wheel_power_w
from advisory.physics.params import G_MPS2, PAPER_54KWH, SPEED_LIMIT_MPS

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
    assert battery_power_w(wheel, ETA, 1.0, 60e3, 0.0) == pytest.approx(battery, rel=1e-12)
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
    assert battery_power_w(-100e3, 0.73, 1.0, 60e3, 0.0) == pytest.approx(-60e3)
    assert battery_power_w(-100e3, 0.73, 0.0, 60e3, 0.0) == 0.0  # no regen: all friction


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
    battery = battery_power_w(wheel, ETA, share, 60e3, 0.0)
    if wheel < 0:
        # recovered power is at most the braking power at the wheels, times the chain efficiency
        assert -battery <= -wheel * ETA * (1 + 1e-12)
        assert battery <= 0
    else:
        assert battery >= wheel  # driving always costs more than the wheel work


def test_speed_limit_constant():
    assert SPEED_LIMIT_MPS * 3.6 == pytest.approx(88.51, abs=0.01)
