"""The choice under uncertain timing (advisory/advice/choice.py and the advisor's use of it): the priced motion against
the project's scoring, the chance of a stop against a brute-force count, and the advisor's hard and chance
constraints as invariants over random timings."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from advisory.advice import choice
from advisory.advice.advisor import KEEP_MODES, MODE_CODES, AdvisorParams, LightView, Observation, advise, crossing_time_s
from advisory.evaluation.scoring import score_trace
from advisory.physics.params import model_params

PARAMS = AdvisorParams(uncertain_choice="expected_cost")
RATES, COAST, IDLE = choice.rate_tables(PARAMS.vehicle, PARAMS.comfort_decel_mps2, PARAMS.normal_accel_mps2, PARAMS.firm_decel_mps2)
V_LIM = 50 / 3.6


@pytest.mark.parametrize("row, a_mps2", [(choice.CRUISE, 0.0), (choice.ACCEL_COMFORT, 1.5), (choice.BRAKE_COMFORT, -1.5), (choice.BRAKE_FIRM, -3.0)])
def test_rate_tables_price_a_drive_as_the_scoring_does(row, a_mps2):
    """A constant-rate speed change priced from the rate tables costs what paper Eq. 4 in the scoring says (0.5 %)."""
    v0 = 12.0
    v1 = v0 + a_mps2 * 4.0 if a_mps2 else v0
    t = np.linspace(0.0, 4.0, 401)
    scored = score_trace(t, np.linspace(v0, v1, t.size), model_params(PARAMS.vehicle)).total_usd
    mid = 0.5 * (t[1:] + t[:-1])
    priced = sum(np.interp(v0 + a_mps2 * m, np.arange(RATES.shape[1]) * choice.RATE_DV_MPS, RATES[row]) * 0.01 for m in mid)
    assert priced == pytest.approx(scored, rel=5e-3)


def test_a_plan_that_holds_the_limit_with_no_light_in_the_way_costs_cruising():
    """Hand answer: at the limit already, to a point 500 m on, the motion is a cruise: 500 / v seconds at the cruise rate."""
    d = np.array([300.0])
    usd, t_end, stop_usd, stop_s = choice._drive(V_LIM, 0, 1.0, choice.ACCEL_COMFORT, 1.5, V_LIM, d, 500.0, V_LIM, RATES, COAST, 1.5, 3.0, 2.0)
    cruise = np.interp(V_LIM, np.arange(RATES.shape[1]) * choice.RATE_DV_MPS, RATES[choice.CRUISE])
    assert t_end == pytest.approx(500.0 / V_LIM, rel=1e-3)
    assert usd == pytest.approx(cruise * 500.0 / V_LIM, rel=1e-3)
    # a comfortable stop at the line begins v² / 2b before it and takes v / b
    brake_m = V_LIM**2 / 3.0
    assert stop_s[0] == pytest.approx((300.0 - brake_m) / V_LIM + V_LIM / 1.5, abs=choice.STEP_S + 1e-6)


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(st.floats(0.0, 60.0), st.floats(0.5, 40.0)), min_size=1, max_size=8), st.lists(st.floats(1.0, 90.0), min_size=1, max_size=6))
def test_chance_of_a_stop_is_the_share_of_timings_whose_red_the_plan_meets(reds, crossings):
    """Brute force: a plan stops in a timing when it reaches the line inside that timing's red or within the margin after
    (and likelier the closer before it: :func:`_meets`)."""
    margin = 2.0
    n = len(crossings)
    windows = np.full((1, len(reds), 1, 2), np.inf)
    for k, (a, dur) in enumerate(reds):
        windows[0, k, 0] = (a, a + dur)
    vts, modes = np.full(n, V_LIM), np.zeros(n, dtype=np.int64)
    cross = np.array(crossings, dtype=float).reshape(n, 1)
    _, p_stop = choice.expected_costs(vts, modes, np.ones(n), np.full(n, choice.ACCEL_COMFORT), np.full(n, 1.5), V_LIM, np.array([300.0]), windows, 1,
                                      400.0, V_LIM, margin, 4.5e-4, cross, RATES, COAST, IDLE, 1.5, 3.0, 2.0)  # fmt: skip
    for c, tc in enumerate(crossings):
        assert p_stop[c] == pytest.approx(sum(_meets(tc, a, a + dur, margin) for a, dur in reds) / len(reds))


def _meets(tc, a, b, margin=PARAMS.green_margin_s):
    """The chance a crossing at ``tc`` meets a timing's red ``[a, b)``: 1 inside it or within the margin after; rising
    from 0 to 1 over the ``EDGE_S`` before it (a change to red known to within a couple of seconds)."""
    if a <= tc < b + margin:
        return 1.0
    return max(0.0, (tc - (a - choice.EDGE_S)) / choice.EDGE_S) if tc < a else 0.0


def _timings(start_s, length_s, n=20, spread_s=0.0):
    """n equally likely timings of one red: start spread evenly over [start, start + spread], each ``length_s`` long."""
    return tuple(((start_s + spread_s * (k + 0.5) / n, start_s + spread_s * (k + 0.5) / n + length_s),) for k in range(n))


def _view(distance_m, scenarios):
    starts = [w[0][0] for w in scenarios]
    ends = [w[0][1] for w in scenarios]
    mid = len(scenarios) // 2
    return LightView(7, distance_m, red_windows_s=((min(starts), max(ends)),), likely_red_windows_s=(scenarios[mid][0],),
                     late_red_windows_s=((max(starts), max(ends)),), scenario_red_windows_s=scenarios)  # fmt: skip


def _stop_share(advice, obs, scenarios):
    """The share of timings in which the advised plan (or driving normally, for no speed advice) meets the red."""
    light = obs.lights[0]
    if advice.target_speed_mps is None:
        tc = crossing_time_s(light.distance_m, obs.speed_mps, obs.speed_limit_mps, PARAMS, "auto", 0.0)
    else:
        tc = crossing_time_s(light.distance_m, obs.speed_mps, advice.target_speed_mps, PARAMS, KEEP_MODES[advice.action])
    return sum(max(_meets(tc, a, b) for a, b in w) for w in scenarios) / len(scenarios)


@settings(max_examples=80, deadline=None)
@given(st.floats(80.0, 600.0), st.floats(3.0, V_LIM), st.floats(0.0, 40.0), st.floats(5.0, 60.0), st.floats(0.0, 30.0))
def test_advice_never_makes_a_stop_likelier_than_driving_normally_beyond_the_risk_allowed(distance_m, v_mps, start_s, length_s, spread_s):
    """The chance constraint, checked by counting: a speed advised under uncertain timing meets the red in at most
    ``stop_risk_frac`` more of the timings than driving normally does."""
    scenarios = _timings(start_s, length_s, spread_s=spread_s)
    obs = Observation(v_mps, V_LIM, (_view(distance_m, scenarios),))
    advice, _ = advise(obs, params=PARAMS)
    if advice.target_speed_mps is None or advice.action in ("stop", "resume") or advice.reason != "green_wave":
        return
    normal = _stop_share(advice.__class__("none", "x"), obs, scenarios)
    assert _stop_share(advice, obs, scenarios) <= normal + PARAMS.stop_risk_frac + 1e-9
    assert advice.target_speed_mps <= V_LIM + 1e-9


@settings(max_examples=80, deadline=None)
@given(st.floats(40.0, 400.0), st.floats(0.0, V_LIM), st.floats(0.5, 6.0))
def test_no_plan_crosses_a_red_held_in_every_timing(distance_m, v_mps, hold_s):
    """The hard constraint: a published red (held in every timing) is never crossed, nor within the after-red margin;
    a plan advised then reaches the line after it."""
    scenarios = tuple(((0.0, hold_s), (hold_s + 30.0 + k, hold_s + 60.0 + k)) for k in range(20))
    light = LightView(7, distance_m, red_windows_s=((0.0, hold_s), (hold_s + 30.0, hold_s + 79.0)), likely_red_windows_s=scenarios[10],
                      scenario_red_windows_s=scenarios)  # fmt: skip
    obs = Observation(v_mps, V_LIM, (light,))
    advice, _ = advise(obs, params=PARAMS)
    if advice.reason == "green_wave":
        tc = crossing_time_s(distance_m, v_mps, advice.target_speed_mps, PARAMS, KEEP_MODES[advice.action])
        assert tc >= hold_s + PARAMS.green_margin_s - 1e-9


def test_a_red_that_comes_whatever_the_plan_is_met_by_lifting_off_then_a_stop():
    """Every timing reds before any plan can reach the line, long after: far out, lift off; near, prepare to stop."""
    scenarios = _timings(2.0, 90.0, spread_s=4.0)
    far, _ = advise(Observation(V_LIM, V_LIM, (_view(300.0, scenarios),)), params=PARAMS)
    near, _ = advise(Observation(V_LIM, V_LIM, (_view(70.0, scenarios),)), params=PARAMS)
    assert (far.action, far.reason) == ("coast", "red_ahead") and "Lift off and coast" in far.message
    assert (near.action, near.reason) == ("stop", "red_ahead")


def test_a_green_the_car_makes_as_it_goes_in_every_timing_is_not_advised_away():
    """Green in every timing until long after the car is over the line: the advice holds the speed (or says nothing),
    never slows the car."""
    scenarios = _timings(40.0, 30.0, spread_s=10.0)
    advice, _ = advise(Observation(V_LIM, V_LIM, (_view(200.0, scenarios),)), params=PARAMS)
    assert advice.target_speed_mps is None or advice.target_speed_mps >= V_LIM - PARAMS.hysteresis_mps


def test_the_plan_followed_is_kept_while_it_is_as_good_as_any():
    """Hysteresis by price: a driver following a plan (no new reaction) keeps it unless another is better by more than
    a reaction's worth of time."""
    scenarios = _timings(0.0, 25.0, spread_s=6.0)
    obs = Observation(V_LIM, V_LIM, (_view(350.0, scenarios),))
    first, memory = advise(obs, params=PARAMS)
    assert first.reason == "green_wave" and first.target_speed_mps < V_LIM
    v = first.target_speed_mps
    nxt = Observation(v, V_LIM, (_view(350.0 - 2 * v, tuple(((a - 2, b - 2),) for ((a, b),) in scenarios)),))
    again, _ = advise(nxt, memory, PARAMS)
    assert again.target_speed_mps == pytest.approx(first.target_speed_mps)
    assert MODE_CODES[KEEP_MODES[again.action]] == MODE_CODES[KEEP_MODES[first.action]]
