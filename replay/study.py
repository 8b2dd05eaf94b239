"""`ecodrive study`: the paper's whole study, in parallel, with progress, tables, CSV/JSON and figures."""

from __future__ import annotations

import argparse
import csv
import json
import os
import sys
import textwrap
import time
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import replace
from pathlib import Path

import warnings

import numpy as np

from advisory.physics.params import VehicleParams
from advisory.signals import PAPER_SPACINGS_M, PAPER_TIMINGS_S, paper_scenario
from advisory.evaluation.study import STUDY_GRID, VARIANTS, CaseResult, run_case, study_cases
from replay import figures, paper_tables

SPACINGS = [int(s) for s in PAPER_SPACINGS_M]
TIMINGS = [(int(x), int(y)) for x in PAPER_TIMINGS_S for y in PAPER_TIMINGS_S]


def _run(args) -> CaseResult:
    variant, x, y, s, grid, overrides, exit_m = args
    return run_case(variant, x, y, s, grid, overrides, exit_m)


def run_study(cases, grid, workers: int, progress=sys.stderr, overrides: dict | None = None, exit_m: float = 100.0) -> dict:
    """Run ``cases`` (variant, x, y, s) on ``workers`` processes, showing progress on ``progress``."""
    results: dict = {}
    t0 = time.perf_counter()
    tasks = [(*c, grid, overrides or {}, exit_m) for c in cases]

    def report(n: int, res: CaseResult) -> None:
        results[res.key] = res
        if progress is not None:
            elapsed = time.perf_counter() - t0
            eta = elapsed / n * (len(tasks) - n)
            bar = "#" * int(30 * n / len(tasks))
            line = f"study [{bar:<30}] {n}/{len(tasks)} cases, {elapsed:5.1f} s, ~{eta:4.0f} s left "
            if progress.isatty():
                progress.write("\r" + line)
            elif n == len(tasks) or n % max(1, len(tasks) // 10) == 0:
                progress.write(line + "\n")
            progress.flush()

    if workers <= 1:
        for n, task in enumerate(tasks, 1):
            report(n, _run(task))
    else:
        with ProcessPoolExecutor(max_workers=workers) as pool:
            futures = [pool.submit(_run, t) for t in tasks]
            for n, fut in enumerate(as_completed(futures), 1):
                report(n, fut.result())
    if progress is not None and progress.isatty():
        progress.write("\n")
    return results


def _cell(results, variant, x, y, s, what="cost"):
    res = results.get((variant, float(x), float(y), float(s)))
    return np.nan if res is None else res.reduction_pct(what)


def table2(results, variant="lfp54", what="cost") -> np.ndarray:
    return np.array([[_cell(results, variant, x, y, s, what) for s in SPACINGS] for x, y in TIMINGS])


def table3(results) -> np.ndarray:
    """Decay reduction 54 -> 75 kWh (both x10 decay), per spacing (regular, eco). [%]"""
    out = np.full((len(TIMINGS), 2 * len(SPACINGS)), np.nan)
    for r, (x, y) in enumerate(TIMINGS):
        for c, s in enumerate(SPACINGS):
            small = results.get(("nca54", float(x), float(y), float(s)))
            big = results.get(("nca75", float(x), float(y), float(s)))
            if small and big:
                out[r, 2 * c] = 100 * (1 - big.regular.soh_lost_frac / small.regular.soh_lost_frac)
                out[r, 2 * c + 1] = 100 * (1 - big.eco.soh_lost_frac / small.eco.soh_lost_frac)
    return out


def _pct(value: float) -> str:
    """One decimal, without the '-0.0' of a saving that is zero to rounding."""
    return f"{round(value, 1) + 0.0:.1f}"


def _md_table(header, rows) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(str(c) for c in row) + " |" for row in rows]
    return "\n".join(lines)


