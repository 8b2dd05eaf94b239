"""`ecodrive spat-eval LOG [--json]`: the advisor on a recorded controller, judged on what really happened.

The log (the ``../shared/data/spat`` CSV format) is replayed through the whole advisory path: its rows become
J2735 movement states (:func:`spat_feed.transport.recorded.read_spat_csv`), each second's state becomes a plan
(:func:`spat_feed.timing.messages.plan_from_movement`) and a :class:`~spat_feed.prediction.observe.PlanReading` (fresh while
the last snapshot is under ``stale_after_s`` old), the advisor's observation comes from
:func:`spat_feed.prediction.observe.light_view`, and the virtual driver of :func:`advisory.drivers.closed_loop.simulate`
follows the advice, seeing the light's real colour. The source has watched the log from its start: each
intersection's :class:`~spat_feed.prediction.observe.IntersectionHistory` (what the advisor knows of the phases after the
published one: each group's durations, and the changes of other groups its phases follow) holds every snapshot up
to the reading's. The truth is the log itself: a phase switches midway
between the last snapshot in it and the first after it; red is every J2735 stop state (unavailable and dark
are not red: one recording publishes the non-red state of some groups as unavailable). Amber (J2735 clearance)
is green for the rules and a warning to the driver's eye, who stops at it if that takes at most 4 m/s²; a
group whose log never shows amber is given :data:`AMBER_S` before each red.

Approaches: each signal group in turn as the one light (entry ``approach_m`` before its stop line, zone end
``exit_m`` past it), and pairs of groups in series as a two-light corridor (``spacing_m`` apart), entered at
the limit at instants spread evenly over the recording. Each is scored against the paper's regular driver
on the same truth and against a DP that knows the truth (``hindsight``; 20 m stages, see below).

Output keys: ``approaches``, ``red_entries`` (advised crossings while the recorded phase is red),
``hard_brakes`` (runs that needed more than 4 m/s²), ``saving_frac`` (mean cost saving against the regular
driver), ``hindsight_saving_frac`` (the DP's), ``kept_frac`` (their ratio), ``worst_cost_frac`` (the
costliest approach against the regular driver), ``advice_availability_frac`` (share of approach seconds with
speed advice), ``time_lost_s`` (mean, against the regular driver), and the same per kind (single / pair).

The hindsight DP is :func:`advisory.drivers.closed_loop.hindsight_optimum`; approaches where it fails are left out
of the hindsight mean (``hindsight_invalid``). 20 m stages instead of the study's 10 m keep a recording within
minutes on two cores; at 20 m the DP costs ~0.5 % more (a slightly lenient yardstick).
"""

from __future__ import annotations

import argparse
import json
import math
import multiprocessing as mp
import sys
from collections.abc import Sequence
from dataclasses import dataclass, replace
from functools import lru_cache

import numpy as np

from advisory.advice.advisor import AdvisorParams, LightView, Observation
from advisory.drivers.closed_loop import DriverModel, hindsight_optimum, red_light_violations, simulate
from advisory.drivers.regular import regular_driver
from advisory.evaluation.endstate import score_in_end_state
from advisory.optimizer.dp import GridSpec
from advisory.physics.params import model_params
from advisory.signals import Scenario, TimelineSignal
from spat_feed.road.corridors import IntersectionSpec, SignalGroupSpec
from spat_feed.timing.messages import MovementState, plan_from_movement, to_unix_s
from spat_feed.prediction.observe import CycleStats, IntersectionHistory, PlanReading, light_view
from spat_feed.timing.plans import STOP_STATES, PhaseClass, phase_class

HINDSIGHT_GRID = GridSpec(stage_m=20.0)
HARD_BRAKE_MPS2 = 4.0
AMBER_S = 3.0
"""Amber before each red of a group whose log never shows one (Belgian urban signals: 3 s at 50 km/h). [s]"""


@dataclass(frozen=True, slots=True)
class Setup:
    """Approach geometry and sampling. Units in names."""

    speed_limit_mps: float = 50 / 3.6  # an urban arterial
    approach_m: float = 300.0
    spacing_m: float = 300.0
    exit_m: float = 100.0
    every_s: float = 180.0  # single-light entries this far apart (pairs twice as far)
    horizon_s: float = 240.0  # an approach needs this much recording after its entry
    stale_after_s: float = 3.0


