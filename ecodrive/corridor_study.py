"""`ecodrive study --corridor FILE [--timing PLAN]`: the paper's comparison on a user's own arterial.

The paper varies the lights' timing against a car's arrival ([x y] x spacing). On a real corridor the timing is
the plan, so the arrival varies instead: ``entries`` zone-entry instants spread evenly over one common period
of the lights' cycles (the plan's pattern in force at ``start``), each a case
(:class:`advisory.evaluation.study.StudyCase`) scored like the paper's: the regular driver and the DP optimum
through all N lights to the common end state. Where the stop lines are not on the DP's stage grid, both drivers
run on the lights moved to the nearest 10 m boundary (``replay.drive.dp_scenario``; the report says how far).
Writes REPORT.md, results.csv/json and a figure of the cost per entry under ``out``.
"""

from __future__ import annotations

import csv
import json
import math
from dataclasses import replace
from datetime import datetime
from pathlib import Path
from zoneinfo import ZoneInfo

import numpy as np

from advisory.evaluation.study import StudyCase
from advisory.optimizer.dp import GridSpec
from replay.drive import dp_scenario
from spat_feed.road.corridors import Corridor, load_corridor
from spat_feed.transport.scenarios import advisory_scenario_at, make_scenario, resolve_timing
from spat_feed.timing.signal_plans import SignalPlan

DEFAULT_START = "2024-05-01T12:00"
"""A Wednesday noon, local time of the plan: the off-peak pattern of most plans. Override with --start."""
MAX_PERIOD_S = 3600.0
"""Entries spread over the lights' common period, at most this long. [s]"""


def parse_start(text: str, plan) -> float:
    """Unix seconds of ``text``: a number, or an ISO 8601 time (without an offset: the plan's local time)."""
    try:
        return float(text)
    except ValueError:
        pass
    when = datetime.fromisoformat(text)
    if when.tzinfo is None:
        zone = plan.time_zone if isinstance(plan, SignalPlan) else "UTC"
        when = when.replace(tzinfo=ZoneInfo(zone))
    return when.timestamp()


def corridor_cases(corridor: Corridor, timing, variants, entries: int, start_unix_s: float, grid: GridSpec) -> tuple[list[StudyCase], GridSpec, float, float]:
    """(cases, the grid they need, the largest stop-line move, the period the entries span)."""
    base = advisory_scenario_at(make_scenario(corridor, timing, start_unix_s), start_unix_s)
    cycles = [round(s.cycle_s * 10) for s in base.signals]
    period = min(math.lcm(*cycles) / 10.0, MAX_PERIOD_S) if cycles else 60.0
    _, stage_m, moved = dp_scenario(base, grid.stage_m)
    cases = []
    for k in range(entries):
        entry = start_unix_s + period * k / entries
        sc = advisory_scenario_at(make_scenario(corridor, timing, entry), entry)
        solvable, _, _ = dp_scenario(sc, grid.stage_m)
        solvable = replace(solvable, name=f"{corridor.name} {timing.name} +{entry - start_unix_s:.0f}s")
        cases += [StudyCase(solvable, v, (round(entry - start_unix_s, 3),)) for v in variants]
    return cases, replace(grid, stage_m=stage_m), moved, period


def run(args, run_study, grouped_bars) -> int:
    """The corridor study behind ``ecodrive study --corridor`` (``run_study``, ``grouped_bars``: ecodrive.study's)."""
    import time

    corridor = load_corridor(args.corridor, plans=tuple(t for t in [args.timing] if t and t.lower().endswith((".json", ".toml"))))
    timing = resolve_timing(corridor, args.timing, 0.0)
    start = parse_start(args.start, timing)
    grid = GridSpec(stage_m=args.stage_m, time_buffer_frac=args.time_buffer)
    cases, grid, moved, period = corridor_cases(corridor, timing, args.variants, args.entries, start, grid)
    t0 = time.perf_counter()
    results = run_study(cases, grid, args.workers)
    elapsed = time.perf_counter() - t0
    out: Path = args.out
    out.mkdir(parents=True, exist_ok=True)
    rows = []
    for res in sorted(results.values(), key=lambda r: r.key):
        rows.append({"entry_offset_s": res.case.label[0], **res.row()})
    with (out / "results.csv").open("w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    (out / "results.json").write_text(json.dumps({"corridor": corridor.name, "timing": timing.name, "start_unix_s": start, "grid": repr(grid), "cases": rows}, indent=1))
    lines = [
        f"# Eco-driving on {corridor.name}, timing {timing.name}",
        "",
        f"{len(corridor.intersections)} lights, {corridor.length_m:.0f} m, limit {cases[0].scenario.speed_limit_mps * 3.6:.0f} km/h. "
        f"{args.entries} zone entries spread over {period:.0f} s from {datetime.fromtimestamp(start, ZoneInfo(getattr(timing, 'time_zone', 'UTC'))).isoformat(timespec='minutes')} "
        f"(Unix {start:.0f}); regular driver vs DP optimum through all the lights, scored to the common end state. "
        f"DP stage {grid.stage_m:g} m" + (f"; stop lines moved to the grid by at most {moved:.1f} m" if moved else "") + f". {len(results)} cases in {elapsed:.1f} s.",
        "",
        "| variant | entry +s | regular ¢ | eco ¢ | energy % | decay % | cost % | regular s | eco s |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for res in sorted(results.values(), key=lambda r: r.key):
        lines.append(f"| {res.case.variant} | {res.case.label[0]:.0f} | {res.regular.cost_usd * 100:.3f} | {res.eco.cost_usd * 100:.3f} | "
                     + " | ".join(f"{round(res.reduction_pct(w), 1) + 0.0:.1f}" for w in ("energy", "decay", "cost")) + f" | {res.regular.time_s:.1f} | {res.eco.time_s:.1f} |")  # fmt: skip
    summary = []
    for v in args.variants:
        red = [r.reduction_pct("cost") for r in results.values() if r.case.variant == v]
        summary.append(f"{v}: mean cost reduction {np.mean(red) + 0.0:.1f} % (min {np.min(red) + 0.0:.1f}, max {np.max(red) + 0.0:.1f}) over {len(red)} entries")
    lines += ["", *summary, ""]
    first = [r for r in sorted(results.values(), key=lambda r: r.key) if r.case.variant == args.variants[0]]
    figures = []
    if not args.no_figures:
        (out / "figures").mkdir(exist_ok=True)
        figures.append(grouped_bars([f"+{r.case.label[0]:.0f}" for r in first],
                                    [("regular", [r.regular.cost_usd * 100 for r in first]), ("DP optimum", [r.eco.cost_usd * 100 for r in first])],
                                    "cost [US cents]", f"{corridor.name}, {timing.name}: cost by zone entry (s after the start)",
                                    out / "figures" / "cost_by_entry.png"))  # fmt: skip
        lines += [f"- [{p.name}](figures/{p.name})" for p in figures]
    (out / "REPORT.md").write_text("\n".join(lines) + "\n")
    print(f"{len(results)} cases in {elapsed:.1f} s on {args.workers} processes; {summary[0]}; wrote {out}/REPORT.md")
    return 0
