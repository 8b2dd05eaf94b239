"""The phase-end predictor: calibrated against known distributions, the cycle of a coordinated controller found, the
hard bounds kept; ``predict-eval`` on every recording, scored independently of the code under test."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from spat_feed.prediction.history import IntersectionHistory, PhaseHistory
from spat_feed.prediction.predictor import ChangeForecast, _spread_on_cycle, cycle_period_s, forecast
from spat_feed.timing.plans import ChangeWindow, MovementPhaseState, PhaseClass, UncertainPlan
from tests.conftest import SHARED_DATA

RED, GREEN, AMBER = MovementPhaseState.STOP_AND_REMAIN, MovementPhaseState.PROTECTED_MOVEMENT_ALLOWED, MovementPhaseState.PROTECTED_CLEARANCE
T0 = 1_700_000_000.0
UNKNOWN_END_S = 3600.0


def state_only(state: MovementPhaseState, t: float) -> UncertainPlan:
    """What a controller that publishes its state only says: the phase may end now, the latest end is unknown."""
    return UncertainPlan((state, MovementPhaseState.UNAVAILABLE), (ChangeWindow(t, t, math.inf),))


def test_quantiles_are_the_inverse_of_the_samples_distribution():
    fc = ChangeForecast(PhaseClass.RED, PhaseClass.GREEN, 0.0, np.array([1.0, 2.0, 3.0, 4.0]), "duration")
    assert [fc.quantile(q) for q in (0.0, 0.25, 0.26, 0.5, 0.9, 1.0)] == [1.0, 1.0, 2.0, 2.0, 4.0, 4.0]
    assert fc.interval(0.5) == (1.0, 3.0) and fc.within_frac(2.5, 0.5) == 0.5
    tail = ChangeForecast(PhaseClass.RED, None, 0.0, np.array([1.0, math.inf]), "duration")
    assert tail.likely_unix_s == 1.0 and tail.quantile(0.9) == math.inf


def _drive(history: PhaseHistory | IntersectionHistory, phases, t: float, group: int = 1, on_step=None) -> float:
    """Feed ``(state, duration)`` phases at 1 Hz from ``t``; ``on_step(t, state, since, duration)`` at each reading."""
    for state, duration in phases:
        start = t
        while t < start + duration - 1e-9:
            plan = state_only(state, t)
            if isinstance(history, IntersectionHistory):
                history.record(t, {group: plan})
            else:
                history.record(t, plan)
            if on_step is not None:
                on_step(t, state, start, duration)
            t += 1.0
    return t


def test_state_only_reds_of_random_length_are_forecast_with_calibrated_intervals():
    """Reds drawn from 20..60 s (uniform, whole seconds), greens of 30 s, published as state only. Once 40 reds are
    seen, at every second of a red's first 45 s the stated 80 % interval of its end holds about 80 % of the true ends, and the
    likely end errs by about what the conditional distribution of a uniform red says (its mean absolute deviation
    from the median: a quarter of the remaining range on average)."""
    rng = np.random.default_rng(7)
    history = IntersectionHistory()
    reds = [float(rng.integers(20, 61)) for _ in range(160)]
    phases = [p for r in reds for p in ((RED, r), (GREEN, 30.0))]
    inside, errors, expected = [], [], []

    def check(t, state, start, duration):
        if state is not RED or start < T0 + 40 * 75.0 or t - start > 45.0:  # (later, few reds seen last as long)
            return
        fc = forecast(state_only(RED, t), t, history.stats(1))[0]
        lo, hi = fc.interval(0.8)
        inside.append(lo <= start + duration <= hi)
        errors.append(abs(fc.likely_unix_s - (start + duration)))
        left = np.arange(max(20.0, t - start + 1.0), 61.0)  # the reds that have lasted this long, equally likely
        expected.append(np.mean(np.abs(left - np.median(left))))

    _drive(history, phases, T0, on_step=check)
    assert len(inside) > 3000
    assert 0.75 <= np.mean(inside) <= 0.88, np.mean(inside)
    assert np.mean(errors) == pytest.approx(np.mean(expected), rel=0.25)


def test_the_cycle_of_a_coordinated_controller_is_found_and_tells_the_end_of_a_green_of_any_length():
    """A coordinated controller with a 90 s cycle: the main green ends at its force-off (20 s past each cycle's start)
    unless no side street called, then at the next one (green 1-3 cycles long); the side phase (red for this group)
    lasts 25-35 s. The durations spread over three cycles; the cycle point does not: once the period is known, the
    likely end is a force-off (within a second), the right one at least half the time (the rest a whole cycle off: a
    side street called or not), and the 80 % interval holds the real end at least 80 % of the time (the law is
    discrete: an interval from one force-off to another holds more)."""
    rng = np.random.default_rng(3)
    history = IntersectionHistory()
    t, phases = T0 + 20.0, []
    while t < T0 + 200 * 90.0:
        red = float(rng.integers(25, 36))
        cycles = int(rng.choice([1, 1, 2, 3]))
        force_off = math.floor((t + red) / 90.0) * 90.0 + 20.0 + 90.0 * cycles  # a later force-off
        green = force_off - (t + red) - 4.0
        phases += [(RED, red), (GREEN, green), (AMBER, 4.0)]
        t += red + green + 4.0
    errors = []

    def check(t, state, start, duration):
        if state is GREEN and start > T0 + 100 * 90.0 and 10.0 <= start + duration - t <= 30.0:
            fc = forecast(state_only(GREEN, t), t, history.stats(1))[0]
            lo, hi = fc.interval(0.8)
            errors.append((fc.likely_unix_s - (start + duration), fc.method, lo <= start + duration <= hi))

    _drive(history, phases, T0 + 20.0, on_step=check)
    assert history.period_s == pytest.approx(90.0, abs=0.5)
    assert len(errors) > 100 and np.mean([m == "cycle" for _, m, _ in errors]) >= 0.9  # (the scores of the two may cross)
    errors = [row for row in errors if row[1] == "cycle"]
    off = np.array([e for e, _, _ in errors])
    assert np.all(np.abs((off + 45.0) % 90.0 - 45.0) <= 1.0)  # a whole number of cycles off, to a second
    assert np.mean(np.abs(off) <= 1.0) >= 0.5 and np.mean([c for _, _, c in errors]) >= 0.8  # (a discrete law: at least)


def test_a_cycle_off_the_search_grid_is_refined_and_its_error_is_in_the_forecast():
    """A coordinated controller whose cycle (75.04 s: a controller clock a little fast, say) is not on the period
    search's 0.1 s grid: its green ends 50 s into each cycle, +-3 s, dated to the second. The search says 75.1 s; a
    change 40 cycles back moved to now by it is 2.4 s off, and a forecast that moves every past change so without
    saying it held 64 % of the changes 10-30 s ahead in its central 80 % (the randomized PIT). Refined by least squares
    (:func:`period_fit_s`) the period is within three standard errors of the truth, and the
    forecast, which moves the latest phases' changes and spreads each by the period's error times the cycles it moved
    it (:func:`_spread_on_cycle`: 40 cycles, 40 times), holds at least 68 % (69.9 %, 68.8 % unspread)."""
    from ecodrive.predict_eval import pit_coverage

    rng = np.random.default_rng(7)
    history = IntersectionHistory()
    period_s, t, k, phases = 75.04, T0 + 20.0, 1, []
    while t < T0 + 120 * period_s:
        end = float(round(T0 + k * period_s + 50.0 + rng.uniform(-3.0, 3.0)))
        red = float(rng.integers(20, 30))
        phases += [(RED, red), (GREEN, end - (t + red) - 4.0), (AMBER, 4.0)]
        t, k = end, k + 1
    held, held_unspread = [], []

    def check(t, state, start, duration):
        if state is GREEN and start > T0 + 40 * period_s and 10.0 <= start + duration - t <= 30.0:
            for stats, out in ((history.stats(1), held), (replace(history.stats(1), period_error_s=0.0), held_unspread)):
                fc = forecast(state_only(GREEN, t), t, stats)[0]
                s, end = fc.samples_unix_s, start + duration
                if fc.method == "cycle":
                    out.append(pit_coverage(tuple(np.searchsorted(s, x + 1e-6, side="right") / len(s) for x in (end - 1.0, end)), 0.8))

    _drive(history, phases, T0 + 20.0, on_step=check)
    se = history.period_error_s
    assert abs(history.period_s - period_s) <= 3.0 * se and 0.0 < se < 0.05
    assert len(held) > 1000 and np.mean(held) >= 0.68 and np.mean(held) >= np.mean(held_unspread), (np.mean(held), np.mean(held_unspread))
    moved = np.array([T0 + 40 * period_s, T0 + period_s])  # a change at T0 moved 40 cycles on, and 1
    spread = _spread_on_cycle(moved, np.array([T0]), period_s, 0.05)
    half_s = np.sqrt(1.5) * 0.05 * np.array([40.0, 1.0])  # the three-point rule of a normal law of sd 40 x 0.05 s, 1 x 0.05 s
    assert np.allclose(np.sort(spread - np.tile(moved, 3)), np.sort(np.r_[-half_s, 0.0, 0.0, half_s]), atol=1e-5)


def test_durations_are_conditioned_on_the_other_groups_state():
    """An actuated controller with no fixed cycle: group 1's red lasts 16-24 s when group 2 is not served during it
    and 44-56 s when it is (group 2 green from 2 s after 1's red begins to 2 s before it ends), half each at random;
    1's green lasts 25-35 s. The durations alone mix the two (their median errs ~13 s); seen 5 s into a red, with
    group 2's state known, the forecast (method ``state``) errs what the uniform law of that kind of red does (its
    mean absolute deviation from the median: 2 s or 3 s), and its 80 % interval holds the end about that often."""
    rng = np.random.default_rng(11)
    history = IntersectionHistory()
    t, rows = T0, []
    for k in range(160):
        served = bool(rng.integers(0, 2))
        red_s = float(rng.integers(44, 57) if served else rng.integers(16, 25))
        start = t
        while t < start + red_s - 1e-9:
            s2 = GREEN if served and 2.0 <= t - start < red_s - 2.0 else RED
            history.record(t, {1: state_only(RED, t), 2: state_only(s2, t)})
            if k >= 60 and t - start == 5.0:
                fc = forecast(state_only(RED, t), t, history.stats(1))[0]
                lo, hi = fc.interval(0.8)
                rows.append((fc.method, abs(fc.likely_unix_s - (start + red_s)), lo <= start + red_s <= hi))
            t += 1.0
        t = _drive(history, [(GREEN, float(rng.integers(25, 36)))], t)
    assert len(rows) == 100 and all(m == "state" for m, _, _ in rows)
    assert np.mean([e for _, e, _ in rows]) <= 3.5 and np.mean([c for _, _, c in rows]) >= 0.75


@pytest.mark.parametrize("stage_tells", [True, False])
def test_a_red_that_waits_for_a_stage_is_told_by_how_long_the_stage_has_run(stage_tells):
    """An actuated controller: group 2's green (a stage) begins 2-20 s (evenly, whole seconds) after group 1's red
    does. With ``stage_tells``, 1's red ends 3 s after that green, which lasts 20-24 s: from a reading 5 s into the
    stage the red ends 18-22 s later, evenly (its median errs 1.2 s), where counted from the red's start it spreads
    over 25-47 s (the stage's law by the phase's start errs ~4 s). Otherwise 1's red lasts 40-44 s whatever the
    stage does (its green ends 2 s before), and the stage's start says nothing. The two laws of ``state`` are scored
    at each red's end: the one that tells takes most of the pool (``stage_weight``), and the forecast 5 s into the
    stage errs about what the true law does."""
    rng = np.random.default_rng(13)
    history = IntersectionHistory()
    t, errors, true_mad = T0, [], []
    for k in range(120):
        delay_s, stage_s = float(rng.integers(2, 21)), float(rng.integers(20, 25))
        red_s = delay_s + stage_s + 3.0 if stage_tells else float(rng.integers(40, 45))
        stage_s = stage_s if stage_tells else red_s - delay_s - 2.0
        start = t
        while t < start + red_s - 1e-9:
            s2 = GREEN if delay_s <= t - start < delay_s + stage_s else RED
            history.record(t, {1: state_only(RED, t), 2: state_only(s2, t)})
            if k >= 60 and t - start == delay_s + 5.0:
                fc = forecast(state_only(RED, t), t, history.stats(1))[0]
                errors.append((fc.method, abs(fc.likely_unix_s - (start + red_s))))
            t += 1.0
        t = _drive(history, [(GREEN, float(rng.integers(25, 36)))], t)
    weight = history.stats(1).stage_weight[PhaseClass.RED]
    mae = np.mean([e for _, e in errors])
    assert len(errors) == 60 and all(m == "state" for m, _ in errors)
    if stage_tells:  # the true law 18-22 s ahead, evenly: mean absolute deviation 1.2 s
        assert weight > 0.6 and mae <= 2.0, (weight, mae)
    else:  # 40-44 s from the red's start, evenly: 1.2 s
        assert weight < 0.2 and mae <= 2.0, (weight, mae)


def test_a_red_whose_length_drifts_with_the_traffic_is_told_by_the_latest_phases():
    """An actuated controller whose reds grow with the traffic: group 1's red lasts ``20 + 0.5 k`` s (+-1 s, whole
    seconds) at its ``k``-th cycle, group 2 green from 2 s after it begins to 2 s before it ends; 1's green 25-35 s.
    Seen 5 s into a red, the law of the 40 phases kept (``PhaseHistory.keep``) lags the drift by half of them, 20
    phases or 10 s; that of the latest 20 (``RECENT_PHASES``) by 5 s. The two are scored at each red's end and
    pooled (``recent_weight``): the latter takes most of the pool, and the forecast (method ``state``) errs less than
    the 10 s of every phase kept."""
    rng = np.random.default_rng(17)
    history = IntersectionHistory()
    t, errors = T0, []
    for k in range(120):
        red_s = 20.0 + 0.5 * k + float(rng.integers(-1, 2))
        start = t
        while t < start + red_s - 1e-9:
            s2 = GREEN if 2.0 <= t - start < red_s - 2.0 else RED
            history.record(t, {1: state_only(RED, t), 2: state_only(s2, t)})
            if k >= 80 and t - start == 5.0:
                fc = forecast(state_only(RED, t), t, history.stats(1))[0]
                errors.append((fc.method, fc.likely_unix_s - (start + red_s)))
            t += 1.0
        t = _drive(history, [(GREEN, float(rng.integers(25, 36)))], t)
    weight = history.stats(1).recent_weight[PhaseClass.RED]
    mean_error = np.mean([e for _, e in errors])
    assert len(errors) == 40 and all(m == "state" for m, _ in errors)
    assert weight > 0.6 and -7.5 <= mean_error <= -4.0, (weight, mean_error)


def test_a_pool_is_scored_at_every_horizon_of_a_phase_once():
    """Each phase end scores the two laws of a pool at every horizon of ``POOL_SCORE_AHEAD_S`` and counts once: the
    running mean takes the mean of each law's squared errors over the horizons. By hand: errors (1, 3), (3, 1) and
    (2, 2) s at three horizons give both laws (1 + 9 + 4) / 3 s², so after three such phases each has half the pool;
    the first horizon alone would have given the first law 9 / (1 + 9) = 0.9 of it."""
    from spat_feed.prediction.history import _scored, _share

    score, first_only = [0, 0.0, 0.0], [0, 0.0, 0.0]
    for _ in range(3):
        _scored(score, [(1.0, 3.0), (3.0, 1.0), (2.0, 2.0)])
        _scored(first_only, [(1.0, 3.0)])
    assert score[0] == 3 and score[1] == pytest.approx(14.0 / 3.0) and score[2] == pytest.approx(14.0 / 3.0)
    assert _share(score) == pytest.approx(0.5) and _share(first_only) == pytest.approx(0.9)


def test_a_pool_gives_each_law_its_share_however_few_its_samples():
    """The linear pool of two laws weighs each by its share of the forecast's samples, not by how many samples it
    has: the ``state`` law of 3 phases with its prior of 3 (``PRIOR_PHASES``) is half and half."""
    from spat_feed.prediction.predictor import N_SAMPLES, _mixed

    pooled = _mixed(np.array([10.0, 11.0, 12.0]), np.arange(100.0, 140.0), 0.5)
    assert len(pooled) == N_SAMPLES and np.count_nonzero(pooled < 50.0) == N_SAMPLES // 2


def test_a_published_window_is_read_by_the_readings_of_past_phases_with_a_like_window():
    """An actuated controller that publishes each red's window from its start: reds last 20-60 s (whole seconds,
    evenly), ``minEndTime`` is a draw ``U`` (0-10 s, evenly) before the real end and ``maxEndTime`` 10 s after it, so
    while ``minEndTime`` is ahead the end is ``minEndTime + U``: its median 5 s after it, its 80 % interval 1-9 s
    after it, whatever the red's length (the durations alone spread over 40 s). Once 40 reds are seen, at every
    reading of a red before its ``minEndTime`` the law the past readings give (``ends_given_window``) errs what the
    true law does (its mean absolute deviation from its median: 2.5 s); scored against the durations it takes most
    of the forecast, which errs far less than the durations alone and whose 80 % interval holds 75-90 % of the ends
    (the durations' share widens it); none before ``minEndTime``."""
    from spat_feed.prediction.predictor import ends_given_window, sample_quantile

    rng = np.random.default_rng(5)
    history = IntersectionHistory()
    t, law_errors, inside, pooled, plain, early = T0, [], [], [], [], 0
    for k in range(160):
        red_s, u = float(rng.integers(20, 61)), float(rng.uniform(0.0, 10.0))
        start, end = t, t + red_s
        while t < end - 1e-9:
            min_end, max_end = end - u, end - u + 10.0
            plan = UncertainPlan((RED, MovementPhaseState.UNAVAILABLE), (ChangeWindow(min_end, min_end, max_end),))
            history.record(t, {1: plan})
            if k >= 40 and t < min_end:
                stats = history.stats(1)
                by_window = np.sort(ends_given_window(stats.window_law_s[PhaseClass.RED], start, t, min_end, max_end, stats.state_id))
                law_errors.append(abs(sample_quantile(by_window, 0.5) - end))
                fc = forecast(plan, t, stats)[0]
                lo, hi = fc.interval(0.8)
                inside.append(lo <= end <= hi)
                early += fc.samples_unix_s[0] < min_end
                pooled.append(abs(fc.likely_unix_s - end))
                left = np.array([d for d in stats.durations(PhaseClass.RED) if start + d > t])  # the durations alone
                plain.append(abs(max(start + float(np.median(left)), min_end) - end))
            t += 1.0
        t = _drive(history, [(GREEN, 30.0)], t)
    assert len(law_errors) > 2000 and early == 0
    assert history.stats(1).window_weight[PhaseClass.RED] > 0.75  # scored: the window law errs far less, it takes most of the pool
    assert np.mean(law_errors) == pytest.approx(2.5, abs=0.5) and 0.75 <= np.mean(inside) <= 0.9, (np.mean(law_errors), np.mean(inside))
    assert np.mean(pooled) < 0.6 * np.mean(plain), (np.mean(pooled), np.mean(plain), np.mean(inside))


def test_the_window_law_distances_are_the_plain_numpy_expressions_bit_for_bit():
    """``_window_distance_s`` (one pass over a window law's arrays) gives what the plain numpy expressions give, bit
    for bit, and as many readings that speak: the same ``argpartition`` then picks the same readings. Laws of 0-300
    random readings (known and unknown ``maxEndTime``, four intersection states, phases outlasted or not, all of
    them outlasted), read now with a known or an unknown ``maxEndTime``."""
    from spat_feed.prediction.predictor import OTHER_STATE_S, UNBOUNDED_APART_S, _window_distance_s

    def plain(el, to_min, to_max, state, duration, elapsed, to_floor, to_max_end, state_id):
        alive = duration > elapsed
        if outlasted := not alive.any():
            alive = np.ones_like(alive)
        if math.isinf(to_max_end):
            apart = np.where(np.isinf(to_max), 0.0, UNBOUNDED_APART_S)
        else:
            apart = np.minimum(np.abs(to_max - to_max_end), UNBOUNDED_APART_S)
        d = np.abs(to_min - to_floor) + apart
        if not outlasted:
            d += np.abs(el - elapsed)
        d += OTHER_STATE_S * (state != state_id)
        d[~alive] = np.inf
        return d, int(np.count_nonzero(alive))

    rng = np.random.default_rng(31)
    cases = 0
    for _ in range(300):
        n = int(rng.integers(0, 300))
        el, duration = rng.uniform(0.0, 90.0, n), rng.uniform(5.0, 120.0, n)
        to_min = np.where(rng.random(n) < 0.3, 0.0, rng.uniform(0.0, 60.0, n))
        to_max = np.where(rng.random(n) < 0.3, np.inf, rng.uniform(0.0, 2000.0, n))
        state = rng.integers(0, 4, n)
        for elapsed in (rng.uniform(0.0, 60.0), 200.0):  # (200 s: every phase outlasted)
            for to_max_end in (rng.uniform(0.0, 90.0), math.inf):
                args = (el, to_min, to_max, state, duration, elapsed, rng.uniform(0.0, 30.0), to_max_end, int(rng.integers(0, 4)))
                d, k = _window_distance_s(*args)
                want, want_k = plain(*args)
                assert k == want_k and d.tobytes() == want.tobytes()
                cases += n > 0
    assert cases > 1000


def test_a_min_end_published_without_a_max_end_is_read_by_the_readings_of_past_phases_with_a_like_one():
    """As above, but the controller publishes no ``maxEndTime`` (unknown: an actuated red with no call on K648), only
    ``minEndTime``, a draw ``U`` (0-10 s, evenly) before the real end. While it is ahead it says as much as before:
    the end is ``minEndTime + U``, whose median errs 2.5 s (the true law's mean absolute deviation from its median),
    where the durations (20-60 s) err ~9 s. Read as no window (the window law only for a known ``maxEndTime``), the
    forecast was the durations' (held at ``minEndTime``); now the past readings with an unknown ``maxEndTime`` speak:
    scored, the window law takes most of the pool, the forecast errs less than 0.6 times the durations', its 80 %
    interval holds 75-90 % of the ends, and none is put before ``minEndTime``."""
    rng = np.random.default_rng(6)
    history = IntersectionHistory()
    t, inside, pooled, plain, early = T0, [], [], [], 0
    for k in range(160):
        red_s, u = float(rng.integers(20, 61)), float(rng.uniform(0.0, 10.0))
        start, end = t, t + red_s
        while t < end - 1e-9:
            min_end = end - u
            plan = UncertainPlan((RED, MovementPhaseState.UNAVAILABLE), (ChangeWindow(min_end, min_end, math.inf),))
            history.record(t, {1: plan})
            left = [d for d in history.stats(1).durations(PhaseClass.RED) if start + d > t]  # the durations alone
            if k >= 40 and t < min_end and left:
                stats = history.stats(1)
                fc = forecast(plan, t, stats)[0]
                lo, hi = fc.interval(0.8)
                inside.append(lo <= end <= hi)
                early += fc.samples_unix_s[0] < min_end
                pooled.append(abs(fc.likely_unix_s - end))
                plain.append(abs(max(start + float(np.median(left)), min_end) - end))
            t += 1.0
        t = _drive(history, [(GREEN, 30.0)], t)
    assert len(pooled) > 2000 and early == 0
    assert history.stats(1).window_weight[PhaseClass.RED] > 0.75
    assert np.mean(pooled) < 0.6 * np.mean(plain) and 0.75 <= np.mean(inside) <= 0.9, (np.mean(pooled), np.mean(plain), np.mean(inside))


def test_a_window_law_that_drifts_with_the_traffic_is_told_by_the_latest_phases():
    """An actuated controller that publishes each red's ``minEndTime`` (no ``maxEndTime``) 10-30 s after the red begins
    (evenly) and holds the red ``0.25 k`` s past it (+ 0-2 s, evenly) at its ``k``-th cycle: the traffic grows. Read
    before ``minEndTime``, the readings of the 40 phases kept (``PhaseHistory.keep``) lag the drift by half of them,
    20 phases or 5 s; those of the latest 20 (``RECENT_PHASES``) by 2.5 s. The two window laws are scored at each
    red's end and pooled (``recent_window_weight``): the latter takes most of the pool, and the forecast errs less
    than the 5 s of every phase kept (-2.6 s; the law of every phase kept alone: -4.9 s); none before ``minEndTime``."""
    rng = np.random.default_rng(7)
    history = IntersectionHistory()
    t, errors, early = T0, [], 0
    for k in range(160):
        start = t
        min_end = start + float(rng.integers(10, 31))
        end = min_end + 0.25 * k + float(rng.uniform(0.0, 2.0))
        while t < end - 1e-9:
            plan = UncertainPlan((RED, MovementPhaseState.UNAVAILABLE), (ChangeWindow(min_end, min_end, math.inf),))
            history.record(t, {1: plan})
            if k >= 120 and t < min_end:
                fc = forecast(plan, t, history.stats(1))[0]
                errors.append(fc.likely_unix_s - end)
                early += fc.samples_unix_s[0] < min_end
            t += 1.0
        t = _drive(history, [(GREEN, 30.0)], t)
    weight = history.stats(1).recent_window_weight[PhaseClass.RED]
    mean_error = np.mean(errors)
    assert len(errors) > 400 and early == 0
    assert weight > 0.6 and -4.0 <= mean_error <= -1.5, (weight, mean_error)


def test_a_phase_that_outlasted_every_one_seen_is_read_by_its_window():
    """An actuated controller that publishes each red's window: ``minEndTime`` a draw ``U`` (0-4 s, evenly) before the
    real end, ``maxEndTime`` 180 s after the red began (a far, soft bound, as K648 publishes before demand comes). After
    40 reds of 20-40 s comes one of 90 s (demand the history has not seen). Once it has outlasted every red seen, the
    durations say nothing; the readings of past reds with a like window do: the end comes 0-4 s after ``minEndTime``,
    so the forecast errs about what the true law does (its mean absolute deviation from its median: 1 s), where the
    window spread evenly (what it said before) puts the end half way to ``maxEndTime``, ~50 s off. Ten such
    afternoons; every reading of the long red from 41 s in until its ``minEndTime``."""
    errors, spread_errors, early = [], [], 0
    for seed in range(10):
        rng = np.random.default_rng(seed)
        history = IntersectionHistory()
        t = T0
        for k in range(41):
            red_s, u = (90.0 if k == 40 else float(rng.integers(20, 41))), float(rng.uniform(0.0, 4.0))
            start, end = t, t + red_s
            while t < end - 1e-9:
                min_end, max_end = end - u, start + 180.0
                plan = UncertainPlan((RED, MovementPhaseState.UNAVAILABLE), (ChangeWindow(min_end, min_end, max_end),))
                history.record(t, {1: plan})
                if k == 40 and t - start > 40.0 and t < min_end:
                    fc = forecast(plan, t, history.stats(1))[0]
                    assert fc.method == "window"
                    errors.append(abs(fc.likely_unix_s - end))
                    spread_errors.append(abs(0.5 * (min_end + max_end) - end))
                    early += fc.samples_unix_s[0] < min_end
                t += 1.0
            t = _drive(history, [(GREEN, 30.0)], t)
    assert len(errors) > 300 and early == 0
    assert np.mean(errors) <= 1.5 and np.mean(spread_errors) > 40.0, (np.mean(errors), np.mean(spread_errors))


@pytest.mark.parametrize("level", [0.5, 0.8, 0.9])
def test_interval_coverage_of_a_forecast_that_is_the_true_law_is_its_level(level):
    """A change that comes at a whole second drawn evenly from 10..49, seen at the first reading after it (the one
    before it a second earlier), forecast by exactly that law: over the 40 equally likely outcomes the share inside the
    central interval is the level, exactly (the randomized PIT of a discrete law); the closed interval between the two
    quantiles holds more (0.525 / 0.825 / 0.925: its ends carry mass)."""
    from ecodrive.predict_eval import pit_coverage

    fc = ChangeForecast(PhaseClass.RED, PhaseClass.GREEN, 0.0, np.arange(10.0, 50.0), "duration")
    s = fc.samples_unix_s
    pits = [(np.searchsorted(s, y - 1.0, side="right") / len(s), np.searchsorted(s, y, side="right") / len(s)) for y in s]
    assert np.mean([pit_coverage(p, level) for p in pits]) == pytest.approx(level)
    lo, hi = fc.interval(level)
    assert np.mean([lo <= y <= hi for y in s]) == pytest.approx({0.5: 0.525, 0.8: 0.825, 0.9: 0.925}[level])


def test_predict_eval_bins_forecasts_by_their_stated_spread_and_method():
    """Forty reds whose ends come at every whole second of 10..49 s after they begin, forecast at their first reading
    by that law (``duration``: calibrated, an 80 % interval 32 s wide), and twenty forecast sure of an instant 5 s
    before the change (``linked``, one sample: width 0). Over all, the 80 % interval holds 2/3 of 80 %, which says
    little; by width and by method, the sure ones hold nothing and err 5 s, the calibrated ones hold their levels
    exactly (the PIT of a discrete law, as above)."""
    from ecodrive.predict_eval import scored, summarize

    items, t = [], T0
    law = np.arange(10.0, 50.0)
    for k in range(60):
        d = law[k % 40]
        fc = ChangeForecast(PhaseClass.RED, PhaseClass.GREEN, t, t + law, "duration") if k < 40 else \
            ChangeForecast(PhaseClass.RED, PhaseClass.GREEN, t, np.array([t + d - 5.0]), "linked")  # fmt: skip
        items += [(t + s, PhaseClass.RED, fc if s == 0 else None, None, math.inf) for s in range(int(d))]
        items += [(t + d + s, PhaseClass.GREEN, None, None, math.inf) for s in range(10)]
        t += d + 10.0
    summary = summarize(scored({(1, 1): items}))
    assert summary["interval_coverage"]["80"] == pytest.approx(2 / 3 * 0.8)
    narrow, wide = summary["coverage_by_width"]["0-2"], summary["coverage_by_width"][">10"]
    assert set(summary["coverage_by_width"]) == {"0-2", ">10"} and narrow["predictions_frac"] == pytest.approx(1 / 3)
    assert narrow["interval_coverage"] == {"50": 0.0, "80": 0.0, "90": 0.0} and narrow["mae_s"] == pytest.approx(5.0)
    assert wide["interval_coverage"] == pytest.approx({"50": 0.5, "80": 0.8, "90": 0.9})
    assert wide["mae_s"] == pytest.approx(np.mean(np.abs(law - 29.0)))  # the median of 10..49 (the 20th of 40) is 29
    assert summary["coverage_by_method"]["linked"] == narrow and summary["coverage_by_method"]["duration"] == wide


def test_predict_eval_tells_whether_the_late_tail_holds_for_greens_and_reds_apart():
    """Forty greens that end at every whole second of 10..49 s, forecast at their first reading by that law (calibrated;
    ``maxEndTime`` published 45 s after their start: 4 of 40 outlast it, and the law puts 4 of its 40 samples past
    it), each followed by a red of 20 s forecast sure of an instant 15 s early (``linked``). The greens' changes come
    after the 90 % and 97.5 % quantiles exactly 10 % and 2.5 % of the time (the randomized PIT of a discrete law),
    past ``maxEndTime`` 10 % as stated; every red's comes after both."""
    from ecodrive.predict_eval import scored, summarize

    items, t = [], T0
    law = np.arange(10.0, 50.0)
    for d in law:
        green = ChangeForecast(PhaseClass.GREEN, PhaseClass.RED, t, t + law, "duration")
        items += [(t + s, PhaseClass.GREEN, green if s == 0 else None, None, t + 45.0) for s in range(int(d))]
        t += d
        red = ChangeForecast(PhaseClass.RED, PhaseClass.GREEN, t, np.array([t + 5.0]), "linked")
        items += [(t + s, PhaseClass.RED, red if s == 0 else None, None, math.inf) for s in range(20)]
        t += 20.0
    items.append((t, PhaseClass.GREEN, None, None, math.inf))
    tail = summarize(scored({(1, 1): items}))["late_tail"]
    assert set(tail) == {"green", "red"} and tail["green"]["predictions_frac"] == pytest.approx(0.5)
    assert tail["green"]["after"] == pytest.approx({"90": 0.1, "97.5": 0.025})
    assert tail["green"]["max_end_known_frac"] == 1.0
    assert tail["green"]["past_max_end_frac"] == pytest.approx(0.1) and tail["green"]["past_max_end_stated_frac"] == pytest.approx(0.1)
    assert tail["red"]["after"] == {"90": 1.0, "97.5": 1.0} and tail["red"]["max_end_known_frac"] == 0.0 and tail["red"]["past_max_end_frac"] is None
    assert set(tail["green"]["by_method"]) == {"duration"} and tail["red"]["by_method"]["linked"]["after"] == tail["red"]["after"]
    assert tail["red"]["by_likely_ahead"]["0-10"]["predictions_frac"] == 1.0  # (the reds said "in 5 s")


def test_a_link_that_failed_no_longer_says_the_phase_ends_now():
    """Group 2's green comes 2 s after group 1's green ends (the stage sequence: a link; 12 s in one cycle of 20, as a
    link allows), unless group 2 has no demand that cycle (one in four, at random): then its red goes on through
    group 1's next green. Right after group 1's green ends the link tells group 2's end to the second; 10 s after a
    change whose usual lag has passed with group 2 still red, the forecast is not "now" (the lags passed are out;
    the ones left, or the other methods, say when), as it was while any lag was ahead."""
    rng = np.random.default_rng(5)
    history = IntersectionHistory()
    t, linked, failed = T0, [], []
    for k in range(120):
        served = rng.random() >= 0.25
        g1_green_s, g1_red_s = float(rng.integers(20, 40)), float(rng.integers(30, 50))
        for phase_s, s1 in ((g1_green_s, GREEN), (g1_red_s, RED)):
            start = t
            while t < start + phase_s - 1e-9:
                s2 = GREEN if s1 is RED and served and (12.0 if k % 20 == 0 else 2.0) <= t - start < phase_s - 2.0 else RED
                history.record(t, {1: state_only(s1, t), 2: state_only(s2, t)})
                if k >= 60 and s1 is RED and t - start in (1.0, 10.0) and s2 is RED:
                    fc = forecast(state_only(RED, t), t, history.stats(2))[0]
                    if served and k % 20 and t - start == 1.0:
                        linked.append((fc.method, fc.likely_unix_s - t))
                    elif not served and t - start == 10.0:
                        failed.append((fc.method, fc.likely_unix_s - t))
                t += 1.0
    assert len(linked) > 30 and all(m == "linked" and abs(e - 1.0) <= 1.0 for m, e in linked), [x for x in linked if x != ("linked", 1.0)]
    assert len(failed) > 10 and all(e >= 2.0 for m, e in failed), failed


def test_a_link_whose_lags_the_published_min_end_has_passed_speaks_by_the_lags_left():
    """Group 2's red ends 6 s after group 1's green does (a link), but in one cycle of 11 the controller extends it:
    from group 1's green end on, it publishes ``minEndTime`` held 8 s ahead (moved with the clock), and the red ends
    12-20 s after group 1's green (evenly, whole seconds). One second after group 1's green ends in such a cycle,
    ``minEndTime`` (9 s on) is past the usual lag: the lags it leaves, the extended cycles', say when (the true law's
    mean absolute deviation from its median: 20/9 = 2.2 s, here from the 3-4 such lags of the last 40), where the
    usual lag held at ``minEndTime`` says 9 s on (6.1 s off); in the usual cycles the link still tells the end."""
    rng = np.random.default_rng(3)
    history = IntersectionHistory()
    t, extended, usual = T0, [], []
    for k in range(200):
        held = k % 11 == 5
        lag_s = float(rng.integers(12, 21)) if held else 6.0
        start, end = t, t + 30.0 + lag_s
        while t < start + 70.0 - 1e-9:
            if t < end:
                min_end = min(t + 8.0, end) if held and t - start >= 30.0 else start + 36.0
                plan2 = UncertainPlan((RED, MovementPhaseState.UNAVAILABLE), (ChangeWindow(min_end, min_end, start + 66.0),))
            else:
                plan2 = state_only(GREEN, t)
            history.record(t, {1: state_only(GREEN if t - start < 30.0 else RED, t), 2: plan2})
            if k >= 80 and t - start == 31.0:
                fc = forecast(plan2, t, history.stats(2))[0]
                (extended if held else usual).append((fc.method, abs(fc.likely_unix_s - end), lag_s - 9.0))
            t += 1.0
    assert len(extended) == 11 and all(m == "linked" for m, _, _ in extended)
    assert np.mean([e for _, e, _ in extended]) <= 3.5 and np.mean([at_min for _, _, at_min in extended]) > 6.0
    assert all(m == "linked" and e == 0.0 for m, e, _ in usual)


def test_cycle_period_needs_enough_changes_and_a_real_cycle():
    rng = np.random.default_rng(1)
    assert cycle_period_s([[T0 + 60.0 * k for k in range(5)]]) is None  # too few to tell
    random_ends = [np.cumsum(rng.uniform(30.0, 120.0, 40)) + T0 for _ in range(6)]
    assert cycle_period_s(random_ends) is None  # an actuated controller with no cycle
    assert cycle_period_s([[T0 + 120.0 * k + j for k in range(25)] for j in (0.0, 47.0, 90.0)]) == pytest.approx(120.0, abs=0.2)


def test_no_forecast_ends_a_phase_before_its_min_end_and_an_exact_window_is_kept():
    history = PhaseHistory()
    t = T0
    for _ in range(10):
        t = _drive(history, [(RED, 30.0), (GREEN, 20.0)], t)
    published = UncertainPlan((RED, GREEN), (ChangeWindow(t + 40.0, t + 45.0, t + 90.0),))
    stats = history.update(t, published)
    fc = forecast(published, t, stats)[0]
    assert fc.earliest_unix_s == t + 40.0 and fc.samples_unix_s.min() >= t + 40.0  # the reds of 30 s are held to it
    exact = UncertainPlan((RED, GREEN), (ChangeWindow(t + 12.0, t + 12.0, t + 12.0),))
    assert forecast(exact, t, stats)[0].samples_unix_s.tolist() == [t + 12.0]


def test_the_phases_after_the_current_one_chain_on_the_history():
    """Reds of 30 s, greens of 20 s: seen from 10 s into a red, the red ends in 20 s, the green after it 20 s later."""
    history = PhaseHistory()
    t = T0
    for _ in range(10):
        t = _drive(history, [(RED, 30.0), (GREEN, 20.0)], t)
    t = _drive(history, [(RED, 10.0)], t)
    changes = forecast(state_only(RED, t), t, history.update(t, state_only(RED, t)))
    assert [c.ends for c in changes[:2]] == [PhaseClass.RED, PhaseClass.GREEN]
    assert changes[0].likely_unix_s == pytest.approx(t + 20.0) and changes[1].likely_unix_s == pytest.approx(t + 40.0)


@pytest.mark.parametrize("path", sorted((SHARED_DATA / "spat").glob("*.csv.gz")), ids=lambda p: p.name)
def test_predict_eval_on_every_recording(path, recorded_snapshots, shared_recordings_parsed_once):
    """``ecodrive predict-eval``'s keys on the first 40 minutes of each recording, its errors recomputed here from the
    log itself (the first snapshot of another phase class is the change) for a sample of its predictions. The log is
    parsed once (``read_spat_csv``, 3 s a day): ``evaluate_log`` is handed the same snapshots the check reads."""
    from ecodrive.predict_eval import evaluate_log
    from spat_feed.timing.plans import phase_class

    snapshots = recorded_snapshots(path)
    summary, rows = evaluate_log(str(path), limit_s=2400.0)
    assert {"changes", "mae_s", "mae_s_by_horizon", "within_2s_frac", "within_5s_frac", "baseline_mae_s", "interval_coverage", "early_red_frac"} <= set(summary)
    assert set(summary["mae_s_by_horizon"]) == {"0-10", "10-30", "30-60"} and set(summary["interval_coverage"]) == {"50", "80", "90"}
    assert summary["changes"] > 50 and summary["early_red_frac"] == 0.0
    assert summary["mae_s"] < summary["baseline_mae_s"]
    for by in ("coverage_by_width", "coverage_by_method"):  # every bounded forecast in one bin of each
        assert sum(b["predictions_frac"] for b in summary[by].values()) == pytest.approx(1.0)
    assert set(summary["coverage_by_width"]) <= {"0-2", "2-5", "5-10", ">10"} and set(summary["coverage_by_method"]) <= set(summary["method_frac"])
    series: dict = {}
    for ix in snapshots:
        for m in ix.states:
            series.setdefault(m.signal_group, []).append((ix.timestamp.timestamp(), phase_class(m.state_time_speed[0].event_state)))
    for row in rows[:: max(1, len(rows) // 200)]:
        seen = series[row["key"][1]]
        k = next(i for i, (ts, _) in enumerate(seen) if ts >= row["t"] - 1e-6)
        cls = seen[k][1]
        change = next(ts for ts, c in seen[k:] if c is not cls)
        assert change == pytest.approx(row["change_unix_s"], abs=1e-3)


@pytest.mark.parametrize("path", sorted((SHARED_DATA / "spat").glob("*.csv.gz")), ids=lambda p: p.name)
def test_a_light_view_is_the_same_from_its_shortcuts_as_from_the_plain_path(path, recorded_snapshots):
    """``light_view``'s shortcuts answer as the plain path does: the forecast chained after the phase in progress,
    cached per group history (``observe._chain``, its steps ``observe._chain_steps``), gives the views of 200 readings
    (10 min in, two groups each) that the same readings give with both caches emptied before each; and every equally likely timing's windows, read at once
    (``observe._scenario_windows``), are the windows read at that level alone (``observe._windows``)."""
    from spat_feed.prediction import observe as ob
    from spat_feed.road.corridors import IntersectionSpec, SignalGroupSpec
    from spat_feed.timing.messages import plan_from_movement, to_unix_s

    spec = IntersectionSpec(id=1, name="light", stop_line_m=300.0, lat_deg=0.0, lon_deg=0.0, approach_heading_deg=0.0, signal_groups=(SignalGroupSpec(id=1),))
    history, readings = IntersectionHistory(), []
    for k, ix in enumerate(recorded_snapshots(path)[:800]):
        t = to_unix_s(ix.timestamp)
        plans = {m.signal_group: plan_from_movement(m, t) for m in ix.states}
        history.record(t, plans)
        if k >= 600:
            readings += [(t, ob.PlanReading(plans[g], cycle=history.stats(g))) for g in sorted(plans)[:2]]
    warm = [ob.light_view(spec, r, 0.0, t, speed_mps=12.0) for t, r in readings]
    snapshots = {id(r.cycle): r.cycle for _, r in readings}.values()
    assert sum(len(c.chains) for c in snapshots) < 0.9 * len(readings)  # (chains were kept and read again: 20-60 % of the views)
    cold = []
    for t, r in readings:
        r.cycle.chains.clear()
        r.cycle.chain_steps.clear()
        cold.append(ob.light_view(spec, r, 0.0, t, speed_mps=12.0))
    assert warm == cold
    assert sum(v.scenario_red_windows_s is not None for v in warm) > len(readings) // 2
    for t, r in readings:
        phases = ob.predicted_phases(r.plan, t, ob.HORIZON_S, r.cycle)
        assert ob._scenario_windows(phases, t, ob.HORIZON_S) == tuple(ob._windows(phases, t, ob.HORIZON_S, q, q) for q in ob.SCENARIO_LEVELS)


def test_a_phase_seen_whole_is_scored_once_whatever_else_its_successors_readings_change():
    """The cycle and the durations are scored on each phase seen whole, once (``IntersectionHistory._score``). A
    reading that changes the history without a change of phase (here each green's exact end, published 5 s ahead)
    used to score the phase before it again: the red that ended 25 s earlier counted twice, and on 2019-05-17 a spurious
    cycle won classes by it. Counted by hand: 40 cycles of red 40 s, green 30 s, amber 5 s are 120 phases, of which all
    but the first (its start unseen) and the last (its end unseen) are seen whole: 118."""
    scored = []

    class Counted(IntersectionHistory):
        def _score(self, group, ended):
            scored.append(ended[:3])
            super()._score(group, ended)

    history = Counted()
    t = T0
    for _ in range(40):
        for state, duration in ((RED, 40.0), (GREEN, 30.0), (AMBER, 5.0)):
            end = t + duration
            for k in range(int(duration)):
                now = t + k
                window = ChangeWindow(end, end, end) if state is GREEN and end - now <= 5.0 else ChangeWindow(now, now, math.inf)
                history.record(now, {1: UncertainPlan((state, MovementPhaseState.UNAVAILABLE), (window,))})
            t = end
    assert len(scored) == 118 and len(set(scored)) == 118


def test_a_reading_stamped_at_its_phase_s_latest_end_is_not_an_unknown_phase():
    """SUMO's source stamps a phase due to switch at that step with ``maxEndTime`` = the stamp (2 % of its readings).
    Taken as a phase, each such reading was a 1 s "unknown" after each amber and red, and the cycle went red ->
    unknown -> red, never green: a red published to end within 9 s was forecast to be followed by another red. Here
    each phase publishes its exact end (red 17 s, green 20 s, amber 4 s); the forecast 8 s into a red chains red,
    green, amber at those durations."""
    history = IntersectionHistory()
    t = T0
    cycle = [(RED, 17.0), (GREEN, 20.0), (AMBER, 4.0)]
    for _ in range(8):
        for state, duration_s in cycle:
            end = t + duration_s
            for k in range(1, int(duration_s) + 1):  # readings up to and including the one stamped at the end
                history.record(t + k, {1: UncertainPlan((state, MovementPhaseState.UNAVAILABLE), (ChangeWindow(end, end, end),))})
            t = end
    red_end = t + 17.0
    for k in range(1, 9):
        history.record(t + k, {1: UncertainPlan((RED, MovementPhaseState.UNAVAILABLE), (ChangeWindow(red_end, red_end, red_end),))})
    now = t + 8.0
    stats = history.stats(1)
    assert PhaseClass.UNKNOWN not in stats.durations_s and stats.following[PhaseClass.RED] is PhaseClass.GREEN
    changes = forecast(state_only(RED, now), now, stats)
    assert [c.ends for c in changes[:3]] == [PhaseClass.RED, PhaseClass.GREEN, PhaseClass.AMBER]
    # the red's end, dated by the first reading that shows the green (1 s after it): 17 s in, 9-10 s from now
    assert now + 9.0 <= changes[0].likely_unix_s <= now + 10.0
    assert changes[1].likely_unix_s - changes[0].likely_unix_s == pytest.approx(20.0, abs=1.0)
