"""`ecodrive study`: run a study's cases in parallel, then write its report, CSV/JSON and figures.

The cases and their scoring are pure (``advisory.evaluation.study``: a case is a scenario driven by a
vehicle variant); this module adds what needs processes, files and matplotlib: :func:`run_study`
(process pool, tqdm progress), :func:`write_outputs` (REPORT.md, results.csv, results.json, figures)
and the command line (:func:`main`). The paper's four trajectory panels come from
``replay.figures.trajectory_panels``, shared with ``replay --plot``.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import sys
import textwrap
import time
import warnings
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import replace
from pathlib import Path

import numpy as np
from tqdm import tqdm

from advisory.evaluation.study import (
    OFF_PAPER_POINTS,
    PAPER_15_15_S800_PCT,
    PAPER_M15_15_COST,
    PAPER_NCA_15_15_COST,
    PAPER_TABLE2_COST_REDUCTION_PCT,
    PAPER_TABLE3_DECAY_REDUCTION_PCT,
    PINNED_SLACK_S,
    SPACINGS,
    STUDY_GRID,
    TIMINGS,
    VARIANTS,
    WHY_OFF_PAPER,
    CaseResult,
    StudyCase,
    by_scenario,
    paper_cases,
    run_cases,
    table2,
    table3,
    why_table2_cell,
    why_table3_cell,
)
from advisory.optimizer.dp import GridSpec
from advisory.physics.params import VehicleParams
from advisory.signals import paper_scenario


def run_study(
    cases: Sequence[StudyCase], grid: GridSpec = STUDY_GRID, workers: int = 1, overrides: dict | None = None, progress: bool = True
) -> dict:
    """Run ``cases`` on ``workers`` processes (a tqdm bar on stderr unless ``progress`` is False); results by case key.

    A task is a scenario's variants (``run_cases``: each starts its DP from the optima of those before it), the
    longest approaches first so that no long task is left for the end."""
    results: dict = {}
    groups = sorted(by_scenario(cases), key=lambda g: -g[0].scenario.zone_length_m)
    bar = tqdm(total=len(cases), desc="study", unit="case", disable=not progress, file=sys.stderr)
    if workers <= 1:
        for group in groups:
            for res in run_cases(group, grid, overrides):
                results[res.key] = res
            bar.update(len(group))
    else:
        with ProcessPoolExecutor(max_workers=workers) as pool:
            futures = [pool.submit(run_cases, group, grid, overrides) for group in groups]
            for fut in as_completed(futures):
                done = fut.result()
                for res in done:
                    results[res.key] = res
                bar.update(len(done))
    bar.close()
    return results


def _pct(value: float) -> str:
    """One decimal, without the '-0.0' of a saving that is zero to rounding."""
    return f"{round(value, 1) + 0.0:.1f}"


def _md_table(header, rows) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(str(c) for c in row) + " |" for row in rows]
    return "\n".join(lines)


def _ours_vs_paper(ours: np.ndarray, paper: np.ndarray, header) -> str:
    rows = [[f"[{x} {y}]"] + [f"{_pct(o)} / {p:.1f}" for o, p in zip(ours[r], paper[r], strict=True)] for r, (x, y) in enumerate(TIMINGS)]
    with warnings.catch_warnings():  # variants left out leave all-NaN columns
        warnings.simplefilter("ignore", RuntimeWarning)
        mean = np.nanmean(ours, 0)
    rows.append(["**average**"] + [f"**{o:.1f} / {p:.1f}**" for o, p in zip(mean, paper.mean(0), strict=True)])
    return _md_table(header, rows)


def _off_cells(results: dict, ours: np.ndarray, paper: np.ndarray, columns: Sequence[tuple[str, int, str | None]], why) -> list[str]:
    """The report's lines under a table: each cell more than OFF_PAPER_POINTS from the paper's, why (a kind of
    WHY_OFF_PAPER and what in this cell), and each kind explained once."""
    rows, kinds = [], []
    for r, (x, y) in enumerate(TIMINGS):
        for c, (label, s, who) in enumerate(columns):
            if np.isfinite(ours[r, c]) and abs(round(ours[r, c], 1) - paper[r, c]) > OFF_PAPER_POINTS:
                reasons = why(results, x, y, s) if who is None else why(results, x, y, s, who)
                kinds += [k for k, _ in reasons if k not in kinds]
                text = "; ".join(f"**{k}**" + (f": {detail}" if detail else "") for k, detail in reasons)
                rows.append([f"[{x} {y}] {label}", f"{_pct(ours[r, c])} / {paper[r, c]:.1f}", f"{ours[r, c] - paper[r, c]:+.1f}", text or "-"])
    if not rows:
        return ["", f"Every cell within {OFF_PAPER_POINTS:g} points of the paper's."]
    return ["", f"### The {len(rows)} cells more than {OFF_PAPER_POINTS:g} points off the paper, and why", "",
            _md_table(["cell", "ours / paper", "points", "why"], rows), "", *[f"* **{k}**: {WHY_OFF_PAPER[k]}." for k in kinds]]


def render_report(results: dict, grid: GridSpec, elapsed_s: float, overrides: dict | None = None) -> str:
    """REPORT.md: every table of the paper, ours / paper cell by cell."""
    ours2 = table2(results)
    parts = [
        "# Reproduction of the paper's study",
        "",
        f"Grid: stage {grid.stage_m} m, coasting-chain speeds (split {grid.coast_split}), time bins {grid.time_bin_s} s, "
        f"trip-time buffer {grid.time_buffer_frac:+.0%}; a case timed by a light (its optimum ends > {PINNED_SLACK_S:g} s before the "
        f"trip-time limit) solved again on {grid.stage_m / 2:g} m stages (`solve_case`). {len(results)} cases in {elapsed_s:.1f} s. "
        "Both drivers are scored to the common end state (back at the limit, `advisory/evaluation/endstate.py`)."
        + (f" Overrides: {overrides}." if overrides else ""),
        "",
        "## Table 2: cost reduction (%), ours / paper",
        "",
        _ours_vs_paper(ours2, PAPER_TABLE2_COST_REDUCTION_PCT, ["timing [x y]"] + [f"s = {s} m" for s in SPACINGS]),
        "",
        f"Average over the 64 cases: ours {np.nanmean(ours2):.1f} %, paper {PAPER_TABLE2_COST_REDUCTION_PCT.mean():.1f} %.",
        *_off_cells(results, ours2, PAPER_TABLE2_COST_REDUCTION_PCT, [(f"{s} m", s, None) for s in SPACINGS], why_table2_cell),
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
    parts += ["", f"Paper, [15 15] at s = 800 m: energy {PAPER_15_15_S800_PCT['energy']} %, decay "
              f"{PAPER_15_15_S800_PCT['decay']} %, cost {PAPER_15_15_S800_PCT['cost']} %. Paper, [-15 15]: cost {PAPER_M15_15_COST}."]
    rows = []
    for s in SPACINGS:
        base, nca = results.get(("lfp54", 15.0, 15.0, float(s))), results.get(("nca54", 15.0, 15.0, float(s)))
        if base and nca:
            share = nca.regular.wear_usd / nca.regular.cost_usd * 100
            rows.append([s] + [_pct(v) for v in (base.reduction_pct("cost"), nca.reduction_pct("cost"), nca.reduction_pct("decay"))] + [f"{share:.0f}"])
    parts += ["", "## 10x battery decay (NCA), [15 15]", "",
              _md_table(["s [m]", "cost % (LFP)", "cost % (10x)", "decay % (10x)", "wear share of regular cost %"], rows),
              "", f"Paper: cost reduction {PAPER_NCA_15_15_COST}."]
    for variant in VARIANTS:
        ours = table2(results, variant)
        if not np.isnan(ours).all():
            parts += ["", f"Average cost reduction over the 64 cases, {variant}: {np.nanmean(ours):.1f} %"]
    header = ["timing"] + [f"{s} m {who}" for s in SPACINGS for who in ("reg", "eco")]
    parts += ["", "## Table 3: decay reduction (%) from 54 to 75 kWh (10x decay), ours / paper", "",
              _ours_vs_paper(table3(results), PAPER_TABLE3_DECAY_REDUCTION_PCT, header),
              *_off_cells(results, table3(results), PAPER_TABLE3_DECAY_REDUCTION_PCT,
                          [(f"{s} m {'reg' if who == 'regular' else 'eco'}", s, who) for s in SPACINGS for who in ("regular", "eco")], why_table3_cell),
              "", "## Figures", ""]
    return "\n".join(parts) + "\n"


def write_outputs(results: dict, grid: GridSpec, out: Path, elapsed_s: float, make_figures: bool = True, overrides: dict | None = None) -> list[Path]:
    """REPORT.md, results.csv, results.json and (optionally) the figures under ``out``."""
    out.mkdir(parents=True, exist_ok=True)
    rows = [r.row() for r in sorted(results.values(), key=lambda r: r.key)]
    with (out / "results.csv").open("w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    (out / "results.json").write_text(json.dumps({"grid": repr(grid), "overrides": overrides or {}, "cases": rows}, indent=1))
    figs = make_study_figures(results, out / "figures") if make_figures else []
    report = render_report(results, grid, elapsed_s, overrides or {})
    report += "\n".join(f"- [{p.name}](figures/{p.name})" for p in figs) + "\n"
    (out / "REPORT.md").write_text(report)
    return [out / "results.csv", out / "results.json", out / "REPORT.md", *figs]


# --- figures -------------------------------------------------------------------------------------------------------


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _save(fig, path: Path) -> Path:
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    _plt().close(fig)
    return path


def cost_bars(groups: Sequence[str], bars, title: str, path: Path, note=None) -> Path:
    """Stacked electricity + wear bars per group; ``bars``: (label, electricity $ per group, wear $ per group)."""
    from matplotlib.patches import Patch

    fig, ax = _plt().subplots(figsize=(10, 5))
    width = 0.8 / len(bars)
    x = np.arange(len(groups))
    for k, (label, elec, wear) in enumerate(bars):
        pos = x - 0.4 + width * (k + 0.5)
        hatch = "//" if "regular" in label else None
        ax.bar(pos, np.array(elec) * 100, width, color="tab:blue", hatch=hatch, edgecolor="k", lw=0.5)
        ax.bar(pos, np.array(wear) * 100, width, bottom=np.array(elec) * 100, color="tab:orange", hatch=hatch, edgecolor="k", lw=0.5)
        for p, e, w in zip(pos, elec, wear, strict=True):
            ax.text(p, (e + w) * 100, label.split()[0], ha="center", va="bottom", fontsize=7, rotation=90)
    if note is not None:
        tops = np.max([np.array(e) + np.array(w) for _, e, w in bars], axis=0) * 100
        for xi, top, text in zip(x, tops, note, strict=True):
            ax.text(xi, top * 1.12, text, ha="center", fontsize=9, fontweight="bold")
    handles = [Patch(facecolor="tab:blue", label="electricity"), Patch(facecolor="tab:orange", label="battery wear"),
               Patch(facecolor="white", hatch="//", edgecolor="k", label="regular driver (hatched)")]
    ax.set_xticks(x, groups)
    ax.set(ylabel="cost [US cents]", title=title)
    ax.set_ylim(0, ax.get_ylim()[1] * 1.25)
    ax.legend(handles=handles, fontsize=8, loc="upper left")
    ax.grid(axis="y", alpha=0.3)
    return _save(fig, path)


def grouped_bars(groups, series, ylabel: str, title: str, path: Path, note=None) -> Path:
    """Plain grouped bars; ``series``: (label, value per group)."""
    fig, ax = _plt().subplots(figsize=(10, 5))
    width = 0.8 / len(series)
    x = np.arange(len(groups))
    for k, (label, values) in enumerate(series):
        ax.bar(x - 0.4 + width * (k + 0.5), values, width, label=label)
    if note is not None:
        for xi, top, text in zip(x, np.max([v for _, v in series], axis=0), note, strict=True):
            ax.text(xi, top * 1.05, text, ha="center", fontsize=8)
    ax.set_xticks(x, groups)
    ax.set(ylabel=ylabel, title=title)
    ax.set_ylim(0, ax.get_ylim()[1] * 1.15)
    ax.legend(fontsize=8)
    ax.grid(axis="y", alpha=0.3)
    return _save(fig, path)


def table_maps(row_labels, col_labels, ours: np.ndarray, paper: np.ndarray, title: str, path: Path) -> Path:
    """A table as two heat maps (ours, paper) and their difference, values printed in the cells."""
    fig, axes = _plt().subplots(1, 3, figsize=(13, 7))
    vmax = max(np.nanmax(ours), np.nanmax(paper))
    for ax, data, name, cmap, lim in ((axes[0], ours, "ours", "viridis", (0, vmax)), (axes[1], paper, "paper", "viridis", (0, vmax)),
                                      (axes[2], ours - paper, "ours - paper", "coolwarm", (-vmax / 2, vmax / 2))):
        im = ax.imshow(data, cmap=cmap, vmin=lim[0], vmax=lim[1], aspect="auto")
        for (r, c), value in np.ndenumerate(data):
            ax.text(c, r, f"{round(value) + 0.0:.0f}", ha="center", va="center", fontsize=8, color="k" if name == "ours - paper" else "w")
        ax.set_xticks(range(len(col_labels)), col_labels)
        ax.set_yticks(range(len(row_labels)), row_labels if ax is axes[0] else [""] * len(row_labels))
        ax.set_title(name)
        fig.colorbar(im, ax=ax, fraction=0.05)
    fig.suptitle(title)
    return _save(fig, path)


def _bars(results: list[CaseResult], who: str):
    return [getattr(r, who).electricity_usd for r in results], [getattr(r, who).wear_usd for r in results]


def make_study_figures(results: dict, out: Path) -> list[Path]:
    """The paper's figures from ``results`` (whatever of them the cases present allow)."""
    from replay.figures import trajectory_panels

    out.mkdir(parents=True, exist_ok=True)
    paths: list[Path] = []

    def at(variant, x, y):
        return [r for s in SPACINGS if (r := results.get((variant, float(x), float(y), float(s)))) is not None]

    labels = [f"s = {s} m" for s in SPACINGS]
    for x, y in ((15, 15), (-15, 15)):
        found = at("lfp54", x, y)
        if found:
            tag = f"{x}_{y}".replace("-", "m")
            runs = [(f"s = {r.case.label[2]:g} m", r.eco.zone.series, r.regular.zone.series, r.case.scenario.signals) for r in found]
            paths.append(trajectory_panels(runs, f"[{x} {y}]: eco-driver (solid) vs regular driver (dashed), LFP 54 kWh", out / f"trajectories_{tag}.png"))
            paths.append(cost_bars(labels[: len(found)], [("regular", *_bars(found, "regular")), ("eco", *_bars(found, "eco"))],
                                   f"[{x} {y}]: cost in the common end state (electricity + wear)", out / f"cost_{tag}.png",
                                   [f"-{r.reduction_pct('cost'):.0f} %" for r in found]))
    base, nca, big = at("lfp54", 15, 15), at("nca54", 15, 15), at("nca75", 15, 15)
    if len(base) == len(nca) == len(SPACINGS):  # 10x decay: trajectories barely change (paper Sec. 4.2)
        runs = [(f"s = {s} m", n.eco.zone.series, b.eco.zone.series, n.case.scenario.signals) for s, b, n in zip(SPACINGS, base, nca, strict=True)]
        paths.append(trajectory_panels(runs, "[15 15] eco-driver: 10x decay rate (solid) vs LFP (dashed)", out / "decay_rate_trajectories_15_15.png", ("10x decay", "LFP")))
        paths.append(cost_bars(labels, [("regular", *_bars(nca, "regular")), ("eco", *_bars(nca, "eco"))], "[15 15] with 10x battery decay: cost",
                               out / "cost_15_15_decay10x.png", [f"-{r.reduction_pct('cost'):.0f} %" for r in nca]))
    if len(nca) == len(big) == len(SPACINGS):  # battery size, 10x decay (paper Sec. 4.3)
        bars = [("regular 54", *_bars(nca, "regular")), ("eco 54", *_bars(nca, "eco")), ("regular 75", *_bars(big, "regular")), ("eco 75", *_bars(big, "eco"))]
        paths.append(cost_bars(labels, bars, "[15 15], 10x decay: 54 vs 75 kWh cost", out / "cost_battery_size_15_15.png"))
        decay = [(f"{who} {kwh}", [getattr(r, who).soh_lost_frac * 1e6 for r in rs]) for who in ("regular", "eco") for kwh, rs in ((54, nca), (75, big))]
        note = [f"reg -{100 * (1 - b.regular.soh_lost_frac / a.regular.soh_lost_frac):.0f} %, eco -{100 * (1 - b.eco.soh_lost_frac / a.eco.soh_lost_frac):.0f} %"
                for a, b in zip(nca, big, strict=True)]
        paths.append(grouped_bars(labels, decay, "SOH lost [1e-6 of life]", "[15 15], 10x decay: capacity decay, 54 vs 75 kWh", out / "decay_battery_size_15_15.png", note))
    advisor_case = results.get(("lfp54", 15.0, 15.0, 400.0))
    if advisor_case is not None:
        paths.append(advisor_figure(advisor_case, out / "advisor_vs_dp_15_15_s400.png"))
    ours2 = table2(results)
    if not np.all(np.isnan(ours2)):
        paths.append(table_maps([f"[{x} {y}]" for x, y in TIMINGS], [f"{s} m" for s in SPACINGS], ours2, PAPER_TABLE2_COST_REDUCTION_PCT,
                                "Table 2: cost reduction (%)", out / "table2_cost_reduction.png"))
    return paths


