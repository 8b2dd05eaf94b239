"""A corridor as a SUMO network: straight road, its lights at the stop-line stations, background traffic.

The corridor's route is laid straight along SUMO's x axis (``x = station + lead_in_m``): SUMO's car following and
lights need no curvature, and every position maps back to the corridor's own station and so to its real lat/lon
(:meth:`~spat_feed.road.corridors.Corridor.position`), which is what a connected car's phone sends. The road starts
``lead_in_m`` before the zone entry (queues at a first light near the entry fit on it; cars enter there) and runs
``tail_m`` past the zone's end. Edges break at every stop line and speed-limit change (each edge takes the lowest
limit over its stretch); ``lanes`` lanes each way of travel along the corridor, through movements only.

Each intersection is a SUMO traffic light (``tls`` id ``J<intersection id>``) joining the corridor with a cross
street (one lane each way, ``CROSS_M`` long on each side): the corridor's through movement is link 0 .. lanes - 1,
the cross street's two through movements the next two. Its stop line is the end of the corridor's incoming lane; the
network is built twice so that this end lies exactly at the intersection's ``stop_line_m`` (netconvert draws the
junction's area before the node: the first pass measures how far).

Programs (one per light, its corridor plan's cycle; :func:`light_phases`):

* ``fixed``: SUMO ``static`` logic from the light's :class:`~spat_feed.timing.plans.FixedTimePlan` (red, green,
  amber, the plan's offset on the Unix axis): the corridor's red is the cross street's green then its amber
  (``cross_amber_s``), then the corridor's green and amber. The program is positioned so that SUMO's state at
  simulation time ``t`` is the plan's at ``t0_unix_s + t`` (tested second by second).
* ``actuated``: SUMO's own ``actuated`` logic on the same phases (a plan without amber gets the ITE yellow change
  interval for the approach's limit out of its green: :func:`yellow_change_s`), each green between ``min_green_frac`` and
  ``max_green_frac`` of the plan's duration (at least ``MIN_GREEN_S``), extended by SUMO's induction loops while
  cars keep arriving (SUMO's defaults: ``max-gap`` 3 s, loops placed ``detector-gap`` 2 s of travel upstream).

Traffic (:func:`write_routes`): one SUMO ``flow`` per corridor direction at ``demand_vph_per_lane`` x ``lanes``
vehicles per hour, exponential headways (``period="exp(rate)"``, SUMO's Poisson arrivals), drawn from SUMO's own
random numbers (``--seed``); cross streets ``cross_demand_vph`` each way. One vehicle type for every car
(:data:`VTYPE`): the paper's regular driver's rates (accelerate 2 m/s², brake up to 4 m/s²), no random dawdling and
no speed deviation (``sigma`` 0, ``speedDev`` 0: every car wants exactly the limit), so that a saving measured is the
advice's and not SUMO's noise; SUMO's Krauss car following keeps every car behind the one ahead.
"""

from __future__ import annotations

import math
import os
import shutil
import subprocess
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path
from xml.sax.saxutils import quoteattr

from advisory.advice.views import AdvisorParams
from server.advising import approach_m
from spat_feed.road.corridors import Corridor
from spat_feed.timing.plans import FixedTimePlan
from spat_feed.transport.scenarios import make_scenario
from spat_feed.transport.simulator import shared_scenario

CROSS_M = 100.0
"""Length of each arm of a cross street. [m]"""
CROSS_SPEED_MPS = 50 / 3.6
MIN_GREEN_S = 5.0
"""Shortest green an actuated phase may give. [s]"""
VTYPE = dict(id="car", vClass="passenger", accel="2.0", decel="4.0", emergencyDecel="9.0", sigma="0", tau="1.0",
             length="5.0", minGap="2.5", speedFactor="1", speedDev="0")  # fmt: skip
"""Every car's SUMO type: the paper's regular driver's rates (Sec. 2: 2 m/s² up, at most 4 m/s² braking), SUMO's
passenger length and gaps, no dawdling, every car at the limit."""
DRIVEN_VTYPE = "car_driven"
"""The same car driven by the virtual driver (advised runs): SUMO's own driver goes on through the first 0.75 s of an
amber (``jmDriveAfterYellowTime``), so that the virtual driver, who sees the amber one step after SUMO, decides."""


def sumo_home() -> Path:
    """SUMO's installation (the ``eclipse-sumo`` wheel's ``sumo.SUMO_HOME``, else ``$SUMO_HOME``)."""
    try:
        import sumo

        return Path(sumo.SUMO_HOME)
    except ImportError:
        home = os.environ.get("SUMO_HOME")
        if not home:
            raise RuntimeError("SUMO is not installed: pip install 'ecodrive[traffic]' (eclipse-sumo, libsumo)") from None
        return Path(home)


