"""Queue-aware advice (issue 28, item 3): the queue model, the service's board, and a queue in SUMO that makes the
queue-blind target stop while the queue-aware one glides."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from advisory.advice.advisor import advise
from advisory.advice.behind import GIVE_UP_SLACK_S, cut_behind, cut_off, gives_up_green, platoon_through, pushed_past
from advisory.advice.choice import WAIT_CAP_S
from advisory.advice.kinematics import KEEP_MODES, crossing_time_s
from advisory.advice.queue import _held_until, _held_untils, PastRed, Probe, Probes, QueueEstimate, QueueModel, apply, behind_s, estimate, followers, normal_drive_s, normal_drives_s
from advisory.advice.queue_words import said_truly, tail_glide
from advisory.advice.views import Advice, AdvisorParams, LightView, Observation, time_price
from advisory.advice.wording import published_speed_mps, spoken_speed
from server.queue import QueueBoard

M = QueueModel()
ONE = replace(M, startup_s=M.fast_startup_s, headway_s=M.fast_headway_s)
"""The discharge at its fast end alone: one level of it, where a scene's counts are worked by hand at that end."""


def _obs(distance_m=300.0, speed=13.0, reds=((0.0, 20.0), (60.0, 90.0)), limit=13.4, second=None):
    lights = (LightView(1, distance_m, red_windows_s=reds),) + ((second,) if second is not None else ())
    return Observation(speed, limit, lights, position_m=100.0)


def test_no_cars_ahead_no_change():
    obs = _obs()
    est = estimate(obs, [])
    assert est.free_at_s == (0.0,) and est.cars == (0.0,) and not est.in_queue and est.follow_mps is None
    assert apply(obs, est) == obs


def test_standing_cars_hold_the_line_until_they_have_crossed():
    """Four cars standing at a red ending in 20 s: discharging slowly the first crosses 3 s after it, the rest 2 s
    apart (the fourth at 20 + 3 + 3 x 2 = 29 s, this car 2 s later), fast 2 s after it and 1.4 s apart (the fourth at
    20 + 2 + 3 x 1.4 = 26.2 s). The line is closed to this car until the fourth has crossed (the advisor's margin after
    it is this car's headway): surely until 26.2 s, and in the equally likely timings until 26.2-29 s, evenly."""
    probes = [Probe(300.0 - 1.0 - 7.5 * k, 0.0) for k in range(4)]
    est = estimate(_obs(), probes)
    assert est.cars == (4.0,) and est.known == (4,)
    assert est.free_at_s[0] == pytest.approx(20.0 + 3.0 + 3 * 2.0 + 2.0)
    assert est.clear_s[0] == pytest.approx((26.2, 29.0)) and est.after_red_s[0] == pytest.approx((6.2, 9.0))
    out = apply(_obs(), est)
    assert np.allclose(out.lights[0].red_windows_s, ((0.0, 26.2), (60.0, 90.0)))
    held = [w[0][1] for w in out.lights[0].scenario_red_windows_s]
    assert len(held) == 20 and held == pytest.approx([26.2 + 2.8 * (k + 0.5) / 20 for k in range(20)])
    assert all(w[1:] == ((60.0, 90.0),) for w in out.lights[0].scenario_red_windows_s)


def test_a_car_arriving_after_the_queue_has_gone_holds_nobody_up():
    probes = [Probe(50.0, 13.4)]  # 250 m from the line at the limit: there in 18.7 s, before the red ends -> queued
    assert estimate(_obs(), probes).cars == (1.0,)
    probes = [Probe(10.0, 13.4)]  # 290 m out, at 21.6 s: after the red (20 s) and nobody queued: free
    assert estimate(_obs(), probes).cars == (0.0,) and estimate(_obs(), probes).free_at_s == (0.0,)


def test_unconnected_cars_from_the_arrival_rate():
    """Half the cars connected, 720 veh/h arriving, red on for 10 s, this car 22 s from the line: (1 - 0.5) x 0.2 x
    (20 + 10) = 3 cars not seen stand in front of it."""
    est = estimate(_obs(), [], arrivals_vps=0.2, connected_share=0.5, red_elapsed_s=10.0)
    assert est.cars == (3.0,) and est.known == (0,)
    assert estimate(_obs(), [], arrivals_vps=0.2, connected_share=1.0, red_elapsed_s=10.0).cars == (0.0,)


@pytest.mark.parametrize("mean, counts", [
    (2.0, [0] * 3 + [1] * 5 + [2] * 6 + [3] * 3 + [4] * 2 + [5]),
    (10.0, [4, 6, 6, 7, 8, 8, 8, 9, 9, 10, 10, 10, 11, 11, 12, 12, 13, 14, 15, 17]),
])
def test_the_unseen_count_is_poisson_and_each_timing_clears_at_its_level(mean, counts):
    """No car connected ahead, the cars not connected arriving over the red (0 to 20 s) of an exact light 300 m out,
    as many as ``mean`` on average (2: half of 720 veh/h over 20 s; 10: 1,800 veh/h, none connected): their count is
    Poisson, and the k-th of the light's 20 equally likely timings (level q = (k + 1/2) / 20) is closed until the
    clearing of the count at that level (the fewest n with P(N <= n) >= q) at the discharge at that level: 20 + 2 +
    1.4 (n - 1) + (1 + 0.6 (n - 1)) q for n cars (fast 2 s + 1.4 s a car, slow 3 s + 2 s a car), the red's end for
    none. By hand, mean 2: P(N <= n) = e^-2 (1, 3, 5, 19/3, 7, 109/15) = 0.135, 0.406, 0.677, 0.857, 0.947, 0.983;
    mean 10 (``counts``): 0.029 at 4, 0.067 at 5, 0.130 at 6, ..., 0.951 at 15, 0.973 at 16, 0.986 at 17 (the sums
    e^-10 10^i / i! written out below, not the module's recurrence). The sure view holds the mean's count at the
    fast end, as before (the hard constraint); ``cars`` is the mean."""
    rate, share = (0.2, 0.5) if mean == 2.0 else (0.5, 0.0)
    est = estimate(_obs(), [], arrivals_vps=rate, connected_share=share, red_elapsed_s=0.0)
    assert est.cars == (mean,)
    law = lambda n: sum(math.exp(-mean) * mean**i / math.factorial(i) for i in range(n + 1))  # noqa: E731
    assert counts == [next(n for n in range(40) if law(n) >= (k + 0.5) / 20) for k in range(20)]
    held = apply(_obs(), est).lights[0]
    until = [20.0 if n == 0 else 22.0 + 1.4 * (n - 1) + (1.0 + 0.6 * (n - 1)) * (k + 0.5) / 20 for k, n in enumerate(counts)]
    assert [w[0][1] for w in held.scenario_red_windows_s] == pytest.approx(until)
    assert all(w[1:] == ((60.0, 90.0),) for w in held.scenario_red_windows_s)
    assert held.red_windows_s[0][1] == pytest.approx(22.0 + 1.4 * (mean - 1))  # the mean's, fast: surely standing
    # no flow, or every car connected: no law, the count sure, as before
    assert estimate(_obs(), [Probe(299.0, 0.0)]).law == estimate(_obs(), [], arrivals_vps=rate, connected_share=1.0).law == ((),)


def test_a_published_queue_length_counts_first():
    """The controller's detectors publish a 30 m queue (J2735 ``queueLength``): 30 / 7.5 = 4 cars stand at the red
    ending in 20 s, so the line is closed to this car for 20 + 2 + 3 x 2 + 2 = 30 s, as four connected cars standing
    there would close it; a connected car standing inside the published queue is one of those four, not a fifth;
    with the published queue the arrival-rate estimate is not made (the detectors counted); a stale reading's queue
    says nothing."""
    published = _obs(reds=((0.0, 20.0), (60.0, 90.0)))
    published = Observation(published.speed_mps, published.speed_limit_mps, (LightView(1, 300.0, red_windows_s=((0.0, 20.0), (60.0, 90.0)), queue_m=30.0),), position_m=100.0)
    est = estimate(published, [])
    assert est.cars == (4.0,) and est.known == (0,)
    assert est.free_at_s[0] == pytest.approx(20.0 + M.startup_s + 3 * M.headway_s + M.headway_s)
    assert estimate(published, [Probe(300.0 - 1.0, 0.0)]).cars == (4.0,)  # the first car, connected: counted once
    assert estimate(published, [Probe(300.0 - 60.0, 0.0)]).cars == (5.0,)  # 60 m back: behind the published queue
    assert estimate(published, [], arrivals_vps=0.2, connected_share=0.5, red_elapsed_s=10.0).cars == (4.0,)
    stale = Observation(13.0, 13.4, (LightView(1, 300.0, fresh=False, red_windows_s=((0.0, 20.0),), queue_m=30.0),), position_m=100.0)
    assert estimate(stale, []).cars == (0.0,)
    # no more cars than fit between the line and this car: 20 m out, two spacings at most
    near = Observation(5.0, 13.4, (LightView(1, 20.0, red_windows_s=((0.0, 20.0),), queue_m=300.0),), position_m=100.0)
    assert estimate(near, []).cars == (2.0,)


def test_in_queue_and_following():
    assert estimate(_obs(speed=0.5), []).in_queue
    assert not estimate(_obs(distance_m=2.0, speed=0.0), []).in_queue  # first at the line
    est = estimate(_obs(speed=12.0), [Probe(20.0, 6.0)])  # closing in on a slower car 20 m ahead
    assert est.follow_mps == 6.0
    assert estimate(_obs(speed=12.0), [Probe(80.0, 6.0)]).follow_mps is None


def test_the_advisor_aims_at_the_queue_having_cleared():
    """300 m from a red ending in 20 s with 6 cars standing: queue-blind the advice aims at the green (~22 s),
    queue-aware at the queue having crossed (~36 s): a lower target."""
    params = AdvisorParams(units="kmh")
    obs = _obs(reds=((0.0, 20.0), (80.0, 110.0)))
    blind, _ = advise(obs, None, params)
    aware, _ = advise(apply(obs, estimate(obs, [Probe(300.0 - 1.0 - 7.5 * k, 0.0) for k in range(6)])), None, params)
    assert blind.target_speed_mps is not None and aware.target_speed_mps is not None
    assert aware.target_speed_mps < blind.target_speed_mps - 2.0


def test_the_queue_clears_as_a_distribution_and_the_plan_aims_within_it():
    """An exact light, red for 20 s more, six cars standing at it, this car 300 m out at 13 m/s: the queue's last car
    crosses 20 + 2 + 5 x 1.4 = 29 s from now discharging fast, 20 + 3 + 5 x 2 = 33 s slowly; with the advisor's 2 s
    margin (this car's headway behind it) this car can cross from 31 s (fast) to 35 s (slow). The plan never reaches
    the line before 31 s (the queue surely stands until then), and, priced over the clearing's distribution, does
    not wait for the slowest discharge (one conservative instant had it cross at 36 s or later: the slow clearing
    plus a headway, plus the margin); queue-blind it aims at the green, 23 s."""
    params = AdvisorParams(units="kmh")
    obs = _obs(reds=((0.0, 20.0), (80.0, 110.0)))
    est = estimate(obs, [Probe(300.0 - 1.0 - 7.5 * k, 0.0) for k in range(6)])
    assert est.clear_s[0] == pytest.approx((29.0, 33.0))
    aware, _ = advise(apply(obs, est), None, params)
    blind, _ = advise(obs, None, params)
    crossing = crossing_time_s(300.0, 13.0, aware.target_speed_mps, params, KEEP_MODES[aware.action])
    assert 29.0 + params.green_margin_s <= crossing < 33.0 + params.green_margin_s
    assert crossing_time_s(300.0, 13.0, blind.target_speed_mps, params, KEEP_MODES[blind.action]) < 20.0 + 2 * params.green_margin_s


