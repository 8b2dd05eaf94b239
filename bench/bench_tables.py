"""Lookup tables for any plan: build time and memory on a 10-light corridor with distinct plans, and
advise() latency with them, against the paper corridor's tables measured in the same run.

Run: .venv/bin/python bench/bench_tables.py [--workers N] [--seed S]

* A 10-light corridor (spacing 150-450 m, limit 55 mph), every light its own plan: cycles drawn from
  60, 70, 80, 90, 100, 110, 120 s, red share 35-60 %, amber 3-4 s, random offsets. Targets: built in < 30 s
  on 2 cores, < 200 MB (tables held, and the build's traced peak; the process's max RSS is printed with its
  level before the build, numba and the libraries included).
* advise() over the observations of a closed-loop drive through those 10 lights with their tables, and
  through the paper's [15 15] s = 400 m with its tables: p50 / p99 (target p99 < 0.5 ms, unchanged).
* The OSM import of the shared West Oakland extract (if present): time and what it found.
"""

from __future__ import annotations

import argparse
import resource
import sys
import time
import tracemalloc
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from advisory.advice.advisor import advise  # noqa: E402
from advisory.advice.views import AdvisorMemory  # noqa: E402
from advisory.advice.tables import AdviceTables, TableGrid, paper_offsets_s  # noqa: E402
from advisory.drivers.closed_loop import observe, red_light_violations, simulate  # noqa: E402
from advisory.physics.params import model_params  # noqa: E402
from advisory.signals import FixedTimeSignal, Scenario, paper_scenario  # noqa: E402

PARAMS = model_params()
REPO = Path(__file__).resolve().parents[1]
SHARED_OSM = next((p for p in (REPO.parent / "shared", REPO.parents[1] / "shared") if p.is_dir()), REPO.parent / "shared") / "data" / "osm" / "west-oakland.osm.bz2"


def ten_lights(seed: int) -> Scenario:
    rng = np.random.default_rng(seed)
    positions = np.round(np.cumsum(rng.uniform(150.0, 450.0, 10)), 1)
    signals = []
    for x in positions:
        cycle = float(rng.choice([60, 70, 80, 90, 100, 110, 120]))
        amber = float(rng.choice([3, 4]))
        red = float(round(rng.uniform(0.35, 0.6) * cycle))
        signals.append(FixedTimeSignal(float(x), float(rng.integers(0, int(cycle))), red, cycle - red))  # amber counts as green
    return Scenario("ten", tuple(signals), float(positions[-1] + 100.0))


def latency_ms(sc: Scenario, tables: AdviceTables, repeats: int = 20) -> tuple[np.ndarray, float]:
    run = simulate(sc, tables=tables)
    obs = [observe(sc, t, float(run.trajectory.position_at(t)), float(run.trajectory.speed_at(t))) for t, _ in run.advice]
    memory = AdvisorMemory()
    for o in obs:  # warm up
        memory = advise(o, memory, None, tables)[1]
    lat = []
    for _ in range(repeats):
        memory = AdvisorMemory()
        for o in obs:
            t1 = time.perf_counter()
            _, memory = advise(o, memory, None, tables)
            lat.append(time.perf_counter() - t1)
    share = np.mean([a.source == "dp_table" for _, a in run.advice if a.target_speed_mps is not None])
    assert not red_light_violations(run.trajectory, sc)
    return np.array(lat) * 1e3, float(share)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--seed", type=int, default=7)
    args = ap.parse_args()

    # compile / load the numba kernels outside the measurement
    AdviceTables.build(paper_scenario(15, 15, 200), PARAMS, TableGrid(), workers=1)

    sc = ten_lights(args.seed)
    cycles = [s.cycle_s for s in sc.signals]
    print(f"10-light corridor: {sc.zone_length_m:.0f} m, cycles {[int(c) for c in cycles]} s, spacing "
          f"{np.diff([0.0] + [s.position_m for s in sc.signals]).round().astype(int).tolist()} m")  # fmt: skip
    rss0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e3
    tracemalloc.start()
    t0, cpu0 = time.perf_counter(), time.process_time()
    tables = AdviceTables.build(sc, PARAMS, TableGrid(), workers=args.workers)
    build_s, cpu_s = time.perf_counter() - t0, time.process_time() - cpu0
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    rss1 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e3
    periods = [int(t.period_s) for ts in tables.tables for t in ts if t.is_pair]
    print(f"  tables: {tables.n_tables} ({len(periods)} pair tables, joint periods {periods} s) built in {build_s:.1f} s on {args.workers} "
          f"thread(s) ({cpu_s:.1f} s of CPU; target < 30 s on 2 cores); held {tables.nbytes / 1e6:.1f} MB, build peak {peak / 1e6:.1f} MB traced "
          f"(target < 200 MB); process max RSS {rss1:.0f} MB ({rss0:.0f} MB before the build)")  # fmt: skip

    t0 = time.perf_counter()
    paper = AdviceTables.build(paper_scenario(15, 15, 400), PARAMS, TableGrid(), paper_offsets_s(), workers=args.workers)
    print(f"  paper corridor s = 400 m, 4 offsets: {paper.n_tables} tables, {paper.nbytes / 1e6:.1f} MB, {time.perf_counter() - t0:.1f} s")

    lat10, share10 = latency_ms(sc, tables)
    latp, sharep = latency_ms(paper_scenario(15, 15, 400), paper)
    print(f"advise() with tables, 10 lights: p50 {np.percentile(lat10, 50):.3f} ms, p99 {np.percentile(lat10, 99):.3f} ms "
          f"({lat10.size} calls, {100 * share10:.0f} % of targets from the tables)")  # fmt: skip
    print(f"advise() with tables, paper [15 15] s = 400: p50 {np.percentile(latp, 50):.3f} ms, p99 {np.percentile(latp, 99):.3f} ms "
          f"({100 * sharep:.0f} % from the tables); p99 ratio 10 lights / paper {np.percentile(lat10, 99) / np.percentile(latp, 99):.2f} "
          f"(target p99 < 0.5 ms)")  # fmt: skip

    if SHARED_OSM.exists():
        from spat_feed.road.osm import corridors_from_osm

        t0 = time.perf_counter()
        result = corridors_from_osm(SHARED_OSM, "7th Street")
        dt = time.perf_counter() - t0
        for c in result.corridors:
            print(f"OSM import {SHARED_OSM.name} '7th Street' ({dt:.2f} s): {c.name} {c.length_m:.0f} m, {c.units}, lights at "
                  f"{[ix.stop_line_m for ix in c.intersections]} m, limit {c.zone_speed_limit_mps():.2f} m/s")  # fmt: skip
        for note in result.notes:
            print(f"  note: {note}")


if __name__ == "__main__":
    main()