def sumo_binary(name: str) -> str:
    """Path of one of SUMO's programs (``netconvert``, ``sumo``)."""
    path = sumo_home() / "bin" / name
    if path.exists():
        return str(path)
    found = shutil.which(name)
    if found is None:
        raise RuntimeError(f"SUMO's {name} not found under {sumo_home()} or on PATH")
    return found


@dataclass(frozen=True, slots=True)
class Light:
    """One corridor light in SUMO: J2735 ids, SUMO's tls id and link, stop line, its corridor plan."""

    intersection_id: int
    signal_group: int
    name: str
    tls_id: str
    link_index: int  # SUMO link of the corridor's through movement (lane 0; every lane's link shows the same state)
    stop_line_m: float  # station
    plan: FixedTimePlan  # on the Unix axis


@dataclass(frozen=True, slots=True)
class TrafficNetwork:
    """A built network: files, geometry and lights. Stations = SUMO x - ``x0_m``."""

    corridor: Corridor
    folder: Path
    net_file: Path
    control: str  # "fixed" or "actuated"
    lanes: int
    lead_in_m: float
    tail_m: float
    t0_unix_s: float  # Unix instant of simulation time 0
    lights: tuple[Light, ...]
    main_edges: tuple[str, ...]
    cross_routes: tuple[tuple[str, str], ...]  # (incoming, outgoing) edge of each cross street direction
    speed_limit_mps: float  # the zone's lowest limit (the DP's and the regular driver's)

    @property
    def x0_m(self) -> float:
        return self.lead_in_m

    def station(self, x_m: float) -> float:
        return x_m - self.lead_in_m


def light_plans(corridor: Corridor, timing: str | None, t0_unix_s: float) -> dict[tuple[int, int], FixedTimePlan]:
    """Every light's fixed-time plan on the Unix axis at ``t0_unix_s``: the corridor's default plan (or, without
    plans, the service's shared ``15_15``) when ``timing`` is None; else a plan of the corridor by name, a paper
    timing by name (relative to ``t0_unix_s``) or a plan file. ``ValueError`` for a light without a fixed plan."""
    scenario = shared_scenario(corridor, t0_unix_s) if timing is None else make_scenario(corridor, timing, t0_unix_s)
    plans = scenario.fixed_plans()
    missing = [ix.id for ix in corridor.intersections if (ix.id, ix.signal_groups[0].id) not in plans]
    if missing:
        raise ValueError(f"intersection(s) {missing} of {corridor.name!r} have no fixed-time plan in {scenario.timing.name!r} (live lights cannot run in SUMO)")
    return plans


def yellow_change_s(speed_mps: float, perception_s: float = 1.0, decel_mps2: float = 3.05) -> float:
    """The ITE yellow change interval for an approach speed on the level: ``perception_s + v / (2 decel)`` (ITE,
    *Traffic Control Devices Handbook*, 2nd ed., 2013, ch. 13: 1 s perception-reaction, 10 ft/s² = 3.05 m/s²). [s]

    Examples
    --------
    >>> round(yellow_change_s(24.5872), 1), round(yellow_change_s(13.4112), 1)
    (5.0, 3.2)
    """
    return round(perception_s + speed_mps / (2.0 * decel_mps2), 1)


