"""``ecodrive corridor ...``: corridor and plan files from the command line.

* ``from-osm FILE.osm[.bz2|.gz|.pbf] --street NAME [-o OUT] [--direction D] [--name N] [--units U]``: build
  corridor files from OpenStreetMap data (``spat_feed.road.osm``), one per direction of travel.
* ``show FILE_OR_PRESET [--timing PLAN.json] [--json]``: the corridor as the product understands it
  (``length_m``, ``lights`` with their ``station_m``, limits, plans); also validates the files.
* ``tables FILE_OR_PRESET [--timing PLAN.json] [--cache DIR] [--workers N]``: build (or load) the DP
  lookup tables, printing build time and memory.
* ``schema corridor|plan``: the JSON Schema of the files.

Errors (a bad file, an unknown street) are one line on stderr naming the file, the field and the reason;
exit status 2.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence
from pathlib import Path

from spat_feed.files import FileFormatError


def describe(corridor, default_limit_mps: float | None = None) -> dict:
    """The corridor as the product uses it: geometry, limits, lights (stations), plans."""
    from advisory.physics.params import SPEED_LIMIT_MPS

    default = default_limit_mps or SPEED_LIMIT_MPS
    starts, limits, grades = corridor.limit_profile(default)
    ends = list(starts[1:]) + [corridor.length_m]
    lights = []
    previous = 0.0
    for ix in corridor.intersections:
        lights.append({
            "intersection_id": ix.id,
            "name": ix.name,
            "signal_group": ix.signal_groups[0].id,
            "station_m": ix.stop_line_m,
            "spacing_m": round(ix.stop_line_m - previous, 3),
            "approach_heading_deg": ix.approach_heading_deg,
            "lat_deg": ix.lat_deg,
            "lon_deg": ix.lon_deg,
            "approach_speed_limit_mps": corridor.speed_limit_mps_over(previous, ix.stop_line_m, default),
        })  # fmt: skip
        previous = ix.stop_line_m
    plans = []
    for plan in corridor.plans:
        plans.append({
            "name": plan.name,
            "reference": plan.reference,
            "time_zone": plan.time_zone,
            "patterns": {
                name: [{"intersection_id": lt.intersection_id, "kind": lt.kind,
                        **({"cycle_s": lt.cycle_sum_s, "red_s": lt.red_s, "green_s": lt.green_s, "amber_s": lt.amber_s, "offset_s": lt.offset_s} if lt.kind == "fixed" else {})}
                       for lt in pattern.lights]
                for name, pattern in plan.patterns.items()
            },
            "schedule": [p.model_dump() for p in plan.schedule],
            "default_pattern": plan.fallback_pattern,
            "source": plan.source,
        })  # fmt: skip
    return {
        "name": corridor.name,
        "schema_version": corridor.schema_version,
        "description": corridor.description,
        "units": corridor.units,
        "length_m": corridor.length_m,
        "zone_speed_limit_mps": corridor.zone_speed_limit_mps(default),
        "segments": [{"start_m": float(a), "end_m": float(b), "speed_limit_mps": float(v), "grade_frac": float(g)} for a, b, v, g in zip(starts, ends, limits, grades)],
        "lights": lights,
        "plans": plans,
        "default_plan": corridor.default_plan or (corridor.plans[0].name if len(corridor.plans) == 1 else None),
    }


def _text(d: dict) -> str:
    unit, k = ("mph", 1 / 0.44704) if d["units"] == "imperial" else ("km/h", 3.6)
    out = [f"{d['name']} (schema {d['schema_version']}, spoken in {unit}): {d['length_m']:.1f} m, {len(d['lights'])} light(s)"]
    if d["description"]:
        out.append(f"  {d['description']}")
    for s in d["segments"]:
        out.append(f"  {s['start_m']:8.1f} - {s['end_m']:8.1f} m   limit {s['speed_limit_mps'] * k:5.1f} {unit}   grade {100 * s['grade_frac']:+.1f} %")
    for light in d["lights"]:
        out.append(f"  light {light['intersection_id']:>3} sg {light['signal_group']:>2} at {light['station_m']:8.1f} m (+{light['spacing_m']:.1f} m), "
                   f"heading {light['approach_heading_deg']:5.1f} deg  {light['name']}")  # fmt: skip
    for plan in d["plans"]:
        out.append(f"  plan {plan['name']}: {len(plan['patterns'])} pattern(s), reference {plan['reference']} ({plan['time_zone']}), "
                   f"{len(plan['schedule'])} period(s), default {plan['default_pattern']}" + (f"; {plan['source']}" if plan["source"] else ""))  # fmt: skip
    return "\n".join(out)


def _load(target: str, timing: Sequence[str] = ()):
    from spat_feed.road.corridors import load_corridor

    return load_corridor(target, plans=tuple(timing))


def cmd_show(args) -> int:
    corridor = _load(args.corridor, args.timing or ())
    d = describe(corridor)
    print(json.dumps(d, indent=1) if args.json else _text(d))
    return 0


def cmd_from_osm(args) -> int:
    from spat_feed.road.osm import corridors_from_osm

    result = corridors_from_osm(args.file, args.street, name=args.name, units=args.units, direction=args.direction, first_id=args.first_id)
    for note in result.notes:
        print(f"note: {note}", file=sys.stderr)
    corridors = result.corridors
    if args.output is None:
        if len(corridors) > 1:
            names = ", ".join(c.name for c in corridors)
            print(f"error: {args.street!r} gives {len(corridors)} routes ({names}): pick one with --direction, or write them with -o", file=sys.stderr)
            return 2
        print(corridors[0].model_dump_json(indent=1, exclude_defaults=False))
        return 0
    out = Path(args.output)
    for c in corridors:
        if out.is_dir() or args.output.endswith(("/", "\\")):
            path = out / f"{c.name}.json"
        elif len(corridors) == 1:
            path = out
        else:
            path = out.with_name(f"{out.stem}_{c.name.rsplit('_', 1)[-1]}{out.suffix or '.json'}")
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(c.model_dump_json(indent=1) + "\n", encoding="utf-8")
        print(f"wrote {path}: {c.name}, {c.length_m:.0f} m, lights at {', '.join(f'{ix.stop_line_m:.0f}' for ix in c.intersections) or 'none'} m", file=sys.stderr)
    return 0


def cmd_tables(args) -> int:
    from advisory.advice.tables import TableGrid
    from advisory.physics.params import model_params
    from spat_feed.road.corridor_tables import corridor_tables, default_cache_dir, table_timings

    from spat_feed.road.corridors import load_plan

    corridor = _load(args.corridor, args.timing or ())
    timings = [corridor.plan(load_plan(t).name) for t in args.timing] if args.timing else None
    cache = None if args.no_cache else Path(args.cache) if args.cache else default_cache_dir()
    grid = TableGrid(stage_m=args.stage_m, tau_step_s=args.tau_step_s)
    if timings is None and not table_timings(corridor):
        print(f"{corridor.name}: no plan to tabulate (give --timing PLAN.json)", file=sys.stderr)
        return 2
    tables, report = corridor_tables(corridor, model_params(args.vehicle), grid, timings=timings or None, cache_dir=cache, workers=args.workers, measure=True)
    if tables is None:
        print(f"{corridor.name}: no light has a fixed-time plan: no table can exist (the advisor uses its rules)")
        return 0
    print(report.line())
    for k, ts in enumerate(tables.tables):
        kinds = ", ".join(f"{'pair' if t.is_pair else 'one'} {t.period_s:g} s" for t in ts) or "none"
        print(f"  light {k + 1} at {tables.light_positions_m[k]:.1f} m: {kinds}")
    return 0


def cmd_schema(args) -> int:
    from spat_feed.road.corridors import Corridor
    from spat_feed.timing.signal_plans import SignalPlan

    model = Corridor if args.kind == "corridor" else SignalPlan
    print(json.dumps(model.model_json_schema(), indent=1))
    return 0


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="ecodrive corridor", description="Corridor and signal-plan files (docs/CORRIDORS.md).")
    sub = p.add_subparsers(dest="command", required=True)
    osm = sub.add_parser("from-osm", help="build corridor files from OpenStreetMap data (offline)")
    osm.add_argument("file", help="OSM XML (.osm, .osm.bz2, .osm.gz) or .pbf (needs the 'osmium' extra)")
    osm.add_argument("--street", required=True, help="the street's name (OSM name tag)")
    osm.add_argument("-o", "--output", help="output file (several directions: FILE_<direction>.json), or a folder; default: stdout")
    osm.add_argument("--direction", choices=("northbound", "eastbound", "southbound", "westbound"), help="keep only this direction")
    osm.add_argument("--name", help="corridor name prefix (default: the street's), suffixed with the direction")
    osm.add_argument("--units", choices=("metric", "imperial"), help="spoken units (default: guessed from maxspeed and location)")
    osm.add_argument("--first-id", type=int, default=1, help="intersection id of the first signal along the street (ids count up from it; use the operator's J2735 ids for live SPaT)")
    osm.set_defaults(func=cmd_from_osm)
    show = sub.add_parser("show", help="print a corridor as the product understands it")
    show.add_argument("corridor", help="a corridor file (.json/.toml) or preset name")
    show.add_argument("--timing", action="append", metavar="PLAN", help="a plan file to attach and check (repeatable)")
    show.add_argument("--json", action="store_true", help="JSON (length_m, lights with station_m, segments, plans)")
    show.set_defaults(func=cmd_show)
    tab = sub.add_parser("tables", help="build (or load) the DP lookup tables; prints build time and memory")
    tab.add_argument("corridor", help="a corridor file or preset name")
    tab.add_argument("--timing", action="append", metavar="PLAN", help="plan file(s) to tabulate (default: the corridor's plans, or the paper's timings)")
    tab.add_argument("--cache", help="cache folder (default: $ECO_TABLES_CACHE or ~/.cache/ecodrive/tables)")
    tab.add_argument("--no-cache", action="store_true", help="build in memory only")
    tab.add_argument("--workers", type=int, default=None, help="threads (default: all cores)")
    tab.add_argument("--vehicle", default="paper_54kwh", help="vehicle preset (default paper_54kwh)")
    tab.add_argument("--stage-m", type=float, default=20.0, help="stage length (default 20 m)")
    tab.add_argument("--tau-step-s", type=float, default=0.5, help="phase step (default 0.5 s)")
    tab.set_defaults(func=cmd_tables)
    schema = sub.add_parser("schema", help="print the JSON Schema of corridor or plan files")
    schema.add_argument("kind", choices=("corridor", "plan"))
    schema.set_defaults(func=cmd_schema)
    return p


def main(argv: Sequence[str] | None = None) -> int:
    from spat_feed.road.osm import OsmError

    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except (FileFormatError, OsmError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except KeyError as exc:
        print(f"error: {exc.args[0]}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
