"""Closed-loop safety: red entries and hard brakes over randomized actuated runs and the paper's 64 scenarios.

Run: .venv/bin/python bench/bench_closed_loop_safety.py [--runs N] [--workers W] [--variants amber,no-amber]
     [--driver lenient|careful] [--first-seed S] [--no-paper] [--no-tables]

* N randomized closed-loop runs per variant (``spat_feed.transport.actuated.random_case``, default 10,000): two
  lights 150-1000 m apart, cycle 40-120 s, windows up to ±15 s with the real switch anywhere inside and up to 10 %
  beyond, up to two dropouts of 2-10 s, a feed clock off by up to ±3 s (the receiver told only the bound), half the
  controllers publishing their current phase only. Variants: ``amber`` (each green ends in a 4 s amber, published as
  J2735 protected-clearance, as a real controller does) and ``no-amber`` (the stress case: a green turns red at once).
* Hard brakes: a run's hardest braking above 4 m/s² (the regular driver's hardest). Stalled runs: the car never
  reached the zone's end (held at a line until the simulation's 600 s: no red entry, and no drive either).
* For each red entry and hard brake, whether it was avoidable (:func:`spat_feed.transport.actuated.safety_events`):
  could a car braking at the advisor's firm rate (3 m/s²), from the first reading whose published window admitted
  that red (at the crossing, or at the braking), have stopped at the line? Only the avoidable ones are the advisor's
  failures; both counts are printed.
* What the driver hears: advice changes (the (action, reason) differs from the second before's) and advices spoken, in
  all runs (issue 31: words that flip while the plan stays the same).
* The paper's 64 scenarios (fixed-time, exact SPaT), rules only and with the DP tables: red entries, hard brakes.

Targets (issue 31): 0 red entries and 0 hard brakes with an amber and on the paper's scenarios; without an amber, 0
avoidable ones; no stalled run (the exit status is 1 otherwise). Progress goes
to stderr. Seeds are ``S .. S + N - 1`` for each variant (the same cases with and without amber).
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import replace
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from advisory.advice.views import AdvisorParams  # noqa: E402
from advisory.drivers.closed_loop import DRIVERS, red_light_violations, simulate  # noqa: E402
from advisory.signals import PAPER_SPACINGS_M, PAPER_TIMINGS_S, paper_scenario  # noqa: E402
from spat_feed.transport.actuated import random_case, safety_events  # noqa: E402

HARD_BRAKE_MPS2 = 4.0
"""Braking harder than this is a hard brake (the regular driver's hardest, paper Sec. 2). [m/s²]"""

VARIANTS = {"amber": None, "no-amber": 0.0}
"""Each variant's ``amber_s`` for :func:`random_case` (None: the lights' own 4 s amber)."""


def actuated_run(job: tuple[int, str, str]):
    """One randomized run: (seed, red entries and hard brakes (:func:`safety_events`), advised above the limit, surprises,
    stalled: the car never reached the zone's end, held at a line until the simulation's 600 s, advice changes, advices
    spoken)."""
    seed, variant, driver = job
    truth, feed, noise = random_case(seed, amber_s=VARIANTS[variant])
    run = simulate(truth, AdvisorParams(), driver=replace(DRIVERS[driver], noise_mps=noise, seed=seed), feed=feed)
    events = safety_events(run.trajectory, feed, AdvisorParams().firm_decel_mps2, HARD_BRAKE_MPS2)
    stalled = bool(run.trajectory.x_m[-1] < truth.zone_length_m - 1e-6)
    said = [(a.action, a.reason) for _, a in run.advice]
    changes = sum(a != b for a, b in zip(said, said[1:]))
    spoken = sum(a.speak for _, a in run.advice)
    return seed, events, run.max_advised_mps > truth.speed_limit_mps + 1e-9, run.surprises, stalled, changes, spoken


def paper_run(job: tuple[tuple[float, float, float], bool]):
    """One paper scenario with exact SPaT: (case, red entries, hardest braking [m/s²])."""
    case, with_tables = job
    sc = paper_scenario(*case)
    tables = None
    if with_tables:
        from advisory.advice.tables import AdviceTables, TableGrid, paper_offsets_s
        from advisory.physics.params import model_params

        tables = _tables(case[2], AdviceTables, TableGrid, paper_offsets_s, model_params)
    run = simulate(sc, AdvisorParams(), tables=tables)
    return case, len(red_light_violations(run.trajectory, sc)), float(-run.trajectory.accel_mps2.min())


_TABLES: dict = {}


def _tables(spacing_m, AdviceTables, TableGrid, paper_offsets_s, model_params):  # noqa: N803 (the classes, imported late)
    if spacing_m not in _TABLES:
        _TABLES[spacing_m] = AdviceTables.build(paper_scenario(0, 0, spacing_m), model_params(), TableGrid(), paper_offsets_s())
    return _TABLES[spacing_m]


def _progress(label: str, done: int, total: int, t0: float) -> None:
    elapsed = time.perf_counter() - t0
    eta = elapsed / done * (total - done) if done else math.nan
    print(f"\r  {label}: {done:,}/{total:,} ({elapsed:.0f} s, ~{eta:.0f} s left)", end="", file=sys.stderr, flush=True)


def run_variant(variant: str, seeds: range, driver: str, pool: ProcessPoolExecutor) -> list:
    t0 = time.perf_counter()
    out = []
    every = max(1, len(seeds) // 50)
    for k, res in enumerate(pool.map(actuated_run, [(s, variant, driver) for s in seeds], chunksize=max(1, min(50, len(seeds) // 40))), 1):
        out.append(res)
        if k % every == 0 or k == len(seeds):
            _progress(variant, k, len(seeds), t0)
    print(file=sys.stderr)
    return out


def _line(seed: int, e) -> str:
    what = (f"crossed at {e.at_s:.1f} s, {e.at_s - e.red_start_s:.2f} s into the red" if e.kind == "red_entry"
            else f"braked at {e.brake_mps2:.2f} m/s² at {e.at_s:.1f} s (red from {e.red_start_s:.1f} s)")  # fmt: skip
    known = (f"known at {e.known_s:.0f} s, {e.distance_m:.0f} m out at {e.speed_mps:.1f} m/s (stop needs {e.stop_decel_mps2:.2f} m/s²)"
             if math.isfinite(e.known_s) else "never told before")  # fmt: skip
    decided = f"exact at {e.decided_s:.0f} s" if math.isfinite(e.decided_s) else "never exact before"
    return f"  seed {seed} light {e.light + 1}: {what}; {known}; {decided}; {'AVOIDABLE' if e.avoidable else 'unavoidable'}"


def report_variant(variant: str, res: list, driver: str, elapsed_s: float) -> dict:
    events = [(seed, e) for seed, es, *_ in res for e in es]
    counts = {}
    for kind in ("red_entry", "hard_brake"):
        of_kind = [e for _, e in events if e.kind == kind]
        counts[kind] = (len(of_kind), sum(e.avoidable for e in of_kind))
    above = sum(r[2] for r in res)
    surprises = sum(r[3] for r in res)
    stalled = [r[0] for r in res if r[4]]
    amber = "4 s amber (published as protected-clearance)" if VARIANTS[variant] is None else "no amber (a green turns red at once)"
    firm = AdvisorParams().firm_decel_mps2
    (red, red_avoidable), (hard, hard_avoidable) = counts["red_entry"], counts["hard_brake"]
    print(f"{variant}: {len(res):,} randomized actuated runs, {amber}, {driver} driver, ±3 s skew, dropouts: "
          f"{red} red entries ({red_avoidable} avoidable: advisor failures; {red - red_avoidable} unavoidable: told too late to stop at "
          f"{firm:g} m/s²); {hard} hard brakes > {HARD_BRAKE_MPS2:g} m/s² ({hard_avoidable} avoidable, {hard - hard_avoidable} unavoidable); "
          f"{above} advised speeds above the limit; {surprises} surprises; {len(stalled)} stalled runs{f' (seeds {stalled[:20]})' if stalled else ''}; "
          f"{sum(r[5] for r in res):,} advice changes, {sum(r[6] for r in res):,} advices spoken ({elapsed_s:.0f} s)")
    for seed, e in events[:40]:
        print(_line(seed, e))
    if len(events) > 40:
        print(f"  ... and {len(events) - 40} more")
    return {"runs": len(res), "red_entries": red, "avoidable": red_avoidable + hard_avoidable, "hard_brakes": hard, "above_limit": above, "stalled": len(stalled)}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="bench_closed_loop_safety", description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=int, default=10_000, help="randomized runs per variant (default 10,000)")
    parser.add_argument("--first-seed", type=int, default=0)
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    parser.add_argument("--variants", default="amber,no-amber", help="comma-separated, of: " + ", ".join(VARIANTS))
    parser.add_argument("--driver", default="lenient", choices=sorted(DRIVERS))
    parser.add_argument("--no-paper", action="store_true", help="skip the paper's 64 scenarios")
    parser.add_argument("--no-tables", action="store_true", help="paper scenarios with the rules only")
    args = parser.parse_args(argv)
    variants = [v for v in args.variants.split(",") if v]
    if unknown := [v for v in variants if v not in VARIANTS]:
        parser.error(f"unknown variant(s) {unknown}; choose from {sorted(VARIANTS)}")
    seeds = range(args.first_seed, args.first_seed + args.runs)
    failures = 0
    with ProcessPoolExecutor(args.workers) as pool:
        if not args.no_paper:
            cases = [(x, y, s) for s in PAPER_SPACINGS_M for x in PAPER_TIMINGS_S for y in PAPER_TIMINGS_S]
            for with_tables in (False,) if args.no_tables else (False, True):
                t0 = time.perf_counter()
                res = list(pool.map(paper_run, [(c, with_tables) for c in cases], chunksize=4))
                red = [(c, n) for c, n, _ in res if n]
                hard = [(c, b) for c, _, b in res if b > HARD_BRAKE_MPS2 + 1e-9]
                print(f"paper's 64 scenarios, exact SPaT, {'with DP tables' if with_tables else 'rules only'}: {sum(n for _, n in red)} red entries, "
                      f"{len(hard)} hard brakes (> {HARD_BRAKE_MPS2:g} m/s²); hardest braking {max(b for *_, b in res):.2f} m/s² "
                      f"({time.perf_counter() - t0:.0f} s)" + (f"; red: {red}" if red else "") + (f"; hard: {hard}" if hard else ""))
                failures += len(red) + len(hard)
        for variant in variants:
            t0 = time.perf_counter()
            res = run_variant(variant, seeds, args.driver, pool)
            summary = report_variant(variant, res, args.driver, time.perf_counter() - t0)
            failures += summary["avoidable"] + summary["above_limit"] + summary["stalled"] + (summary["red_entries"] + summary["hard_brakes"] if variant == "amber" else 0)
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