def light_phases(plan: FixedTimePlan, t0_unix_s: float, control: str, lanes: int, cross_amber_s: float = 3.0,
                 min_green_frac: float = 0.5, max_green_frac: float = 1.5, yellow_s: float = 0.0) -> tuple[list[dict], float]:  # fmt: skip
    """SUMO phases of one light (dicts of ``tlLogic/phase`` attributes) and the program's ``offset``.

    Order: cross green (the corridor's red), cross amber, corridor green, corridor amber (if any). SUMO starts a
    static program at phase 0 at simulation time ``offset``... counted backwards: at time 0 it is ``-offset`` into
    its cycle, so the offset is minus the plan's time in cycle at ``t0_unix_s``.

    ``actuated`` with a plan that has no amber (the paper's timings): the corridor's green ends in a ``yellow_s``
    amber taken from the green's end (the cycle stays the plan's). A fixed-time plan's green ends when its SPaT says,
    to the second; an actuated green may end at any second after its minimum, and without an amber a car a few
    metres from the line then meets a red no one can stop for (SUMO: 31 hard brakes of 196 advised cars, 9-32 m/s²,
    paper_s400 at 900 veh/h). No real controller goes from green to red."""
    red, green, amber = plan.red_s, plan.green_s, plan.amber_s
    if control == "actuated" and amber <= 0.0 and yellow_s > 0.0:
        green, amber = green - yellow_s, yellow_s
    ca = min(cross_amber_s, red / 4.0)
    main = {"r": "r" * lanes, "G": "G" * lanes, "y": "y" * lanes}
    phases = [
        dict(duration=red - ca, state=main["r"] + "GG", kind="cross_green"),
        dict(duration=ca, state=main["r"] + "yy", kind="amber"),
        dict(duration=green, state=main["G"] + "rr", kind="main_green"),
    ]
    if amber > 0:
        phases.append(dict(duration=amber, state=main["y"] + "rr", kind="amber"))
    if control == "actuated":
        for p in phases:
            if p["kind"] != "amber":
                p["minDur"] = max(MIN_GREEN_S, min_green_frac * p["duration"])
                p["maxDur"] = max(p["minDur"], max_green_frac * p["duration"])
    elif control != "fixed":
        raise ValueError(f"control must be 'fixed' or 'actuated', not {control!r}")
    in_cycle = (t0_unix_s - plan.offset_s) % plan.cycle_s  # the plan's red starts at offset_s: phase 0 starts with it
    return phases, -in_cycle


def _fmt(x: float) -> str:
    return f"{x:.3f}".rstrip("0").rstrip(".") if math.isfinite(x) else str(x)


def _cuts(corridor: Corridor, stop_lines: list[float], length_m: float) -> list[float]:
    starts, _, _ = corridor.limit_profile()
    out = sorted({0.0, *stop_lines, *(s for s in starts.tolist() if 0.0 < s < length_m)})
    return out


def build_network(
    corridor: Corridor,
    folder: str | Path,
    timing: str | None = None,
    control: str = "fixed",
    lanes: int = 1,
    lead_in_m: float = 300.0,
    tail_m: float = 200.0,
    t0_unix_s: float = 1_714_590_000.0,
) -> TrafficNetwork:
    """Build ``corridor``'s SUMO network in ``folder`` (see the module docstring). ``t0_unix_s`` is the Unix instant
    of simulation time 0 (default 2024-05-01 19:00 UTC: a Wednesday, noon in California, 21:00 in Paris)."""
    if lanes < 1:
        raise ValueError("lanes must be >= 1")
    if not corridor.intersections:
        raise ValueError(f"corridor {corridor.name!r} has no signalised intersection")
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    plans = light_plans(corridor, timing, t0_unix_s)
    limit = corridor.zone_speed_limit_mps()
    stops = [ix.stop_line_m for ix in corridor.intersections]
    shift = {ix.id: 0.0 for ix in corridor.intersections}  # node x - stop line x, measured by the first pass
    for attempt in range(2):
        net = _write_and_convert(corridor, folder, plans, control, lanes, lead_in_m, tail_m, t0_unix_s, shift)
        ends = _stop_line_x(net, corridor, lanes)
        if attempt == 0:
            shift = {k: (stops[i] + lead_in_m) - ends[k] for i, k in enumerate(shift)}
    for ix in corridor.intersections:
        if abs(ends[ix.id] - (ix.stop_line_m + lead_in_m)) > 0.05:
            raise RuntimeError(f"netconvert put the stop line of {ix.id} at station {ends[ix.id] - lead_in_m:.2f}, not {ix.stop_line_m:.2f}")
    lights = tuple(
        Light(ix.id, ix.signal_groups[0].id, ix.name, f"J{ix.id}", 0, ix.stop_line_m, plans[(ix.id, ix.signal_groups[0].id)])
        for ix in corridor.intersections
    )
    edges = _main_edge_ids(corridor, lanes, lead_in_m, tail_m)
    cross = tuple((f"c{ix.id}{d}_in", f"c{ix.id}{d}_out") for ix in corridor.intersections for d in ("s", "n"))
    return TrafficNetwork(corridor, folder, net, control, lanes, lead_in_m, tail_m, t0_unix_s, lights, edges, cross, limit)


def _main_nodes(corridor: Corridor, lead_in_m: float, tail_m: float) -> list[tuple[str, float, int | None]]:
    """(node id, station, intersection id or None) along the corridor, from the lead-in's start to the tail's end."""
    stops = {ix.stop_line_m: ix.id for ix in corridor.intersections}
    nodes = [("start", -lead_in_m, None)]
    for k, s in enumerate(_cuts(corridor, list(stops), corridor.length_m)):
        nodes.append((f"J{stops[s]}" if s in stops else f"n{k}", s, stops.get(s)))
    nodes += [("zone_end", corridor.length_m, None), ("end", corridor.length_m + tail_m, None)]
    return nodes