def advisor_figure(res: CaseResult, path: Path) -> Path:
    """The advisor in closed loop (virtual driver, 1 s reaction) against the DP optimum and the regular driver."""
    from advisory.advice.tables import AdviceTables, TableGrid
    from advisory.drivers.closed_loop import simulate
    from advisory.evaluation.endstate import score_in_end_state
    from advisory.evaluation.study import variant_params
    from replay.figures import trajectory_panels

    sc = res.case.scenario
    params = variant_params(res.case.variant)
    run = simulate(sc, tables=AdviceTables.build(sc, params, TableGrid()))
    advised = score_in_end_state(run.trajectory, params, sc.speed_limit_mps, keep_series=True)
    runs = [("advised driver (solid) vs DP optimum (dashed)", advised.zone.series, res.eco.zone.series, sc.signals),
            ("regular driver", res.regular.zone.series, None, ())]
    spoken = "\n".join(textwrap.wrap("; ".join(f"{t:.0f} s: {a.message}" for t, a in run.advice if a.speak), 130))
    title = (f"{sc.name}: cost regular {res.regular.cost_usd * 100:.2f} c, "
             f"advised {advised.cost_usd * 100:.2f} c, DP {res.eco.cost_usd * 100:.2f} c\n{spoken}")
    return trajectory_panels(runs, title, path, ("advised / regular", "DP optimum"))


