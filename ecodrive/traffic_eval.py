"""`ecodrive traffic-eval`: the advisor among other cars, in Eclipse SUMO; the same scenario three ways.

    ecodrive traffic-eval --corridor NAME_OR_FILE [--plan FILE_OR_NAME] [--control fixed|actuated]
                          --demand VEH_PER_HOUR_PER_LANE --penetration FRAC --seed N [--json]

One scenario (corridor, plan, control, demand, penetration, seed) runs three times on the same SUMO network, with
the same ``--seed``, demand and so the same arrivals (every car's scheduled departure is checked to agree across the
runs) and the same connected cars (:func:`ecodrive.traffic.sim.connected_ids`): advised by ecodrive through the
service's own path, with SUMO's GLOSA device (``use-queue`` on), and unadvised (:mod:`ecodrive.traffic.sim`).

Every car is scored from its SUMO trajectory with this project's EV model (the paper's preset unless
``--vehicle``): energy, battery wear and their cost from its insertion (the lead-in's start, ``lead_in_m`` before
the zone entry) to the zone's end, plus the re-acceleration penalty of the common end state
(:func:`advisory.evaluation.endstate.score_in_end_state`: a car leaving slower still has to speed up); its time from
its *scheduled* departure (a car held at the entry by the queue loses that time too) to the zone's end, plus the
penalty's time. Only cars that reach the zone's end in all three runs count.

Keys (``--json``): ``advised_cars`` (connected cars counted), ``red_entries`` (stop lines crossed by advised cars
while their light was red, in the advised run), ``hard_brakes`` (advised cars that braked harder than 3.5 m/s² at
any step, in the advised run), ``saving_frac`` (1 - the advised cars' summed cost / the same cars' unadvised),
``glosa_saving_frac`` (the same with GLOSA), ``energy_saving_frac`` and ``glosa_energy_saving_frac`` (energy
alone), ``stops_per_advised_car`` (advised run), ``stops_per_glosa_car``, ``stops_per_unadvised_car`` (the same cars
unadvised), ``time_change_frac`` (advised cars' summed time / unadvised - 1), ``glosa_time_change_frac``,
``others_time_change_frac`` and ``others_energy_change_frac`` (the cars that are not connected, advised run against
unadvised: does advice slow the traffic behind?), ``glosa_others_time_change_frac``, ``glosa_others_energy_change_frac``,
``glosa_red_entries``, ``glosa_hard_brakes``, ``unadvised_red_entries``, ``unadvised_hard_brakes`` (the connected cars
in those runs), ``cars`` (every car counted), ``spat_messages`` (SUMO's states the store accepted in the advised run),
``advice_actions`` (advised cars' fixes by action), ``setup``, ``wall_s``.

``--hindsight`` adds what is reachable (:func:`hindsight_summary`, :mod:`ecodrive.traffic.hindsight`): each connected
car's hindsight bound (the DP that knows the lights it met, from its insertion, within its own unadvised time, alone
on the road), ``hindsight_saving_frac`` and ours and GLOSA over the same cars (``hindsight_ours_saving_frac``,
``hindsight_glosa_saving_frac``), the bound from where the service begins to advise
(``hindsight_from_approach_saving_frac``) and also 2 s clear of each red's end (``hindsight_advisable_saving_frac``),
that one kept behind the car ahead as it drove unadvised (``hindsight_behind_saving_frac``),
the same car alone on the road against its bound (``hindsight_alone_saving_frac``), the cars whose bound does not run
into the car ahead (``hindsight_free_saving_frac``), and one row per car (``hindsight_rows``).

A stop: the speed falls to 0.5 m/s or below after having been above 3 m/s since the last stop (a car creeping up in
a queue stops once). A hard brake: speed falling faster than 3.5 m/s² over a step (:data:`HARD_BRAKE_MPS2`).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import tempfile
import time
from collections import Counter
from collections.abc import Sequence
from dataclasses import asdict, dataclass

import numpy as np

from advisory.evaluation.endstate import score_in_end_state
from advisory.physics.params import model_params
from advisory.trajectory import Trajectory

HARD_BRAKE_MPS2 = 3.5
STOP_MPS = 0.5
MOVING_MPS = 3.0


@dataclass(frozen=True, slots=True)
class CarScore:
    cost_usd: float
    energy_kwh: float
    time_s: float
    stops: int
    hard_brake: bool
    red_entries: int


def zone_trajectory(car, zone_end_m: float) -> Trajectory | None:
    """One car's run from its first step to the zone's end, the crossing of the end interpolated at constant
    acceleration within its step (None if it never got there)."""
    t, x, v = (np.asarray(a, dtype=float) for a in (car.t, car.x, car.v))
    k = int(np.searchsorted(x, zone_end_m, side="left"))
    if k >= len(x) or k == 0:
        return None
    # the crossing of the zone's end within step k - 1 .. k (constant acceleration within it)
    t0, x0, v0, t1, v1 = t[k - 1], x[k - 1], v[k - 1], t[k], v[k]
    a = (v1 - v0) / (t1 - t0)
    d = zone_end_m - x0
    tau = d / v0 if abs(a) < 1e-9 and v0 > 0 else ((-v0 + math.sqrt(max(v0 * v0 + 2 * a * d, 0.0))) / a if abs(a) > 1e-9 else t1 - t0)
    tau = min(max(tau, 0.0), t1 - t0)
    tt = np.append(t[:k], t0 + tau)
    vv = np.append(v[:k], v0 + a * tau)
    xx = np.append(x[:k], zone_end_m)
    if tt[-1] - tt[-2] < 1e-6:
        tt, vv, xx = tt[:-1], vv[:-1], xx[:-1]
        xx[-1] = zone_end_m
    return Trajectory(tt, xx, vv)


def score_car(car, zone_end_m: float, speed_limit_mps: float, params) -> CarScore | None:
    """One car's score over its run up to the zone's end (None if it never got there)."""
    traj = zone_trajectory(car, zone_end_m)
    if traj is None:
        return None
    tt, vv = traj.t_s, traj.v_mps
    s = score_in_end_state(traj, params, speed_limit_mps)
    k = int(np.searchsorted(np.asarray(car.x, dtype=float), zone_end_m, side="left"))
    acc = np.diff(np.asarray(car.v[:k + 1], dtype=float)) / np.diff(np.asarray(car.t[:k + 1], dtype=float))
    return CarScore(s.cost_usd, s.energy_kwh, float(tt[-1] - car.depart_s + (s.time_s - (tt[-1] - tt[0]))), count_stops(vv),
                    bool((acc < -HARD_BRAKE_MPS2 - 1e-6).any()), sum(1 for c in car.crossings if c[2] == "red"))  # fmt: skip


def count_stops(v_mps) -> int:
    """Stops in a speed trace: falls to :data:`STOP_MPS` or below after being above :data:`MOVING_MPS`.

    Examples
    --------
    >>> count_stops([10, 5, 0.2, 0.0, 1.0, 0.3, 4.0, 0.0])
    2
    """
    stops, moving = 0, True
    for s in v_mps:
        if moving and s <= STOP_MPS:
            stops, moving = stops + 1, False
        elif s > MOVING_MPS:
            moving = True
    return stops


def _frac(new: float, old: float) -> float | None:
    """``new / old - 1``; None where there is nothing to compare (no such cars: every car connected, say)."""
    return float(new / old - 1.0) if old > 0 else None


def _neg(x: float | None) -> float | None:
    return None if x is None else -x


def paired_summary(results: dict, network, params) -> dict:
    """The keys (see the module docstring) from the three runs' :class:`~ecodrive.traffic.sim.RunResult`."""
    scores = {}
    for mode, r in results.items():
        scores[mode] = {vid: score_car(car, network.corridor.length_m, network.speed_limit_mps, params) for vid, car in r.cars.items()}
    base = results["unadvised"].cars
    for mode, r in results.items():
        for vid, car in r.cars.items():
            if vid in base and abs(car.depart_s - base[vid].depart_s) > 1e-6:
                raise RuntimeError(f"{mode} run: car {vid} scheduled at {car.depart_s:.3f} s, unadvised at {base[vid].depart_s:.3f} s: the runs are not paired")
    common = [vid for vid in base if all(scores[m].get(vid) is not None for m in results)]
    conn = [vid for vid in common if base[vid].connected]
    others = [vid for vid in common if not base[vid].connected]

    def total(mode, ids, what):
        return float(sum(getattr(scores[mode][vid], what) for vid in ids))

    out = {"advised_cars": len(conn), "cars": len(common)}
    out["red_entries"] = int(total("advised", conn, "red_entries"))
    out["hard_brakes"] = int(sum(scores["advised"][vid].hard_brake for vid in conn))
    out["saving_frac"] = _neg(_frac(total("advised", conn, "cost_usd"), total("unadvised", conn, "cost_usd")))
    out["glosa_saving_frac"] = _neg(_frac(total("glosa", conn, "cost_usd"), total("unadvised", conn, "cost_usd")))
    out["energy_saving_frac"] = _neg(_frac(total("advised", conn, "energy_kwh"), total("unadvised", conn, "energy_kwh")))
    out["glosa_energy_saving_frac"] = _neg(_frac(total("glosa", conn, "energy_kwh"), total("unadvised", conn, "energy_kwh")))
    n = max(len(conn), 1)
    out["stops_per_advised_car"] = total("advised", conn, "stops") / n
    out["stops_per_glosa_car"] = total("glosa", conn, "stops") / n
    out["stops_per_unadvised_car"] = total("unadvised", conn, "stops") / n
    out["time_change_frac"] = _frac(total("advised", conn, "time_s"), total("unadvised", conn, "time_s"))
    out["glosa_time_change_frac"] = _frac(total("glosa", conn, "time_s"), total("unadvised", conn, "time_s"))
    out["others_time_change_frac"] = _frac(total("advised", others, "time_s"), total("unadvised", others, "time_s"))
    out["others_energy_change_frac"] = _frac(total("advised", others, "energy_kwh"), total("unadvised", others, "energy_kwh"))
    out["glosa_others_time_change_frac"] = _frac(total("glosa", others, "time_s"), total("unadvised", others, "time_s"))
    out["glosa_others_energy_change_frac"] = _frac(total("glosa", others, "energy_kwh"), total("unadvised", others, "energy_kwh"))
    if "blind" in results:  # the same service with queue-blind advice
        out["blind_saving_frac"] = _neg(_frac(total("blind", conn, "cost_usd"), total("unadvised", conn, "cost_usd")))
        out["stops_per_blind_car"] = total("blind", conn, "stops") / n
        out["blind_time_change_frac"] = _frac(total("blind", conn, "time_s"), total("unadvised", conn, "time_s"))
        out["blind_others_time_change_frac"] = _frac(total("blind", others, "time_s"), total("unadvised", others, "time_s"))
    for mode in [m for m in ("blind", "glosa", "unadvised") if m in results]:
        out[f"{mode}_red_entries"] = int(total(mode, conn, "red_entries"))
        out[f"{mode}_hard_brakes"] = int(sum(scores[mode][vid].hard_brake for vid in conn))
    for mode, r in results.items():  # SUMO's collisions (bumpers overlapping; the pairs), never a teleport (--collision.action warn)
        out[f"{mode}_collisions"] = len({(c[1], c[2]) for c in r.collisions})
    out["spat_messages"] = int(results["advised"].spat_verdicts.get("ok", 0))
    out["spat_rejected"] = int(sum(n for k, n in results["advised"].spat_verdicts.items() if k != "ok"))
    actions = Counter()
    for vid in conn:
        actions.update(results["advised"].cars[vid].advice)
    out["advice_actions"] = dict(sorted(actions.items()))
    return out


