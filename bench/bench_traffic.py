"""Bench and figure of issue 28: the 18-scenario matrix of `ecodrive traffic-eval` for a corridor, and saving
against demand, one line per penetration, ecodrive and SUMO's GLOSA (``use-queue`` on).

Run: .venv/bin/python bench/bench_traffic.py [--corridor NAME ...] [--group CONTROL/DEMAND/PEN ...] [--seeds N] [--first-seed K] [--jobs J] [--out FILE.jsonl] [--figure]
     .venv/bin/python bench/bench_traffic.py --figure-only FILE.jsonl [FILE.jsonl ...]

A scenario is (corridor, control fixed|actuated, demand 300|600|900 veh/h per lane, penetration 10|50|100 %, seed):
18 per corridor and seed, each run three ways (advised, GLOSA, unadvised; ``ecodrive.traffic_eval.evaluate``).
``--jobs`` scenarios run at once in worker processes (default 2: the issue's budget is 10 minutes on 2 cores for one
corridor's 18). Each finished scenario is one JSON line in ``--out`` (default ``bench/traffic_matrix.jsonl``), so a
long matrix can be built in parts and ``--figure-only`` draws them. ``--group actuated/900/0.5`` (repeatable) runs only
those groups of the matrix: a change judged on a few groups with more seeds (on actuated lights five seeds pin a
group's mean to about +-5 points). Prints per row the keys the issue's targets are
about, the targets' verdicts over the rows, and the wall time; ``--figure`` (or ``--figure-only``) writes
docs/figures/traffic_saving.png: mean saving over seeds against demand, one panel per corridor and control.
"""

from __future__ import annotations

import argparse
import itertools
import json
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

DEMANDS_VPH = (300.0, 600.0, 900.0)
PENETRATIONS = (0.1, 0.5, 1.0)
CONTROLS = ("fixed", "actuated")
FIGURE = ROOT / "docs" / "figures" / "traffic_saving.png"
KEYS = ("advised_cars", "red_entries", "hard_brakes", "saving_frac", "glosa_saving_frac", "stops_per_advised_car", "stops_per_glosa_car",
        "stops_per_unadvised_car", "time_change_frac", "others_time_change_frac", "others_energy_change_frac")  # fmt: skip


def scenario(args: tuple) -> dict:
    """One scenario's summary (``evaluate``'s keys) with its setup; runs in a worker process."""
    from ecodrive.traffic_eval import evaluate

    corridor, control, demand, penetration, seed = args
    return evaluate(corridor, None, control, demand, penetration, seed)


def _pct(x) -> str:
    return "   n/a" if x is None else f"{100 * x:+6.1f}"


def row_text(r: dict) -> str:
    s = r["setup"]
    return (f"{s['corridor'][:22]:22s} {s['control']:8s} {s['demand_vph_per_lane']:4.0f} {s['penetration_frac']:4.1f} {s['seed']:2d} | "
            f"cars {r['advised_cars']:3d} red {r['red_entries']} hard {r['hard_brakes']:2d} | saving {_pct(r['saving_frac'])} glosa {_pct(r['glosa_saving_frac'])} | "
            f"stops {r['stops_per_advised_car']:.2f}/{r['stops_per_glosa_car']:.2f}/{r['stops_per_unadvised_car']:.2f} | time {_pct(r['time_change_frac'])} "
            f"others {_pct(r['others_time_change_frac'])} | {r['wall_s']:5.1f} s")  # fmt: skip


def verdicts(rows: list[dict]) -> list[str]:
    """The issue's targets over ``rows``: per (corridor, control, demand, penetration), means over seeds."""
    import numpy as np

    groups: dict[tuple, list[dict]] = {}
    for r in rows:
        s = r["setup"]
        groups.setdefault((s["corridor"], s["control"], s["demand_vph_per_lane"], s["penetration_frac"]), []).append(r)

    def mean(rs, k):
        vals = [r[k] for r in rs if r[k] is not None]
        return float(np.mean(vals)) if vals else None

    out = []
    out.append(f"red entries: {sum(r['red_entries'] for r in rows)} in {len(rows)} runs (target 0)")
    out.append(f"hard brakes: {sum(r['hard_brakes'] for r in rows)} in {len(rows)} runs, runs with any {sum(r['hard_brakes'] > 0 for r in rows)} (target 0)")
    above = [(k, mean(g, "saving_frac"), mean(g, "glosa_saving_frac")) for k, g in groups.items()]
    out.append(f"more than GLOSA (mean over seeds): {sum(a > b for _, a, b in above)} of {len(above)} groups")
    out.append(f"never costlier than unadvised: {sum(a >= 0 for _, a, _ in above)} of {len(above)} groups")
    for demand, target in ((300.0, 0.15), (600.0, 0.08)):
        got = [(k, a) for k, a, _ in above if k[2] == demand]
        out.append(f"saving >= {100 * target:.0f} % at {demand:.0f} veh/h: {sum(a >= target for _, a in got)} of {len(got)} groups "
                   f"({', '.join(f'{k[0][:9]} {k[1][:3]} {k[3]:g}: {100 * a:.1f}' for k, a in got)})")  # fmt: skip
    others = [(k, mean(g, "others_time_change_frac")) for k, g in groups.items()]
    others = [(k, o) for k, o in others if o is not None]
    out.append(f"others' time <= +2 %: {sum(o <= 0.02 for _, o in others)} of {len(others)} groups; worst "
               + ", ".join(f"{k[0][:9]} {k[1][:3]} {k[2]:.0f} {k[3]:g}: {100 * o:+.1f} %" for k, o in sorted(others, key=lambda x: -x[1])[:4]))
    return out