# --- command line --------------------------------------------------------------------------------------------------


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="ecodrive study", description="Reproduce the paper's study (Table 2, Table 3, 10x decay, figures).")
    parser.add_argument("--out", type=Path, default=Path("out/study"), help="output folder (default out/study)")
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 1, help="processes (default: all cores)")
    parser.add_argument("--variants", nargs="+", default=list(VARIANTS), choices=list(VARIANTS))
    parser.add_argument("--stage-m", type=float, default=STUDY_GRID.stage_m, help=f"DP stage length [m] (default {STUDY_GRID.stage_m})")
    parser.add_argument("--time-buffer", type=float, default=0.0, help="relative trip-time buffer (paper: +-0.03)")
    parser.add_argument("--exit-m", type=float, default=100.0, help="exit zone after light 2 [m] (paper: 100, also says 200)")
    parser.add_argument("--no-figures", action="store_true")
    parser.add_argument("--corridor", help="study a corridor file or preset instead of the paper's cases (docs/CORRIDORS.md)")
    parser.add_argument("--timing", help="with --corridor: a plan of the corridor, a plan file or a paper preset (default: its own plan)")
    parser.add_argument("--entries", type=int, default=16, help="with --corridor: zone entries spread over the lights' common period")
    parser.add_argument("--start", default=None, help="with --corridor: first entry, ISO 8601 (plan's local time) or Unix s (default 2024-05-01T12:00)")
    parser.add_argument("--set", action="append", default=[], metavar="FIELD=VALUE",
                        help="override a vehicle parameter in every variant, e.g. --set regen_power_max_w=60000")
    args = parser.parse_args(argv)
    overrides = {}
    numeric = [f for f, t in VehicleParams.__annotations__.items() if t == "float"]
    for item in args.set:
        name, _, value = item.partition("=")
        if name not in numeric or not value:
            parser.error(f"--set {item!r}: expected FIELD=VALUE with FIELD one of {sorted(numeric)}")
        try:
            overrides[name] = float(value)
        except ValueError:
            parser.error(f"--set {item!r}: {value!r} is not a number")
    if args.corridor:  # a user's own arterial: cases over zone-entry instants (ecodrive/corridor_study.py)
        from ecodrive.corridor_study import DEFAULT_START, run
        from spat_feed.files import FileFormatError

        args.start = args.start or DEFAULT_START
        try:
            return run(args, run_study, grouped_bars)
        except (FileFormatError, KeyError, ValueError) as exc:
            parser.error(str(exc.args[0]) if isinstance(exc, KeyError) else str(exc))
    grid = replace(STUDY_GRID, stage_m=args.stage_m, time_buffer_frac=args.time_buffer)
    t0 = time.perf_counter()
    try:
        results = run_study(paper_cases(args.variants, exit_m=args.exit_m), grid, args.workers, overrides)
    except ValueError as exc:  # e.g. an override out of range, or a stage that does not divide the zone
        parser.error(str(exc))
    elapsed = time.perf_counter() - t0
    if args.exit_m != 100.0:
        overrides = {**overrides, "exit_m": args.exit_m}
    paths = write_outputs(results, grid, args.out, elapsed, make_figures=not args.no_figures, overrides=overrides)
    avg = np.nanmean(table2(results, args.variants[0]))
    print(f"{len(results)} cases in {elapsed:.1f} s on {args.workers} processes; average cost reduction ({args.variants[0]}) "
          f"{avg:.1f} % (paper {PAPER_TABLE2_COST_REDUCTION_PCT.mean():.1f} %); wrote {len(paths)} files under {args.out}/")
    return 0


if __name__ == "__main__":
    sys.exit(main())
