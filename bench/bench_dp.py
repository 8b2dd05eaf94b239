"""DP benchmarks: one solve of the largest case, numba vs plain NumPy, convergence table, full study.

Run: .venv/bin/python bench/bench_dp.py [--quick]

* Largest case: s = 800 m (a 1000 m zone), timing [15 15] (the paper's showcase), at the resolution where
  halving every step changes the optimal cost by < 1 % (the table shows it); best of 5 after JIT, one core.
* The same problem solved by ``solve_numpy`` (the recursion in plain NumPy/Python) in the same run: ratio.
* Convergence: optimal cost and solve time as stage length, speed spacing (tied to the stage by the
  coasting chain) and time bins are halved, for an easy and two hard cases.
* The full study (64 cases x 3 variants) on all cores, and the memory of one solve.
"""

from __future__ import annotations

import os
import resource
import sys
import time
from pathlib import Path

os.environ.setdefault("NUMBA_NUM_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from advisory.optimizer.dp import GridSpec, build_problem, solve_numpy, solve_problem, time_limit_s  # noqa: E402
from advisory.physics.params import model_params  # noqa: E402
from advisory.drivers.regular import regular_driver  # noqa: E402
from advisory.signals import paper_scenario  # noqa: E402
from advisory.evaluation.study import paper_cases  # noqa: E402
from ecodrive.study import run_study  # noqa: E402

BENCH_GRID = GridSpec(stage_m=20.0, time_bin_s=0.5, dwell_s=1.0)


def problem(case, grid):
    params = model_params()
    sc = paper_scenario(*case)
    return build_problem(sc, params, grid, time_limit_s(regular_driver(sc), params, sc, grid))


def best_time(fn, repeats=5):
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def table_bytes(prob) -> int:
    return (prob.n_stages + 1) * prob.speed_mps.size * prob.n_bins * (8 + 8 + 8)


def main() -> None:
    quick = "--quick" in sys.argv
    case = (15, 15, 800)
    prob = problem(case, BENCH_GRID)
    solve_problem(prob)  # JIT / cache load
    t_fast, sol = best_time(lambda: solve_problem(prob))
    t0 = time.perf_counter()
    ref = solve_numpy(prob)
    t_numpy = time.perf_counter() - t0
    fine = solve_problem(problem(case, BENCH_GRID.refined(2)))
    print(f"Largest case [15 15], s = 800 m (1000 m zone), grid {BENCH_GRID.stage_m} m / {prob.speed_mps.size} speeds / bins {BENCH_GRID.time_bin_s} s")
    print(f"  numba solve      : {t_fast * 1e3:7.1f} ms (best of 5, one core; target < 50 ms)")
    print(f"  plain NumPy solve: {t_numpy * 1e3:7.0f} ms  -> numba is {t_numpy / t_fast:.0f}x faster; same cost: {abs(ref.cost_usd - sol.cost_usd) < 1e-12}")
    print(f"  halving every step changes the optimum by {100 * (fine.cost_usd / sol.cost_usd - 1):+.2f} % (target < 1 %)")
    print(f"  DP tables of one solve: {table_bytes(prob) / 1e6:.1f} MB (refined grid: {table_bytes(problem(case, BENCH_GRID.refined(2))) / 1e6:.1f} MB; target < 200 MB)")

    print("\nConvergence (cost in thousandths of a dollar; change vs the coarser grid):")
    print(f"  {'case':18} {'stage m':>7} {'speeds':>6} {'bin s':>6} {'cost m$':>9} {'change':>8} {'solve ms':>9} {'tables MB':>9}")
    for c in ((15, 15, 800), (-15, 15, 400), (0, 0, 800)):
        prev = None
        for factor in (1, 2, 4) if not quick else (1, 2):
            g = BENCH_GRID.refined(factor) if factor > 1 else BENCH_GRID
            p = problem(c, g)
            solve_problem(p)
            t, s = best_time(lambda p=p: solve_problem(p), repeats=2)
            change = "" if prev is None else f"{100 * (s.cost_usd / prev - 1):+.2f}%"
            name = f"[{c[0]} {c[1]}] s={c[2]}"
            print(f"  {name:18} {g.stage_m:7.1f} {p.speed_mps.size:6d} {g.time_bin_s:6.3f} {s.cost_usd * 1e3:9.4f} {change:>8} {t * 1e3:9.1f} {table_bytes(p) / 1e6:9.1f}")
            prev = s.cost_usd

    if not quick:
        cases = paper_cases()
        workers = os.cpu_count() or 1
        t0 = time.perf_counter()
        run_study(cases, GridSpec(stage_m=10.0), workers, progress=False)
        t_study = time.perf_counter() - t0
        print(f"\nFull study: {len(cases)} cases (64 x 3 variants) at stage 10 m on {workers} processes: {t_study:.1f} s (target < 30 s on 2 cores)")
    print(f"Peak RSS of this process: {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MB")


if __name__ == "__main__":
    main()