@dataclass
class GroupLog:
    """One signal group's snapshots: times [Unix s] and J2735 movement states, and its truth."""

    key: tuple[int, int]  # (intersection id, signal group)
    t_s: np.ndarray
    movements: list[MovementState]
    truth: TimelineSignal  # position 0: placed by the approach
    plans: list = None  # each snapshot read as a receiver does (plan_from_movement)
    cycles: list = None  # what the receiver had learnt of the group by then (IntersectionHistory), one per snapshot

    def reading(self, t_s: float, stale_after_s: float) -> PlanReading | None:
        """What the SPaT source holds at ``t_s``: the latest snapshot, aged, with the history learnt so far."""
        i = int(np.searchsorted(self.t_s, t_s, side="right")) - 1
        if i < 0:
            return None
        age = t_s - float(self.t_s[i])
        return PlanReading(self.plans[i], fresh=age <= stale_after_s, age_s=age, cycle=self.cycles[i])


def group_logs(snapshots) -> list[GroupLog]:
    """Per (intersection, signal group): its snapshots and the truth (switches midway between snapshots)."""
    rows: dict[tuple[int, int], list[tuple[float, MovementState, object, CycleStats]]] = {}
    histories: dict[int, IntersectionHistory] = {}
    for ix in snapshots:  # read as a receiver does: each message's plans, and what was learnt by then
        t = to_unix_s(ix.timestamp)
        plans = {}
        for m in ix.states:
            plans.setdefault(m.signal_group, plan_from_movement(m, t))
        history = histories.setdefault(ix.id, IntersectionHistory())
        history.record(t, plans)
        for m in ix.states:
            rows.setdefault((ix.id, m.signal_group), []).append((t, m, plans[m.signal_group], history.stats(m.signal_group)))
    out = []
    for key, items in sorted(rows.items()):
        t = np.array([r[0] for r in items])
        red = np.array([r[1].state_time_speed[0].event_state in STOP_STATES for r in items])
        reds, start = [], (-math.inf if red[0] else None)
        for i in range(1, len(items)):
            if red[i] != red[i - 1]:
                mid = 0.5 * (t[i - 1] + t[i])
                if red[i]:
                    start = mid
                else:
                    reds.append((start, mid))
                    start = None
        if start is not None:
            reds.append((start, math.inf))
        amber = np.array([phase_class(r[1].state_time_speed[0].event_state) is PhaseClass.AMBER for r in items])
        edges = np.flatnonzero(np.diff(amber.astype(int))) + 1  # snapshots where amber begins or ends
        mids = [-math.inf] + [0.5 * (t[i - 1] + t[i]) for i in edges] + [math.inf]
        ambers = tuple((mids[k], mids[k + 1]) for k in range(len(mids) - 1) if amber[0 if k == 0 else edges[k - 1]])
        if not amber.any():  # a group that never publishes its amber (its non-red state as unavailable): it had one
            ends = [-math.inf] + [b for _, b in reds]
            ambers = tuple((max(a - AMBER_S, e), a) for (a, _), e in zip(reds, ends) if math.isfinite(a))
        out.append(GroupLog(key, t, [r[1] for r in items], TimelineSignal(0.0, tuple(reds), ambers), [r[2] for r in items], [r[3] for r in items]))
    return out


_LOGS: list[GroupLog] = []


@lru_cache(maxsize=64)
def _spec(n: int, position_m: float) -> IntersectionSpec:
    return IntersectionSpec(id=n + 1, name=f"light {n + 1}", stop_line_m=position_m, lat_deg=0.0, lon_deg=0.0,
                            approach_heading_deg=0.0, signal_groups=(SignalGroupSpec(id=1),))  # fmt: skip


