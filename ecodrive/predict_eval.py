"""`ecodrive predict-eval LOG [--json] [--plot FILE]`: every phase-end prediction of a recording, scored.

The log (``../shared/data/spat`` CSV, ``.csv`` or ``.csv.gz``) is replayed second by second as the service reads
it: each snapshot's movements become plans (:func:`spat_feed.timing.messages.plan_from_movement`), the
intersection's :class:`~spat_feed.prediction.history.IntersectionHistory` learns from the past only, and at every
snapshot each signal group's current phase gets a forecast (:func:`spat_feed.prediction.predictor.forecast`). When
the phase really ended is the first snapshot that shows another phase class (red, amber, green, unknown), as the
history times it; a change seen only after a gap of more than :data:`MAX_GAP_S` in the group's snapshots is not
scored (when it came is not known).

Keys: ``changes`` (phase ends scored), ``predictions`` (forecasts of them made 0-60 s ahead), ``predicted_frac``
(share of those with a finite likely time), ``mae_s`` (mean absolute error of the likely time, changes 0-60 s ahead,
over the predictions the baseline makes too: the same changes at the same horizons), ``mae_s_all`` (over all of
ours: also the first minutes, before any history, on the controller's window alone), ``mae_s_by_horizon``
(``"0-10"``, ``"10-30"``, ``"30-60"``: by how far ahead the change really was; same predictions as ``mae_s``),
``within_2s_frac`` / ``within_5s_frac`` (all of ours), ``baseline_mae_s`` and ``baseline_mae_s_by_horizon`` (the
median of the past durations of the same group and class from the phase's start, or now once that has passed),
``interval_coverage`` (share of changes inside the forecast's central 50 / 80 / 90 % intervals: keys ``"50"``,
``"80"``, ``"90"``; a change is known only to lie between the last snapshot before it and the first after it, and is
counted by its randomized PIT over that span, :func:`pit_coverage`: a forecast sure of the instant counts its level),
``interval_meets_span_frac`` (the older rule: the closed interval between the two quantiles meets that span; atoms
and the span's leeway make it read high), ``early_red_frac`` (changes to red that came before the forecast's
earliest instant, the hard bound the advisor plans against), ``method_frac`` (share of predictions by method).

Calibration where the advisor relies on it: ``coverage_by_width`` (the forecasts binned by their stated spread, the
width of their central 80 % interval, :data:`WIDTH_BINS_S`) and ``coverage_by_method`` (by ``method``), each bin's
``predictions_frac`` (its share of ours), ``interval_coverage`` (as above) and ``mae_s`` (of all ours in it). A
calibrated forecast holds its levels in every bin; a narrow bin that holds much less is a forecast sure and wrong.
``late_tail`` (:func:`late_tail`): by the class of the phase that ended, then by method and by how far ahead the forecast
put it, the share of changes that came after the forecast's 90 % and 97.5 % quantiles (``after``: the advisor's late
view and last timing; calibrated 10 % and 2.5 %, by the randomized PIT) and, of the readings with a known
``maxEndTime``, the share that came after it (``past_max_end_frac``) against the forecast's own mass there
(``past_max_end_stated_frac``); over every prediction, however far ahead its change came (a cut at 60 s would keep
the early ends of long phases and drop their late ones).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections import Counter
from collections.abc import Sequence

import numpy as np

from spat_feed.prediction.history import LATE_QUANTILE, IntersectionHistory, past_its_events
from spat_feed.prediction.observe import SCENARIO_LEVELS
from spat_feed.prediction.predictor import forecast
from spat_feed.timing.messages import plan_from_movement, to_unix_s
from spat_feed.timing.plans import PhaseClass, phase_class

MAX_GAP_S = 2.0
"""Snapshots further apart than this around a change leave it unscored. [s]"""

HORIZONS_S = {"0-10": (0.0, 10.0), "10-30": (10.0, 30.0), "30-60": (30.0, 60.0)}
SCORED_AHEAD_S = 60.0
"""The error and coverage keys score predictions of changes at most this far ahead (``late_tail`` every one). [s]"""
LIKELY_AHEAD_S = {**HORIZONS_S, ">60": (60.0, math.inf)}
"""Bins of how far ahead a forecast puts its likely time (``late_tail``'s ``by_likely_ahead``: known when it is made,
unlike how far ahead the change was, which picks late changes in the far bins). [s]"""
LEVELS = (0.5, 0.8, 0.9)

WIDTH_BINS_S = {"0-2": (0.0, 2.0), "2-5": (2.0, 5.0), "5-10": (5.0, 10.0), ">10": (10.0, math.inf)}
"""Bins of a forecast's stated spread, the width of its central 80 % interval (``coverage_by_width``): the narrow
ones are the forecasts the advisor takes as sure. [s]"""


def predictions(snapshots) -> dict[tuple[int, int], list[tuple]]:
    """Per (intersection, group): one row per snapshot, ``(t, class, forecast of the current phase's end or None,
    baseline likely end or None, the published maxEndTime of the current phase (``inf``: unknown))``, each made from
    the snapshots up to it."""
    histories: dict[int, IntersectionHistory] = {}
    rows: dict[tuple[int, int], list[tuple]] = {}
    for ix in snapshots:
        t = to_unix_s(ix.timestamp)
        plans = {}
        for m in ix.states:
            plans.setdefault(m.signal_group, plan_from_movement(m, t))
        history = histories.setdefault(ix.id, IntersectionHistory())
        history.record(t, plans)
        for g, plan in plans.items():
            if past_its_events(plan, t):  # no reading of the phase now, as the history takes it
                continue
            stats = history.stats(g)
            i = sum(1 for c in plan.changes if c.max_end_s <= t)
            cls = phase_class(plan.states[i])
            fc = forecast(plan, t, stats)
            durations = stats.durations(cls) if stats is not None else ()
            since = stats.since_unix_s if stats is not None and stats.current is cls else None
            base = max(since + float(np.median(durations)), t) if durations and since is not None else None
            max_end = plan.changes[i].max_end_s if i < len(plan.changes) else math.inf
            rows.setdefault((ix.id, g), []).append((t, cls, fc[0] if fc else None, base, max_end))
    return rows


def scored(rows: dict[tuple[int, int], list[tuple]]) -> list[dict]:
    """One dict per prediction of a change that was seen (no gap around it), however far ahead (:func:`summarize`
    scores those :data:`SCORED_AHEAD_S` ahead at most, but for ``late_tail``: a cut by the outcome would drop late
    changes)."""
    out = []
    for key, items in rows.items():
        start = 0
        for k in range(1, len(items)):
            if items[k][1] is items[k - 1][1]:
                continue
            t_change, cls_before, cls_after = items[k][0], items[k - 1][1], items[k][1]
            if t_change - items[k - 1][0] <= MAX_GAP_S:
                for j in range(start, k):
                    t, cls, fc, base, max_end = items[j]
                    ahead = t_change - t
                    if cls is not cls_before or (j > start and items[j][0] - items[j - 1][0] > MAX_GAP_S):
                        continue
                    row = {"key": key, "t": t, "ahead_s": ahead, "change_unix_s": t_change, "last_before_unix_s": items[k - 1][0], "from": cls_before, "to": cls_after, "base": base, "max_end": max_end}
                    if fc is not None:
                        s = fc.samples_unix_s
                        intervals = {lv: fc.interval(lv) for lv in LEVELS}
                        row.update(likely=fc.likely_unix_s, earliest=fc.earliest_unix_s, method=fc.method, intervals=intervals,
                                   width_s=intervals[0.8][1] - intervals[0.8][0],
                                   pit=tuple(np.searchsorted(s, x + 1e-6, side="right") / len(s) for x in (items[k - 1][0], t_change)),
                                   past_max_end=float(np.count_nonzero(s > max_end + 1e-6)) / len(s))  # fmt: skip
                    out.append(row)
            start = k
    return out


def pit_coverage(pit: tuple[float, float], level: float) -> float:
    """The chance that a change known to lie in ``(last, first]`` (the last snapshot before it, the first after) fell
    inside the forecast's central ``level`` interval: its probability integral transform is uniform on ``pit`` =
    ``(F(last), F(first))``, ``F`` the forecast's distribution function, and the interval is ``[(1 - level) / 2,
    (1 + level) / 2]`` on that scale (the randomized PIT of forecasts with atoms [1]: a forecast sure of the
    instant counts ``level``, not 1). [-]

    References
    ----------
    .. [1] C. Czado, T. Gneiting and L. Held, "Predictive model assessment for count data," Biometrics, vol. 65,
       pp. 1254-1261, 2009, doi:10.1111/j.1541-0420.2009.01191.x.

    Examples
    --------
    >>> pit_coverage((0.0, 1.0), 0.8), pit_coverage((0.5, 0.5), 0.8), pit_coverage((0.0, 0.05), 0.8)
    (0.8, 1.0, 0.0)
    """
    return pit_share(pit, 0.5 - level / 2.0, 0.5 + level / 2.0)


def pit_share(pit: tuple[float, float], lo: float, hi: float) -> float:
    """The chance that the randomized PIT of a change (uniform on ``pit``, :func:`pit_coverage`) lies in ``[lo, hi]``:
    ``pit_share(pit, q, 1)`` is the chance that the change came after the forecast's ``q`` quantile. [-]

    Examples
    --------
    >>> pit_share((0.8, 1.0), 0.9, 1.0), pit_share((1.0, 1.0), 0.975, 1.0), pit_share((0.0, 0.5), 0.9, 1.0)
    (0.5, 1.0, 0.0)
    """
    a, b = pit
    if b - a < 1e-12:
        return float(lo <= a <= hi)
    return max(0.0, min(b, hi) - max(a, lo)) / (b - a)


def span_after(last_s: float, first_s: float, t_s: float) -> float:
    """The share of ``(last_s, first_s]`` (the last snapshot before a change and the first after it) later than
    ``t_s``: the chance that the change came after ``t_s``, the change evenly likely in its span. [-]

    Examples
    --------
    >>> span_after(10.0, 11.0, 10.25), span_after(10.0, 11.0, 12.0), span_after(10.0, 11.0, 9.0)
    (0.75, 0.0, 1.0)
    """
    return min(1.0, max(0.0, (first_s - max(last_s, t_s)) / (first_s - last_s)))


def _mae(errors: list[float]) -> float | None:
    return float(np.mean(errors)) if errors else None


def _calibration(rows: list[dict]) -> dict:
    """A bin's share of ``rows`` is the caller's; here its coverage of the central intervals (:func:`pit_coverage`)
    and the mean absolute error of the likely time (``rows``: ours, finite likely times)."""
    return {"interval_coverage": {f"{round(100 * lv)}": float(np.mean([pit_coverage(r["pit"], lv) for r in rows])) for lv in LEVELS},
            "mae_s": _mae([abs(r["likely"] - r["change_unix_s"]) for r in rows])}  # fmt: skip


def calibration_by(rows: list[dict], key) -> dict:
    """``{bin: {"predictions_frac", "interval_coverage", "mae_s"}}`` of ``rows`` (ours) grouped by ``key(row)``; bins
    with no row are left out."""
    return {k: {"predictions_frac": len(g) / len(rows), **_calibration(g)} for k, g in _groups(rows, key).items()}


def width_bin(width_s: float) -> str:
    """The :data:`WIDTH_BINS_S` name of a stated 80 % interval width.

    Examples
    --------
    >>> width_bin(0.0), width_bin(2.0), width_bin(9.9), width_bin(math.inf)
    ('0-2', '2-5', '5-10', '>10')
    """
    return next(name for name, (lo, hi) in WIDTH_BINS_S.items() if lo <= width_s < hi or (hi == math.inf and width_s >= lo))


TAIL_LEVELS = {f"{100 * q:g}": q for q in (LATE_QUANTILE, SCENARIO_LEVELS[-1])}
"""The upper quantiles the advisor plans to (``late_tail``): its late view (:data:`~spat_feed.prediction.history.LATE_QUANTILE`,
``"90"``) and the last of its 20 timings (:data:`~spat_feed.prediction.observe.SCENARIO_LEVELS`, ``"97.5"``). [-]"""


def _tail(rows: list[dict]) -> dict:
    """The share of ``rows`` (ours) whose change came after each :data:`TAIL_LEVELS` quantile of its forecast
    (calibrated: 1 - the level), and of those read with a known ``maxEndTime``, the share whose change came after it
    against the share the forecast put there."""
    known = [r for r in rows if math.isfinite(r["max_end"])]
    return {"after": {k: float(np.mean([pit_share(r["pit"], q, 1.0) for r in rows])) for k, q in TAIL_LEVELS.items()},
            "max_end_known_frac": len(known) / len(rows),
            "past_max_end_frac": float(np.mean([span_after(r["last_before_unix_s"], r["change_unix_s"], r["max_end"]) for r in known])) if known else None,
            "past_max_end_stated_frac": float(np.mean([r["past_max_end"] for r in known])) if known else None}  # fmt: skip


def late_tail(rows: list[dict]) -> dict:
    """``{class the change ends: {"predictions_frac", "after", ..., "by_method": {method: {...}}, "by_likely_ahead":
    {bin: {...}}}}`` (:func:`_tail`) of ``rows`` (ours, every horizon): whether the forecast's upper tail, which the
    advisor's late view and last timings read, is calibrated for greens and reds apart, by method and by how far
    ahead the forecast put the change (:data:`LIKELY_AHEAD_S`)."""

    def split(mine: list[dict], key) -> dict:
        return {k: {"predictions_frac": len(g) / len(mine), **_tail(g)} for k, g in _groups(mine, key).items()}

    def ahead(r: dict) -> str:
        return next(name for name, (lo, hi) in LIKELY_AHEAD_S.items() if r["likely"] - r["t"] < hi)

    return {cls.value: {"predictions_frac": len(mine) / len(rows), **_tail(mine), "by_method": split(mine, lambda r: r["method"]), "by_likely_ahead": split(mine, ahead)}
            for cls, mine in _groups(rows, lambda r: r["from"]).items()}  # fmt: skip


def _groups(rows: list[dict], key) -> dict:
    """``rows`` grouped by ``key(row)``, the keys sorted."""
    out: dict = {}
    for r in rows:
        out.setdefault(key(r), []).append(r)
    return dict(sorted(out.items(), key=lambda kv: str(kv[0].value if hasattr(kv[0], "value") else kv[0])))


def summarize(rows: list[dict]) -> dict:
    """The keys of the module docstring from :func:`scored` rows."""
    tail = late_tail([r for r in rows if math.isfinite(r.get("likely", math.inf))])
    rows = [r for r in rows if r["ahead_s"] <= SCORED_AHEAD_S]
    ours = [r for r in rows if math.isfinite(r.get("likely", math.inf))]
    both = [r for r in ours if r["base"] is not None]
    err = [abs(r["likely"] - r["change_unix_s"]) for r in ours]
    by_h = {name: _mae([abs(r["likely"] - r["change_unix_s"]) for r in both if lo <= r["ahead_s"] < hi]) for name, (lo, hi) in HORIZONS_S.items()}
    base_by_h = {name: _mae([abs(r["base"] - r["change_unix_s"]) for r in both if lo <= r["ahead_s"] < hi]) for name, (lo, hi) in HORIZONS_S.items()}
    reds = [r for r in rows if r["to"] is PhaseClass.RED and "earliest" in r]
    methods = Counter(r.get("method", "none") for r in rows)
    return {
        "changes": len({(r["key"], r["change_unix_s"]) for r in rows}),
        "predictions": len(rows),
        "predicted_frac": len(ours) / len(rows) if rows else None,
        "mae_s": _mae([abs(r["likely"] - r["change_unix_s"]) for r in both]),
        "mae_s_all": _mae(err),
        "mae_s_by_horizon": by_h,
        "within_2s_frac": float(np.mean([e <= 2.0 for e in err])) if err else None,
        "within_5s_frac": float(np.mean([e <= 5.0 for e in err])) if err else None,
        "baseline_mae_s": _mae([abs(r["base"] - r["change_unix_s"]) for r in both]),
        "baseline_mae_s_by_horizon": base_by_h,
        "interval_coverage": {f"{round(100 * lv)}": float(np.mean([pit_coverage(r["pit"], lv) for r in ours])) if ours else None for lv in LEVELS},
        "interval_meets_span_frac": {f"{round(100 * lv)}": float(np.mean([r["intervals"][lv][0] <= r["change_unix_s"] and r["intervals"][lv][1] > r["last_before_unix_s"]
                                                                          for r in ours])) if ours else None for lv in LEVELS},  # fmt: skip
        "early_red_frac": float(np.mean([r["change_unix_s"] < r["earliest"] for r in reds])) if reds else 0.0,
        "method_frac": {m: n / len(rows) for m, n in sorted(methods.items())},
        "coverage_by_width": {k: v for k, v in sorted(calibration_by(ours, lambda r: width_bin(r["width_s"])).items(), key=lambda kv: list(WIDTH_BINS_S).index(kv[0]))},
        "coverage_by_method": dict(sorted(calibration_by(ours, lambda r: r["method"]).items())),
        "late_tail": tail,
    }


def evaluate_log(path: str, limit_s: float | None = None) -> tuple[dict, list[dict]]:
    """Replay the log at ``path`` (its first ``limit_s`` seconds if given): the summary and the scored rows."""
    from spat_feed.transport.recorded import read_spat_csv

    snapshots = read_spat_csv(path)
    if limit_s is not None and snapshots:
        t0 = to_unix_s(snapshots[0].timestamp)
        snapshots = [s for s in snapshots if to_unix_s(s.timestamp) - t0 <= limit_s]
    rows = scored(predictions(snapshots))
    return {"log": path, **summarize(rows)}, rows


def plot(results: list[tuple[str, list[dict]]], path: str) -> None:
    """Mean absolute error against how far ahead the change was (5 s bins), ours and the baseline, per log."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7.5, 4.2), dpi=120)
    edges = np.arange(0.0, 61.0, 5.0)
    mids = 0.5 * (edges[:-1] + edges[1:])
    for k, (name, rows) in enumerate(results):
        color = f"C{k}"
        ours = [r for r in rows if math.isfinite(r.get("likely", math.inf)) and r["base"] is not None]
        for field, style, label in (("likely", "-", "ecodrive"), ("base", ":", "median of past durations")):
            mae = [np.mean([abs(r[field] - r["change_unix_s"]) for r in ours if a <= r["ahead_s"] < b] or [np.nan]) for a, b in zip(edges[:-1], edges[1:])]
            ax.plot(mids, mae, style, color=color, marker="o" if field == "likely" else None, ms=3, label=f"{name}: {label}")
    ax.set_xlabel("how far ahead the change really was [s]")
    ax.set_ylabel("mean absolute error of the likely time [s]")
    ax.set_title("Phase-end prediction on recorded controllers (ecodrive predict-eval)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, ncol=1)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="ecodrive predict-eval", description=__doc__.split("\n\n")[0])
    ap.add_argument("logs", nargs="+", metavar="LOG", help="recorded SPaT CSV (.csv or .csv.gz), the shared format")
    ap.add_argument("--json", action="store_true", help="print the summary as JSON")
    ap.add_argument("--limit-s", type=float, default=None, help="use only the first seconds of each log")
    ap.add_argument("--plot", metavar="FILE", help="write the error-against-horizon figure (PNG)")
    args = ap.parse_args(argv)
    from spat_feed.transport.recorded import RecordedLogError

    results, all_rows = [], []
    for path in args.logs:
        print(f"predict-eval: {path} ...", file=sys.stderr)
        try:
            summary, rows = evaluate_log(path, args.limit_s)
        except (OSError, RecordedLogError) as exc:
            print(f"ecodrive predict-eval: {exc}", file=sys.stderr)
            return 2
        results.append(summary)
        all_rows.append((path.rsplit("/", 1)[-1].split(".")[0], rows))
    if args.plot:
        plot(all_rows, args.plot)
    if args.json:
        print(json.dumps(results[0] if len(results) == 1 else results, indent=2))
        return 0
    for r in results:
        h = r["mae_s_by_horizon"]
        print(f"{r['log']}: {r['changes']} changes, {r['predictions']} predictions ({100 * (r['predicted_frac'] or 0):.0f} % bounded); "
              f"MAE {r['mae_s']:.2f} s (0-10 s: {h['0-10']:.2f}, 10-30 s: {h['10-30']:.2f}, 30-60 s: {h['30-60']:.2f}) "
              f"against {r['baseline_mae_s']:.2f} s for the median of past durations; 80 % interval holds "
              f"{100 * r['interval_coverage']['80']:.0f} %; early reds {100 * r['early_red_frac']:.1f} %")
        by_width = ", ".join(f"{k} s {100 * v['interval_coverage']['80']:.0f} % ({100 * v['predictions_frac']:.0f} % of them)" for k, v in r["coverage_by_width"].items())
        print(f"  80 % intervals by their width: {by_width}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
