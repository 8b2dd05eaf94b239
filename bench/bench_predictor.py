"""Phase prediction on a recorded controller: what a reading costs the history, what a light's view costs, in one run.

Run: .venv/bin/python bench/bench_predictor.py [LOG ...]   (default: every recording in ../shared/data/spat)

For each recording, the same snapshots in the same process, timed after the first :data:`WARM`:

* parse: each movement read into a plan (``plan_from_movement``), the receiver's unavoidable work per reading;
* update: the intersection's history fed with those plans (``IntersectionHistory.record``: durations, links, the
  cycle and the scores of its methods), per reading per group (target <= 50 us), and its ratio to parsing;
* view: one light's view with the whole forecast chain over 150 s (``light_view``), p50 / p99;
* advise: ``advise()`` on an observation of two such lights, p50 / p99 (target p99 <= 0.5 ms);
* a fix: the two views and ``advise()`` together, what the service spends on a fix with the predictor in the path
  (the target's "advise() with the predictor in the path").

Each in wall time and in the thread's CPU time (``time.thread_time``): on a shared machine the wall time's p99 is the
scheduler's (a call that loses the CPU waits out another process's time slice, 2-6 ms: at load 4.5 on 2 cores, 0.42
ms calls measured p99 6.1 ms wall, 0.69 ms CPU), the CPU time is the advisor's own cost, and the load is printed with
them.
"""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path

import numpy as np

from advisory.advice.advisor import advise
from advisory.advice.views import AdvisorMemory, Observation
from spat_feed.prediction.history import IntersectionHistory
from spat_feed.prediction.observe import PlanReading, light_view
from spat_feed.road.corridors import IntersectionSpec, SignalGroupSpec
from spat_feed.timing.messages import plan_from_movement, to_unix_s
from spat_feed.transport.recorded import read_spat_csv

SHARED = Path(__file__).resolve().parents[2] / "shared" / "data" / "spat"


def spec(n: int, stop_line_m: float) -> IntersectionSpec:
    return IntersectionSpec(id=n, name=f"light {n}", stop_line_m=stop_line_m, lat_deg=0.0, lon_deg=0.0, approach_heading_deg=0.0,
                            signal_groups=(SignalGroupSpec(id=1),))  # fmt: skip


WARM = 600
"""Snapshots (10 minutes) before anything is timed: the history has phases to go by, and the code's one-time costs are
paid (numba loads its kernels on their first call in a process, 0.5-1 s: spread over the 37,598 readings of 05-01's
4,000 snapshots, 15-30 us per reading, wherever the first kernel call happens to fall). [-]"""


def bench(path: Path, limit: int = 4000) -> None:
    snapshots = read_spat_csv(path)[:limit]
    t_parse = t_update = 0.0
    n_readings = 0
    views, views_cpu, advice, advice_cpu, fix, fix_cpu = [], [], [], [], [], []
    history = IntersectionHistory()
    lights = (spec(1, 300.0), spec(2, 600.0))
    memory = AdvisorMemory()
    for k, ix in enumerate(snapshots):
        t = to_unix_s(ix.timestamp)
        t0 = time.perf_counter()
        plans = {m.signal_group: plan_from_movement(m, t) for m in ix.states}
        t1 = time.perf_counter()
        history.record(t, plans)
        t2 = time.perf_counter()
        if k < WARM:  # the first minutes: no history to speak of, the code's first calls
            continue
        t_parse += t1 - t0
        t_update += t2 - t1
        n_readings += len(plans)
        groups = sorted(plans)[:2]
        readings = [PlanReading(plans[g], cycle=history.stats(g)) for g in groups]
        a, a_cpu = time.perf_counter(), time.thread_time()
        obs_lights = tuple(light_view(spec_, r, 0.0, t, speed_mps=12.0) for spec_, r in zip(lights, readings))
        b, b_cpu = time.perf_counter(), time.thread_time()
        adv, memory = advise(Observation(12.0, 50 / 3.6, obs_lights, position_m=0.0), memory)
        c_cpu, c = time.thread_time(), time.perf_counter()
        views.append((b - a) / len(obs_lights))
        views_cpu.append((b_cpu - a_cpu) / len(obs_lights))
        advice.append(c - b)
        advice_cpu.append(c_cpu - b_cpu)
        fix.append(c - a)
        fix_cpu.append(c_cpu - a_cpu)
    per_parse, per_update = 1e6 * t_parse / n_readings, 1e6 * t_update / n_readings
    v, v_cpu, a, a_cpu, f, f_cpu = (1e3 * np.array(x) for x in (views, views_cpu, advice, advice_cpu, fix, fix_cpu))

    def pct(x: np.ndarray) -> str:
        return f"p50 {np.percentile(x, 50):.3f} p99 {np.percentile(x, 99):.3f} ms"

    print(f"{path.name}: {len(snapshots)} snapshots, {n_readings} group readings timed (after the first {WARM} snapshots)")
    print(f"   parse {per_parse:.1f} us, history update {per_update:.1f} us per reading per group "
          f"(ratio {per_update / per_parse:.2f}; target <= 50 us)")
    print(f"   light_view {pct(v)}; advise() {pct(a)} (target p99 <= 0.5 ms); a fix, 2 views + advise() {pct(f)}")
    print(f"   CPU time: light_view {pct(v_cpu)}; advise() {pct(a_cpu)}; a fix {pct(f_cpu)}; load {os.getloadavg()[0]:.1f} "
          f"on {os.cpu_count()} cores")


def main(argv: list[str]) -> int:
    paths = [Path(p) for p in argv] or sorted(SHARED.glob("*.csv.gz"))
    if not paths:
        print("bench_predictor: no recordings (../shared/data/spat)")
        return 0
    for p in paths:
        bench(p)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