def hindsight_summary(results: dict, network, params, from_m: float, after_red_s: float = 0.0, alone: dict | None = None) -> dict:
    """The hindsight bound (:mod:`ecodrive.traffic.hindsight`) of every connected car that reached the zone's end in
    all the runs, on the lights of the unadvised run, against the same car unadvised, and the other runs (ours,
    GLOSA: those in ``results``) over the same cars: ``hindsight_*`` keys and one row per car (``hindsight_rows``).
    ``from_m``: where the service begins to advise (the second bound, ``hindsight_from_approach_saving_frac``, keeps
    the car's own drive up to there); ``after_red_s``: the third, ``hindsight_advisable_saving_frac``, from there too
    and no line crossed within this long after a red ends (the advisor's ``green_margin_s``); the fourth,
    ``hindsight_behind_saving_frac``, is that one kept a car's length behind the car ahead as it drove unadvised
    (:func:`~ecodrive.traffic.hindsight.behind_lights`: alone on the road the bound may drive through it). ``alone``: each car's
    run alone on the road (:func:`alone_runs`); ``hindsight_alone_*``: its bound against that drive (the empty
    road's bound, the same lights)."""
    from advisory.drivers.closed_loop import red_light_violations
    from advisory.signals import Scenario, TimelineSignal
    from ecodrive.traffic.hindsight import hindsight_drive, runs_into

    alone = alone or {}
    base = results["unadvised"]
    end_m, v_lim, lines = network.corridor.length_m, network.speed_limit_mps, [lt.stop_line_m for lt in network.lights]
    own = {vid: zone_trajectory(car, end_m) for vid, car in base.cars.items()}
    order = sorted(base.cars, key=lambda vid: base.cars[vid].depart_s)
    truth = Scenario("run", tuple(TimelineSignal(line, reds) for line, reds in zip(lines, base.reds)), 2.0 * end_m + 1e4)  # the lines where they are
    rows = []
    for n, vid in enumerate(order):
        scores = {mode: score_car(r.cars[vid], end_m, v_lim, params) if vid in r.cars else None for mode, r in results.items()}
        if not base.cars[vid].connected or any(s is None for s in scores.values()):
            continue
        row = {"vid": vid, **{f"{m}_{k}": getattr(s, k) for m, s in scores.items() for k in ("cost_usd", "stops", "time_s")}}
        if "advised" in results:
            row["advice"] = dict(results["advised"].cars[vid].advice)
        car_ahead = base.cars[order[n - 1]] if n > 0 else None  # its whole drive, past the zone's end
        ahead = None if car_ahead is None else Trajectory(*(np.asarray(a, dtype=float) for a in (car_ahead.t, car_ahead.x, car_ahead.v)))
        for key, start, late_s, behind in (("hindsight", -np.inf, 0.0, None), ("hindsight_from_approach", from_m, 0.0, None),
                                           ("hindsight_advisable", from_m, after_red_s, None), ("hindsight_behind", from_m, after_red_s, ahead)):  # fmt: skip
            reds = [[(a, min(b + late_s, nxt)) for (a, b), nxt in zip(light, [a for a, _ in light[1:]] + [np.inf])] for light in base.reds]
            best = hindsight_drive(own[vid], lines, reds, end_m, v_lim, params, from_m=start, ahead=behind)
            row[f"{key}_cost_usd"] = None if best is None else score_in_end_state(best, params, v_lim).cost_usd
            if key == "hindsight":
                zone_ahead = own.get(order[n - 1]) if n > 0 else None
                row["hindsight_runs_into_car_ahead"] = bool(best is not None and zone_ahead is not None and runs_into(best, zone_ahead))
                row["hindsight_red_at_true_lines"] = bool(best is not None and red_light_violations(best, truth))
        if vid in alone:  # the same car alone on the road (SUMO's driver, the same departure)
            drive = zone_trajectory(alone[vid][0], end_m)
            best = None if drive is None else hindsight_drive(drive, lines, alone[vid][1], end_m, v_lim, params)
            row["alone_cost_usd"] = None if drive is None else score_in_end_state(drive, params, v_lim).cost_usd
            row["hindsight_alone_cost_usd"] = None if best is None else score_in_end_state(best, params, v_lim).cost_usd
        rows.append(row)
    out = {"hindsight_rows": rows}
    others = [("ours", "advised"), ("glosa", "glosa")]
    for key in ("hindsight", "hindsight_from_approach", "hindsight_advisable", "hindsight_behind"):
        ok = [r for r in rows if r[f"{key}_cost_usd"] is not None]
        out[f"{key}_cars"] = len(ok)
        unadvised = sum(r["unadvised_cost_usd"] for r in ok)
        out[f"{key}_saving_frac"] = _neg(_frac(sum(r[f"{key}_cost_usd"] for r in ok), unadvised))
        for name, mode in others:
            if mode in results:
                out[f"{key}_{name}_saving_frac"] = _neg(_frac(sum(r[f"{mode}_cost_usd"] for r in ok), unadvised))
    alone_ok = [r for r in rows if r.get("hindsight_alone_cost_usd") is not None]
    out["hindsight_alone_cars"] = len(alone_ok)
    out["hindsight_alone_saving_frac"] = _neg(_frac(sum(r["hindsight_alone_cost_usd"] for r in alone_ok), sum(r["alone_cost_usd"] for r in alone_ok)))
    free = [r for r in rows if r["hindsight_cost_usd"] is not None and not r["hindsight_runs_into_car_ahead"]]
    out["hindsight_free_cars"] = len(free)
    out["hindsight_free_saving_frac"] = _neg(_frac(sum(r["hindsight_cost_usd"] for r in free), sum(r["unadvised_cost_usd"] for r in free)))
    return out