def render_report(results, grid, elapsed_s: float, overrides: dict | None = None) -> str:
    ours2 = table2(results)
    paper2 = np.array(paper_tables.TABLE2_COST_REDUCTION_PCT)
    rows = [[f"[{x} {y}]"] + [f"{_pct(o)} / {p:.1f}" for o, p in zip(ours2[r], paper2[r], strict=True)] for r, (x, y) in enumerate(TIMINGS)]
    rows.append(["**average**"] + [f"**{o:.1f} / {p:.1f}**" for o, p in zip(np.nanmean(ours2, 0), paper2.mean(0), strict=True)])
    parts = [
        "# Reproduction of the paper's study",
        "",
        f"Grid: stage {grid.stage_m} m, coasting-chain speeds (split {grid.coast_split}), time bins {grid.time_bin_s} s, "
        f"dwell {grid.dwell_s} s, trip-time buffer {grid.time_buffer_frac:+.0%}. {len(results)} cases in {elapsed_s:.1f} s. "
        "Both drivers are scored to the common end state (back at the limit, `advisory/evaluation/endstate.py`)."
        + (f" Overrides: {overrides}." if overrides else ""),
        "",
        "## Table 2: cost reduction (%), ours / paper",
        "",
        _md_table(["timing [x y]"] + [f"s = {s} m" for s in SPACINGS], rows),
    ]
    for x, y in ((15, 15), (-15, 15)):
        rows = []
        for s in SPACINGS:
            res = results.get(("lfp54", float(x), float(y), float(s)))
            if res:
                rows.append([s] + [_pct(res.reduction_pct(w)) for w in ("energy", "decay", "cost")]
                            + [f"{res.regular.cost_usd * 100:.3f}", f"{res.eco.cost_usd * 100:.3f}", f"{res.regular.time_s:.1f}", f"{res.eco.time_s:.1f}"])
        parts += ["", f"## [{x} {y}]: reductions by eco-driving (LFP, 54 kWh)", "",
                  _md_table(["s [m]", "energy %", "decay %", "cost %", "regular ¢", "eco ¢", "regular s", "eco s"], rows)]
    parts += ["", f"Paper, [15 15] at s = 800 m: energy {paper_tables.FIG_15_15_S800['energy']} %, decay "
              f"{paper_tables.FIG_15_15_S800['decay']} %, cost {paper_tables.FIG_15_15_S800['cost']} %. "
              f"Paper, [-15 15]: cost {paper_tables.FIG_M15_15_COST}."]
    rows = []
    for s in SPACINGS:
        base = results.get(("lfp54", 15.0, 15.0, float(s)))
        nca = results.get(("nca54", 15.0, 15.0, float(s)))
        if base and nca:
            share = nca.regular.wear_usd / nca.regular.cost_usd * 100
            rows.append([s] + [_pct(v) for v in (base.reduction_pct("cost"), nca.reduction_pct("cost"), nca.reduction_pct("decay"))] + [f"{share:.0f}"])
    parts += ["", "## 10x battery decay (NCA), [15 15]", "",
              _md_table(["s [m]", "cost % (LFP)", "cost % (10x)", "decay % (10x)", "wear share of regular cost %"], rows),
              "", f"Paper: cost reduction {paper_tables.NCA_15_15_COST}."]
    for variant in VARIANTS:
        ours = table2(results, variant)
        if not np.isnan(ours).all():
            parts += ["", f"Average cost reduction over the 64 cases, {variant}: {np.nanmean(ours):.1f} %"]
    with warnings.catch_warnings():  # variants left out leave all-NaN columns
        warnings.simplefilter("ignore", RuntimeWarning)
        ours3 = table3(results)
        mean3 = np.nanmean(ours3, 0)
    paper3 = np.array(paper_tables.TABLE3_DECAY_REDUCTION_PCT)
    rows = [[f"[{x} {y}]"] + [f"{_pct(o)} / {p:.1f}" for o, p in zip(ours3[r], paper3[r], strict=True)] for r, (x, y) in enumerate(TIMINGS)]
    rows.append(["**average**"] + [f"**{o:.1f} / {p:.1f}**" for o, p in zip(mean3, paper3.mean(0), strict=True)])
    header = ["timing"] + [f"{s} m {who}" for s in SPACINGS for who in ("reg", "eco")]
    parts += ["", "## Table 3: decay reduction (%) from 54 to 75 kWh (10x decay), ours / paper", "", _md_table(header, rows)]
    parts += ["", "## Figures", ""]
    return "\n".join(parts) + "\n"


