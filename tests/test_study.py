"""The study command end to end on a coarse grid, and the physics the paper's tables rest on."""

import csv

import numpy as np
import pytest

from advisory.evaluation.study import SPACINGS, TIMINGS, StudyCase, paper_cases, run_case, table2
from advisory.optimizer.dp import GridSpec
from advisory.signals import paper_scenario
from ecodrive.cli import main as ecodrive

COARSE = GridSpec(stage_m=20.0)


def test_study_command_writes_report_csv_and_figures(tmp_path, capsys):
    out = tmp_path / "study"
    assert ecodrive(["study", "--out", str(out), "--variants", "lfp54", "--stage-m", "20", "--workers", "2"]) == 0
    rows = list(csv.DictReader((out / "results.csv").open()))
    assert len(rows) == 64
    report = (out / "REPORT.md").read_text()
    assert "Table 2" in report and "[15 15]" in report and "figures/table2_cost_reduction.png" in report
    pngs = sorted((out / "figures").glob("*.png"))
    assert len(pngs) >= 5
    assert all(p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" for p in pngs)
    assert "64 cases" in capsys.readouterr().out


@pytest.mark.parametrize("args", [["--set", "warp_drive=1"], ["--set", "mass_kg=heavy"], ["--set", "name=x"], ["--stage-m", "30"]])
def test_study_rejects_bad_options_with_a_message(tmp_path, args, capsys):
    with pytest.raises(SystemExit) as exc:
        ecodrive(["study", "--out", str(tmp_path), "--variants", "lfp54", "--workers", "1", "--no-figures", *args])
    assert exc.value.code == 2
    assert "error:" in capsys.readouterr().err


def test_a_case_is_a_scenario_and_a_variant():
    cases = paper_cases(["lfp54", "nca75"])
    assert len(cases) == 128 and cases[0].key == ("lfp54", -30.0, -30.0, 200.0)
    mine = StudyCase(paper_scenario(15, 15, 400), "nca75")  # any scenario, no label needed
    res = run_case(mine, COARSE)
    assert res.key == ("nca75",) and res.reduction_pct("cost") > 0


def test_light_one_timing_is_irrelevant_when_both_pass_it_at_four_seconds():
    """[-30 y] and [15 y] are the same drive: light 1 is green at t = 4 s in both (paper rows differ for y = 15)."""
    a, b = (run_case(StudyCase(paper_scenario(x, 15, 400), "lfp54"), COARSE) for x in (-30, 15))
    assert a.regular.cost_usd == pytest.approx(b.regular.cost_usd)
    assert a.eco.cost_usd == pytest.approx(b.eco.cost_usd)
    assert a.reduction_pct("cost") > 20


def test_bigger_pack_cuts_cruise_decay_by_pack_ratio():
    """Below 0.5 C wear is per Ah: decay ratio 75/54 kWh = power ratio x 54/75 (Table 3's 25.5 % cells)."""
    small, big = (run_case(StudyCase(paper_scenario(-30, -30, 200), v), COARSE) for v in ("nca54", "nca75"))
    power_ratio = big.regular.energy_kwh / small.regular.energy_kwh
    assert 1 - big.regular.soh_lost_frac / small.regular.soh_lost_frac == pytest.approx(1 - power_ratio * 54 / 75, rel=1e-6)


def test_table2_layout():
    assert table2({}).shape == (len(TIMINGS), len(SPACINGS)) and np.isnan(table2({})).all()