def approach(job: tuple[tuple[int, ...], float, Setup]) -> dict | None:
    """One approach: groups ``job[0]`` in series entered at Unix time ``job[1]``; None if the truth runs out."""
    groups, entry_s, setup = job
    v_lim = setup.speed_limit_mps
    positions = [setup.approach_m + k * setup.spacing_m for k in range(len(groups))]
    zone_m = positions[-1] + setup.exit_m
    truths = tuple(replace(_LOGS[g].truth.shifted(entry_s), position_m=p) for g, p in zip(groups, positions))
    if any(not math.isfinite(s.next_green_start_s(setup.horizon_s)) for s in truths):
        return None
    scenario = Scenario("+".join(str(_LOGS[g].key[1]) for g in groups), truths, zone_m, v_lim, v_lim)

    def feed(t_s: float, x_m: float, v_mps: float) -> Observation:
        views: list[LightView] = []
        for n, (g, p) in enumerate(zip(groups, positions)):
            if p > x_m and len(views) < 2:
                reading = _LOGS[g].reading(entry_s + t_s, setup.stale_after_s)
                views.append(light_view(_spec(n, p), reading, x_m, entry_s + t_s))
        return Observation(v_mps, v_lim, tuple(views), position_m=x_m)

    params = model_params()
    run = simulate(scenario, AdvisorParams(units="kmh"), None, DriverModel(), feed=feed)
    regular = regular_driver(scenario)
    reg = score_in_end_state(regular, params, v_lim)
    adv = score_in_end_state(run.trajectory, params, v_lim)
    at_m = np.interp([t for t, _ in run.advice], run.trajectory.t_s, run.trajectory.x_m)
    ahead = [a for (_, a), x in zip(run.advice, at_m) if x < positions[-1]]
    out = {
        "kind": "single" if len(groups) == 1 else "pair",
        "groups": [int(_LOGS[g].key[1]) for g in groups],
        "entry_unix_s": entry_s,
        "red_entry": bool(red_light_violations(run.trajectory, scenario)),
        "hard_brake": bool(run.trajectory.accel_mps2.min() < -HARD_BRAKE_MPS2 - 1e-9),
        "saving_frac": 1.0 - adv.cost_usd / reg.cost_usd,
        "time_lost_s": adv.time_s - reg.time_s,
        "advice_s": int(sum(a.target_speed_mps is not None for a in ahead)),
        "approach_s": len(ahead),
        "hindsight_saving_frac": None,
    }
    best = hindsight_optimum(scenario, params, HINDSIGHT_GRID, regular)
    if best is not None:
        out["hindsight_saving_frac"] = 1.0 - score_in_end_state(best, params, v_lim).cost_usd / reg.cost_usd
    return out


def jobs(logs: Sequence[GroupLog], setup: Setup) -> list:
    """Single groups every ``every_s``, and each group with the next one as a pair every ``2 every_s``."""
    t0 = max(float(g.t_s[0]) for g in logs) + 5.0
    t1 = min(float(g.t_s[-1]) for g in logs) - setup.horizon_s
    out = []
    for n in range(len(logs)):
        out += [((n,), float(t), setup) for t in np.arange(t0 + n * setup.every_s / len(logs), t1, setup.every_s)]
    for n in range(len(logs) - 1):
        out += [((n, n + 1), float(t), setup) for t in np.arange(t0 + n * setup.every_s / len(logs), t1, 2 * setup.every_s)]
    return out


def summarize(rows: list[dict]) -> dict:
    """The JSON keys (see the module) over ``rows``."""
    if not rows:
        return {"approaches": 0}
    hind = [r for r in rows if r["hindsight_saving_frac"] is not None]
    saving = float(np.mean([r["saving_frac"] for r in rows]))
    hindsight = float(np.mean([r["hindsight_saving_frac"] for r in hind])) if hind else float("nan")
    return {
        "approaches": len(rows),
        "red_entries": int(sum(r["red_entry"] for r in rows)),
        "hard_brakes": int(sum(r["hard_brake"] for r in rows)),
        "saving_frac": saving,
        "hindsight_saving_frac": hindsight,
        "kept_frac": saving / hindsight if hind and hindsight > 0 else None,
        "kept_frac_same_approaches": float(np.mean([r["saving_frac"] for r in hind]) / hindsight) if hind and hindsight > 0 else None,
        "hindsight_invalid": len(rows) - len(hind),
        "worst_cost_frac": float(max(-r["saving_frac"] for r in rows)),
        "costlier_than_regular_by_10pct": int(sum(r["saving_frac"] < -0.10 for r in rows)),
        "advice_availability_frac": float(sum(r["advice_s"] for r in rows) / max(sum(r["approach_s"] for r in rows), 1)),
        "time_lost_s": float(np.mean([r["time_lost_s"] for r in rows])),
        "worst_time_lost_s": float(max(r["time_lost_s"] for r in rows)),
    }


