"""spat_feed.observe (SPaT plans -> LightView/Observation) and server.gps (map matching, ordering, speed): pure."""

from __future__ import annotations

import math

import pytest

from spat_feed.messages import plan_from_movement
from spat_feed.plans import FixedTimePlan, UncertainPlan, ChangeWindow, MovementPhaseState as S, uncertain_from_fixed
from spat_feed.scenarios import Uncertainty, make_scenario
from spat_feed.source import InProcessSpatSource

from server.gps import RouteMatcher, Track
from spat_feed.observe import PlanReading, confidence_frac, intersections_ahead, light_view, observation, red_windows_s
from server.spat import SimulatedSpat

T0 = 1_700_000_000.0


def test_fixed_plan_windows_relative_to_fix():
    plan = FixedTimePlan(30, 30, offset_s=T0)
    assert red_windows_s(plan, T0 + 10.0, horizon_s=100.0) == ((0.0, 20.0), (50.0, 80.0))
    assert red_windows_s(plan, T0 + 30.0, horizon_s=100.0) == ((30.0, 60.0), (90.0, 120.0))  # green starts at 30: green now
    assert confidence_frac(plan, T0) == 1.0


def test_uncertain_windows_are_conservative():
    plan = uncertain_from_fixed(FixedTimePlan(30, 30, offset_s=T0), T0 - 60, T0 + 300, early_s=2, late_s=5, confidence_frac=0.8)
    windows = red_windows_s(plan, T0 + 40.0, horizon_s=100.0)
    # red planned 60..90 after T0: may start 2 s early (58) and end 5 s late (95)
    assert windows[0] == pytest.approx((18.0, 55.0))
    assert confidence_frac(plan, T0 + 40.0) == 0.8


def test_inside_a_change_window_red_is_possible_now():
    plan = UncertainPlan((S.PROTECTED_MOVEMENT_ALLOWED, S.STOP_AND_REMAIN, S.UNAVAILABLE), (ChangeWindow(T0 - 1, T0 + 2, T0 + 4, 0.9), ChangeWindow(T0 + 34, T0 + 34, T0 + 34)))
    w = red_windows_s(plan, T0)
    assert w[0][0] == 0.0 and w[0][1] == math.inf  # red, then unknown: blocked from now on


def test_unknown_state_now_is_not_fresh():
    plan = UncertainPlan((S.UNAVAILABLE,), ())
    corridor = make_scenario("paper_s200").corridor
    view = light_view(corridor.intersections[0], PlanReading(plan), 0.0, T0)
    assert not view.fresh and view.red_windows_s == ()


def test_lights_ahead_nearest_first_and_only_ahead():
    corridor = make_scenario("paper_s400").corridor
    assert [ix.id for ix in intersections_ahead(corridor, 0.0)] == [1, 2]
    assert [ix.id for ix in intersections_ahead(corridor, 100.0)] == [2]  # on the line: passed
    assert intersections_ahead(corridor, 600.0) == ()
    sc = make_scenario("paper_s400", "15_15", T0)
    obs = observation(corridor, 40.0, 20.0, T0 + 2.0, SimulatedSpat(sc).readings(T0 + 2.0), 24.0)
    assert [round(light.distance_m, 6) for light in obs.lights] == [60.0, 460.0]
    assert obs.lights[0].red_windows_s[0] == pytest.approx((13.0, 43.0))  # red at entry + 15 s
    assert observation(corridor, 40.0, 20.0, T0, {}, 24.0, on_route=False).on_route is False


def test_no_reading_gives_a_light_without_data():
    corridor = make_scenario("paper_s400").corridor
    obs = observation(corridor, 10.0, 20.0, T0, {}, 24.0)
    assert [light.fresh for light in obs.lights] == [False, False]


@pytest.mark.parametrize("uncertainty", [Uncertainty(), Uncertainty(2.0, 5.0, 0.8)])
@pytest.mark.parametrize("dt_s", [0.0, 7.3, 29.9, 44.0])
def test_simulated_plans_equal_the_feed_message_round_trip(uncertainty, dt_s):
    """The in-process shortcut (scenario plans) and the message path (InProcessSpatSource) agree."""
    sc = make_scenario("paper_s400", "-15_15", T0, uncertainty)
    t = T0 + dt_s
    direct = SimulatedSpat(sc).readings(t)
    msg = InProcessSpatSource(sc, clock=lambda: t, n_events=8).message()
    for ix in msg.intersections:
        via_msg = plan_from_movement(ix.movement(2))
        a = red_windows_s(direct[ix.id].plan, t, horizon_s=90.0)
        b = red_windows_s(via_msg, t, horizon_s=90.0)
        flat_a = [x for w in a if w[1] < 90 for x in w]
        flat_b = [x for w in b if w[1] < 90 for x in w]
        assert flat_a == pytest.approx(flat_b, abs=1e-3)


# -- GPS ---------------------------------------------------------------------------------------------


def test_projection_on_and_off_route(s200):
    m = RouteMatcher(s200)
    lat, lon = s200.position(123.0)
    on = m.match(lat, lon)
    assert on.station_m == pytest.approx(123.0, abs=0.05) and on.offset_m < 0.05
    # 60 m north of the route (it runs WNW): well off
    from spat_feed.corridors import WGS84

    lon2, lat2, _ = WGS84.fwd(lon, lat, 25.5, 60.0)
    off = m.match(lat2, lon2)
    assert off.offset_m > 40
    # 200 m before the zone start, on the axis: distance to the entry, not 0
    lat0, lon0 = s200.position(0.0)
    az = WGS84.inv(*s200.position(10.0)[::-1], lon0, lat0)[0]
    lon3, lat3, _ = WGS84.fwd(lon0, lat0, az, 200.0)
    before = m.match(lat3, lon3)
    assert before.station_m == 0.0 and before.offset_m == pytest.approx(200.0, abs=0.5)


def test_track_orders_fixes_and_derives_speed():
    tr = Track(dropout_s=5.0)
    assert tr.order(10.0) == "ok"
    p = tr.add(10.0, 0.0, None)
    assert p.speed_mps is None and p.speed_source == "none"
    assert tr.order(10.0) == "duplicate" and tr.order(9.0) == "out_of_order" and tr.order(11.0) == "ok"
    tr.add(11.0, 15.0, None)
    p = tr.add(12.0, 30.0, None)
    assert p.speed_mps == pytest.approx(15.0) and p.speed_source == "positions"
    assert tr.add(13.0, 45.0, 14.2).speed_mps == 14.2  # the fix's own speed wins
    p = tr.add(20.0, 150.0, None)  # after a 7 s dropout: no speed until two new fixes
    assert p.speed_mps is None
    assert tr.add(21.0, 165.0, None).speed_mps == pytest.approx(15.0)


def test_speed_from_noisy_positions_is_close():
    import random

    rng = random.Random(3)
    tr = Track()
    for k in range(10):
        p = tr.add(float(k), 20.0 * k + rng.gauss(0, 2.0), None)
    assert p.speed_mps == pytest.approx(20.0, abs=3.0)


def test_server_doctests():
    import doctest

    import spat_feed.observe
    import server.ratelimit

    for module in (spat_feed.observe, server.ratelimit):
        assert doctest.testmod(module).failed == 0
