"""spat_feed.transport.actuated: the switch-time fit on the recordings, actuated truth, and what the controller publishes."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from advisory.signals import FixedTimeSignal, paper_scenario
from spat_feed.transport.actuated import ActuatedFeed, SwitchFit, actuated_light, actuated_scenario, fit_switches, switch_observations
from spat_feed.timing.messages import to_unix_s

from tests.conftest import SPAT_RECORDINGS as RECORDINGS
from tests.conftest import publishes_windows

WINDOWED = [p for p in RECORDINGS if publishes_windows(p)]
STATE_ONLY = [p for p in RECORDINGS if not publishes_windows(p)]


@pytest.mark.parametrize("path", WINDOWED, ids=lambda p: p.name)
def test_fit_on_a_real_recording(path, shared_recordings_parsed_once):
    """README (Antwerp): windows red 80-97 s / green 18 s wide, never ended before minEnd, after maxEnd 6-12 % of the
    time; on each recording whose controller publishes windows (parsed once for the package's tests)."""
    fits = fit_switches([path])
    red, green = fits["red"], fits["green"]
    assert red.n > 300 and green.n > 1000
    assert red.before_min_n == 0 and green.before_min_n == 0
    assert 60 <= red.median_width_s <= 110 and 10 <= green.median_width_s <= 25
    assert 0.03 < green.late_frac < 0.3 and 0.03 < red.late_frac < 0.4
    for fit in fits.values():
        q = np.array(fit.inside_quantiles)
        assert q[0] >= 0 and q[-1] <= 1 and np.all(np.diff(q) >= 0)
        assert 0 < fit.late_mean_s < 30


@pytest.mark.parametrize("path", STATE_ONLY, ids=lambda p: p.name)
def test_a_recording_without_windows_has_nothing_to_fit(path, shared_recordings_parsed_once):
    """A controller that publishes its state only (the US one): no phase has a bounded window, and the fit says so."""
    with pytest.raises(ValueError, match="no phase with a bounded window"):
        fit_switches([path])


def test_draws_follow_the_fit():
    fit = SwitchFit("green", 100, 0, 0.2, tuple(np.linspace(0, 1, 11) ** 2), 5.0, 15.0)
    rng = np.random.default_rng(1)
    draws = np.array([fit.draw_s(100.0, 115.0, rng) for _ in range(20_000)])
    assert draws.min() >= 100.0
    assert np.mean(draws > 115.0) == pytest.approx(0.2, abs=0.015)
    assert np.mean(draws[draws > 115.0] - 115.0) == pytest.approx(5.0, rel=0.08)
    inside = (draws[draws <= 115.0] - 100.0) / 15.0
    assert np.median(inside) == pytest.approx(0.25, abs=0.03)  # u = p² at p = 0.5


def _random_lights(n, seed=0, **kwargs):
    rng = np.random.default_rng(seed)
    for _ in range(n):
        cycle = rng.uniform(40, 120)
        share = rng.uniform(0.3, 0.7)
        fixed = FixedTimeSignal(300.0, rng.uniform(-cycle, cycle), cycle * share, cycle * (1 - share))
        yield fixed, actuated_light(fixed, rng.uniform(0, 15), rng, **kwargs)


def test_real_switches_lie_in_their_window_or_up_to_ten_percent_beyond():
    beyond = 0
    for _, light in _random_lights(300):
        for w, s in zip(light.windows, light.switches_s):
            width = w.max_end_s - w.min_end_s
            assert w.min_end_s <= s <= w.max_end_s + 0.1 * width + 1e-9
            beyond += s > w.max_end_s
        assert list(light.switches_s) == sorted(light.switches_s)
        truth = light.truth()
        for a, b in truth.reds_s:
            assert math.isinf(a) or a in light.switches_s
        for s in light.switches_s[:-1]:
            assert truth.is_red(s + 1e-6) != truth.is_red(s - 1e-6)  # every switch changes the colour
    assert beyond > 100  # some really are late


def _real_changes_s(light, t_s):
    """The light's real changes after ``t_s`` as its controller publishes them: each amber's start, then each switch."""
    out = []
    for i in range(int(np.searchsorted(light.switches_s, t_s, side="right")), len(light.switches_s)):
        if (a := light.amber_start_s(i)) is not None and a > t_s:
            out.append((a, light.windows[i].max_end_s - (light.switches_s[i] - a)))
        out.append((light.switches_s[i], light.windows[i].max_end_s))
    return out  # (real instant, the window's own maxEnd)


@pytest.mark.parametrize("amber_s", [4.0, 0.0])
def test_published_windows_narrow_and_become_exact_before_the_switch(amber_s):
    """Every change the controller publishes, the amber's start included (J2735 protected-clearance), in order; each
    change into red no earlier than the real red (minEnd is hard); the next change exact once decided, narrowing."""
    from spat_feed.timing.plans import AMBER, STOP_STATES

    ambers = 0
    for _, light in _random_lights(100, seed=2):
        light = replace(light, amber_s=amber_s)
        previous = None
        for t in np.arange(-50.0, 300.0, 1.0):
            plan = light.plan_at(t)
            real = _real_changes_s(light, t)
            assert plan.states[0] == light.state_at(t)  # the state published now is the real one
            ambers += plan.states[0] == AMBER
            assert len(plan.changes) == len(real) and (AMBER in plan.states) == (amber_s > 0 and len(real) > 1)
            for c in plan.changes:
                assert c.min_end_s >= t - 1e-9  # never a change in the past
            if len(plan.changes) > 1 and plan.states[1] == AMBER:  # the red after the current green's amber
                assert plan.states[2] in STOP_STATES and plan.changes[1].min_end_s <= real[1][0] + 1e-9  # its minEnd is hard
            if plan.changes:
                c, (r, max_end) = plan.changes[0], real[0]
                assert c.min_end_s <= r + 1e-9  # minEnd is hard
                if r - t <= light.decide_s:
                    assert c.min_end_s == c.max_end_s == pytest.approx(r)
                if previous is not None and previous[0] == r and t < max_end:
                    assert c.max_end_s - c.min_end_s <= previous[1] + 1e-9  # narrowing
                previous = (r, c.max_end_s - c.min_end_s)
    assert (ambers > 0) == (amber_s > 0)


def test_the_feed_carries_the_truth_through_j2735_and_the_observation():
    """No late switches, no skew: every red of the truth within the horizon lies inside the advisor's red windows."""
    sc = paper_scenario(-12.0, 20.0, 400.0, red_s=40.0, green_s=35.0)
    truth, lights = actuated_scenario(sc, 10.0, np.random.default_rng(3), beyond_frac=0.0)
    feed = ActuatedFeed(lights, sc.speed_limit_mps, n_events=3)
    for t in np.arange(0.0, 60.0, 1.0):
        obs = feed(float(t), 0.0, 20.0)
        assert [lv.intersection_id for lv in obs.lights] == [1, 2]
        for lv, light in zip(obs.lights, truth.signals):
            assert lv.fresh and lv.distance_m == light.position_m
            for tau in np.arange(0.0, 100.0, 0.5):
                if light.is_red(t + tau):
                    assert lv.is_red_at(tau), (t, tau, lv.red_windows_s)


def test_dropouts_age_the_last_message_and_skew_shifts_the_times():
    sc = paper_scenario(-12.0, 20.0, 400.0)
    _, lights = actuated_scenario(sc, 0.0, np.random.default_rng(4))
    plain = ActuatedFeed(lights, sc.speed_limit_mps)
    skewed = ActuatedFeed(lights, sc.speed_limit_mps, skew_s=2.5)
    a, b = plain(10.0, 0.0, 20.0).lights[0], skewed(10.0, 0.0, 20.0).lights[0]
    assert [s + 2.5 for s, _ in a.red_windows_s[1:]] == pytest.approx([s for s, _ in b.red_windows_s[1:]], abs=2e-3)
    dropped = ActuatedFeed(lights, sc.speed_limit_mps, dropouts_s=[(11.0, 20.0)])
    assert dropped(10.0, 0.0, 20.0).lights[0].fresh
    assert dropped(13.0, 0.0, 20.0).lights[0].fresh  # 3 s old: still fresh
    assert not dropped(14.0, 0.0, 20.0).lights[0].fresh
    assert dropped(20.0, 0.0, 20.0).lights[0].fresh


@pytest.mark.parametrize("path", RECORDINGS, ids=lambda p: p.name)
def test_switch_observations_match_the_raw_rows(path):
    """A phase is observed where its first window is bounded: on every recording that publishes windows, none other."""
    from ecodrive.spat_eval import _read_head

    head = _read_head(str(path), 600.0)
    obs = switch_observations(head)
    if not publishes_windows(path):
        assert obs == []
        return
    assert obs
    for red, lo, hi, end in obs:
        assert lo <= hi and end >= lo - 1.0  # never before minEnd (within the 1 s sampling)
        assert to_unix_s(head[0].timestamp) < end < to_unix_s(head[-1].timestamp)
    assert any(r for r, *_ in obs) and not all(r for r, *_ in obs)


def test_a_conflicting_stage_leads_each_red_end_and_the_receiver_links_them():
    """The conflicting stage is green only while the light is red, and its green ends a fixed lead before the
    light's red does (but in its misfires, which end earlier). A feed that publishes the current phase only (as
    Antwerp's) with it: the receiver learns the link, the view's likely end of a red is the link's (within the
    controller's window), and that is the real end, to the 1 s readings, but after a misfire."""
    from dataclasses import replace

    from spat_feed.transport.actuated import conflicting_light

    sc = paper_scenario(-12.0, 20.0, 400.0, red_s=40.0, green_s=35.0)
    rng = np.random.default_rng(5)
    truth, lights = actuated_scenario(sc, 10.0, rng, t0_s=-1600.0)
    other = conflicting_light(lights[0], rng, misfire_frac=0.1)
    light, stage = lights[0].truth(), other.truth()
    leads = {}  # the light's red (by its end) -> how long before it the stage's green in it ended
    for (_, g0), (g1, _) in zip(stage.reds_s, stage.reds_s[1:]):  # each green of the stage, inside one of the light's reds
        red = next(r for r in light.reds_s if r[0] <= g0 and g1 <= r[1])
        leads[red[1]] = red[1] - g1
    lead = np.median(list(leads.values()))
    misfired = {end for end, x in leads.items() if x > lead + 1e-6}
    assert len(leads) > 15 and all(x >= lead - 1e-6 for x in leads.values()) and 0 < len(misfired) <= 0.25 * len(leads)
    feed = replace(ActuatedFeed(lights, sc.speed_limit_mps, n_events=1, warm_up_s=1500.0), conflicting=[other, None])
    spoke = 0
    for t in np.arange(0.0, 300.0, 1.0):
        view = feed(float(t), 0.0, 10.0).lights[0]
        cycle = feed._last[0][2]
        red = next((r for r in light.reds_s if r[0] <= t < r[1]), None)
        if cycle.linked_end_unix_s is None or red is None or cycle.linked_end_unix_s[1] - feed.epoch_unix_s <= t:
            continue  # (a link whose late end has passed says nothing)
        told = cycle.linked_end_unix_s[0] - feed.epoch_unix_s
        published = feed._last[0][1].changes[0]  # the controller's window of this red's end
        first = (view.likely_red_windows_s or view.red_windows_s)[0]
        likely = t + first[1] if first[0] <= 0.0 else t  # (a red likely ending now is out of the windows)
        # as the link says, within the controller's window, but never before the next reading could say otherwise and
        # the car (10 m/s), crossing 2 s after the red (the advisor's margin), could still stop at firm braking when told
        # (the safety rule: 1 s reading + max(0, 1 s reaction + v / (2 x 3 m/s2) - 2 s margin)), where the controller's
        # window for it is still open (a red whose end it publishes exactly ends then)
        hold_s = 1.0 + max(0.0, 1.0 + 10.0 / (2.0 * 3.0) - 2.0) if published.max_end_s - published.min_end_s >= 0.5 else 0.0
        assert likely == pytest.approx(max(min(max(told, published.min_end_s - feed.epoch_unix_s, t), published.max_end_s - feed.epoch_unix_s), t + hold_s), abs=1e-3)
        assert view.red_windows_s[0][0] <= 0.0 and view.red_windows_s[0][1] + t >= likely - 1e-6  # the late end: later, if anything
        spoke += 1
        if red[1] not in misfired and red[1] > t + hold_s:  # (after a misfire the link is early: the red outlasts it)
            assert likely == pytest.approx(red[1], abs=1.5)
    assert spoke > 5


def test_the_published_current_state_is_the_real_one():
    """A change past its likely time but not yet come was published with likelyTime = now, and J2735 readers (and
    ``movement_events``) take the current state off the likely times: for a second the controller "published" the
    next state (green) while the light was still red (randomized run 7853: a car crept to the line on that green and
    then braked at 4.4 m/s²)."""
    from spat_feed.timing.messages import MovementState, movement_events, plan_from_movement
    from spat_feed.timing.plans import state_at

    sc = paper_scenario(-12.0, 20.0, 400.0, red_s=40.0, green_s=35.0)
    _, lights = actuated_scenario(sc, 10.0, np.random.default_rng(11), beyond_frac=0.5)
    late = 0
    for light in lights:
        for t in np.arange(0.0, 300.0, 0.5):
            plan = light.plan_at(float(t))
            assert state_at(plan, float(t)) == light.state_at(float(t)), t
            received = plan_from_movement(MovementState(signal_group=1, state_time_speed=movement_events(plan, float(t), 1)), float(t))
            assert received.states[0] == light.state_at(float(t))  # what a receiver reads as the current phase
            k = int(np.searchsorted(light.switches_s, t, side="right"))
            late += k < len(light.windows) and light.windows[k].likely_s < t < light.switches_s[k]
    assert late > 10  # changes past their likely time were there to publish


def test_safety_events_say_when_a_red_was_told_and_whether_a_car_could_stop():
    """By hand: a green that turns red at once (no amber) at 12.0 s, published in [10, 20] s, exact 3 s before; a car
    at 24.6 m/s from entry crosses a line 300 m out at 12.2 s, 0.2 s into the red. Told at entry (the window already
    admits a red at the crossing), 300 m out: a stop needed 24.6² / 600 = 1.01 m/s², avoidable at 3. The same line
    100 m out (a red at 3.5 s in [3, 8] s), crossed at 4.07 s: a stop needed 3.03 m/s² from entry, unavoidable at 3.
    A dropout over the first two readings tells it at 2 s; a hard brake is about the light ahead of it."""
    from advisory.trajectory import Trajectory
    from spat_feed.timing.plans import GREEN, RED, ChangeWindow
    from spat_feed.transport.actuated import ActuatedLight, safety_events

    v = 24.6
    drive = Trajectory(np.array([0.0, 30.0]), np.array([0.0, 30.0 * v]), np.array([v, v]))
    far = ActuatedLight(300.0, (GREEN, RED), (ChangeWindow(10.0, 15.0, 20.0, 0.9),), (12.0,), amber_s=0.0)
    (e,) = safety_events(drive, ActuatedFeed([far], v), 3.0)
    assert (e.kind, e.light, e.known_s, e.decided_s) == ("red_entry", 0, 0.0, 9.0)
    assert e.at_s - e.red_start_s == pytest.approx(300.0 / v - 12.0) and e.stop_decel_mps2 == pytest.approx(v * v / 600.0) and e.avoidable
    near = ActuatedLight(100.0, (GREEN, RED), (ChangeWindow(3.0, 5.0, 8.0, 0.9),), (3.5,), amber_s=0.0)
    (e,) = safety_events(drive, ActuatedFeed([near], v), 3.0)
    assert e.stop_decel_mps2 == pytest.approx(v * v / 200.0) and not e.avoidable and e.decided_s == 1.0
    (e,) = safety_events(drive, ActuatedFeed([far], v, dropouts_s=((0.0, 1.5),)), 3.0)
    assert e.known_s == 2.0 and e.distance_m == pytest.approx(300.0 - 2.0 * v)
    assert safety_events(drive, ActuatedFeed([replace(far, switches_s=(13.0,))], v), 3.0) == []  # crossed on green
    brake = Trajectory(np.array([0.0, 2.0, 5.0]), np.array([0.0, 2.0 * v, 2.0 * v + 1.5 * v]), np.array([v, v, 0.0]))  # 8.2 m/s²
    (e,) = safety_events(brake, ActuatedFeed([far, near], v), 3.0)
    assert (e.kind, e.light, e.red_start_s) == ("hard_brake", 1, 3.5) and e.brake_mps2 == pytest.approx(v / 3.0)  # the nearer light