def test_the_choice_under_uncertain_timing_aims_at_the_queue_having_cleared():
    """The same on a light of uncertain timing (the choice prices the forecast's timings): every timing's red is held
    until the queue has crossed, and the advice aims there, not at the green (traced in SUMO, paper_s400 actuated 600
    veh/h: "Green in 5 seconds. Hold 80 km/h" 73 m behind a queue still standing, a hard brake at 3.6 m/s2)."""
    params = AdvisorParams(units="kmh")
    timings = tuple(((0.0, 18.0 + k), (80.0 + k, 110.0)) for k in range(4))  # the red ends in 18-21 s
    light = LightView(1, 300.0, red_windows_s=((0.0, 21.0), (80.0, 113.0)), likely_red_windows_s=((0.0, 19.5), (81.5, 110.0)),
                      late_red_windows_s=((0.0, 21.0), (83.0, 110.0)), scenario_red_windows_s=timings)  # fmt: skip
    obs = Observation(13.0, 13.4, (light,), position_m=100.0)
    est = estimate(obs, [Probe(300.0 - 1.0 - 7.5 * k, 0.0) for k in range(6)])
    held = apply(obs, est)
    # each timing held from its own red's end (18-21 s) by the discharge at its level, fast to slow, in their order
    fast, slow = 2.0 + 5 * 1.4, 3.0 + 5 * 2.0
    assert est.clear_s[0] == pytest.approx((21.0 + fast, 21.0 + slow))
    assert np.allclose([w[0] for w in held.lights[0].scenario_red_windows_s], [(0.0, 18.0 + k + fast + (slow - fast) * (k + 0.5) / 4) for k in range(4)])
    assert np.allclose(held.lights[0].red_windows_s[0], (0.0, 21.0 + fast))  # surely standing until then
    blind, _ = advise(obs, None, params)
    aware, _ = advise(held, None, params)
    assert blind.target_speed_mps is not None and aware.target_speed_mps is not None
    assert aware.target_speed_mps < blind.target_speed_mps - 2.0


def test_a_red_whose_end_only_the_timings_know_is_held_in_each_timing_from_its_own_end():
    """An actuated red on now with no stated latest end (the sure view: red until further notice), its forecast ending
    it in 18-21 s; six cars standing: each timing is closed until its own end plus the discharge at its level (fast
    2 + 5 x 1.4 = 9 s, slow 3 + 5 x 2 = 13 s after it), not until further notice in every timing."""
    timings = tuple(((0.0, 18.0 + k),) for k in range(4))
    light = LightView(1, 300.0, red_windows_s=((0.0, math.inf),), likely_red_windows_s=((0.0, 19.5),), scenario_red_windows_s=timings)
    obs = Observation(13.0, 13.4, (light,), position_m=100.0)
    est = estimate(obs, [Probe(300.0 - 1.0 - 7.5 * k, 0.0) for k in range(6)])
    assert est.after_red_s[0] == pytest.approx((9.0, 13.0)) and est.clear_s[0] == (math.inf, math.inf)
    held = apply(obs, est).lights[0]
    assert np.allclose([w[0][1] for w in held.scenario_red_windows_s], [18.0 + k + 9.0 + 4.0 * (k + 0.5) / 4 for k in range(4)])
    assert held.red_windows_s == ((0.0, math.inf),) and held.likely_red_windows_s == ((0.0, 19.5 + 11.0),)


def test_a_stop_is_named_after_the_light_the_stop_plan_meets_in_a_red():
    """At the limit 235 m before a light that turns red in 10 s with no amber (0.4 s to spare at its speed, inside the
    advisor's 2 s margin before such a red for a slowing plan), a queue at the second light: no plan is allowed and the
    car is to stop at the first light. Said so ("Red in 10 seconds. Prepare to stop.", the first light's), not named
    after the second light's green with a lift-off (traced in SUMO, paper_s400 fixed 600 veh/h, every car connected,
    seed 2: "Red light ahead. Green in 45 seconds. Lift off and coast.", never "stop", so the driver's eye went on
    for the first light and a slower car ahead took it 0.5 s into the red)."""
    lim = 24.5872
    reds = ((10.0, 40.0), (70.0, 100.0))
    obs = Observation(24.59, lim, (LightView(1, 235.1, red_windows_s=reds, amber_s=0.0), LightView(2, 635.1, red_windows_s=reds, amber_s=0.0)), position_m=100.0)
    # the traced fix's estimate: the second light closed until 44.8-47 s (four cars arriving in its red), the first free
    est = QueueEstimate((0.0, 4.0), (0, 4), (0.0, 49.0), clear_s=((0.0, 0.0), (44.8, 47.0)), after_red_s=(None, (4.8, 7.0)))
    advice, _ = advise(apply(obs, est), None, AdvisorParams())
    assert (advice.action, advice.light_ahead, advice.seconds_to_change_s) == ("stop", 1, 10.0)


def test_normal_drive_and_given_up_greens():
    assert normal_drive_s(100.0, 0.0, 20.0, 2.0) == pytest.approx(10.0)
    params = AdvisorParams()
    # 200 m to a light green for 20 s more: a normal drive from 5 m/s makes it; a crawl for the next green gives it up
    obs = _obs(distance_m=200.0, speed=5.0, reds=((20.0, 50.0),), limit=24.6)
    crawl = Advice("cruise", "green_wave", 4.5)
    assert gives_up_green(obs, crawl, params)
    assert not gives_up_green(obs, Advice("accelerate", "green_wave", 24.6), params)
    assert not gives_up_green(_obs(distance_m=200.0, speed=5.0, reds=((5.0, 50.0),), limit=24.6), crawl, params)


def test_normal_drives_of_many_cars_are_each_cars_normal_drive_to_the_bit():
    """The array form (the service's runs of cars, :func:`normal_drives_s`) gives each car's :func:`normal_drive_s`
    exactly: at the limit, speeding up and reaching it, speeding up all the way, standing, a negative speed read as 0;
    and the probes as arrays read back as the same cars, in order."""
    rng = np.random.default_rng(3)
    distance_m = np.concatenate(([0.0, 5.0, 100.0, 100.0, 400.0, 1e-9], rng.uniform(0.0, 800.0, 2000)))
    v_mps = np.concatenate(([0.0, 30.0, 13.4, -0.0, -2.0, 13.399999], rng.choice((0.0, 13.4, 25.0), 2000) * rng.uniform(0.0, 1.0, 2000)))
    for limit_mps, accel_mps2 in ((13.4, 2.0), (0.05, 2.0), (24.6, 1.3)):
        want = [normal_drive_s(d, v, limit_mps, accel_mps2) for d, v in zip(distance_m.tolist(), v_mps.tolist())]
        assert normal_drives_s(distance_m, v_mps, limit_mps, accel_mps2).tolist() == want
    cars = [Probe(-30.0, 20.0), Probe(12.5, 0.0), Probe(-30.0, 20.0)]
    probes = Probes.of(cars)
    assert list(probes) == cars and probes == tuple(cars) and probes[1] == cars[1] and probes[1:] == cars[1:] and Probes.of(probes) is probes


def test_a_lights_windows_closed_until_many_instants_are_each_instants_union_to_the_bit():
    """:func:`_held_untils` (one sweep of a light's windows for its views and timings) gives :func:`_held_until`'s
    tuples for every instant: windows from now, past, touching, nested, one from 0 or -0.0 ending before or after the
    instant, unsorted (as it was), none."""
    rng = np.random.default_rng(5)
    cases = [None, (), ((0.0, 10.0),), ((-0.0, 10.0), (10.0, 20.0)), ((-5.0, -1.0), (0.0, 3.0), (3.0, 8.0), (30.0, 60.0)),
             ((0.0, 100.0), (10.0, 20.0), (50.0, 60.0)), ((40.0, 70.0), (5.0, 10.0))]  # fmt: skip
    for _ in range(300):
        edges = np.sort(rng.choice(np.arange(-20.0, 120.0, 2.5), size=2 * rng.integers(1, 5), replace=False)).tolist()
        cases.append(tuple(zip(edges[::2], edges[1::2])))
    for windows in cases:
        held = _held_untils(windows)
        for until_s in (-1.0, 0.0, 1e-9, 2.5, 3.0, 10.0, 20.0, 31.7, 60.0, 200.0, *rng.uniform(0.0, 130.0, 10).tolist()):
            got, want = held(until_s), _held_until(windows, until_s)
            assert got == want and [math.copysign(1.0, a) for a, _ in got or ()] == [math.copysign(1.0, a) for a, _ in want or ()], (windows, until_s)


def _actuated_green(distance_m):
    """A light of uncertain timing green now: surely until its minimum in 4 s, likely 20 s, at the latest 30 s; the
    red after it of unknown end (the history has no red of it yet)."""
    return LightView(1, distance_m, red_windows_s=((4.0, math.inf),), likely_red_windows_s=((20.0, math.inf),), late_red_windows_s=((30.0, math.inf),),
                     scenario_red_windows_s=tuple(((4.0 + 26.0 * (k + 0.5) / 5, math.inf),) for k in range(5)))  # fmt: skip


def test_a_queue_discharging_on_an_actuated_green_holds_it_until_its_maximum():
    """Traced in SUMO (paper_s400 actuated 900 veh/h, 50 %, seed 5, ``main.11``, docs/history/TRAFFIC.md): the queue in
    front of the car discharges on a green whose minimum comes before it has crossed. Four cars stand at the line (on a
    green: one car a headway), a fifth arrives 60 m out at 10 m/s, at the line in (-10 + sqrt(100 + 4 x 60)) / 2 =
    4.22 s: after the green's minimum (4 s), before its last car has crossed. Before, it waited for the red after the
    minimum, whose end is unknown: the queue never cleared, and the line was closed to the car behind for ever. The
    discharge holds the controller's detector busy (headways shorter than its passage time), so the green lasts under
    it until its maximum (30 s): the fifth joins the queue, over the line at 4 x 1.4 = 5.6 s (fast) to 4 x 2 = 8 s
    (slow)."""
    probes = [Probe(100.0 - 1.0 - 7.5 * k, 0.0) for k in range(4)] + [Probe(40.0, 10.0)]  # the car 100 m out
    est = estimate(Observation(6.0, 24.6, (_actuated_green(100.0),), position_m=100.0), probes)
    assert est.cars == (5.0,) and est.clear_s[0] == pytest.approx((5.6, 8.0)) and est.after_red_s == (None,)
    # an exact light turns red when its plan says: the fifth waits for the red's end
    exact = Observation(6.0, 24.6, (LightView(1, 100.0, red_windows_s=((4.0, 34.0),)),), position_m=100.0)
    assert min(estimate(exact, probes).clear_s[0]) >= 34.0


def test_a_crawl_gives_up_an_actuated_green_that_the_queue_in_front_holds_for_a_normal_drive():
    """The same queue; this car 100 m out at 6 m/s: a normal drive reaches the line in (-6 + sqrt(36 + 400)) / 2 =
    7.44 s, within the passage time (2 s) after the queue's last car at the fast end (5.6 s), so the detector never sees
    a gap and the green lasts for it (:func:`advisory.advice.behind.keeps_green`): it makes the light behind the queue
    (7.0 s, a fast headway after its last car, before the latest red at 30 s), and a crawl at 4.5 m/s (over the line at
    22.2 s) gives it up. Before, the sure view's red from 4 s had the normal drive stop too: nothing was weighed, and
    in SUMO the crawling car let the green end (no car at the detector), it and the cars behind it waiting for the
    next one. 130 m out (at the line in 9.0 s, 3.4 s after the queue) it leaves the gap: the green may end as the
    light's timings have it, and the crawl is not weighed against a green the normal drive may not get."""
    params = AdvisorParams()
    crawl = Advice("coast", "red_ahead", 4.5)
    for distance_m, given_up in ((100.0, True), (130.0, False)):
        probes = [Probe(distance_m - 1.0 - 7.5 * k, 0.0) for k in range(4)] + [Probe(distance_m - 60.0, 10.0)]
        real = Observation(6.0, 24.6, (_actuated_green(distance_m),), position_m=100.0)
        est = estimate(real, probes)
        assert est.clear_s[0] == pytest.approx((5.6, 8.0))
        assert gives_up_green(apply(real, est), crawl, params, queue=est, real=real) is given_up, distance_m
        assert not gives_up_green(apply(real, est), Advice("accelerate", "green_wave", 24.6), params, queue=est, real=real)


