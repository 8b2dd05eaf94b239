"""``spat-eval --forecast truth | truth-jitter`` (issue 31): the oracle forecasts, on a constructed recording of a
fixed-time controller whose truth is known by hand."""

from __future__ import annotations

import math

import numpy as np
import pytest

import ecodrive.spat_eval as spat_eval
from ecodrive.cli import main as cli
from ecodrive.spat_eval import Setup
from spat_feed.prediction import oracle
from spat_feed.prediction.observe import HORIZON_S, light_view
from spat_feed.prediction.predictor import ChangeForecast
from spat_feed.road.corridors import IntersectionSpec, SignalGroupSpec
from spat_feed.timing.messages import IntersectionState, MovementEvent, MovementState, TimeChangeDetails, from_unix_s
from spat_feed.timing.plans import FixedTimePlan, PhaseClass, state_at
from spat_feed.transport.player import JsonlRecorder

T0_S = 1_700_000_000.0
PLANS = {1: FixedTimePlan(red_s=30.0, green_s=27.0, amber_s=3.0, offset_s=T0_S + 20.25),
         2: FixedTimePlan(red_s=24.0, green_s=33.0, amber_s=3.0, offset_s=T0_S + 45.25)}  # fmt: skip
"""Two groups of one fixed-time controller; every change at a quarter second, midway between two snapshots."""
LENGTH_S = 600.0


def reds_by_hand(plan: FixedTimePlan, t0_s: float, t1_s: float) -> list[tuple[float, float]]:
    """The plan's reds ``[offset + k cycle, + red)`` that overlap ``[t0, t1]``. [s]"""
    k = math.floor((t0_s - plan.offset_s) / plan.cycle_s)
    out = []
    while plan.offset_s + k * plan.cycle_s < t1_s:
        a = plan.offset_s + k * plan.cycle_s
        if a + plan.red_s > t0_s:
            out.append((a, a + plan.red_s))
        k += 1
    return out


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    """Ten minutes of the controller publishing its state only (its end unknown: minEndTime now, maxEndTime an hour
    on, as the US controller's recording), twice a second."""
    path = tmp_path_factory.mktemp("oracle") / "fixed.jsonl"
    recorder = JsonlRecorder(path)
    for t in T0_S + 0.5 * np.arange(int(LENGTH_S / 0.5) + 1):
        now = from_unix_s(float(t))
        timing = TimeChangeDetails(min_end_time=now, max_end_time=from_unix_s(float(t) + 3600.0))
        states = [MovementState(signal_group=g, state_time_speed=[MovementEvent(event_state=state_at(p, float(t)), timing=timing)]) for g, p in PLANS.items()]
        recorder(IntersectionState(id=7, timestamp=now, states=states))
    recorder.close()
    return path


def test_the_truth_oracle_view_is_the_recorded_truth(recording):
    """``truth``: at every second, each group's view has the reds of the fixed-time plan (by hand), exactly (no
    likely or scenario windows: the advisor's exact-timing rules), fresh, through the store's reading."""
    from spat_feed.transport.player import read_spat_log

    logs = spat_eval.load(read_spat_log(str(recording)))
    setup = Setup(forecast="truth")
    spec = IntersectionSpec(id=7, name="x", stop_line_m=300.0, lat_deg=0.0, lon_deg=0.0, approach_heading_deg=0.0, signal_groups=(SignalGroupSpec(id=1),))
    for log in logs:
        plan = PLANS[log.key[1]]
        for t in T0_S + np.arange(10.0, LENGTH_S - 200.0, 7.0):
            reading = spat_eval.oracle_reading(log, spat_eval._REPLAY.reading(log.key, float(t)), float(t), setup)
            view = light_view(spec, reading, 0.0, float(t))
            want = [(max(a - t, 0.0), b - t) for a, b in reds_by_hand(plan, t, t + HORIZON_S)]
            assert view.fresh and view.likely_red_windows_s is None and view.scenario_red_windows_s is None
            assert np.array(view.red_windows_s) == pytest.approx(np.array(want)), (log.key, t - T0_S)


def test_the_advised_car_on_the_truth_keeps_what_the_dp_keeps(recording):
    """On the exact truth the advisor's rules make the greens the hindsight DP makes: no red entry, no hard brake,
    never costlier than the regular driver by more than a rounding, most of the DP's saving (the rest: the advised
    crossings keep ``green_margin_s`` after a red, the DP crosses at its end; docs/ADVISOR.md "What is lost to the
    forecast"); the service's predictor, learning the same state-only controller as it goes, keeps less."""
    rows: list[dict] = []
    truth = spat_eval.evaluate_log(str(recording), Setup(every_s=23.0, forecast="truth"), workers=1, progress=False, rows_out=rows)
    assert truth["approaches"] >= 30 and truth["red_entries"] == 0 and truth["hard_brakes"] == 0
    assert truth["setup"]["forecast"] == "truth" and truth["hindsight_invalid"] == 0
    assert all(r["saving_frac"] > -0.01 and r["saving_frac"] <= r["hindsight_saving_frac"] + 1e-9 for r in rows)
    assert truth["hindsight_saving_frac"] > 0.1 and truth["kept_frac"] >= 0.75, truth
    predictor = spat_eval.evaluate_log(str(recording), Setup(every_s=23.0), workers=1, progress=False)
    assert predictor["hindsight_saving_frac"] == truth["hindsight_saving_frac"] and predictor["saving_frac"] < truth["saving_frac"]


