"""`replay TRACE --corridor FILE --timing FILE`: a GPS drive on a user's own five-light corridor, and one on
the shipped OSM corridor found by map matching and timed by its own plan; compared with the regular driver and
the DP optimum through all the lights."""

from __future__ import annotations

import json

import numpy as np
import pytest

from advisory.drivers.regular import regular_driver
from advisory.evaluation.endstate import score_in_end_state
from advisory.physics.params import model_params
from replay.cli import main
from replay.make_field_test import ENTRY_UNIX_S, gps_fixes, write_csv
from spat_feed.road.corridors import load_corridor
from spat_feed.transport.scenarios import advisory_scenario_at, make_scenario
from tests.server.test_corridor_dir import five_light_files


def test_replay_on_own_corridor_and_plan_files(tmp_path, capsys):
    five_light_files(tmp_path)
    corridor = load_corridor(tmp_path / "five.json", plans=(tmp_path / "five-plan.json",))
    scenario = advisory_scenario_at(make_scenario(corridor, "fixed", ENTRY_UNIX_S), ENTRY_UNIX_S)
    regular = regular_driver(scenario)
    trace = write_csv(tmp_path / "drive.csv", {}, gps_fixes(regular, corridor, np.random.default_rng(1)))
    code = main([str(trace), "--corridor", str(tmp_path / "five.json"), "--timing", str(tmp_path / "five-plan.json"), "--json"])
    assert code == 0
    out = json.loads(capsys.readouterr().out)
    assert out["corridor"]["name"] == "five" and out["complete"]
    comp = out["comparison"]
    expected = score_in_end_state(regular, model_params(), scenario.speed_limit_mps)
    assert comp["regular"]["duration_s"] == pytest.approx(regular.duration_s, abs=1.0)  # the regular driver through all five lights
    # measured as the drive was (1 Hz, smoothed alike: braking peaks rounded off; measured -2.7 %), not exactly
    assert comp["regular"]["cost_usd"] == pytest.approx(expected.cost_usd, rel=0.04)
    assert comp["dp_optimum"]["cost_usd"] < comp["regular"]["cost_usd"]
    assert abs(comp["savings_frac"]["driven"]["energy"]) < 0.05  # the drive was the regular driver's, plus GPS noise
    # a plan for another corridor, and a name that is no timing: clear errors
    assert main([str(trace), "--corridor", str(tmp_path / "five.json"), "--timing", "15_15"]) == 2
    assert "has 2 lights, corridor 'five' has 5" in capsys.readouterr().err
    assert main([str(trace), "--corridor", str(tmp_path / "five.json"), "--timing", "rush"]) == 2
    assert "unknown timing 'rush'" in capsys.readouterr().err


def test_replay_finds_the_oakland_corridor_and_uses_its_plan(tmp_path, capsys):
    corridor = load_corridor("oakland_7th_westbound")
    scenario = advisory_scenario_at(make_scenario(corridor, None, ENTRY_UNIX_S), ENTRY_UNIX_S)
    assert scenario.speed_limit_mps == pytest.approx(13.4112)
    regular = regular_driver(scenario)
    fixes = gps_fixes(regular, corridor, np.random.default_rng(2), v_lim_mps=scenario.speed_limit_mps)
    trace = write_csv(tmp_path / "oakland.csv", {}, fixes)
    assert main([str(trace), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["corridor"]["name"] == "oakland_7th_westbound" and out["timing"] == "plausible"
    assert out["comparison"]["dp_optimum"] is not None and out["comparison"]["regular"]["duration_s"] == pytest.approx(regular.duration_s, abs=1.0)
    assert any("DP optimum on 10 m stages" in n for n in out["notes"])  # real stop lines are off the 20 m grid