def test_a_plan_slowing_for_a_discharging_queue_is_weighed_against_a_normal_drive_behind_it():
    """Traced in SUMO (paper_s400 fixed 300 veh/h, 50 %, seed 2, ``main.6`` at 105 s): 112.8 m before light 1 at
    23.1 m/s, its red over, two cars of it still to cross (3.4 s fast, 5 s slow), light 2 400 m on, red from 30 s; told
    "Brake to 69 km/h" (19.2 m/s: over light 1 at 5.5 s). The check counted the plan as holding 69 km/h to light 2, 4.5
    s after a normal drive at the limit: "Drive normally.", and the car slowed at 3.0-3.2 m/s² behind the queue. Past
    the light it is for the plan's car is advised again (a normal drive on from its speed there): the plan stands.

    And a normal drive into a queue still discharging is held by it, not priced as on an empty road: 250 m before a
    light whose red ends in 6 s, two cars clearing it 9.4-11 s from now, a normal drive at the limit is over the line
    at 10.2 s only on an empty road; behind the queue at 10.8 s (the fast end's headway, 1.4 s, after its last car at
    the fast end: the earliest a driver following it crosses). A plan slowing to 12 m/s, over it at 15.4 s, gives up
    5.2 s against the first, 4.6 s against the second: it stands; a crawl at 4.5 m/s still gives the green up. A normal drive that would meet the queue surely standing
    (before its fast clearing) does not make the light: no plan is given up for it."""
    params = AdvisorParams(units="kmh")
    lights = (LightView(1, 112.85, red_windows_s=((0.0, 3.4), (30.0, math.inf))), LightView(2, 512.85, red_windows_s=((30.0, math.inf),)))
    obs = Observation(23.12, 24.59, lights, followers=0.22)
    queue = QueueEstimate((2.0, 0.0), (0, 0), (7.0, 0.0), clear_s=((3.4, 5.0), (0.0, 0.0)))
    plan = Advice("brake_to", "green_wave", 19.22, light_red=True, seconds_to_change_s=3.4, light_id=1)
    assert crossing_time_s(512.85, 23.12, 19.22, params, "firm") - normal_drive_s(512.85, 23.12, 24.59, 2.0) > GIVE_UP_SLACK_S / 1.22
    assert not gives_up_green(obs, plan, params) and not gives_up_green(obs, plan, params, queue=queue)
    one = Observation(24.59, 24.59, (LightView(1, 250.0, red_windows_s=((0.0, 9.4), (40.0, math.inf))),))
    queue = QueueEstimate((2.0,), (0,), (13.0,), clear_s=((9.4, 11.0),))
    slowing = Advice("slow_down", "green_wave", 12.0, light_id=1)
    assert crossing_time_s(250.0, 24.59, 12.0, params, "brake") == pytest.approx(15.38, abs=0.01)
    assert gives_up_green(one, slowing, params) and not gives_up_green(one, slowing, params, queue=queue)
    assert gives_up_green(one, Advice("slow_down", "green_wave", 4.5, light_id=1), params, queue=queue)
    standing = replace(queue, clear_s=((12.0, 14.0),))  # surely standing when the normal drive gets there (10.2 s)
    assert not gives_up_green(replace(one, lights=(LightView(1, 250.0, red_windows_s=((0.0, 12.0), (40.0, math.inf))),)),
                              Advice("slow_down", "green_wave", 4.5, light_id=1), params, queue=standing)  # fmt: skip


def test_a_green_held_by_the_queue_is_said_as_the_queue_not_as_a_green_to_come():
    """What the driver sees is true: where the light is green and the car waits for its queue, the countdown is the
    light's own (its red, ``light_red`` false: the schema's meaning), and the words say the queue ("Queue ahead clears
    in 3 seconds"), never "Green in 3 seconds" under a green light; where the light is red and its queue clears after
    its green, the countdown is the light's green and the words the queue's. A light the queue does not hold: as
    advised."""
    real = (LightView(1, 112.85, red_windows_s=((30.0, 60.0),)),)
    held = (LightView(1, 112.85, red_windows_s=((0.0, 3.4), (30.0, 60.0))),)
    plan = Advice("brake_to", "green_wave", 19.22, light_red=True, seconds_to_change_s=3.4, message="Green in 3 seconds. Brake to 69 kilometers per hour.",
                  light_id=1)  # fmt: skip
    out = said_truly(plan, real, held, "kmh")
    assert (out.light_red, out.seconds_to_change_s, out.counts_down_to) == (False, 30.0, "red")
    assert out.message == "Queue ahead clears in 3 seconds. Brake to 69 kilometers per hour."
    red = (LightView(1, 200.0, red_windows_s=((0.0, 6.0), (36.0, 66.0))),)
    stop = Advice("stop", "red_ahead", 0.0, light_red=True, seconds_to_change_s=14.0, light_id=1)
    out = said_truly(stop, red, (LightView(1, 200.0, red_windows_s=((0.0, 14.0), (36.0, 66.0))),), "mph")
    assert (out.light_red, out.seconds_to_change_s, out.message) == (True, 6.0, "Queue ahead clears in 14 seconds. Prepare to stop.")
    assert said_truly(plan, held, held, "kmh") == plan
    # through the board: a car 60 m before a green light whose last red's queue still discharges (0.8-3 s)
    board, t = QueueBoard(arrivals_vph=720.0, connected_share=0.5), 1000.0
    board.see("c", "watcher", t, Observation(13.4, 13.4, (LightView(1, 500.0, red_windows_s=((0.0, 30.0), (70.0, 100.0))),), position_m=-300.0))
    board.see("c", "watcher", t + 30.0, Observation(13.4, 13.4, (LightView(1, 300.0, red_windows_s=((40.0, 70.0),)),), position_m=-100.0))
    obs, _ = board.see("c", "car", t + 34.0, _green_obs())
    advice, _ = advise(obs, None, AdvisorParams())
    assert advice.light_red and advice.message.startswith("Green in")  # the advisor sees the queue as a red
    out = board.check(obs, advice, AdvisorParams(), "car")
    assert (out.light_red, out.seconds_to_change_s, out.target_speed_mps) == (False, 40.0, advice.target_speed_mps)
    assert out.message.startswith("Queue ahead clears in") and "Green" not in out.message, out.message


def test_a_stop_that_only_the_queue_asks_for_is_a_glide_that_meets_its_tail():
    """Traced in SUMO (paper_s400 fixed 600 veh/h, every car connected, seed 1, ``main.8``): 271.9 m before light 1 at
    the limit, its red (no amber) ending in 6 s, four cars standing at the line (the line closed to this car until
    12.2-15 s). The advisor saw a red ending about when the car, holding its speed, would be at the line: a stop to
    wait a moment, said as nothing; the car ran on at the limit into the queue and braked at 3.5 m/s² behind it. Its
    place behind the four is 30 m before the line; a car standing there would start 5.5 s before it crosses (30 m at
    2 m/s²): at 8.1 s (fast) to 9.8 s (middle). The glide slows the car to the fastest speed that gets it there no
    sooner than such a car had reached that speed, and it crosses the line behind the queue, after its slow clearing
    plus a headway. None where the queue stands longer than any glide can wait (a red 15 s more, 120 m out at 13 m/s:
    ``tests/server/test_queue_shared.py``), nor where the light's own red stops the car."""
    params = AdvisorParams(units="kmh")
    lights = tuple(LightView(k + 1, 271.9 + 400.0 * k, red_windows_s=((0.0, 6.0), (36.0, math.inf)), amber_s=0.0) for k in range(2))
    obs = Observation(24.59, 24.59, lights, position_m=0.0)
    est = estimate(obs, [Probe(270.9 - 7.5 * k, 0.0) for k in range(4)])
    assert est.cars[0] == 4.0 and est.clear_s[0] == pytest.approx((12.2, 15.0))
    advice, _ = advise(apply(obs, est), None, params)
    assert (advice.action, advice.reason) == ("none", "short_wait")  # silence, towards a queue standing
    glide = tail_glide(obs, est, advice, params)
    assert (glide.action, glide.reason, glide.light_red, glide.seconds_to_change_s) == ("slow_down", "queue", True, 6.0)
    assert glide.message == f"Queue ahead clears in 14 seconds. Slow down to {spoken_speed(glide.target_speed_mps, 'kmh')} kilometers per hour."
    v, a = glide.target_speed_mps, M.drive_accel_mps2
    start_s = math.sqrt(2.0 * 30.0 / a)  # a car standing at this car's place starts this long before it crosses the line
    reach = lambda target: crossing_time_s(271.9 - 30.0, 24.59, target, params, "brake")  # noqa: E731
    assert params.min_cruise_speed_mps <= v < 24.59
    assert reach(v) >= 13.6 + 1.7 - start_s + v / a  # behind such a car (middle of the discharge) at its speed
    assert reach(v + params.speed_step_mps) < 13.6 + 1.7 - start_s + (v + params.speed_step_mps) / a  # the fastest such
    assert crossing_time_s(271.9, 24.59, v, params, "brake") >= 15.0 + M.headway_s  # over the line behind the queue
    long_red = Observation(13.0, 24.59, (LightView(1, 120.0, red_windows_s=((0.0, 15.0), (45.0, 75.0))),), position_m=0.0)
    est_long = estimate(long_red, [Probe(119.0 - 7.5 * k, 0.0) for k in range(5)])
    assert tail_glide(long_red, est_long, Advice("coast", "red_ahead", 13.0, light_id=1), params) is None
    own_red = replace(obs, lights=(replace(lights[0], red_windows_s=((0.0, 6.0), (14.0, 44.0))),))
    assert tail_glide(own_red, estimate(own_red, [Probe(270.9 - 7.5 * k, 0.0) for k in range(4)]), advice, params) is None
    # through the board: the service's check answers it, spoken once
    board = QueueBoard()
    for k in range(4):
        board.see("c", f"q{k}", 1000.0, Observation(0.0, 24.59, (replace(lights[0], distance_m=1.0 + 7.5 * k),), position_m=270.9 - 7.5 * k))
    held, _ = board.see("c", "car", 1000.0, obs)
    said = board.check(held, advise(held, None, params)[0], params, "car")
    assert (said.action, said.reason, said.speak) == ("slow_down", "queue", True) and said.target_speed_mps == pytest.approx(v)
    again = board.check(held, advise(held, None, params)[0], params, "car", {"reason": "queue", "target_speed_mps": said.target_speed_mps})
    assert again.speak is False


def _green_obs(distance_m=60.0, position_m=140.0):
    """A car at the limit (13.4 m/s) ``distance_m`` before light 1, green now, its next red in 40 s."""
    return Observation(13.4, 13.4, (LightView(1, distance_m, red_windows_s=((40.0, 70.0),)),), position_m=position_m)


def test_the_last_reds_queue_goes_on_discharging_after_its_end():
    """The queue forgotten at the green (traced in SUMO: a car at the limit told to drive normally into a queue still
    discharging, 3.5 m/s² behind its tail). A 30 s red ended 4 s ago; 720 veh/h, half connected: (1 - 0.5) x 0.2 x 30
    = 3 cars not connected stood in it, the last over the line at -4 + 2 + 2 x 1.4 = 0.8 s from now (fast) or
    -4 + 3 + 2 x 2 = 3 s (slow); a connected car standing in front of this one joins behind them (2.2 s, 5 s), this
    car crosses a headway later. A 40 m jam published in the red: 5 cars (3.6 s, 7 s), the connected car standing
    10 m from the line one of them. Gone once they have all crossed; nothing to wait for without a flow or a jam."""
    obs, kw = _green_obs(), {"arrivals_vps": 0.2, "connected_share": 0.5}
    est = estimate(obs, [], **kw, past_red=PastRed(-34.0, -4.0))
    assert est.clear_s[0] == pytest.approx((0.8, 3.0)) and est.free_at_s[0] == pytest.approx(5.0) and est.after_red_s == (None,)
    standing = [Probe(50.0, 0.0)]
    assert estimate(obs, standing, **kw).clear_s[0] == (0.0, 0.0)  # before: the standing car a headway from now, no more
    est = estimate(obs, standing, **kw, past_red=PastRed(-34.0, -4.0))
    assert est.clear_s[0] == pytest.approx((2.2, 5.0)) and est.free_at_s[0] == pytest.approx(7.0) and est.cars == (3.0,)
    for probes in ([], standing):
        est = estimate(obs, probes, **kw, past_red=PastRed(-34.0, -4.0, queue_m=40.0))
        assert est.clear_s[0] == pytest.approx((3.6, 7.0)) and est.cars == (4.0,)
    held = apply(obs, estimate(obs, standing, **kw, past_red=PastRed(-34.0, -4.0))).lights[0]
    ends = [w[0][1] for w in held.scenario_red_windows_s]  # each timing until the clearing at its level, fast to slow
    assert np.allclose(held.red_windows_s, ((0.0, 2.2), (40.0, 70.0))) and 2.2 < min(ends) < max(ends) < 5.0
    assert estimate(obs, [], **kw, past_red=PastRed(-60.0, -30.0)) == estimate(obs, [], **kw)  # long gone
    assert estimate(obs, [], past_red=PastRed(-34.0, -4.0)) == estimate(obs, [])  # no flow, no jam: the probes alone