def _read_head(path: str, limit_s: float) -> list:
    """The snapshots of the log's first ``limit_s`` seconds, reading no further."""
    import csv
    import gzip

    from spat_feed.transport.recorded import iter_spat_csv

    out = []
    with (gzip.open(path, "rt", encoding="utf-8", newline="") if str(path).endswith(".gz") else open(path, encoding="utf-8", newline="")) as fh:
        for ix in iter_spat_csv(csv.DictReader(fh), source=str(path)):
            if out and (ix.timestamp - out[0].timestamp).total_seconds() > limit_s:
                break
            out.append(ix)
    return sorted(out, key=lambda ix: ix.timestamp)


def evaluate_log(path: str, setup: Setup | None = None, workers: int = 2, limit_s: float | None = None, progress: bool = True) -> dict:
    """Replay the log at ``path`` (optionally only its first ``limit_s`` seconds); the summary and its rows."""
    from tqdm import tqdm

    from spat_feed.transport.recorded import read_spat_csv

    global _LOGS
    setup = setup or Setup()
    snapshots = read_spat_csv(path) if limit_s is None else _read_head(path, limit_s)
    _LOGS = group_logs(snapshots)
    todo = jobs(_LOGS, setup)
    bar = dict(total=len(todo), desc=f"spat-eval {path.rsplit('/', 1)[-1]}", disable=not progress, file=sys.stderr)
    if workers > 1:
        with mp.get_context("fork").Pool(workers) as pool:
            rows = list(tqdm(pool.imap(approach, todo, chunksize=4), **bar))
    else:
        rows = [approach(j) for j in tqdm(todo, **bar)]
    rows = [r for r in rows if r is not None]
    out = {"log": path, **summarize(rows)}
    out["by_kind"] = {k: summarize([r for r in rows if r["kind"] == k]) for k in ("single", "pair")}
    out["setup"] = {k: getattr(setup, k) for k in Setup.__slots__}
    return out


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="ecodrive spat-eval", description=__doc__.split("\n\n")[0])
    ap.add_argument("logs", nargs="+", metavar="LOG", help="recorded SPaT CSV (.csv or .csv.gz), the shared format")
    ap.add_argument("--json", action="store_true", help="print the summary as JSON")
    ap.add_argument("--every-s", type=float, default=Setup().every_s, help="seconds between single-light entries (default %(default)s)")
    ap.add_argument("--limit-s", type=float, default=None, help="use only the first seconds of each log")
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args(argv)
    from spat_feed.transport.recorded import RecordedLogError

    results = []
    for path in args.logs:
        try:
            results.append(evaluate_log(path, Setup(every_s=args.every_s), args.workers, args.limit_s, progress=True))
        except (OSError, RecordedLogError) as exc:
            print(f"ecodrive spat-eval: {exc}", file=sys.stderr)
            return 2
    if args.json:
        print(json.dumps(results[0] if len(results) == 1 else results, indent=2))
        return 0
    for r in results:
        print(f"{r['log']}: {r['approaches']} approaches; red entries {r['red_entries']}, hard brakes {r['hard_brakes']}; "
              f"saving {100 * r['saving_frac']:.1f} % vs hindsight DP {100 * r['hindsight_saving_frac']:.1f} % "
              f"(kept {100 * (r['kept_frac'] or 0):.0f} %); worst {100 * r['worst_cost_frac']:+.1f} % cost; "
              f"speed advice {100 * r['advice_availability_frac']:.0f} % of approach seconds; time lost {r['time_lost_s']:+.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
