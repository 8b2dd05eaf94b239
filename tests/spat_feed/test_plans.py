"""Signal plans: fixed-time against the advisor's FixedTimeSignal, amber, uncertain (actuated) windows."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import assume, given
from hypothesis import strategies as st

from advisory.signals import PAPER_SPACINGS_M, PAPER_TIMINGS_S, paper_scenario
from spat_feed.timing.paper import TIMING_PRESETS
from spat_feed.timing.plans import (
    AMBER,
    GREEN,
    RED,
    ChangeWindow,
    FixedTimePlan,
    MovementPhaseState,
    UncertainPlan,
    next_changes,
    possible_states_at,
    seconds_to_next_green,
    seconds_to_next_red,
    state_at,
    state_start_s,
    to_fixed_time_signal,
    uncertain_from_fixed,
)
from spat_feed.transport.scenarios import make_scenario

TIMES_S = np.arange(-100.0, 200.0, 2.5)  # includes every change instant of the paper's plans


@pytest.mark.parametrize("red_start_s", PAPER_TIMINGS_S + (7.3, 30.0))
def test_fixed_plan_agrees_with_advisory_signal(red_start_s):
    plan = FixedTimePlan(30.0, 30.0, offset_s=red_start_s)
    light = to_fixed_time_signal(plan, 100.0)
    for t in TIMES_S:
        assert (state_at(plan, t) == RED) == bool(light.is_red(t)), t
        assert t + seconds_to_next_green(plan, t).likely_s == pytest.approx(light.next_green_start_s(t))
        assert t + seconds_to_next_red(plan, t).likely_s == pytest.approx(light.next_red_start_s(t))


@pytest.mark.parametrize("x_s", PAPER_TIMINGS_S)
@pytest.mark.parametrize("y_s", PAPER_TIMINGS_S)
@pytest.mark.parametrize("spacing_m", PAPER_SPACINGS_M)
def test_feed_scenario_reproduces_paper_scenario(x_s, y_s, spacing_m):
    entry_unix_s = 1_700_000_000.0
    feed = make_scenario(f"paper_s{spacing_m:g}", f"{x_s:g}_{y_s:g}", entry_unix_s)
    assert feed.advisory_scenario().signals == paper_scenario(x_s, y_s, spacing_m).signals
    assert feed.advisory_scenario().zone_length_m == paper_scenario(x_s, y_s, spacing_m).zone_length_m


def test_field_test_timing():
    """Paper Sec. 4.4: light 1 turns green 15 s, light 2 turns red 30 s after the car enters the zone."""
    feed = make_scenario("paper_s400", "field_test", entry_unix_s=1_000.0)
    plans = feed.fixed_plans()
    light1, light2 = plans[(1, 2)], plans[(2, 2)]
    assert state_at(light1, 1_000.0) == RED and seconds_to_next_green(light1, 1_000.0).likely_s == 15.0
    assert state_at(light2, 1_000.0) == GREEN and seconds_to_next_red(light2, 1_000.0).likely_s == 30.0
    assert len(TIMING_PRESETS) == 17


def test_half_open_intervals_at_change_instants():
    plan = FixedTimePlan(30, 30, offset_s=0)
    assert state_at(plan, 0.0) == RED and state_at(plan, 30.0) == GREEN and state_at(plan, 60.0) == RED
    assert seconds_to_next_green(plan, 30.0).likely_s == 0.0
    assert next_changes(plan, 30.0, 1)[0].likely_s == 60.0  # the change at t itself is not "next"
    assert state_start_s(plan, 45.0) == 30.0 and state_start_s(plan, 60.0) == 60.0


def test_amber_sits_between_green_and_red():
    plan = FixedTimePlan(red_s=30, green_s=27, amber_s=3, offset_s=0)
    assert [state_at(plan, t) for t in (0, 29.9, 30, 56.9, 57, 59.9, 60)] == [RED, RED, GREEN, GREEN, AMBER, AMBER, RED]
    assert seconds_to_next_red(plan, 58.0).likely_s == pytest.approx(2.0)
    assert seconds_to_next_green(plan, 58.0).likely_s == pytest.approx(32.0)  # through the next red
    light = to_fixed_time_signal(plan, 50.0)
    assert light.green_s == 30.0 and not light.is_red(58.0)  # amber counts as "may cross"


@given(
    offset_s=st.floats(-1e4, 1e4),
    t_s=st.floats(-1e5, 1e5),
    red_s=st.floats(1, 120),
    green_s=st.floats(1, 120),
    amber_s=st.sampled_from([0.0, 3.0, 4.5]),
    k=st.integers(1, 8),
)
def test_next_changes_follow_the_cycle(offset_s, t_s, red_s, green_s, amber_s, k):
    plan = FixedTimePlan(red_s, green_s, amber_s, offset_s)
    changes = next_changes(plan, t_s, k)
    assert len(changes) == k
    times = [c.likely_s for c in changes]
    assert times[0] > t_s and all(b > a for a, b in zip(times, times[1:]))
    assert times[0] - t_s <= plan.cycle_s + 1e-6
    for c in changes:
        assert state_at(plan, c.likely_s + 1e-6 * plan.cycle_s) == c.state
    assert changes[0].state != state_at(plan, t_s)


def test_fixed_plan_rejects_bad_durations():
    with pytest.raises(ValueError):
        FixedTimePlan(0, 30)
    with pytest.raises(ValueError):
        FixedTimePlan(30, 30, amber_s=-1)


# ---------------------------------------------------------------------------------------- uncertain


def actuated() -> UncertainPlan:
    """Red until a window [10, 20] (likely 14), green until [40, 50] (likely 45), then unknown."""
    return UncertainPlan(
        (RED, GREEN, RED, MovementPhaseState.UNAVAILABLE),
        (ChangeWindow(10, 14, 20, 0.8), ChangeWindow(40, 45, 50, 0.6), ChangeWindow(80, 80, 80)),
    )


def test_uncertain_before_the_window_is_certain():
    plan = actuated()
    assert possible_states_at(plan, 5.0) == {RED}
    assert seconds_to_next_green(plan, 5.0) == (5.0, 9.0, 15.0, 0.8)
    assert seconds_to_next_red(plan, 5.0) == (0.0, 0.0, 0.0, 1.0)


def test_uncertain_inside_the_window_is_either():
    plan = actuated()
    assert possible_states_at(plan, 12.0) == {RED, GREEN}
    assert state_at(plan, 12.0) == RED and state_at(plan, 16.0) == GREEN
    # at 16 s green is likely on; at worst it comes at 20 s
    assert seconds_to_next_green(plan, 16.0) == (0.0, 0.0, 4.0, 1.0)
    # red: possibly now (no green yet), likely after the green (45 s), at worst 50 s
    assert seconds_to_next_red(plan, 16.0) == (0.0, 29.0, 34.0, 0.6)


def test_uncertain_beyond_the_horizon_is_unknown():
    plan = actuated()
    assert state_at(plan, 90.0) == MovementPhaseState.UNAVAILABLE
    assert seconds_to_next_green(plan, 60.0) is None
    assert next_changes(plan, 60.0, 5) == next_changes(plan, 60.0, 1)  # only the step to unavailable is left
    assert state_start_s(plan, 0.0) == -math.inf


def test_uncertain_open_ended_window():
    plan = UncertainPlan((RED, GREEN), (ChangeWindow(10, 10, math.inf, 0.5),))
    assert seconds_to_next_green(plan, 0.0) == (10.0, 10.0, math.inf, 0.5)
    assert possible_states_at(plan, 1e9) == {RED, GREEN}


@pytest.mark.parametrize(
    "states, changes",
    [
        ((RED, GREEN), ()),  # one state too many
        ((RED, GREEN, RED), (ChangeWindow(10, 12, 20), ChangeWindow(15, 16, 30))),  # overlap
    ],
)
def test_uncertain_plan_rejects_inconsistent_input(states, changes):
    with pytest.raises(ValueError):
        UncertainPlan(states, changes)


def test_change_window_rejects_disorder():
    with pytest.raises(ValueError):
        ChangeWindow(10, 9, 20)
    with pytest.raises(ValueError):
        ChangeWindow(10, 12, 20, confidence_frac=1.5)


@given(
    offset_s=st.floats(-100, 100),
    t_s=st.floats(-50, 250),
    early_s=st.floats(0, 10),
    late_s=st.floats(0, 10),
)
def test_uncertain_from_fixed_brackets_the_fixed_answer(offset_s, t_s, early_s, late_s):
    fixed = FixedTimePlan(30, 30, offset_s=offset_s)
    assume(abs((t_s - offset_s + 15.0) % 30.0 - 15.0) > 1e-6)  # not on a change instant (float ties)
    plan = uncertain_from_fixed(fixed, -100.0, 400.0, early_s=early_s, late_s=late_s, confidence_frac=0.9)
    assert state_at(plan, t_s) == state_at(fixed, t_s)  # the likely times are the fixed ones
    assert state_at(fixed, t_s) in possible_states_at(plan, t_s)
    for fn in (seconds_to_next_green, seconds_to_next_red):
        u, f = fn(plan, t_s), fn(fixed, t_s)
        assert u.min_s <= u.likely_s <= u.max_s
        assert u.likely_s == pytest.approx(f.likely_s, abs=1e-9)


def test_exact_windows_behave_like_the_fixed_plan():
    fixed = FixedTimePlan(30, 30, offset_s=5.0)
    plan = uncertain_from_fixed(fixed, 0.0, 600.0)
    for t in TIMES_S[(TIMES_S > 0) & (TIMES_S < 500)]:
        assert seconds_to_next_green(plan, t) == seconds_to_next_green(fixed, t)
        assert possible_states_at(plan, t) == {state_at(fixed, t)}