def test_the_advisor_slows_a_car_at_the_limit_for_the_last_reds_queue():
    """60 m out at the limit (there in 4.5 s), the red's 3 cars and a connected one standing: the line is closed until
    2.2-5 s, plus the advisor's margin; the car is slowed for it, where it held the limit before."""
    obs, kw = _green_obs(), {"arrivals_vps": 0.2, "connected_share": 0.5}
    before, _ = advise(apply(obs, estimate(obs, [Probe(50.0, 0.0)], **kw)), None, AdvisorParams())
    after, _ = advise(apply(obs, estimate(obs, [Probe(50.0, 0.0)], **kw, past_red=PastRed(-34.0, -4.0))), None, AdvisorParams())
    assert before.target_speed_mps == pytest.approx(13.4)
    assert after.target_speed_mps is not None and after.target_speed_mps < 13.4 - 5.0


def test_board_keeps_the_last_red_and_its_queue_after_the_green():
    """The board keeps a light's last red (its start, its end as the last fix in it had it, the jam last published
    in it), so a car that never saw the red meets its queue: a fix at the red's start, another 30 s later on the green,
    the car 4 s after that (the queue of ``test_the_last_reds_queue_goes_on_discharging_after_its_end``)."""
    t = 1000.0
    for jam_m, want in ((None, (0.8, 3.0)), (40.0, (3.6, 7.0))):
        board = QueueBoard(arrivals_vph=720.0, connected_share=0.5)
        red = LightView(1, 500.0, red_windows_s=((0.0, 30.0), (70.0, 100.0)), queue_m=jam_m)
        board.see("c", "watcher", t, Observation(13.4, 13.4, (red,), position_m=-300.0))
        green = LightView(1, 300.0, red_windows_s=((40.0, 70.0),))
        board.see("c", "watcher", t + 30.0, Observation(13.4, 13.4, (green,), position_m=-100.0))
        assert board._red_ended[1][:2] == (t, t + 30.0) and board._red_since == {}
        obs, held = board.see("c", "car", t + 34.0, _green_obs())
        assert held is None and np.allclose(obs.lights[0].red_windows_s, ((0.0, want[0]), (40.0, 70.0)))
        ends = [w[0][1] for w in obs.lights[0].scenario_red_windows_s]
        assert want[0] < min(ends) < max(ends) < want[1]
    late = QueueBoard(arrivals_vph=720.0, connected_share=0.5)  # the first fix on the green 8 s after it began
    late.see("c", "watcher", t, Observation(13.4, 13.4, (LightView(1, 500.0, red_windows_s=((0.0, 30.0),)),), position_m=-300.0))
    late.see("c", "watcher", t + 38.0, Observation(13.4, 13.4, (LightView(1, 200.0, red_windows_s=((32.0, 62.0),)),), position_m=0.0))
    assert late._red_ended[1][:2] == (t, t + 30.0)  # when the last fix in the red had it end, not 8 s later


def test_board_counts_a_red_from_its_own_start_when_no_fix_saw_the_green_before_it():
    """With few connected cars no fix may see a light's green: a red seen 60 s after one that the last fix in it had
    surely end 30 s after it is another red (elapsed 0 at its first fix, the one before kept as ended), not 60 s of one
    red; an actuated green past its minimum (the sure view red from now, the late view green: it may end any second
    but shows green) is no red either. Traced: paper_s400 actuated 900 veh/h, 10 %, seed 5, ``main.91``, 19 cars
    counted in a queue of 5 (the red counted from a fix 70 s before, on the green before the red before it)."""
    t = 1000.0
    red = Observation(13.4, 13.4, (LightView(1, 500.0, red_windows_s=((0.0, 30.0),)),), position_m=-300.0)
    board = QueueBoard(arrivals_vph=720.0, connected_share=0.5)
    assert board.red_elapsed(red, t) == 0.0 and board.red_elapsed(red, t + 20.0) == 20.0  # one red, seen twice
    assert board.red_elapsed(red, t + 60.0) == 0.0  # the red before surely ended at t + 50 (its last fix's view)
    assert board._red_ended[1][:2] == (t, t + 50.0)
    endless = Observation(13.4, 13.4, (LightView(1, 500.0, red_windows_s=((0.0, math.inf),)),), position_m=-300.0)
    board = QueueBoard(arrivals_vph=720.0, connected_share=0.5)
    assert board.red_elapsed(endless, t) == 0.0 and board.red_elapsed(endless, t + 60.0) == 60.0  # no end known: one red
    past_min = LightView(1, 500.0, red_windows_s=((0.0, math.inf),), late_red_windows_s=((12.0, 40.0),))
    board = QueueBoard(arrivals_vph=720.0, connected_share=0.5)
    assert board.red_elapsed(Observation(13.4, 13.4, (past_min,), position_m=-300.0), t) is None and board._red_since == {}
    shown = LightView(1, 400.0, red_windows_s=((0.0, math.inf),), late_red_windows_s=((0.0, 28.0),))
    assert board.red_elapsed(Observation(13.4, 13.4, (shown,), position_m=-200.0), t + 15.0) == 0.0


def test_board_holds_a_queued_car_until_it_is_over_the_line_then_plans_afresh():
    board = QueueBoard()
    t = 1000.0
    lead = Observation(0.0, 13.4, (LightView(1, 1.0, red_windows_s=((0.0, 15.0),)),), position_m=299.0)
    car = Observation(0.5, 13.4, (LightView(1, 9.0, red_windows_s=((0.0, 15.0),)),), position_m=291.0)
    assert board.see("c", "lead", t, lead)[1] is None  # first at the line: the advisor's (too close)
    obs, held = board.see("c", "car", t, car)
    assert held is not None and (held.action, held.reason, held.light_red) == ("none", "queue", True) and held.speak
    moving = Observation(8.0, 13.4, (LightView(1, 3.0, red_windows_s=((50.0, 80.0),)),), position_m=297.0)
    assert board.see("c", "car", t + 12.0, moving, "queue")[1] is not None  # still short of the line: followed
    assert board.see("c", "car", t + 12.0, moving, "queue")[1].speak is False
    past = Observation(9.0, 13.4, (LightView(2, 300.0, red_windows_s=((50.0, 80.0),)),), position_m=303.0)
    assert board.see("c", "car", t + 13.0, past, "queue")[1] is None and QueueBoard.fresh("queue")
    assert board.held == 3


@pytest.mark.parametrize("units, lead_mps, want", [("mph", 10.0, "Queue ahead. Ease off to 22 miles per hour."),
                                                     ("kmh", 10.0, "Queue ahead. Ease off to 35 kilometers per hour."),
                                                     ("mph", 6.0, "Queue ahead. Ease off to 13 miles per hour."),
                                                     ("mph", 3.0, "Queue ahead. Follow the car in front.")])
def test_a_car_closing_in_on_a_slower_connected_car_lifts_off_to_its_speed(units, lead_mps, want):
    """At 13.4 m/s, 30 m behind a connected car at ``lead_mps`` (within the 3 s follow gap and a car), 200 m before a
    green light: told only to follow, the car closed in and braked where the gap ran out, and so did every car behind
    it (traced in SUMO, docs/TRAFFIC.md). It is told to lift off to the car ahead's speed, in the advisor's whole mph
    at or below it (never faster than the traffic ahead allows; km/h as spoken: 22 mph = 9.83 m/s = 35 km/h), spoken
    once, again where that speed moves by 5 mph; behind a car crawling below the slowest advised speed (10 mph) it
    follows, no speed. Over the line it is advised afresh, as before."""
    board, t, params = QueueBoard(), 1000.0, AdvisorParams(units=units)
    green = (LightView(1, 200.0, red_windows_s=((40.0, 70.0),)),)
    lead = Observation(lead_mps, 13.4, tuple(replace(lv, distance_m=170.0) for lv in green), position_m=130.0)
    board.see("c", "lead", t, lead)
    _, held = board.see("c", "car", t, Observation(13.4, 13.4, green, position_m=100.0), params=params)
    assert held is not None and held.reason == "queue" and held.message == want and held.speak
    if held.target_speed_mps is not None:
        assert held.action == "ease_off" and held.target_speed_mps <= lead_mps < held.target_speed_mps + 0.44704
    closer = Observation(12.0, 13.4, tuple(replace(lv, distance_m=188.0) for lv in green), position_m=112.0)
    _, again = board.see("c", "car", t + 1.0, closer, "queue", params=params, told_mps=held.target_speed_mps)
    assert again.message == want and not again.speak  # said once
    slower = replace(lead, speed_mps=lead_mps - 3.0)
    board.see("c", "lead", t + 1.0, slower)
    if lead_mps >= 8.0:
        _, moved = board.see("c", "car", t + 1.0, closer, "queue", params=params, told_mps=held.target_speed_mps)
        assert moved.target_speed_mps < held.target_speed_mps - 2.2 and moved.speak  # 3 m/s slower ahead: said again


@pytest.mark.parametrize("amber_s, red_s, stops", [(0.0, 4.0, True), (0.0, 6.0, True), (0.0, 8.0, False), (None, 5.0, False), (4.0, 4.0, False)])
def test_a_car_behind_one_that_takes_the_last_of_the_green_prepares_to_stop_instead_of_following(amber_s, red_s, stops):
    """At 22 m/s, 80 m before a light that turns red in ``red_s`` (its own drive at the limit there in 3.25 s: it
    would make it alone), 20 m behind a connected car at 15 m/s, slower: the old service said "follow the car in
    front", behind which it crosses after the red. By hand: that car, holding its speed, is 7.5 m past the line
    (67.5 m) after 4.5 s, and this car crosses (20 - 7.5) / 15 = 0.83 s later (the time it is behind that car now, less
    than the 2 s headway), at 5.33 s. At a light that shows no amber (SUMO's paper lights, seed 1 at 900 veh/h: entered
    0.5 s into such a red) it is to stop where that is less than 2 s before the red (it closes in on a slower car), and
    advised so; else it follows, and where an amber announces the red (or may: unknown) it follows too, as the
    regular driver meets any amber."""
    lead = 67.5 / 15.0 + 12.5 / 15.0
    assert behind_s(80.0, [(20.0, 15.0)]) == pytest.approx(lead) and lead == pytest.approx(5.33, abs=0.01)
    lights = (LightView(1, 80.0, red_windows_s=((red_s, red_s + 30.0), (red_s + 60.0, red_s + 90.0)), amber_s=amber_s),)
    obs = Observation(22.0, 24.5872, lights, position_m=100.0)
    est = estimate(obs, [Probe(20.0, 15.0)])
    assert est.follow_mps == 15.0 and est.stop_behind is stops  # closing in on a slower car, either way
    board = QueueBoard()
    board.see("c", "lead", 0.0, Observation(15.0, 24.5872, tuple(replace(lv, distance_m=60.0) for lv in lights), position_m=120.0))
    seen, held = board.see("c", "car", 0.0, obs)
    if not stops:
        assert held is not None and held.reason == "queue"
        return
    assert held is None and seen.lights[0].red_windows_s[0] == (0.0, red_s + 30.0)  # closed to it until the red's end
    advice, _ = advise(seen)
    assert advice.action == "stop" and advice.target_speed_mps == 0.0 and "Prepare to stop" in advice.message


