import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from advisory.drivers.regular import DriverParams, regular_driver
from advisory.signals import paper_scenario, paper_scenarios
from tests.checks import violations

V_LIM = 55 * 0.44704


@pytest.mark.parametrize("scenario", paper_scenarios(), ids=lambda s: s.name)
def test_regular_driver_obeys_every_rule_in_all_64_paper_scenarios(scenario):
    traj = regular_driver(scenario)
    assert violations(traj, scenario) == []


def test_decision_distance_lets_it_stop_at_4_mps2():
    d = DriverParams().decision_distance_m(V_LIM)
    assert d == pytest.approx(V_LIM**2 / 8 + 1.0)  # 76.57 m > the paper's 75 m
    assert DriverParams(look_ahead_m=100).decision_distance_m(V_LIM) == 100


def test_stop_for_red_by_hand():
    # [-30 15], s = 400: light 2 at 500 m is red 15..45 s. Decision point 500 - 76.568 m reached at
    # 423.432 / 24.5872 = 17.222 s, red -> brake at 24.5872² / (2 * 75.568) = 4.000 m/s², standstill
    # 1 m before the line at 17.222 + 6.147 = 23.369 s, wait to 45 s, 1 m at 2 m/s² -> crosses at 46.0 s.
    sc = paper_scenario(-30, 15, 400)
    traj = regular_driver(sc)
    assert traj.accel_mps2.min() == pytest.approx(-V_LIM**2 / (2 * (V_LIM**2 / 8)), rel=1e-9)
    assert traj.crossing_time_s(500.0) == pytest.approx(46.0, abs=1e-9)
    stopped = traj.t_s[(traj.v_mps == 0)]
    assert stopped.min() == pytest.approx(17.2218 + 6.1468, abs=1e-3) and stopped.max() == pytest.approx(45.0)
    assert traj.position_at(30.0) == pytest.approx(499.0)


def test_no_light_in_the_way_means_cruise_at_the_limit():
    traj = regular_driver(paper_scenario(-30, -30, 200))
    assert np.allclose(traj.v_mps, V_LIM)
    assert traj.duration_s == pytest.approx(400 / V_LIM)


def test_green_while_braking_means_accelerate_without_stopping():
    # light 1 at 100 m turns green 5 s after entry: seen red at the decision point (0.96 s), green before a stop
    sc = paper_scenario(-25, -30, 400)
    traj = regular_driver(sc)
    assert traj.v_mps.min() > 0
    assert traj.accel_mps2.min() < 0
    assert violations(traj, sc) == []


@settings(max_examples=150, deadline=None)
@given(
    x=st.floats(-60, 60),
    y=st.floats(-60, 60),
    spacing=st.floats(150, 1000),
    red=st.floats(20, 60),
    green=st.floats(20, 60),
)
def test_random_timings_never_violate(x, y, spacing, red, green):
    sc = paper_scenario(x, y, spacing, red_s=red, green_s=green)
    assert violations(regular_driver(sc), sc) == []