def _main_edge_ids(corridor: Corridor, lanes: int, lead_in_m: float, tail_m: float) -> tuple[str, ...]:
    nodes = _main_nodes(corridor, lead_in_m, tail_m)
    return tuple(f"m{k}" for k in range(len(nodes) - 1))


def _write_and_convert(corridor, folder: Path, plans, control, lanes, lead_in_m, tail_m, t0_unix_s, shift) -> Path:
    nodes = _main_nodes(corridor, lead_in_m, tail_m)
    starts, limits, _ = corridor.limit_profile()
    approach = approach_m(corridor, AdvisorParams(), corridor.zone_speed_limit_mps())  # the service advises from there (server.advising)
    nod = ["<nodes>"]
    for nid, s, ix in nodes:
        x = s + lead_in_m + (shift[ix] if ix is not None else 0.0)
        if ix is None:
            nod.append(f'  <node id="{nid}" x="{_fmt(x)}" y="0" type="priority"/>')
        else:
            nod.append(f'  <node id="{nid}" x="{_fmt(x)}" y="0" type="traffic_light" tl="{nid}"/>')
            nod.append(f'  <node id="c{ix}n" x="{_fmt(x)}" y="{_fmt(CROSS_M)}" type="priority"/>')
            nod.append(f'  <node id="c{ix}s" x="{_fmt(x)}" y="{_fmt(-CROSS_M)}" type="priority"/>')
    nod.append("</nodes>")
    edg = ["<edges>"]
    con = ["<connections>"]
    for k in range(len(nodes) - 1):
        (a, sa, _), (b, sb, _) = nodes[k], nodes[k + 1]
        lo, hi = max(sa, 0.0), min(sb, corridor.length_m)
        speed = corridor.speed_limit_mps_over(lo, max(hi, lo)) if hi > lo else corridor.speed_limit_mps_over(min(max(sa, 0.0), corridor.length_m), min(max(sa, 0.0), corridor.length_m))
        edg.append(f'  <edge id="m{k}" from="{a}" to="{b}" numLanes="{lanes}" speed="{_fmt(speed)}" priority="3"/>')
        if k + 1 < len(nodes) - 1:
            for lane in range(lanes):
                con.append(f'  <connection from="m{k}" to="m{k + 1}" fromLane="{lane}" toLane="{lane}"/>')
    tll = ["<tlLogics>"]
    for k, (nid, s, ix) in enumerate(nodes):
        if ix is None:
            continue
        for d, (frm, to) in (("s", (f"c{ix}n", f"c{ix}s")), ("n", (f"c{ix}s", f"c{ix}n"))):
            edg.append(f'  <edge id="c{ix}{d}_in" from="{frm}" to="{nid}" numLanes="1" speed="{_fmt(CROSS_SPEED_MPS)}" priority="1"/>')
            edg.append(f'  <edge id="c{ix}{d}_out" from="{nid}" to="{to}" numLanes="1" speed="{_fmt(CROSS_SPEED_MPS)}" priority="1"/>')
            con.append(f'  <connection from="c{ix}{d}_in" to="c{ix}{d}_out" fromLane="0" toLane="0"/>')
        ixspec = corridor.intersection(ix)
        yellow = yellow_change_s(corridor.speed_limit_mps_over(max(s - 1.0, 0.0), s))
        phases, offset = light_phases(plans[(ix, ixspec.signal_groups[0].id)], t0_unix_s, control, lanes, yellow_s=yellow)
        kind = "static" if control == "fixed" else "actuated"
        tll.append(f'  <tlLogic id="{nid}" type="{kind}" programID="0" offset="{_fmt(offset)}">')
        before = max((i.stop_line_m for i in corridor.intersections if i.stop_line_m < s), default=-approach)
        tll.append(f'    <param key="device.glosa.range" value="{_fmt(s - before)}"/>')  # GLOSA hears it where the service advises for it
        for p in phases:
            extra = "".join(f' {key}="{_fmt(p[key])}"' for key in ("minDur", "maxDur") if key in p)
            tll.append(f'    <phase duration="{_fmt(p["duration"])}" state="{p["state"]}"{extra} name={quoteattr(p["kind"])}/>')
        tll.append("  </tlLogic>")
        for lane in range(lanes):
            tll.append(f'  <connection from="m{k - 1}" to="m{k}" fromLane="{lane}" toLane="{lane}" tl="{nid}" linkIndex="{lane}"/>')
        tll.append(f'  <connection from="c{ix}s_in" to="c{ix}s_out" fromLane="0" toLane="0" tl="{nid}" linkIndex="{lanes}"/>')
        tll.append(f'  <connection from="c{ix}n_in" to="c{ix}n_out" fromLane="0" toLane="0" tl="{nid}" linkIndex="{lanes + 1}"/>')
    edg.append("</edges>")
    con.append("</connections>")
    tll.append("</tlLogics>")
    files = {}
    for ext, lines in (("nod", nod), ("edg", edg), ("con", con), ("tll", tll)):
        files[ext] = folder / f"corridor.{ext}.xml"
        files[ext].write_text("\n".join(lines) + "\n", encoding="utf-8")
    net = folder / "corridor.net.xml"
    cmd = [sumo_binary("netconvert"), "-n", str(files["nod"]), "-e", str(files["edg"]), "-x", str(files["con"]), "-i", str(files["tll"]),
           "-o", str(net), "--no-turnarounds", "true", "--offset.disable-normalization", "true", "--no-warnings", "true",
           "--tls.discard-simple", "false", "--geometry.remove", "false"]  # fmt: skip
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    if done.returncode != 0:
        raise RuntimeError(f"netconvert failed ({done.returncode}): {done.stderr.strip()[-2000:]}")
    return net