@pytest.mark.parametrize("told", [None, Advice("slow_down", "green_wave", 8.0), Advice("stop", "red", 0.0)])
def test_a_car_ahead_told_to_slow_down_holds_this_one_longer_than_its_speed_now_says(told):
    """At 20 m/s, 100 m before a light that shows no amber and turns red in 10 s, 37.5 m behind a connected car at 15
    m/s (2 s: 30 m beyond a jam spacing). By hand (Newell's follower, :func:`behind_s`): that car holding 15 m/s is
    7.5 m past the line after 70 m, 4.67 s, and this car crosses 2 s later, at 6.67 s; with the 2 s margin (it closes
    in on a slower car) 8.67 s, before the red: it follows. Told to slow to 8 m/s (the advisor's gentle 1.5 m/s²:
    53.67 m in 4.67 s, then 16.33 m at 8 m/s in 2.04 s), that car is there at 6.71 s, this car at 8.71 s, 10.71 s
    with the margin: after the red's start, and it prepares to stop instead (before, the service took the car ahead
    to hold its 15 m/s and told this one to follow it towards the red). Told to stop at the line, that car never
    crosses before the red: this one prepares to stop too. The service knows what it told the car ahead: its fix's
    advice (``QueueBoard.check``)."""
    limit, params = 24.5872, AdvisorParams()
    lights = (LightView(1, 100.0, red_windows_s=((10.0, 40.0), (70.0, 100.0)), amber_s=0.0),)
    ahead = Observation(15.0, limit, tuple(replace(lv, distance_m=62.5) for lv in lights), position_m=137.5)
    assert behind_s(100.0, [(37.5, 15.0)]) == pytest.approx(70.0 / 15.0 + 2.0)
    board = QueueBoard()
    seen_ahead, held_ahead = board.see("c", "ahead", 0.0, ahead)
    if told is not None:
        assert held_ahead is None
        assert board.check(seen_ahead, told, params, "ahead") == told  # the service's answer to that car: the plan stands
    seen, held = board.see("c", "car", 0.0, Observation(20.0, limit, lights, position_m=100.0))
    if told is None:  # holding its speed: this car follows it (its lift-off to that car's speed)
        assert held is not None and held.reason == "queue"
        return
    assert held is None and seen.lights[0].red_windows_s[0] == (0.0, 40.0)  # closed to it until the red's end
    advice, _ = advise(seen)
    assert advice.action == "stop" and "Prepare to stop" in advice.message


def test_the_board_sees_each_probe_where_it_is_at_the_fix_not_where_it_was():
    """A corridor's fixes arrive one after the other: a car behind that posted 0.9 s before this one is counted where it
    is now (its fix advanced at its speed): 86.4 - 0.9 x 24 = 64.8 m behind at 24 m/s, 2.7 s, within the 3 s window
    of the followers (:func:`followers`), though its fix says 3.6 s."""
    lights = (LightView(1, 125.0, red_windows_s=((10.0, 40.0),)),)
    board = QueueBoard()
    board.see("c", "behind", 100.0, Observation(24.0, 24.5872, tuple(replace(lv, distance_m=211.4) for lv in lights), position_m=13.6))
    seen, held = board.see("c", "car", 100.9, Observation(24.0, 24.5872, lights, position_m=100.0))
    assert held is None and seen.followers == 1.0
    assert followers(Observation(24.0, 24.5872, lights), [Probe(-86.4, 24.0)]) == 0.0  # where its fix was: not behind


def test_engine_with_queue_awareness_tells_a_car_behind_a_queue_to_follow():
    """Through the service's own path: two trips on one corridor, the first standing at a red, the second creeping
    up behind it: the second is told to follow (reason ``queue``) once the queue board is on (ECO_QUEUE_AWARE)."""
    import asyncio

    from server.advising import Engine
    from server.config import Settings
    from server.gps import Fix
    from server.schemas import TripCreate
    from server.spat import SpatHub
    from spat_feed.road.corridors import load_corridor
    from spat_feed.transport.scenarios import make_scenario, spat_message_at

    corridor = load_corridor("paper_s400")
    t0 = 1_714_590_030.0  # 15_15: red from :15 to :45, so red now for 15 s more
    now = [t0]
    settings = Settings(spat_simulate=False, tables=False, speech=False, queue_aware=True)
    hub = SpatHub(settings, {corridor.name: corridor}, lambda: now[0])
    for ix in spat_message_at(make_scenario(corridor, "15_15", 0.0), t0).intersections:
        hub.store.offer(ix)
    engine = Engine(settings, {corridor.name: corridor}, spat=hub, clock=lambda: now[0])

    async def go():
        a = await engine.create_trip(TripCreate(corridor=corridor.name), client="a")
        b = await engine.create_trip(TripCreate(corridor=corridor.name), client="b")
        lat, lon = corridor.position(98.0)
        first = engine.on_fix(a, Fix(t0, lat, lon, speed_mps=0.0))
        lat, lon = corridor.position(88.0)
        second = engine.on_fix(b, Fix(t0, lat, lon, speed_mps=1.0))
        return first, second

    first, second = asyncio.run(go())
    assert first["reason"] != "queue"
    assert (second["action"], second["reason"], second["message"]) == ("none", "queue", "Queue ahead. Follow the car in front.")


libsumo = pytest.importorskip("libsumo")


def test_in_sumo_a_queue_makes_the_queue_blind_target_late_and_the_queue_aware_one_glide(tmp_path):
    """7th Street, Oakland (fixed, its plan at noon: light 1 red from 48 s to 90 s): ten cars reach light 1 during
    its red and stand; an eleventh arrives as it turns green. Unadvised it stops behind the queue. Queue-blind, its
    advice aims at the green: it slows to the slowest advised speed and is held behind the discharging queue (until
    SUMO's lights published their whole cycle it was told to stop, the red's end unknown, and stopped);
    queue-aware (every car connected: the service knows the queue), it aims at the queue having crossed the line and
    glides through without stopping, earlier."""
    from ecodrive.traffic.network import build_network
    from ecodrive.traffic.sim import RunSetup, run
    from ecodrive.traffic_eval import count_stops
    from spat_feed.road.corridors import load_corridor

    corridor = load_corridor("oakland_7th_westbound")
    net = build_network(corridor, tmp_path)
    departures = tuple(5.0 + 3.0 * k for k in range(10)) + (44.0,)
    ids = tuple(f"main.{k}" for k in range(len(departures)))
    setup = RunSetup(0.0, 1.0, 1, 60.0, drain_s=150.0, departures_s=departures, connected=ids)
    line = corridor.intersections[0].stop_line_m
    out = {}
    for mode in ("blind", "advised", "unadvised"):
        car = run(net, setup, mode).cars["main.10"]
        v, x = np.array(car.v), np.array(car.x)
        out[mode] = (count_stops(v), float(v[(x > 0.0) & (x < line)].min()), car.crossings[0])
    assert out["unadvised"][0] == 1 and out["unadvised"][1] < 0.5
    assert out["advised"][0] == 0 and out["advised"][1] > 3.0
    assert out["advised"][2][1] < out["blind"][2][1] and out["advised"][2][2] == "green"


def test_in_sumo_a_queue_published_in_the_spat_makes_the_unconnected_queue_known(tmp_path):
    """The same queue, but only the eleventh car is connected: the service sees no car ahead (and is told of no flow),
    so its advice aims at the green and the car stops behind the ten. With the lights publishing each approach's jam as
    J2735 ``queueLength`` (``RunSetup(spat_queue=True)``, ``traffic-eval --spat-queue``: stop-line detectors), the
    advisor counts the standing cars from the SPaT alone and the car glides through without stopping."""
    from ecodrive.traffic.network import build_network
    from ecodrive.traffic.sim import RunSetup, run
    from ecodrive.traffic_eval import count_stops
    from spat_feed.road.corridors import load_corridor

    corridor = load_corridor("oakland_7th_westbound")
    net = build_network(corridor, tmp_path)
    departures = tuple(5.0 + 3.0 * k for k in range(10)) + (44.0,)
    line = corridor.intersections[0].stop_line_m
    out = {}
    for spat_queue in (False, True):
        setup = RunSetup(0.0, 1.0, 1, 60.0, drain_s=150.0, departures_s=departures, connected=("main.10",), spat_queue=spat_queue)
        car = run(net, setup, "advised").cars["main.10"]
        v, x = np.array(car.v), np.array(car.x)
        out[spat_queue] = (count_stops(v), float(v[(x > 0.0) & (x < line)].min()), car.crossings[0])
    assert out[False][0] == 1 and out[False][1] < 0.5
    # (never standing: the published jam ends when its first car moves, SUMO's halting threshold, so from the green on
    # the car is told to drive normally and meets the discharging queue's tail, slowing to 2.9 m/s at the firm 3 m/s²)
    assert out[True][0] == 0 and out[True][1] > M.queued_mps and out[True][2][2] == "green"


def test_followers_known_behind_and_expected_from_the_flow():
    """The cars a slower plan holds up (issue 28, the traffic behind): 300 m from the line at 13 m/s (limit 13.4), this
    car is there unimpeded in 0.2 + (300 - 2.64) / 13.4 = 22.39 s; the queue in front holds the line until 30 s, so
    every car reaching the line within 30 - 22.39 + 3 (the follow gap) = 10.61 s after it is held up: half of 720 veh/h
    not connected, 0.1 x 10.61 = 1.06 cars, plus a connected car 50 m behind (there 3.7 s after it), not one 200 m
    behind (14.9 s after). On a green with no queue, the window is the follow gap alone."""
    obs = _obs(reds=((0.0, 20.0),))
    behind = [Probe(-50.0, 13.0), Probe(-200.0, 13.0)]
    window = 30.0 - (0.2 + (300.0 - (13.4**2 - 13.0**2) / 4.0) / 13.4) + M.follow_gap_s
    assert followers(obs, [], 30.0, M, 0.2, 0.5) == pytest.approx(0.1 * window)
    assert followers(obs, behind, 30.0, M, 0.2, 0.5) == pytest.approx(1.0 + 0.1 * window)
    assert followers(obs, behind, 0.0, M, 0.2, 1.0) == 0.0  # 3.7 s behind: more than the follow gap on a free line
    # the estimate carries it, and the advisor's view of the lights gets it
    standing = [Probe(300.0 - 1.0 - 7.5 * k, 0.0) for k in range(4)]
    est = estimate(obs, standing + behind, M)
    assert est.free_at_s[0] == pytest.approx(20.0 + M.startup_s + 4 * M.headway_s) and est.followers == 1.0
    assert apply(obs, est).followers == 1.0


def test_a_plan_that_pushes_followers_past_the_end_of_a_green_gives_way():
    """At the limit (24.6 m/s), 150 m from a light green for 9 s more (then red for 30 s), the next light red at a
    normal arrival: the advisor slows the car for the second light's green, over the first line 1.2 s later than a
    normal drive (7.3 s against 6.1 s). Alone, that costs nothing (the car waits at the second light either way). With
    half a car expected behind, 2 s back: it crosses at 8.1 s behind a normal drive, at 9.3 s behind this plan, past
    the red: there with probability 1 - exp(-0.5) = 0.39, it waits 30 s: 11.8 s lost for 5 s allowed: "drive normally"
    (the car is advised again past the first light, with 400 m to slow down in)."""
    params = AdvisorParams()
    lights = (LightView(1, 150.0, red_windows_s=((9.0, 39.0), (69.0, 99.0))), LightView(2, 550.0, red_windows_s=((10.0, 40.0), (70.0, 100.0))))
    alone = Observation(24.6, 24.6, lights)
    plan, _ = advise(alone, None, params)
    assert plan.action == "coast" and plan.target_speed_mps < 24.6 - 5.0
    late = crossing_time_s(150.0, 24.6, plan.target_speed_mps, params, "brake_coast") - 150.0 / 24.6
    assert 1.0 < late < 1.5
    assert cut_off(lights[0], 150.0 / 24.6, 150.0 / 24.6 + late, 0.5, M.headway_s) == pytest.approx((1.0 - np.exp(-0.5)) * 30.0)
    assert not gives_up_green(alone, plan, params)
    followed = Observation(24.6, 24.6, lights, followers=0.5)
    assert gives_up_green(followed, plan, params)
    board = QueueBoard()
    told = board.check(followed, plan, params)
    assert (told.action, told.reason, told.target_speed_mps) == ("none", "tight_green", None)
    assert board.check(alone, plan, params) is plan