def write_outputs(results, grid, out: Path, elapsed_s: float, make_figures: bool = True, overrides: dict | None = None) -> list[Path]:
    out.mkdir(parents=True, exist_ok=True)
    rows = [r.row() for r in sorted(results.values(), key=lambda r: r.key)]
    with (out / "results.csv").open("w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    (out / "results.json").write_text(json.dumps({"grid": grid.__repr__(), "cases": rows}, indent=1))
    written = [out / "results.csv", out / "results.json"]
    figs = make_study_figures(results, out / "figures") if make_figures else []
    report = render_report(results, grid, elapsed_s, overrides or {})
    report = report.replace("## Figures\n", "## Figures\n" + "\n".join(f"- [{p.name}](figures/{p.name})" for p in figs) + "\n")
    (out / "REPORT.md").write_text(report)
    return written + [out / "REPORT.md"] + figs


def make_study_figures(results, out: Path) -> list[Path]:
    out.mkdir(parents=True, exist_ok=True)
    paths = []
    for x, y in ((15, 15), (-15, 15)):
        runs, bars_reg_e, bars_reg_w, bars_eco_e, bars_eco_w, note = [], [], [], [], [], []
        for s in SPACINGS:
            res = results.get(("lfp54", float(x), float(y), float(s)))
            if res is None:
                continue
            runs.append((f"s = {s} m", res.eco.zone.series, res.regular.zone.series, paper_scenario(x, y, s).signals))
            bars_reg_e.append(res.regular.electricity_usd)
            bars_reg_w.append(res.regular.wear_usd)
            bars_eco_e.append(res.eco.electricity_usd)
            bars_eco_w.append(res.eco.wear_usd)
            note.append(f"-{res.reduction_pct('cost'):.0f} %")
        if runs:
            tag = f"{x}_{y}".replace("-", "m")
            paths.append(figures.trajectory_panels(runs, f"[{x} {y}]: eco-driver (solid) vs regular driver (dashed), LFP 54 kWh", out / f"trajectories_{tag}.png"))
            paths.append(figures.cost_bars([f"s = {s} m" for s in SPACINGS[: len(note)]],
                                           [("regular", bars_reg_e, bars_reg_w), ("eco", bars_eco_e, bars_eco_w)],
                                           f"[{x} {y}]: cost in the common end state (electricity + wear)", out / f"cost_{tag}.png", note))
    # 10x decay: trajectories barely change (paper Fig. on decay rates)
    runs = []
    for s in SPACINGS:
        base, nca = results.get(("lfp54", 15.0, 15.0, float(s))), results.get(("nca54", 15.0, 15.0, float(s)))
        if base and nca:
            runs.append((f"s = {s} m", nca.eco.zone.series, base.eco.zone.series, paper_scenario(15, 15, s).signals))
    if runs:
        paths.append(figures.trajectory_panels(runs, "[15 15] eco-driver: 10x decay rate (solid) vs LFP (dashed)", out / "decay_rate_trajectories_15_15.png", ("10x decay", "LFP")))
        bars, note = [], []
        for variant in ("nca54",):
            pairs = [results[(variant, 15.0, 15.0, float(s))] for s in SPACINGS if (variant, 15.0, 15.0, float(s)) in results]
            bars = [("regular", [r.regular.electricity_usd for r in pairs], [r.regular.wear_usd for r in pairs]),
                    ("eco", [r.eco.electricity_usd for r in pairs], [r.eco.wear_usd for r in pairs])]
            note = [f"-{r.reduction_pct('cost'):.0f} %" for r in pairs]
        paths.append(figures.cost_bars([f"s = {s} m" for s in SPACINGS[: len(note)]], bars, "[15 15] with 10x battery decay: cost", out / "cost_15_15_decay10x.png", note))
    # battery size, 10x decay
    small = [results.get(("nca54", 15.0, 15.0, float(s))) for s in SPACINGS]
    big = [results.get(("nca75", 15.0, 15.0, float(s))) for s in SPACINGS]
    if all(small) and all(big):
        bars = [("regular 54", [r.regular.electricity_usd for r in small], [r.regular.wear_usd for r in small]),
                ("eco 54", [r.eco.electricity_usd for r in small], [r.eco.wear_usd for r in small]),
                ("regular 75", [r.regular.electricity_usd for r in big], [r.regular.wear_usd for r in big]),
                ("eco 75", [r.eco.electricity_usd for r in big], [r.eco.wear_usd for r in big])]
        paths.append(figures.cost_bars([f"s = {s} m" for s in SPACINGS], bars, "[15 15], 10x decay: 54 vs 75 kWh cost", out / "cost_battery_size_15_15.png"))
        decay = [("regular 54", [r.regular.soh_lost_frac * 1e6 for r in small]), ("regular 75", [r.regular.soh_lost_frac * 1e6 for r in big]),
                 ("eco 54", [r.eco.soh_lost_frac * 1e6 for r in small]), ("eco 75", [r.eco.soh_lost_frac * 1e6 for r in big])]
        note = [f"reg -{100 * (1 - b.regular.soh_lost_frac / a.regular.soh_lost_frac):.0f} %, eco -{100 * (1 - b.eco.soh_lost_frac / a.eco.soh_lost_frac):.0f} %"
                for a, b in zip(small, big, strict=True)]
        paths.append(figures.grouped_bars([f"s = {s} m" for s in SPACINGS], decay, "SOH lost [1e-6 of life]", "[15 15], 10x decay: capacity decay, 54 vs 75 kWh", out / "decay_battery_size_15_15.png", note))
    base = results.get(("lfp54", 15.0, 15.0, 400.0))
    if base is not None:
        paths.append(advisor_figure(base, out / "advisor_vs_dp_15_15_s400.png"))
    ours2 = table2(results)
    if not np.all(np.isnan(ours2)):
        paths.append(figures.table_maps([f"[{x} {y}]" for x, y in TIMINGS], [f"{s} m" for s in SPACINGS], ours2,
                                        np.array(paper_tables.TABLE2_COST_REDUCTION_PCT), "Table 2: cost reduction (%)", out / "table2_cost_reduction.png"))
    return paths


def advisor_figure(res: CaseResult, path: Path) -> Path:
    """The advisor in closed loop (virtual driver, 1 s reaction) against the DP optimum and the regular driver."""
    from advisory.drivers.closed_loop import simulate
    from advisory.evaluation.endstate import score_in_end_state
    from advisory.physics.params import model_params
    from advisory.advice.tables import AdviceTables, TableGrid

    sc = paper_scenario(res.x_s, res.y_s, res.spacing_m)
    params = model_params()
    run = simulate(sc, tables=AdviceTables.build(sc, params, TableGrid()))
    advised = score_in_end_state(run.trajectory, params, sc.speed_limit_mps, keep_series=True)
    runs = [("advised driver (solid) vs DP optimum (dashed)", advised.zone.series, res.eco.zone.series, sc.signals),
            ("regular driver", res.regular.zone.series, None, ())]
    spoken = "\n".join(textwrap.wrap("; ".join(f"{t:.0f} s: {a.message}" for t, a in run.advice if a.speak), 130))
    title = (f"[{res.x_s:g} {res.y_s:g}], s = {res.spacing_m:g} m: cost regular {res.regular.cost_usd * 100:.2f} c, "
             f"advised {advised.cost_usd * 100:.2f} c, DP {res.eco.cost_usd * 100:.2f} c\n{spoken}")
    return figures.trajectory_panels(runs, title, path, ("advised / regular", "DP optimum"))


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="ecodrive study", description="Reproduce the paper's study (Table 2, Table 3, 10x decay, figures).")
    parser.add_argument("--out", type=Path, default=Path("out/study"), help="output folder (default out/study)")
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    parser.add_argument("--variants", nargs="+", default=list(VARIANTS), choices=list(VARIANTS))
    parser.add_argument("--stage-m", type=float, default=STUDY_GRID.stage_m, help="DP stage length [m]")
    parser.add_argument("--time-buffer", type=float, default=0.0, help="relative trip-time buffer (paper: +-0.03)")
    parser.add_argument("--exit-m", type=float, default=100.0, help="exit zone after light 2 [m] (paper: 100, also says 200)")
    parser.add_argument("--no-figures", action="store_true")
    parser.add_argument("--set", action="append", default=[], metavar="FIELD=VALUE",
                        help="override a vehicle parameter in every variant, e.g. --set regen_power_max_w=200000")
    args = parser.parse_args(argv)
    overrides = {}
    for item in args.set:
        field, _, value = item.partition("=")
        if field not in VehicleParams.__dataclass_fields__ or not value:
            parser.error(f"--set {item!r}: expected FIELD=VALUE with FIELD one of {sorted(VehicleParams.__dataclass_fields__)}")
        overrides[field] = float(value)
    grid = replace(STUDY_GRID, stage_m=args.stage_m, time_buffer_frac=args.time_buffer)
    t0 = time.perf_counter()
    results = run_study(study_cases(tuple(args.variants)), grid, args.workers, overrides=overrides, exit_m=args.exit_m)
    elapsed = time.perf_counter() - t0
    if args.exit_m != 100.0:
        overrides = {**overrides, "exit_m": args.exit_m}
    paths = write_outputs(results, grid, args.out, elapsed, make_figures=not args.no_figures, overrides=overrides)
    print(f"{len(results)} cases in {elapsed:.1f} s; wrote {len(paths)} files under {args.out}/ (REPORT.md, results.csv, figures/)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