def alone_runs(network, setup, cars: dict, folder) -> dict:
    """Each of ``cars`` (vid -> its :class:`~ecodrive.traffic.sim.CarTrace`) alone on the road: an unadvised SUMO run
    with that car's scheduled departure only (the lights of a fixed-time plan are the same; an actuated controller
    serves that car and the cross streets alone); vid -> (its trace there, that run's reds)."""
    from dataclasses import replace

    from ecodrive.traffic.sim import run

    out = {}
    for vid, car in cars.items():
        r = run(network, replace(setup, departures_s=(car.depart_s,), connected=()), "unadvised", folder)
        if "main.0" in r.cars:
            out[vid] = (r.cars["main.0"], r.reds)
    return out


def evaluate(corridor: str, plan: str | None = None, control: str = "fixed", demand_vph_per_lane: float = 600.0, penetration_frac: float = 0.5,
             seed: int = 1, duration_s: float = 900.0, lanes: int = 1, cross_demand_vph: float | None = None, vehicle: str = "paper_54kwh",
             queue_aware: bool = True, blind: bool = False, spat_queue: bool = False, hindsight: bool = False, bound_only: bool = False) -> dict:  # fmt: skip
    """One scenario run three ways (see the module docstring): the summary; ``hindsight``: with the connected cars'
    hindsight bound (:func:`hindsight_summary`); ``bound_only``: the unadvised run alone and the bound (the bound
    needs no other run: ours and GLOSA are left out)."""
    from ecodrive.traffic.network import build_network
    from ecodrive.traffic.sim import RunSetup, run
    from spat_feed.road.corridors import load_corridor

    started = time.perf_counter()
    c = load_corridor(corridor)
    if cross_demand_vph is None:
        cross_demand_vph = 300.0 if control == "actuated" else 0.0
    setup = RunSetup(demand_vph_per_lane, penetration_frac, seed, duration_s, cross_demand_vph=cross_demand_vph, queue_aware=queue_aware,
                     spat_queue=spat_queue)  # fmt: skip
    modes = ("unadvised",) if bound_only else ("advised", "blind", "glosa", "unadvised") if blind else ("advised", "glosa", "unadvised")
    with tempfile.TemporaryDirectory(prefix="ecodrive-traffic-") as tmp:
        network = build_network(c, tmp, plan, control, lanes)
        results = {mode: run(network, setup, mode, tmp) for mode in modes}
        if hindsight or bound_only:
            alone = alone_runs(network, setup, {vid: car for vid, car in results["unadvised"].cars.items() if car.connected}, tmp)
    out = {} if bound_only else paired_summary(results, network, model_params(vehicle))
    if hindsight or bound_only:
        from advisory.advice.views import AdvisorParams
        from server.advising import approach_m

        advisor = AdvisorParams()
        out.update(hindsight_summary(results, network, model_params(vehicle), -approach_m(c, advisor, network.speed_limit_mps), advisor.green_margin_s,
                                     alone))  # fmt: skip
    out["setup"] = {"corridor": c.name, "plan": plan, "control": control, "lanes": lanes, "vehicle": vehicle, **asdict(setup)}
    if "advised" in results:
        out["queue_held_fixes"] = results["advised"].queue_held
    out["wall_s"] = round(time.perf_counter() - started, 2)
    return out


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="ecodrive traffic-eval", description=__doc__.split("\n\n")[0])
    ap.add_argument("--corridor", required=True, help="a corridor name (paper_s400, oakland_7th_westbound, ...) or file")
    ap.add_argument("--plan", default=None, help="a plan of the corridor by name, a paper timing (15_15, field_test) or a plan file (default: the corridor's default plan, else 15_15)")
    ap.add_argument("--control", choices=("fixed", "actuated"), default="fixed", help="fixed-time lights from the plan, or SUMO's actuated controller around it")
    ap.add_argument("--demand", type=float, required=True, metavar="VEH_PER_HOUR", help="corridor traffic, vehicles per hour per lane")
    ap.add_argument("--penetration", type=float, required=True, metavar="FRAC", help="share of the corridor's cars that are connected (0..1)")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--duration", type=float, default=900.0, help="seconds during which cars depart (default %(default)s)")
    ap.add_argument("--lanes", type=int, default=1)
    ap.add_argument("--cross-demand", type=float, default=None, help="each cross street, each way [veh/h] (default: 300 actuated, 0 fixed)")
    ap.add_argument("--vehicle", default="paper_54kwh", help="EV model preset for the scores (default %(default)s)")
    ap.add_argument("--queue-blind", action="store_true", help="the advised run without queue-aware advice (the advisor alone)")
    ap.add_argument("--compare-blind", action="store_true", help="a fourth run, queue-blind advice, reported as blind_* keys")
    ap.add_argument("--spat-queue", action="store_true", help="SUMO's lights publish each approach's jam as J2735 queueLength, as a controller with stop-line detectors can; queue-aware advice counts it first")
    ap.add_argument("--hindsight", action="store_true", help="each connected car's hindsight bound too (hindsight_* keys; a few seconds a car)")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    if not 0.0 <= args.penetration <= 1.0:
        ap.error("--penetration must be within 0..1")
    if args.demand < 0:
        ap.error("--demand must be >= 0")
    try:
        out = evaluate(args.corridor, args.plan, args.control, args.demand, args.penetration, args.seed, args.duration, args.lanes, args.cross_demand,
                       args.vehicle, not args.queue_blind, args.compare_blind, args.spat_queue, args.hindsight)  # fmt: skip
    except (OSError, KeyError, ValueError, RuntimeError) as exc:
        print(f"ecodrive traffic-eval: {exc}", file=sys.stderr)
        return 2
    if args.json:
        print(json.dumps(out, indent=2))
        return 0
    pct = lambda x: "n/a" if x is None else f"{100 * x:+.1f} %"  # noqa: E731
    print(f"{out['setup']['corridor']} ({args.control}), {args.demand:g} veh/h/lane, {100 * args.penetration:g} % connected, seed {args.seed}: "
          f"{out['advised_cars']} advised cars of {out['cars']}")  # fmt: skip
    print(f"  saving: ecodrive {pct(out['saving_frac'])}, GLOSA {pct(out['glosa_saving_frac'])} (cost against the same cars unadvised)")
    print(f"  stops per car: ecodrive {out['stops_per_advised_car']:.2f}, GLOSA {out['stops_per_glosa_car']:.2f}, unadvised {out['stops_per_unadvised_car']:.2f}")
    print(f"  time: advised cars {pct(out['time_change_frac'])}, the others {pct(out['others_time_change_frac'])} (energy {pct(out['others_energy_change_frac'])})")
    print(f"  red entries {out['red_entries']}, hard brakes {out['hard_brakes']} (advised cars)")
    if "hindsight_saving_frac" in out:
        print(f"  hindsight bound over {out['hindsight_cars']} of them: {pct(out['hindsight_saving_frac'])} (ours {pct(out['hindsight_ours_saving_frac'])}, "
              f"GLOSA {pct(out['hindsight_glosa_saving_frac'])}); from the approach {pct(out['hindsight_from_approach_saving_frac'])}, "
              f"2 s after each red too {pct(out['hindsight_advisable_saving_frac'])}, behind the car ahead too {pct(out['hindsight_behind_saving_frac'])}; "
              f"alone on the road {pct(out['hindsight_alone_saving_frac'])}")  # fmt: skip
    if "blind_saving_frac" in out:
        print(f"  queue-blind advice: saving {pct(out['blind_saving_frac'])}, stops per car {out['stops_per_blind_car']:.2f}, time {pct(out['blind_time_change_frac'])}, "
              f"the others {pct(out['blind_others_time_change_frac'])}")  # fmt: skip
    return 0


if __name__ == "__main__":
    sys.exit(main())
