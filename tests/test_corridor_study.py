"""`ecodrive study --corridor FILE --timing FILE`: the paper's comparison on a user's own arterial."""

from __future__ import annotations

import csv

import pytest

from ecodrive.cli import main
from tests.server.test_corridor_dir import five_light_files


def test_study_of_own_corridor_and_plan_files(tmp_path, capsys):
    five_light_files(tmp_path)
    out = tmp_path / "study"
    code = main(["study", "--corridor", str(tmp_path / "five.json"), "--timing", str(tmp_path / "five-plan.json"), "--entries", "3",
                 "--variants", "lfp54", "--workers", "1", "--out", str(out)])  # fmt: skip
    assert code == 0
    rows = list(csv.DictReader((out / "results.csv").open()))
    assert [float(r["entry_offset_s"]) for r in rows] == [0.0, 120.0, 240.0]  # common period of the 60/90/120 s cycles: 360 s
    for r in rows:  # the DP optimum never costs more than the regular driver through the same five lights
        assert float(r["eco_cost_usd"]) <= float(r["regular_cost_usd"]) * (1 + 1e-6) and float(r["regular_time_s"]) >= 1450 / 24.5872
    report = (out / "REPORT.md").read_text()
    assert "five, timing fixed" in report and "5 lights" in report and (out / "figures" / "cost_by_entry.png").exists()
    assert "mean cost reduction" in capsys.readouterr().out
    with pytest.raises(SystemExit) as info:  # a paper timing for two lights on a five-light corridor
        main(["study", "--corridor", str(tmp_path / "five.json"), "--timing", "15_15", "--out", str(out)])
    assert info.value.code == 2 and "has 2 lights, corridor 'five' has 5" in capsys.readouterr().err
