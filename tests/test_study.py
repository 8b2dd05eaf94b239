"""The study command end to end on a coarse grid, and the physics the paper's tables rest on."""

import csv

import numpy as np
import pytest

from advisory.optimizer.dp import GridSpec
from advisory.evaluation.study import run_case
from ecodrive.cli import main as ecodrive
from replay.study import TIMINGS, table2


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


def test_study_rejects_unknown_override(tmp_path):
    with pytest.raises(SystemExit):
        ecodrive(["study", "--out", str(tmp_path), "--set", "warp_drive=1"])


def test_light_one_timing_is_irrelevant_when_both_pass_it_at_four_seconds():
    """[-30 y] and [15 y] are the same drive: light 1 is green at t = 4 s in both (paper rows differ for y = 15)."""
    grid = GridSpec(stage_m=20.0)
    a, b = run_case("lfp54", -30, 15, 400, grid), run_case("lfp54", 15, 15, 400, grid)
    assert a.regular.cost_usd == pytest.approx(b.regular.cost_usd)
    assert a.eco.cost_usd == pytest.approx(b.eco.cost_usd)
    assert a.reduction_pct("cost") > 20


def test_bigger_pack_cuts_cruise_decay_by_pack_ratio():
    """Below 0.5 C wear is per Ah: decay ratio 75/54 kWh = power ratio x 54/75 (Table 3's 25.5 % cells)."""
    small, big = run_case("nca54", -30, -30, 200, GridSpec(stage_m=20.0)), run_case("nca75", -30, -30, 200, GridSpec(stage_m=20.0))
    power_ratio = big.regular.energy_kwh / small.regular.energy_kwh
    assert 1 - big.regular.soh_lost_frac / small.regular.soh_lost_frac == pytest.approx(1 - power_ratio * 54 / 75, rel=1e-6)


def test_table2_layout():
    res = {("lfp54", float(x), float(y), float(s)): None for x, y in TIMINGS for s in (200, 400, 600, 800)}
    assert table2({}).shape == (16, 4) and np.isnan(table2({})).all() and len(res) == 64