def figure(rows: list[dict], path: Path = FIGURE) -> Path:
    """Mean saving over seeds against demand; a panel per (corridor, control); per penetration ecodrive (solid) and
    GLOSA (dashed)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    panels = sorted({(r["setup"]["corridor"], r["setup"]["control"]) for r in rows})
    fig, axes = plt.subplots(1, len(panels), figsize=(4.2 * len(panels), 3.6), sharey=True, squeeze=False)
    colours = {0.1: "tab:blue", 0.5: "tab:orange", 1.0: "tab:green"}
    for ax, (corridor, control) in zip(axes[0], panels):
        mine = [r for r in rows if (r["setup"]["corridor"], r["setup"]["control"]) == (corridor, control)]
        seeds = sorted({r["setup"]["seed"] for r in mine})
        for pen in sorted({r["setup"]["penetration_frac"] for r in mine}):
            for key, style, who in (("saving_frac", "-o", "ecodrive"), ("glosa_saving_frac", "--s", "GLOSA")):
                xs, ys = [], []
                for demand in sorted({r["setup"]["demand_vph_per_lane"] for r in mine}):
                    vals = [r[key] for r in mine if r["setup"]["penetration_frac"] == pen and r["setup"]["demand_vph_per_lane"] == demand and r[key] is not None]
                    if vals:
                        xs.append(demand)
                        ys.append(100.0 * float(np.mean(vals)))
                ax.plot(xs, ys, style, color=colours.get(pen, "k"), label=f"{who}, {100 * pen:g} %", markersize=4)
        ax.axhline(0.0, color="0.6", lw=0.8)
        ax.set_title(f"{corridor}, {control} ({len(seeds)} seed{'s' if len(seeds) > 1 else ''})", fontsize=9)
        ax.set_xlabel("demand [veh/h per lane]")
        ax.set_xticks(DEMANDS_VPH)
    axes[0][0].set_ylabel("saving against the same cars unadvised [%]")
    axes[0][-1].legend(fontsize=7, loc="best")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    return path


def _group(text: str) -> tuple[str, float, float]:
    """``"actuated/900/0.5"`` -> ``("actuated", 900.0, 0.5)``."""
    try:
        control, demand, penetration = text.split("/")
        if control not in CONTROLS:
            raise ValueError(f"control {control!r} is not one of {CONTROLS}")
        return control, float(demand), float(penetration)
    except ValueError as e:
        raise argparse.ArgumentTypeError(f"{text!r}: expected CONTROL/DEMAND/PEN, e.g. actuated/900/0.5 ({e})") from None


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--corridor", action="append", help="corridor(s) (default paper_s400)")
    ap.add_argument("--seeds", type=int, default=1, help="seeds 1..N (default %(default)s)")
    ap.add_argument("--first-seed", type=int, default=1, help="start at this seed: seeds FIRST..N, to add seeds to a matrix in parts")
    ap.add_argument("--group", action="append", type=_group, metavar="CONTROL/DEMAND/PEN",
                    help="only this group of the matrix, e.g. actuated/900/0.5 (repeatable; default all 18)")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--out", type=Path, default=ROOT / "bench" / "traffic_matrix.jsonl")
    ap.add_argument("--figure", action="store_true", help="draw docs/figures/traffic_saving.png from --out afterwards")
    ap.add_argument("--figure-only", nargs="+", type=Path, metavar="JSONL", help="draw the figure from these files; run nothing")
    args = ap.parse_args(argv)
    if args.figure_only:
        rows = [json.loads(line) for p in args.figure_only for line in p.read_text().splitlines() if line.strip()]
        print("\n".join(verdicts(rows)))
        print(f"figure: {figure(rows)}")
        return 0
    groups = args.group or list(itertools.product(CONTROLS, DEMANDS_VPH, PENETRATIONS))
    todo = [(c, *g, seed) for c in args.corridor or ["paper_s400"] for g in groups for seed in range(args.first_seed, args.seeds + 1)]
    started = time.perf_counter()
    rows = []
    with ProcessPoolExecutor(max_workers=max(args.jobs, 1)) as pool, args.out.open("a", encoding="utf-8") as out:
        for r in pool.map(scenario, todo):
            rows.append(r)
            out.write(json.dumps({k: r[k] for k in (*KEYS, "glosa_time_change_frac", "glosa_others_time_change_frac", "setup", "wall_s")}) + "\n")
            out.flush()
            print(row_text(r), flush=True)
    wall = time.perf_counter() - started
    print(f"{len(todo)} scenarios in {wall:.0f} s ({args.jobs} jobs)")
    print("\n".join(verdicts(rows)))
    if args.figure:
        print(f"figure: {figure([json.loads(line) for line in args.out.read_text().splitlines() if line.strip()])}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