def test_the_choice_prices_the_followers_time():
    """Under uncertain timing (the choice of least expected cost), a red on now that ends 19-31 s from now, 350 m
    ahead at 50 km/h: alone, the car is slowed to reach the line after it; with twenty cars behind that lose what it
    loses, time is priced 21 times over and the plan reaches the line no later (a faster target, or no speed advice:
    drive on and stop if the red is still on)."""
    params = AdvisorParams()
    v = 50 / 3.6
    light = LightView(1, 350.0, red_windows_s=((0.0, 31.0),), likely_red_windows_s=((0.0, 25.0),), late_red_windows_s=((0.0, 31.0),),
                      scenario_red_windows_s=tuple(((0.0, 19.0 + k),) for k in range(13)))  # fmt: skip
    alone, _ = advise(Observation(v, v, (light,)), None, params)
    followed, _ = advise(Observation(v, v, (light,), followers=20.0), None, params)
    assert alone.reason == "green_wave" and alone.target_speed_mps < v - 1.0
    assert followed.target_speed_mps is None or followed.target_speed_mps > alone.target_speed_mps
    assert time_price(Observation(v, v, followers=20.0)) == 21.0


def test_a_car_already_slowed_for_a_red_further_on_is_not_sent_back_up():
    """Coasting at 13 m/s on a plan for the second light's green (red at a normal arrival there, 21.5 s), over the
    first line 2.3 s after a normal drive would be: with five cars expected behind, 5 x 2.3 s would be given up, but the
    car has slowed already: sent back up to the limit it would meet that red (or a queue's tail) faster, and the
    followers' time is lost already. The same plan still to be begun at the limit, 200 m from a first light green for
    12 s more, gives way (over that line 3 s late, the first follower pushed past its green)."""
    params = AdvisorParams()
    plan = Advice("coast", "green_wave", 12.96)
    slowed = (LightView(1, 100.0, red_windows_s=((9.0, 39.0),)), LightView(2, 500.0, red_windows_s=((10.0, 40.0),)))
    assert crossing_time_s(100.0, 13.0, 12.96, params, "brake_coast") - normal_drive_s(100.0, 13.0, 24.6, 2.0) > 2.0
    assert not gives_up_green(Observation(13.0, 24.6, slowed, followers=5.0), plan, params)
    ahead = (LightView(1, 200.0, red_windows_s=((12.0, 42.0),)), LightView(2, 600.0, red_windows_s=((15.0, 45.0),)))
    assert gives_up_green(Observation(24.6, 24.6, ahead, followers=5.0), plan, params)
    assert not gives_up_green(Observation(24.6, 24.6, ahead), plan, params)  # alone: the red further on takes it back


def test_a_plan_that_pushes_a_connected_follower_into_a_red_without_amber_gives_way():
    """Traced in SUMO (paper_s400 fixed 600 veh/h, every car connected, seed 1): at the limit (24.58 m/s), 124.5 m
    from a light turning red in 8 s without amber, the second light red at a normal arrival, the advisor slows the car
    for the second light's green, over the first line at 5.75 s instead of 5.06 s. A connected car 61.4 m (2.5 s)
    behind, over the line 0.44 s before the red at its speed, follows 53.9 / 24.59 = 2.19 s after the car in front is
    a jam spacing past the line (Newell's shift, its own lag): 5.37 + 2.19 = 7.56 s behind a normal drive, about 8.4 s
    behind the plan: pushed into the red, whose 30 s it would wait out (it entered it in SUMO, 0.5 s in). Counted as a
    follower arriving at random 2 s behind (one car expected, no position), it crosses at 7.75 s: not pushed."""
    params = AdvisorParams()
    reds = ((8.0, 38.0), (68.0, 98.0))
    lights = (LightView(1, 124.5, red_windows_s=reds, amber_s=0.0), LightView(2, 524.5, red_windows_s=reds, amber_s=0.0))
    obs = Observation(24.58, 24.587, lights, followers=1.0)
    plan = Advice("coast", "green_wave", 9.38)
    follower = Probe(-61.4, 24.59)
    past = crossing_time_s(124.5 + M.jam_spacing_m, 24.58, 9.38, params, "brake_coast")
    normal_past = (124.5 + M.jam_spacing_m) / 24.58
    assert past - normal_past > 0.6
    own = (124.5 + 61.4) / 24.59
    assert own < 8.0 <= past + (61.4 - M.jam_spacing_m) / 24.59
    assert pushed_past(lights[0], normal_past, past, [follower], 24.587, M) == 30.0
    assert not gives_up_green(obs, plan, params)  # the follower as one of the flow's
    assert gives_up_green(obs, plan, params, behind=(follower,))
    assert not gives_up_green(obs, plan, params, behind=(Probe(-100.0, 24.59),))  # 4 s behind: its own drive is past the red's start
    # the board finds the follower at the fixes and the check gives way: "drive normally" (over the line at 5.06 s)
    board = QueueBoard()
    board.see("c", "follower", 1000.0, replace(obs, speed_mps=24.59, position_m=100.0 - 61.4, followers=0.0,
                                                lights=tuple(replace(lv, distance_m=lv.distance_m + 61.4) for lv in lights)))  # fmt: skip
    seen, held = board.see("c", "leader", 1000.0, replace(obs, position_m=100.0, followers=0.0))
    assert held is None and seen.followers == 1.0 and board._behind["leader"] == (follower,)
    told = board.check(seen, plan, params, "leader")
    assert (told.action, told.reason, told.target_speed_mps) == ("none", "tight_green", None)
    assert (told.light_red, told.seconds_to_change_s, told.light_id) == (False, 8.0, 1)  # the countdown of the light it drives through
    assert board.check(seen, plan, params) is plan  # no trip: no follower known where it is


def test_a_plan_made_for_the_queue_is_not_held_across_the_line_on_green():
    """Traced in SUMO (paper_s400 fixed 300 veh/h, 50 % connected, seed 1, ``main.16``): told to slow for the queue
    the board estimates (the red's unconnected arrivals), then silent within 15 m of the line (``too_close``), the
    driver went on with that slow plan across the line on green with no car in front, and sped up past it only; the
    connected cars behind it lost the next light's green. At the line the driver sees the queue itself: the board says
    "drive normally" there where the light itself is green and a normal drive is over the line before its red (2 s
    before one that no amber announces). A plan not made for a queue, or a light red itself, keeps the silence."""
    params = AdvisorParams(units="kmh")
    board, t = QueueBoard(arrivals_vph=720.0, connected_share=0.5), 1000.0

    def light(distance_m, reds):
        return LightView(1, distance_m, red_windows_s=reds, amber_s=0.0)

    board.see("c", "watcher", t - 25.0, Observation(24.6, 24.6, (light(600.0, ((0.0, 45.0), (75.0, 105.0))),), position_m=-600.0))
    far = Observation(6.0, 24.6, (light(120.0, ((-25.0, 20.0), (50.0, 80.0))),), position_m=-120.0)  # red for 25 s
    held, _ = board.see("c", "car", t, far)
    assert held.lights[0] != far.lights[0]  # the queue holds the line past the red's end
    plan = board.check(held, advise(held, None, params)[0], params, "car")
    assert plan.action != "none" and plan.target_speed_mps is not None and plan.target_speed_mps < 24.6 - params.hysteresis_mps
    near = Observation(4.0, 24.6, (light(12.0, ((29.0, 59.0),)),), position_m=-12.0)  # the red ended 1 s ago
    held, _ = board.see("c", "car", t + 21.0, near)
    silent = advise(held, None, params)[0]
    assert (silent.action, silent.reason) == ("none", "too_close")
    out = board.check(held, silent, params, "car")
    assert (out.action, out.reason, out.light_red, out.seconds_to_change_s) == ("none", "tight_green", False, 29.0)
    assert out.message == "Red in 29 seconds. Drive normally."
    # the same silence after a plan made for the light alone (no queue estimated), or at a light red itself: silence
    alone = QueueBoard()
    obs, _ = alone.see("c", "car", t, far)
    alone.check(obs, advise(obs, None, params)[0], params, "car")
    obs, _ = alone.see("c", "car", t + 21.0, near)
    assert alone.check(obs, silent, params, "car").reason == "too_close"
    red = Observation(4.0, 24.6, (light(12.0, ((-20.0, 2.0), (32.0, 62.0))),), position_m=-12.0)
    obs, _ = board.see("c", "car", t + 21.0, red)
    assert board.check(obs, advise(obs, None, params)[0], params, "car").reason == "too_close"


@pytest.mark.parametrize("lead_mps", [4.0, 8.0, 16.0, 24.6])
@pytest.mark.parametrize("line_m", [-30.0, -7.0, 20.0])
def test_a_platoon_crosses_a_line_behind_a_steady_leader_at_the_congested_flow(lead_mps, line_m):
    """Behind a leader at a steady speed ``u`` the platoon crosses any line at the flow of the triangular fundamental
    diagram's congested branch, one car every ``jam / u + gap`` (Newell's car following): before a red ``R`` s from
    now, the cars whose turn comes earlier, counted from the leader's own crossing ``d / u`` (d: the line's distance)."""
    gap_s, jam_m, red_s = 1.1, 7.5, 15.3
    want = math.ceil((red_s - line_m / lead_mps) / (jam_m / lead_mps + gap_s)) - 1
    assert platoon_through(line_m, red_s, lambda x: x / lead_mps, gap_s, jam_m) == want
    assert platoon_through(line_m, red_s, lambda x: x / lead_mps, gap_s, jam_m, first=3) == max(want - 2, 0)  # two places taken


@pytest.mark.parametrize("amber_s, levels_cut", [(0.0, 2), (4.0, 0), (None, 0)])
def test_a_connected_car_behind_keeps_its_margin_before_a_red_no_amber_announces(amber_s, levels_cut):
    """A connected car behind is told to stop where the car in front leaves it less than ``no_amber_margin_s`` (2 s)
    before a red that no amber announces (:func:`estimate`, ``stop_behind``), so its place is cut off that much earlier.
    50 m before a light turning red in 7 s (for 30 s), at 12 m/s, told to hold it; a connected car 20 m behind (it
    reaches the line on its own in 4.1 s). Behind a normal drive (2 m/s² up) it crosses when the car is a jam spacing
    past the line, 3.67 s, plus the gap, 1.16-1.64 s over the discharge's five levels (a car every 1.46-1.94 s behind
    a leader at the limit): 4.83-5.31 s, 2 s before the red at the two fastest levels; behind the plan at 57.5 / 12 +
    the gap, 5.95-6.43 s, less than 2 s before it at all five: cut off at a light without amber in two levels of five,
    0.4 x the red's 30 s; with an amber (or none known), not cut off (before the red at every level).
    (Traced in SUMO, paper_s400 fixed 600 veh/h 50 %, seed 3: a connected car behind a platoon that a connected leader
    held to 11.5 m/s over the first line for the second one's red was told to stop 2 s before the first one's red; it
    and the car behind it lost 33-35 s, and the next red's queue one more car.)"""
    params = AdvisorParams()
    light = LightView(1, 50.0, red_windows_s=((7.0, 37.0),), amber_s=amber_s)
    obs = Observation(12.0, 24.6, (light,))
    hold = Advice("cruise", "green_wave", 12.0, light_id=1)
    gaps = [M.fast_headway_s + (j + 0.5) / 5 * (M.headway_s - M.fast_headway_s) - 7.5 / 24.6 for j in range(5)]
    normal = [normal_drive_s(57.5, 12.0, 24.6, 2.0) + g for g in gaps]
    plan = [57.5 / 12.0 + g for g in gaps]
    assert (normal[0], normal[-1], plan[0], plan[-1]) == pytest.approx((4.83, 5.31, 5.95, 6.43), abs=0.01)
    red_s = 7.0 - (M.no_amber_margin_s if amber_s == 0.0 else 0.0)  # where its place is cut off
    assert sum(n < red_s <= p for n, p in zip(normal, plan)) == levels_cut
    assert cut_behind(light, obs, hold, params, [Probe(-20.0, 12.0)]) == pytest.approx(30.0 * levels_cut / 5)
    assert cut_behind(light, obs, hold, params) == 0.0  # nobody behind


