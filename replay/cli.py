"""`replay trace.csv`: score a recorded drive with the EV energy and battery-wear model.

A speed trace (time + speed) is scored as it is. A GPS trace (CSV with time, lat, lon[, speed]; or a GPX
file) is map-matched onto its corridor, scored over the corridor's zone, and compared with the paper's
regular driver and the DP optimum through the same lights, or without signal timing with the regular driver
on the drive's own stops, and its energy per km with the EPA cycles' (``replay.drive``). ``--server URL`` also
feeds its fixes to a running advisory service and prints what the service advised (``replay.live``).
Exit status: 0 scored, 1 scored but the drive does not cover the zone (GPS), 2 bad input or options.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections.abc import Sequence
from pathlib import Path

from advisory.physics.params import DEFAULT_VEHICLE, VEHICLE_PRESETS, model_params
from advisory.evaluation.scoring import DriveScore, score_trace
from replay.trace_io import GpsTrace, SpeedTrace, TraceError, read_trace


def render_score(score: DriveScore, title: str) -> str:
    rows = [
        ("distance", f"{score.distance_m / 1000:.3f} km"),
        ("duration", f"{score.duration_s:.0f} s"),
        ("battery energy out", f"{score.battery_out_kwh:.4f} kWh"),
        ("regen energy in", f"{score.regen_in_kwh:.4f} kWh"),
        ("net battery energy", f"{score.net_kwh:.4f} kWh"),
        ("consumption", f"{score.wh_per_km:.1f} Wh/km ({score.wh_per_km * 1.609344:.1f} Wh/mi)"),
        ("SOH lost", f"{score.soh_lost_frac:.3e} of life ({score.capacity_loss_pct:.3e} % capacity)"),
        ("electricity cost", f"${score.electricity_usd:.5f}"),
        ("battery wear cost", f"${score.wear_usd:.5f}"),
        ("total cost", f"${score.total_usd:.5f}"),
        ("energy audit residual", f"{score.audit.residual_j:.2e} J"),
    ]
    width = max(len(k) for k, _ in rows)
    return "\n".join([title] + [f"  {k:<{width}}  {v}" for k, v in rows])


COLUMN_WORDS = {"t_s": "time", "lat_deg": "latitude", "lon_deg": "longitude", "speed_mps": "speed", "heading_deg": "heading", "accuracy_m": "accuracy"}


def render_drive(result, title: str) -> str:
    """The GPS report: trace and corridor, the zone score, the comparison table, notes."""
    m = result.matched
    d = result.as_dict()
    fx = d["fixes"]
    head = [
        title,
        f"  corridor   {m.corridor.name} ({m.corridor.length_m:.0f} m, {len(m.corridor.intersections)} lights; {result.corridor.how})",
        f"  timing     {result.timing or '-'}" + (f", anchored at entry_unix_s {result.entry_unix_s:.3f}" if result.entry_unix_s is not None else ""),
        f"  fixes      {fx['n']} ({fx['on_route']} on route, median cross-track {fx['median_cross_track_m'] or 0:.1f} m), "
        f"speed from {fx['speed_source']}, smoothed {result.smooth_s:g} s",
        f"  read       {result.trace.columns.get('file', '?')}: " + "; ".join(
            f"{COLUMN_WORDS.get(k, k)} from {v}" for k, v in result.trace.columns.items() if k != "file"),
        f"  zone entry {result.zone_entry_unix_s:.2f} (Unix s); {'complete' if result.complete else 'INCOMPLETE'}",
        "",
        render_score(result.zone, "Recorded drive over the zone"),
    ]
    if result.regular is not None:
        drivers = [("recorded", result.driven), ("regular", result.regular)] + ([("DP optimum", result.dp)] if result.dp else [])
        rows = [
            ("time to exit [s]", lambda r: f"{r.trajectory.duration_s:.1f}"),
            ("exit speed [km/h]", lambda r: f"{r.score.exit_speed_mps * 3.6:.1f}"),
            ("energy [Wh]", lambda r: f"{r.score.energy_kwh * 1000:.1f}"),
            ("SOH lost [1e-6]", lambda r: f"{r.score.soh_lost_frac * 1e6:.3f}"),
            ("electricity [$]", lambda r: f"{r.score.electricity_usd:.5f}"),
            ("battery wear [$]", lambda r: f"{r.score.wear_usd:.5f}"),
            ("cost [$]", lambda r: f"{r.score.cost_usd:.5f}"),
        ]
        over = "zone" if not result.drive.partial else f"first {result.drive.distance_m:.1f} m the drive covered"
        if result.against == "recorded stops":
            where = ", ".join(f"{st.position_m:.0f} m until {st.until_s:.0f} s" for st in result.stops) or "none: it never stood still"
            lines = ["", f"Comparison on the drive's own stops, no signal timing (the {over} + re-acceleration to the limit): the regular driver",
                     f"stops where the drive stood still and leaves when it left (stops: {where}); it shows how the drive was driven",
                     "between stops, not the stops advice could have saved"]  # fmt: skip
        else:
            lines = ["", f"Comparison through the same lights (the {over} + re-acceleration to the limit, as in the paper)"]
        lines.append(f"  {'':<20}" + "".join(f"{name:>14}" for name, _ in drivers))
        for label, fn in rows:
            lines.append(f"  {label:<20}" + "".join(f"{fn(r):>14}" for _, r in drivers))
        saved = result.savings()
        for key, name in (("driven", "recorded"), ("dp_optimum", "DP optimum")):
            if key in saved:
                if saved[key] is None:
                    lines.append(f"  {name} vs regular: not compared: the drive crossed a red light (Notes)")
                    continue
                lines.append(f"  {name} vs regular: {savings_text(saved[key])}")
        head += lines
    cycles = result.epa_cycles()
    if cycles:
        head += ["", f"Energy per km against the EPA cycles (same vehicle and model, flat road): this drive {result.end_state_wh_per_km:.1f} Wh/km",
                 "  (zone + re-acceleration to the limit, per km of the zone: the kinetic energy it used up is charged, as the cycles end at rest)"]  # fmt: skip
        head += [f"  {c['name']:<20} {c['wh_per_km']:6.1f} Wh/km   this drive x{c['ratio']:.2f}" for c in cycles]
    notes = result.trace.notes + result.notes
    if notes:
        head += ["", "Notes:"] + [f"  - {n}" for n in notes]
    return "\n".join(head)


def savings_text(saved: dict[str, float]) -> str:
    """``savings_frac`` in words: "41.1 % less energy, 41.1 % less wear, 41.1 % less cost" (the app's sign)."""
    return ", ".join(f"{abs(100 * saved[k]):.1f} % {'less' if saved[k] >= 0 else 'more'} {k}" for k in ("energy", "wear", "cost"))


def _finite_json(obj):
    """NaN/inf -> None, so the JSON is strict."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: _finite_json(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_finite_json(v) for v in obj]
    if hasattr(obj, "item"):  # numpy scalars
        return _finite_json(obj.item())
    return obj


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="replay",
        description="Score a recorded drive: a speed CSV, a GPS CSV (time, lat, lon[, speed]) or a GPX file. Details: docs/REPLAY.md",
    )
    parser.add_argument("trace", type=Path, help="CSV (speed or GPS fixes) or .gpx")
    parser.add_argument("--vehicle", default=None, choices=sorted(VEHICLE_PRESETS), help=f"vehicle preset (default: the trace's '# vehicle:', else {DEFAULT_VEHICLE})")
    parser.add_argument("--decay-multiplier", type=float, default=1.0, help="battery decay-rate multiplier (10 = NCA)")
    parser.add_argument("--json", action="store_true", help="print JSON instead of a table")
    parser.add_argument("--plot", type=Path, metavar="OUT.png", help="draw the paper's four panels (time-distance with red bars, speed, energy, decay)")
    gps = parser.add_argument_group("GPS traces")
    gps.add_argument("--corridor", help="corridor preset or JSON file (default: the trace's '# corridor:', else found by map matching)")
    gps.add_argument("--timing", help="signal timing: a plan of the corridor, a paper preset (field_test, -15_15), 'trip', a plan file .json/.toml, "
                     "or a recorded SPaT log .csv[.gz]/.jsonl[.gz] matched by time "
                     "(default: the trace's '# timing:', else the corridor's own plan; none: compared on the drive's own stops)")  # fmt: skip
    gps.add_argument("--entry", type=float, metavar="UNIX_S", help="zone-entry instant the timing is relative to (default: '# entry_unix_s:', else when the fixes cross station 0)")
    gps.add_argument("--smooth-s", type=float, default=None, help="Gaussian speed smoothing sigma [s] of the drive and of the drivers it is compared with (default: 1, as the service's trip score)")
    gps.add_argument("--baseline", type=Path, metavar="TRACE", help="another GPS trace of the same corridor (e.g. a regular drive): print what this drive saved against it")
    gps.add_argument("--no-compare", action="store_true", help="skip the regular driver and the DP optimum")
    live = parser.add_argument_group("live service")
    live.add_argument("--server", metavar="URL", help="also feed the fixes to an advisory service (e.g. http://127.0.0.1:8000) and print its advisories")
    live.add_argument("--speedup", type=float, default=1.0, help="replay N times faster than real time (default 1)")
    live.add_argument("--api-key", help="bearer key for trip creation, if the service requires one")
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        trace = read_trace(args.trace)
        if isinstance(trace, SpeedTrace):
            return _speed_main(trace, args)
        return _gps_main(trace, args)
    except (TraceError, ValueError) as exc:
        print(f"replay: error: {exc}", file=sys.stderr)
        return 2


def _speed_main(trace: SpeedTrace, args) -> int:
    vehicle = args.vehicle or DEFAULT_VEHICLE
    if args.server:
        raise TraceError("--server needs a GPS trace (time, lat, lon)")
    params = model_params(vehicle, args.decay_multiplier)
    score = score_trace(trace.t_s, trace.speed_mps, params, trace.grade_frac, keep_series=args.plot is not None)
    if args.plot is not None:
        from replay.figures import trajectory_panels

        trajectory_panels([(Path(trace.source).name, score.series, None, ())], f"{Path(trace.source).name} ({vehicle})", args.plot, labels=("drive", ""))
    if args.json:
        print(json.dumps({"trace": trace.source, "vehicle": vehicle, **_finite_json(score.as_dict())}, indent=2))
    else:
        print(render_score(score, f"{trace.source} ({vehicle}, decay x{args.decay_multiplier:g})"))
    return 0


def _gps_main(trace: GpsTrace, args) -> int:
    from replay.drive import savings_frac, score_drive

    vehicle = args.vehicle or trace.meta.get("vehicle") or DEFAULT_VEHICLE
    if vehicle not in VEHICLE_PRESETS:
        raise TraceError(f"{trace.source}: unknown vehicle {vehicle!r}; choose from {sorted(VEHICLE_PRESETS)}")
    if args.speedup <= 0:
        raise TraceError("--speedup must be > 0")
    params = model_params(vehicle, args.decay_multiplier)
    result = score_drive(
        trace, params, corridor=args.corridor, timing=args.timing, entry_unix_s=args.entry,
        smooth_s=args.smooth_s, compare=not args.no_compare, vehicle=vehicle, decay_multiplier=args.decay_multiplier,
    )  # fmt: skip
    baseline = None
    if args.baseline is not None:
        other = read_trace(args.baseline)
        if not isinstance(other, GpsTrace):
            raise TraceError(f"{args.baseline}: --baseline needs a GPS trace")
        base = score_drive(other, params, corridor=args.corridor or result.matched.corridor.name, timing=args.timing,
                           smooth_s=args.smooth_s, compare=False)  # fmt: skip
        same_m = abs(base.drive.distance_m - result.drive.distance_m) < 1e-6
        baseline = {"trace": other.source, "complete": base.complete, "compared_m": result.drive.distance_m, "driven": base.driven.as_dict(),
                    "savings_frac": savings_frac(result.driven.score, base.driven.score) if same_m and not result.red_crossings else None}  # fmt: skip
        if not same_m:
            result.notes.append(f"not compared with the baseline: it covers {base.drive.distance_m:.1f} m of the zone, this drive {result.drive.distance_m:.1f} m")
    timeline = None
    if args.server:
        from replay.drive import is_spat_log
        from replay.live import replay_live

        if is_spat_log(result.timing):
            raise TraceError("--server: the service takes a timing by name (a plan of the corridor or a paper preset), not a recorded SPaT log; "
                             "serve the log with ECO_SPAT_LOG=LOG (docs/SERVICE.md) and replay without --timing")  # fmt: skip

        timeline = replay_live(trace, result, args.server, speedup=args.speedup, vehicle=vehicle, api_key=args.api_key,
                               progress=None if args.json else sys.stdout)  # fmt: skip
    if args.plot is not None:
        _plot(result, args.plot, vehicle)
    if args.json:
        out = {"vehicle": vehicle, "decay_multiplier": args.decay_multiplier, **result.as_dict()}
        if baseline is not None:
            out["baseline"] = baseline
        if timeline is not None:
            out["live"] = timeline.as_dict()
        print(json.dumps(_finite_json(out), indent=2))
    else:
        print(render_drive(result, f"{trace.source} ({vehicle}, decay x{args.decay_multiplier:g})"))
        if baseline is not None:
            c, b = baseline["savings_frac"], baseline["driven"]
            change = "  not compared: a red light crossed or another distance (Notes)" if c is None else f"  {savings_text(c)}"
            print(f"\nAgainst the baseline trace {other.source} (energy {b['energy_kwh'] * 1000:.1f} Wh, SOH {b['soh_lost_frac'] * 1e6:.3f}e-6, "
                  f"cost ${b['cost_usd']:.5f}):\n{change}")  # fmt: skip
        if timeline is not None:
            print()
            print(timeline.render(events=False))
    return 0 if result.complete else 1


def _plot(result, path: Path, vehicle: str) -> None:
    from replay.figures import trajectory_panels

    lights = result.scenario.signals if result.scenario is not None else ()
    reg = result.regular.score.zone.series if result.regular else None
    runs = [("recorded drive (solid) / regular driver (dashed)", result.driven.score.zone.series, reg, lights)]
    if result.dp is not None:
        runs.append(("DP optimum", result.dp.score.zone.series, None, lights))
    title = f"{Path(result.trace.source).name}: {result.matched.corridor.name}, timing {result.timing or '-'}, {vehicle}"
    trajectory_panels(runs, title, path, labels=("recorded / DP optimum", "regular driver"))


if __name__ == "__main__":
    sys.exit(main())