def _stop_line_x(net: Path, corridor: Corridor, lanes: int) -> dict[int, float]:
    """x of the end of each light's incoming corridor lane 0 (the stop line) in the built network."""
    root = ET.parse(net).getroot()
    ends = {}
    conns = {(c.get("from"), c.get("tl")) for c in root.iter("connection") if c.get("tl")}
    lane_x = {}
    for edge in root.iter("edge"):
        if edge.get("function") == "internal":
            continue
        for lane in edge.iter("lane"):
            if lane.get("index") == "0":
                pts = [tuple(map(float, p.split(","))) for p in lane.get("shape").split()]
                lane_x[edge.get("id")] = pts[-1][0]
    for ix in corridor.intersections:
        frm = next(f for f, tl in conns if tl == f"J{ix.id}" and f.startswith("m"))
        ends[ix.id] = lane_x[frm]
    return ends


def write_routes(network: TrafficNetwork, path: str | Path, demand_vph_per_lane: float, duration_s: float, cross_demand_vph: float = 0.0,
                 departures_s: tuple[float, ...] = ()) -> Path:  # fmt: skip
    """SUMO routes: the vehicle type, the corridor's flow (``main``: ``demand_vph_per_lane`` per lane, Poisson) and
    each cross street's (``cross<k>``), departing for ``duration_s``. ``departures_s``: instead of the corridor's flow,
    cars ``main.0``, ``main.1``, ... departing at these instants (a scenario built car by car, for tests)."""
    path = Path(path)
    attrs = " ".join(f'{k}="{v}"' for k, v in VTYPE.items())
    driven = " ".join(f'{k}="{v}"' for k, v in {**VTYPE, "id": DRIVEN_VTYPE, "jmDriveAfterYellowTime": "0.75"}.items())
    out = ["<routes>", f"  <vType {attrs}/>", f"  <vType {driven}/>", f'  <route id="main" edges="{" ".join(network.main_edges)}"/>']
    for k, (a, b) in enumerate(network.cross_routes):
        out.append(f'  <route id="cross{k}" edges="{a} {b}"/>')
    rate = demand_vph_per_lane * network.lanes / 3600.0
    for k, t in enumerate(sorted(departures_s)):
        out.append(f'  <vehicle id="main.{k}" type="car" route="main" depart="{_fmt(t)}" departLane="best" departSpeed="max" departPos="base"/>')
    if rate > 0 and not departures_s:
        out.append(f'  <flow id="main" type="car" route="main" begin="0" end="{_fmt(duration_s)}" period="exp({rate:.6g})" '
                   f'departLane="best" departSpeed="max" departPos="base"/>')  # fmt: skip
    if cross_demand_vph > 0:
        for k in range(len(network.cross_routes)):
            out.append(f'  <flow id="cross{k}" type="car" route="cross{k}" begin="0" end="{_fmt(duration_s)}" period="exp({cross_demand_vph / 3600.0:.6g})" '
                       f'departLane="best" departSpeed="max"/>')  # fmt: skip
    out.append("</routes>")
    path.write_text("\n".join(out) + "\n", encoding="utf-8")
    return path
