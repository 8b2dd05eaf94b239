"""What is reachable in traffic (issue 28's saving floors): per group, ours, GLOSA and the hindsight bound over the
same connected cars.

Run: .venv/bin/python bench/bench_traffic_bound.py --corridor paper_s400 --group fixed/300/0.1 [--group ...] [--seeds 5] [--out FILE.jsonl]
     .venv/bin/python bench/bench_traffic_bound.py --summary-only FILE.jsonl [FILE.jsonl ...]

Each scenario runs as ``ecodrive traffic-eval`` does (``evaluate``, advised / GLOSA / unadvised), with each connected
car's hindsight bound (``ecodrive.traffic_eval.hindsight_summary``): the DP that knows the lights of the unadvised
run, from the car's insertion to the zone's end, within its own unadvised time, alone on the road
(``ecodrive.traffic.hindsight``). Per group, means over seeds of: ``bound`` (the DP against the same cars unadvised),
``bound_alone`` (the car in its own SUMO run, alone on the road, against its bound), ``bound_from_approach`` (the
car's own drive up to where the service begins to advise, the DP from there), ``bound_advisable`` (that, and no line
within the advisor's 2 s after a red ends), ``bound_behind`` (that, a car's length behind the car ahead as it drove
unadvised, at every 10 m stage), ``ours`` and ``glosa`` over the same cars, ``bound_free`` (only the cars
whose DP drive does not run into the car ahead as it drove unadvised) and the share of cars whose DP does.
``--bound-only``: the unadvised run and the bounds alone (a car's bound does not depend on the other runs); ours and
GLOSA then come from ``--matrix`` (bench_traffic.py's rows of the same seeds, every connected car: the same cars). One JSON line per scenario in ``--out`` (default
``bench/traffic_bound.jsonl``, with the per-car rows), and the group table as JSON on the last line printed.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench.bench_traffic import _group  # noqa: E402

COLUMNS = (
    ("ours", "hindsight_ours_saving_frac"),
    ("glosa", "hindsight_glosa_saving_frac"),
    ("bound", "hindsight_saving_frac"),
    ("bound_alone", "hindsight_alone_saving_frac"),
    ("bound_from_approach", "hindsight_from_approach_saving_frac"),
    ("bound_advisable", "hindsight_advisable_saving_frac"),
    ("bound_behind", "hindsight_behind_saving_frac"),
    ("bound_free", "hindsight_free_saving_frac"),
)
"""(name in the table, the scenario's key): means over seeds."""


def scenario(corridor: str, control: str, demand: float, penetration: float, seed: int, bound_only: bool) -> dict:
    from ecodrive.traffic_eval import evaluate

    return evaluate(corridor, None, control, demand, penetration, seed, hindsight=True, bound_only=bound_only)


def group_table(rows: list[dict], matrix: list[dict] = ()) -> list[dict]:
    """Per (corridor, control, demand, penetration): the means over seeds of :data:`COLUMNS`, the cars counted, the
    share whose DP runs into the car ahead, and from ``matrix`` (bench_traffic.py's rows) the same seeds' ``saving_frac``
    and ``glosa_saving_frac`` (every connected car)."""
    import numpy as np

    groups: dict[tuple, list[dict]] = {}
    for r in rows:
        s = r["setup"]
        groups.setdefault((s["corridor"], s["control"], s["demand_vph_per_lane"], s["penetration_frac"]), []).append(r)
    out = []
    for (corridor, control, demand, pen), rs in sorted(groups.items()):
        g = {"corridor": corridor, "control": control, "demand_vph_per_lane": demand, "penetration_frac": pen, "seeds": len(rs),
             "cars": sum(r["hindsight_cars"] for r in rs)}
        for name, key in COLUMNS:
            vals = [r[key] for r in rs if r.get(key) is not None]
            g[name] = float(np.mean(vals)) if vals else None
        cars = [c for r in rs for c in r["hindsight_rows"] if c["hindsight_cost_usd"] is not None]
        g["runs_into_car_ahead_frac"] = float(np.mean([c["hindsight_runs_into_car_ahead"] for c in cars])) if cars else None
        g["unadvised_stops_per_car"] = float(np.mean([c["unadvised_stops"] for c in cars])) if cars else None
        g["advised_stops_per_car"] = float(np.mean([c["advised_stops"] for c in cars])) if cars and "advised_stops" in cars[0] else None
        mine = [m for m in matrix if (m["setup"]["corridor"], m["setup"]["control"], m["setup"]["demand_vph_per_lane"], m["setup"]["penetration_frac"])
                == (corridor, control, demand, pen) and m["setup"]["seed"] in {r["setup"]["seed"] for r in rs}]  # fmt: skip
        g["matrix_seeds"] = len(mine)
        for name in ("saving_frac", "glosa_saving_frac"):
            g[f"matrix_{name}"] = float(np.mean([m[name] for m in mine])) if mine else None
        out.append(g)
    return out


def _pct(x) -> str:
    return "   n/a" if x is None else f"{100 * x:6.1f}"


def table_text(groups: list[dict]) -> str:
    lines = ["group                                 seeds cars |   ours  glosa  bound b_alon b_appr b_advi b_behi b_free | into ahead | stops unadv | matrix ours glosa"]
    for g in groups:
        lines.append(f"{g['corridor'][:22]:22s} {g['control']:8s} {g['demand_vph_per_lane']:4.0f} {g['penetration_frac']:4.1f} {g['seeds']:2d} {g['cars']:4d} |"
                     + "".join(_pct(g[name]) for name, _ in COLUMNS)
                     + f" | {_pct(g['runs_into_car_ahead_frac'])} % | {g['unadvised_stops_per_car']:.2f}"
                     + f" | {g['matrix_seeds']} {_pct(g['matrix_saving_frac'])} {_pct(g['matrix_glosa_saving_frac'])}")  # fmt: skip
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--corridor", action="append", help="corridor(s) (default paper_s400)")
    ap.add_argument("--group", action="append", type=_group, metavar="CONTROL/DEMAND/PEN", help="e.g. fixed/300/0.1 (repeatable; default fixed/300/0.1)")
    ap.add_argument("--seeds", type=int, default=5, help="seeds 1..N (default %(default)s)")
    ap.add_argument("--bound-only", action="store_true", help="the unadvised run and the bound alone (ours and GLOSA from --matrix)")
    ap.add_argument("--matrix", type=Path, default=ROOT / "docs" / "figures" / "traffic_saving.jsonl", help="bench_traffic.py's rows (default %(default)s)")
    ap.add_argument("--out", type=Path, default=ROOT / "bench" / "traffic_bound.jsonl")
    ap.add_argument("--summary-only", nargs="+", type=Path, metavar="JSONL", help="the group table from these files; run nothing")
    args = ap.parse_args(argv)
    if args.summary_only:
        rows = [json.loads(line) for p in args.summary_only for line in p.read_text().splitlines() if line.strip()]
    else:
        rows = []
        started = time.perf_counter()
        with args.out.open("a", encoding="utf-8") as out:
            for corridor in args.corridor or ["paper_s400"]:
                for control, demand, pen in args.group or [("fixed", 300.0, 0.1)]:
                    for seed in range(1, args.seeds + 1):
                        r = scenario(corridor, control, demand, pen, seed, args.bound_only)
                        rows.append(r)
                        out.write(json.dumps(r) + "\n")
                        out.flush()
                        print(f"{corridor} {control} {demand:g} {pen:g} seed {seed}: cars {r['hindsight_cars']} ours {_pct(r.get('hindsight_ours_saving_frac'))} "
                              f"glosa {_pct(r.get('hindsight_glosa_saving_frac'))} bound {_pct(r['hindsight_saving_frac'])} "
                              f"from approach {_pct(r['hindsight_from_approach_saving_frac'])} ({r['wall_s']:.0f} s)", flush=True)  # fmt: skip
        print(f"{len(rows)} scenarios in {time.perf_counter() - started:.0f} s")
    matrix = [json.loads(line) for line in args.matrix.read_text().splitlines() if line.strip()] if args.matrix.exists() else []
    groups = group_table(rows, matrix)
    print(table_text(groups))
    print(json.dumps(groups))
    return 0


if __name__ == "__main__":
    sys.exit(main())