def test_jittered_forecasts_are_calibrated_and_ordered():
    """``truth-jitter``: over many changes the truth falls inside the stated 80 % interval about 80 % of the time and
    below the median about half the time (calibrated), the median off by about 0.8 sigma (the mean absolute value of
    a normal error); ``truth-spread``: the median is the truth within the draws' own error. Every change's instants
    come after those of the change before it, rank by rank."""
    inside, below, error, centred = [], [], [], []
    for k in range(400):
        end = 100.0 + k
        phases = [(PhaseClass.RED, end), (PhaseClass.GREEN, end + 4.0), (PhaseClass.RED, math.inf)]
        f = oracle.jittered_forecasts(phases, 0.0, 3.0, (k,))
        lo, hi = f[0].interval(0.8)
        inside.append(lo <= end <= hi)
        below.append(end < f[0].likely_unix_s)
        error.append(abs(f[0].likely_unix_s - end))
        assert np.all(f[1].samples_unix_s >= f[0].samples_unix_s) and np.all(np.diff(f[1].samples_unix_s) >= 0.0)
        assert f[0].samples_unix_s.std() == pytest.approx(3.0, rel=0.35)
        centred.append(oracle.jittered_forecasts(phases, 0.0, 3.0, (k,), centred=True)[0].likely_unix_s - end)
    assert 0.74 <= np.mean(inside) <= 0.86 and 0.42 <= np.mean(below) <= 0.58
    assert np.mean(error) == pytest.approx(3.0 * math.sqrt(2.0 / math.pi), rel=0.15)
    assert np.abs(np.mean(centred)) < 0.15 and np.std(centred) < 3.0 * 0.3  # the median of 64 draws: sd ~ 1.25 sigma / 8


def test_a_published_red_holds_in_the_jittered_views(recording):
    """The safety rule is the predictor's: where the reading says red, every equally likely timing is red now and
    for the hold, whatever the draws (a red ending in 1 s, jittered by 5 s, puts half its draws in the past)."""
    from spat_feed.transport.player import read_spat_log

    logs = spat_eval.load(read_spat_log(str(recording)))
    log = logs[0]
    plan = PLANS[log.key[1]]
    t = plan.offset_s + plan.red_s - 1.25  # 1 s before the red ends
    reading = spat_eval.oracle_reading(log, spat_eval._REPLAY.reading(log.key, t), t, Setup(forecast="truth-jitter", jitter_s=5.0))
    assert isinstance(reading.forecasts[0], ChangeForecast) and reading.forecasts[0].ends is PhaseClass.RED
    spec = IntersectionSpec(id=7, name="x", stop_line_m=300.0, lat_deg=0.0, lon_deg=0.0, approach_heading_deg=0.0, signal_groups=(SignalGroupSpec(id=1),))
    view = light_view(spec, reading, 250.0, t, speed_mps=10.0)
    assert view.scenario_red_windows_s is not None
    assert all(w[0][0] == 0.0 and w[0][1] >= 1.0 for w in view.scenario_red_windows_s)


def test_cli_refuses_a_jitter_without_its_spread(recording, capsys):
    with pytest.raises(SystemExit):
        cli(["spat-eval", str(recording), "--forecast", "truth-jitter"])
    assert "--jitter-s" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        cli(["spat-eval", str(recording), "--jitter-s", "3"])
    with pytest.raises(SystemExit):
        cli(["spat-eval", str(recording), "--forecast", "truth-spread", "--jitter-s", "0"])


def test_a_jittered_forecast_keeps_the_published_min_end():
    """The published phase never ends before its minEndTime in a jittered forecast (a hard bound, as the predictor
    keeps it): a red published to end at 50 s at the earliest, whose truth says 48 s, is drawn at 50 s or later."""
    from spat_feed.prediction.observe import PlanReading
    from spat_feed.timing.plans import GREEN, RED, ChangeWindow, UncertainPlan

    reading = PlanReading(UncertainPlan((RED, GREEN), (ChangeWindow(50.0, 55.0, 70.0),)))
    got = oracle.jitter_reading(reading, ((-10.0, 48.0), (100.0, 130.0)), (), 0.0, 150.0, 5.0, (1,))
    assert [f.ends for f in got.forecasts[:2]] == [PhaseClass.RED, PhaseClass.GREEN]
    assert got.forecasts[0].samples_unix_s.min() >= 50.0 and got.forecasts[0].earliest_unix_s >= 50.0
    assert np.median(got.forecasts[1].samples_unix_s) == pytest.approx(100.0, abs=8.0)