def test_the_connected_cars_not_yet_on_the_route_are_expected_from_the_flow():
    """The service sees a trip from the approach's start on: the connected cars farther back are no probes yet, and the
    board expects them from the flow like the cars that are not connected (:func:`unseen_behind`). At the limit (24.59
    m/s) 160 m before the zone, 260 m before a light, the route beginning 15 m behind the car: it is at the line in
    10.57 s and holds up the cars arriving within the 3 s follow gap after it; of 600 veh/h, half of them not
    connected, 0.25 cars; the connected ones arriving after (260 + 15) / 24.59 = 11.18 s were behind the route's start
    at the fix: 0.5 x (1 / 6) x (13.57 - 11.18) = 0.20 more. (Traced in SUMO, paper_s400 fixed 600 veh/h 50 %, seed 3:
    a car told 224 m before a light green for 16 s more to slow for the next light was priced as cutting off 4.1 s of
    the cars behind it, under the 5 s it may; with the connected ones not yet seen (and their margin, above), 17.9 s:
    the plan raised for them.)"""
    limit = 24.59
    obs = Observation(limit, limit, (LightView(1, 260.0, red_windows_s=((26.0, 56.0),), amber_s=0.0),), position_m=-160.0)
    mine = 260.0 / limit
    alone = 0.5 * (600 / 3600) * M.follow_gap_s
    upstream = 0.5 * (600 / 3600) * (mine + M.follow_gap_s - 275.0 / limit)
    seen, _ = QueueBoard(arrivals_vph=600.0, connected_share=0.5).see("c", "t", 1000.0, obs, view_from_m=-175.0)
    unknown, _ = QueueBoard(arrivals_vph=600.0, connected_share=0.5).see("c", "t", 1000.0, obs)
    assert unknown.followers == pytest.approx(alone) and seen.followers == pytest.approx(alone + upstream)
    assert upstream == pytest.approx(0.199, abs=1e-3)


def test_a_slow_plan_over_a_green_line_prices_the_cars_it_cuts_off_behind_it():
    """A car 7 m past a line turning red in 15 s (for 30 s), at 9.2 m/s, told to hold 29 km/h (8.04 m/s), four
    connected cars standing behind the line, 900 veh/h, half connected, one level of the discharge (its fast end, a car
    every 1.4 s behind a leader at the limit): behind the plan 8 cars cross before the red, behind a normal drive 9
    (:func:`platoon_through`); the four take places 1-4 and the cars not connected, K of them,
    Poisson with a mean of one per connected car (4, more than the flow's 0.125 x (15 + 0.76) = 2.0), the places from
    5 on: the ninth is taken when K >= 5, and then waits the red, and stands first in its queue: every car queuing
    behind it over the red and its discharge, 0.25 x 30 / (1 - 0.25 x 1.4) = 11.5 cars, crosses 1.4 s later (the next
    green not known: no more than a green as long as the red lets over): (30 + 16.2) s x P(K >= 5)."""
    params = AdvisorParams()
    passed = LightView(1, -7.0, red_windows_s=((15.0, 45.0),))
    obs = Observation(9.2, 24.6, (LightView(2, 393.0, red_windows_s=((0.0, 40.0),)),))
    four = [Probe(-7.0 - 7.5 * k, 0.0) for k in (1, 2, 3, 4)]
    hold = Advice("cruise", "green_wave", 8.04)
    p_ge_5 = 1.0 - sum(math.exp(-4.0) * 4.0**j / math.factorial(j) for j in range(5))
    queued = 0.25 * 30.0 / (1.0 - 0.25 * M.fast_headway_s)  # behind the car cut off in the red's queue, a headway each
    assert cut_behind(passed, obs, hold, params, four, 900 / 3600, 0.5, model=ONE) == pytest.approx((30.0 + M.fast_headway_s * queued) * p_ge_5)
    for model in (ONE, M):
        assert cut_behind(passed, obs, hold, params, four, 900 / 3600, 1.0, model=model) == 0.0  # every car connected: nobody beyond the four
        at_limit = replace(obs, speed_mps=24.58)  # holding the limit: as a normal drive
        assert cut_behind(passed, at_limit, Advice("cruise", "green_wave", 24.58), params, four, 900 / 3600, 0.5, model=model) == 0.0
        waits = [cut_behind(passed, obs, Advice("cruise", "green_wave", 0.44704 * k), params, four, 900 / 3600, 0.5, model=model) for k in range(10, 56)]
        assert all(a >= b for a, b in zip(waits, waits[1:]))  # the faster the plan, the fewer cut off (what the board's search needs)
        red = LightView(1, -7.0, red_windows_s=((-1.0, 29.0), (59.0, 89.0)))  # red now: its next green is far off
        assert cut_behind(red, obs, hold, params, four, 900 / 3600, 0.5, model=model) == 0.0


@pytest.mark.parametrize("next_red_s, met", [(70.0, True), (120.0, False)])
def test_a_car_cut_off_also_pushes_the_next_platoon_into_the_next_lights_red(next_red_s, met):
    """The platoon of the previous test, the second light 400 m past the first (393 m ahead): the car cut off at the
    first light's red (15-45 s) stands first in its queue, which leaves the line from 45 s; on to the second light
    (24.6 m/s limit, 2 m/s² up), one level of discharge (2 s start-up, 1.4 s a car): the cut car is there 45 + 2 +
    22.41 s = 69.41 s from now (12.3 s to the limit over 151.29 m, 248.71 m at it), the first car behind it no sooner
    than a headway later, 70.81 s (alone, from 7.5 m back at 5.48 m/s, 68.38 s); without the cut car that car had
    the cut car's place. A red there from 70 s meets it (it waits that red, 30 s), one from 120 s meets no place the
    queue moves (as before). Before, only the first light's red and queue were priced: the second light's red, which
    the delayed platoon's tail met in SUMO, was not (paper_s400 fixed 600 veh/h 50 %, seed 3: 227 of the others' 309
    s, docs/history/TRAFFIC.md)."""
    params = AdvisorParams()
    passed = LightView(1, -7.0, red_windows_s=((15.0, 45.0),))
    nxt = LightView(2, 393.0, red_windows_s=((0.0, 40.0), (next_red_s, next_red_s + 30.0)))
    obs = Observation(9.2, 24.6, (nxt,))
    four = [Probe(-7.0 - 7.5 * k, 0.0) for k in (1, 2, 3, 4)]
    hold = Advice("cruise", "green_wave", 8.04)
    to_limit_s, to_limit_m = 24.6 / 2.0, 24.6**2 / 4.0
    cut_car_s = 45.0 + 2.0 + to_limit_s + (400.0 - to_limit_m) / 24.6
    v1 = math.sqrt(2.0 * 2.0 * 7.5)
    alone_s = 45.0 + 2.0 + 1.4 + (24.6 - v1) / 2.0 + (400.0 - (24.6**2 - v1**2) / 4.0) / 24.6
    assert (cut_car_s, alone_s) == (pytest.approx(69.41, abs=0.01), pytest.approx(68.38, abs=0.01))
    assert cut_car_s < 70.0 <= max(alone_s, cut_car_s + 1.4)  # the first car behind the cut one: before, after
    p_ge_5 = 1.0 - sum(math.exp(-4.0) * 4.0**j / math.factorial(j) for j in range(5))
    queued = 0.25 * 30.0 / (1.0 - 0.25 * M.fast_headway_s)
    spill = 30.0 * (1.0 - math.exp(-queued)) if met else 0.0  # that car is there: P(N >= 1)
    want = (30.0 + M.fast_headway_s * queued + spill) * p_ge_5
    assert cut_behind(passed, obs, hold, params, four, 900 / 3600, 0.5, model=ONE) == pytest.approx(want)


def test_a_slow_plan_towards_an_actuated_green_prices_the_timings_in_which_a_normal_drive_makes_it():
    """An actuated light green now, past its minimum: it may turn red any second (the sure view red from now), the
    red's end not known, and its equally likely timings (``scenario_red_windows_s``) turn it red 10 s or 30 s from now.
    A car 387 m out at 9.6 m/s, told to coast, a connected car 20 m behind it at its speed: a normal drive crosses in
    18.0 s, the one behind it 1.4 s later; behind the coasting car nobody crosses before 30 s. In the timing whose red
    begins at 30 s the follower loses the green to the plan and waits the red (no end known: ``WAIT_CAP_S``); in the
    other one both drives meet the red: half of 150 s expected. Before, the wait was priced on the likely timing alone
    (red from 15 s, a normal drive meeting it too): nothing, and the coast stood. Traced in SUMO (paper_s400 actuated
    900 veh/h, 50 %, seed 2, ``main.15``): told "Lift off and coast." 387 m before the second light, green then, it
    crawled on at 10 -> 5 m/s through the rest of that green, the red after it and the next green, which the controller
    ended (no car at its loop) while the car was 73 m short of the line; it crossed 31 s later than unadvised, the cars
    behind it with it (10 greens at that light ended so over five seeds, none unadvised)."""
    params = AdvisorParams()
    light = LightView(2, 387.0, red_windows_s=((0.0, math.inf),), likely_red_windows_s=((15.0, math.inf),),
                      late_red_windows_s=((30.0, math.inf),), scenario_red_windows_s=(((10.0, math.inf),), ((30.0, math.inf),)))  # fmt: skip
    obs = Observation(9.6, 24.6, (light,))
    coast = Advice("coast", "red_ahead", 9.6, light_id=2)
    one = [Probe(-20.0, 9.6)]
    assert normal_drive_s(387.0, 9.6, 24.6, 2.0) == pytest.approx(18.0, abs=0.05)
    assert cut_behind(light, obs, coast, params, one) == pytest.approx(0.5 * WAIT_CAP_S)
    assert cut_behind(replace(light, scenario_red_windows_s=None), obs, coast, params, one) == 0.0  # the likely timing alone
    early = replace(light, scenario_red_windows_s=(((10.0, math.inf),), ((15.0, math.inf),)))  # a normal drive never makes it
    assert cut_behind(early, obs, coast, params, one) == 0.0
    assert cut_behind(light, obs, coast, params) == 0.0  # nobody behind


def test_the_board_paces_a_plan_that_would_cut_off_the_cars_behind():
    """The board keeps the light a car passed last with the connected cars behind it (:meth:`QueueBoard.see`'s
    ``passed``): 7 m past a line turning red in 15 s at 16 m/s, four connected cars standing behind it, 900 veh/h, half
    connected, told to ease off to 29 km/h for the next light's green: that plan, or holding 16 m/s, cuts the ninth car
    off (6.4 s expected, more than the 5 s slack); the board raises the plan to the slowest whole mph that does not
    (39 mph, the wait shrinking as the speed rises), and keeps it as it is where nobody is behind. The discharge at its
    fast end alone (``ONE``; over its levels the cars behind lose more below the limit: drive normally)."""
    params, t = AdvisorParams(units="kmh"), 1000.0
    passed = LightView(1, -7.0, red_windows_s=((15.0, 45.0),))
    obs = Observation(16.0, 24.6, (LightView(2, 393.0, red_windows_s=((0.0, 40.0),)),), position_m=107.0)
    board = QueueBoard(ONE, arrivals_vph=900.0, connected_share=0.5)
    for k in range(1, 5):
        board.see("c", f"q{k}", t, Observation(0.0, 24.6, (LightView(1, 7.5 * k, red_windows_s=((15.0, 45.0),)),), position_m=100.0 - 7.5 * k))
    seen, _ = board.see("c", "car", t, obs, passed=passed)
    slow = Advice("ease_off", "green_wave", 8.04, light_red=True, seconds_to_change_s=40.0, light_id=2)
    out = board.check(seen, slow, params, "car")
    four = [Probe(-7.0 - 7.5 * k, 0.0) for k in range(1, 5)]

    def lost(v):
        action = "ease_off" if v < 16.0 - params.hysteresis_mps else ("accelerate" if v > 16.0 + params.hysteresis_mps else "cruise")
        return cut_behind(passed, obs, replace(slow, action=action, target_speed_mps=v), params, four, 900 / 3600, 0.5, model=ONE)

    assert lost(8.04) > GIVE_UP_SLACK_S and lost(16.0) > GIVE_UP_SLACK_S
    assert (out.action, out.target_speed_mps) == ("accelerate", published_speed_mps(39 * 0.44704))
    assert lost(out.target_speed_mps) <= GIVE_UP_SLACK_S < lost(38 * 0.44704)
    assert out.message == "Keep up with the traffic. Speed up to 63 kilometers per hour." and out.speak and out.reason == "traffic_behind"
    assert (out.light_red, out.seconds_to_change_s, out.light_id) == (True, 40.0, 2)  # the display's countdown: the light's own
    again = board.check(seen, slow, params, "car", {"action": "cruise", "target_speed_mps": out.target_speed_mps, "reason": "traffic_behind"})
    assert again.target_speed_mps == out.target_speed_mps and not again.speak  # said once (not again as the car reaches it)
    alone = QueueBoard(arrivals_vph=900.0, connected_share=1.0)
    seen, _ = alone.see("c", "car", t, obs, passed=passed)
    assert alone.check(seen, slow, params, "car").target_speed_mps == 8.04


def _paced_scene(units: str, t: float = 1000.0):
    """The scene of the test above, the advisor's own plan asked for: the board and the car's observation (its
    second light 393 m out, red for 40 s more), four connected cars standing behind the line it passed 7 m back; the discharge at its fast end alone (``ONE``)."""
    passed = LightView(1, -7.0, red_windows_s=((15.0, 45.0),))
    obs = Observation(16.0, 24.6, (LightView(2, 393.0, red_windows_s=((0.0, 40.0),)),), position_m=107.0)
    board = QueueBoard(ONE, arrivals_vph=900.0, connected_share=0.5)
    for k in range(1, 5):
        board.see("c", f"q{k}", t, Observation(0.0, 24.6, (LightView(1, 7.5 * k, red_windows_s=((15.0, 45.0),)),), position_m=100.0 - 7.5 * k))
    return board, obs, passed, AdvisorParams(units=units)


@pytest.mark.parametrize("units", ["mph", "kmh"])
def test_a_paced_plan_says_why_and_never_promises_a_green_it_does_not_reach(units):
    """A plan raised for the cars behind is not a plan for the light ahead: its words said that plan's countdown,
    "Green in 40 seconds. Speed up to 63 kilometers per hour.", where 63 km/h is at the line 393 m out in 23 s, in the
    red. Now, at every speed of the car, a paced plan says why ("Keep up with the traffic.") and the speed, the number
    the display shows, and never a countdown to a green it reaches before; the countdown fields stay the light's."""
    import re

    from server.schemas import Reason

    board, obs, passed, params = _paced_scene(units)
    unit = "kilometers per hour" if units == "kmh" else "miles per hour"
    paced = 0
    for v in np.arange(8.0, 24.0, 1.0):
        at = replace(obs, speed_mps=float(v))
        seen, _ = board.see("c", "car", 1000.0, at, passed=passed)
        plan, _ = advise(seen, None, params)
        out = board.check(seen, plan, params, "car")
        if out.target_speed_mps is None or out.target_speed_mps == plan.target_speed_mps:
            continue  # the advisor's own plan, or drive normally: not paced
        paced += 1
        assert out.reason == "traffic_behind" and Reason(out.reason)  # (the API's enum lists it)
        verb = {"accelerate": "Speed up to", "ease_off": "Ease off only to", "cruise": "Hold"}[out.action]
        assert out.message == f"Keep up with the traffic. {verb} {spoken_speed(out.target_speed_mps, units)} {unit}."
        said = re.search(r"Green in (\d+)", out.message)
        arrival_s = crossing_time_s(393.0, float(v), out.target_speed_mps, params, KEEP_MODES[out.action])
        assert said is None or arrival_s >= int(said.group(1)), (v, out.message, arrival_s)
        assert (out.light_red, out.seconds_to_change_s) == (True, 40.0)
    assert paced >= 5  # the scene paces the plan at most of these speeds


def test_a_paced_plan_is_spoken_once_and_the_advisors_plan_again_when_it_ends():
    """Fix by fix as the service makes them (advise, the board's check, the memory the driver heard:
    :func:`server.advising.heard`): the paced plan is spoken at its first fix only, not at each fix that keeps it;
    when nobody is behind any more, the advisor's own plan comes back and is spoken (the driver last heard the pace).
    Before, the advisor took its own plan as heard at the first fix and never spoke it again."""
    from server.advising import heard

    board, obs, passed, params = _paced_scene("kmh")
    memory, last, told = None, None, []
    for k in range(4):  # (the scene held still: what changes is what the driver heard)
        seen, _ = board.see("c", "car", 1000.0 + 0.5 * k, obs, passed=passed if k < 3 else None)  # at the fourth nothing is behind
        before = memory
        plan, memory = advise(seen, memory, params)
        out = board.check(seen, plan, params, "car", last)
        if out is not plan:
            memory = heard(memory, before, out)
        last = out.as_dict()
        told.append((out.reason, out.speak))
    assert told == [("traffic_behind", True), ("traffic_behind", False), ("traffic_behind", False), ("green_wave", True)], told


def test_the_service_says_drive_normally_once_not_at_every_fix():
    """The board's "drive normally" (a plan that gives up a green a normal drive makes) is spoken where the driver
    last heard something else, as the advisor speaks its own; it was spoken at every fix."""
    params, t = AdvisorParams(), 1000.0
    board = QueueBoard(arrivals_vph=900.0, connected_share=0.5)
    lights = (LightView(1, 150.0, red_windows_s=((9.0, 39.0),)), LightView(2, 550.0, red_windows_s=((0.0, 45.0),)))
    seen, _ = board.see("c", "car", t, Observation(20.0, 24.6, lights, position_m=250.0))
    slow = Advice("slow_down", "green_wave", 9.0, light_red=True, seconds_to_change_s=45.0, light_id=2, light_ahead=2)
    first = board.check(seen, slow, params, "car")
    assert (first.action, first.reason, first.speak) == ("none", "tight_green", True)
    again = board.check(seen, slow, params, "car", first.as_dict())
    assert (again.action, again.reason, again.speak, again.message) == ("none", "tight_green", False, first.message)


def test_a_glide_to_the_green_after_a_red_is_not_paced_into_that_red():
    """Traced in SUMO (7th Street fixed time, 900 veh/h, every car connected, seed 1, ``main.12``): 156 m before a light
    red for 33 s more, at 5.5 m/s, a platoon of connected cars following it, the advisor's plan lifts off and coasts
    to the green. The board priced it as cutting off 600 s of the platoon behind and said "Drive normally." (then
    "Keep up with the traffic. Ease off to 11 mph."): its normal drive crossed the line at 14 s, inside the red, and
    the plan's car went on coasting past the line. The car sped up towards the red, was told to stop at the line, and
    the five cars following it stopped behind it (GLOSA's glided through). A normal drive reaching the line in a red
    stands there until it ends (:func:`cut_behind`), and a lift-off for the line does not coast on past it (it holds
    its speed there): nobody behind crosses later than behind a normal drive here, and the glide stands."""
    params, t = AdvisorParams(), 1000.0
    lights = (LightView(7001, 156.4, red_windows_s=((0.0, 33.0), (81.0, math.inf)), amber_s=4.0),
              LightView(7002, 329.0, red_windows_s=((14.0, 46.0), (100.0, math.inf)), amber_s=4.0))
    obs = Observation(5.47, 13.41, lights, position_m=222.7)
    glide = Advice("coast", "green_wave", 13.41, light_red=True, seconds_to_change_s=33.0, light_id=7001)
    platoon = [Probe(-13.0 * k, 5.47) for k in range(1, 5)] + [Probe(-80.5 - 14.0 * k, 6.4) for k in range(7)] + [Probe(-209.3, 13.41)]  # (the trace's)
    assert lights[0].is_red_at(normal_drive_s(156.4, 5.47, 13.41, 2.0))  # a normal drive meets the red
    assert cut_behind(lights[0], obs, glide, params, platoon, 900 / 3600, 1.0) == 0.0
    board = QueueBoard(arrivals_vph=900.0, connected_share=1.0)
    for k, p in enumerate(platoon):
        ahead = tuple(replace(lv, distance_m=lv.distance_m - p.ahead_m) for lv in lights)
        board.see("c", f"f{k}", t, Observation(5.47, 13.41, ahead, position_m=222.7 + p.ahead_m))
    seen, held = board.see("c", "car", t, obs)
    out = board.check(seen, glide, params, "car")
    assert held is None and (out.action, out.reason, out.target_speed_mps) == ("coast", "green_wave", 13.41), out


def test_in_sumo_a_slow_plan_over_the_first_light_does_not_cut_off_the_cars_behind(tmp_path):
    """paper_s400 (fixed 30/30, no amber), three cars of the 900 veh/h flow (seed 1's): a connected one reaching the
    first light 9 s before its red, told to slow for the second light's green, and two behind it (the last connected).
    Before, the first crossed at 10 m/s and the third was cut off at the first light's red (over it at 106 s against
    72.5 s unadvised); now every car crosses the first light in the green it crosses it in unadvised."""
    from ecodrive.traffic.network import build_network
    from ecodrive.traffic.sim import RunSetup, run
    from spat_feed.road.corridors import load_corridor

    net = build_network(load_corridor("paper_s400"), tmp_path)
    setup = RunSetup(900.0, 0.5, 1, 60.0, drain_s=150.0, departures_s=(49.62, 54.41, 54.42), connected=("main.0", "main.2"))
    first = {mode: {vid: car.crossings[0][1] for vid, car in run(net, setup, mode).cars.items()} for mode in ("advised", "unadvised")}
    red_s = 76.0  # the first light's red (green 46-76 s)
    assert all(t < red_s for t in first["unadvised"].values())
    assert all(t < red_s for t in first["advised"].values()), first


def test_in_sumo_cars_follow_a_queue_through_an_actuated_green_that_it_holds(tmp_path):
    """paper_s400 actuated, 900 veh/h, half the cars connected, seed 5's first two minutes (docs/history/TRAFFIC.md,
    "The actuated green held by its queue"): the second light turns green at 71 s with a queue in front of the
    connected cars ``main.4``-``main.8``. Unadvised, they cross it in that green (79.5-85 s). Before, the service took
    the queue to wait for the red after the green's minimum, whose end was not yet known (no red of it in the history):
    the line closed for ever, they crawled on, the green ended for want of a car at the detector and they crossed in
    the next one (109-117 s). Now the queue holds the green in the estimate, as the controller's detector does: every
    one of them crosses in the same green as unadvised."""
    from ecodrive.traffic.network import build_network
    from ecodrive.traffic.sim import RunSetup, run
    from spat_feed.road.corridors import load_corridor

    net = build_network(load_corridor("paper_s400"), tmp_path, control="actuated")
    setup = RunSetup(900.0, 0.5, 5, 120.0, drain_s=60.0, cross_demand_vph=300.0)
    second = {mode: {vid: car.crossings[1][1] for vid, car in run(net, setup, mode).cars.items() if len(car.crossings) > 1} for mode in ("advised", "unadvised")}
    cars = [f"main.{k}" for k in range(4, 9)]
    green_end_s = 90.0  # the green's end, its amber included (unadvised)
    assert all(second["unadvised"][vid] < green_end_s for vid in cars), second["unadvised"]
    assert all(second["advised"][vid] < green_end_s for vid in cars), second["advised"]
