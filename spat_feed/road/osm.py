"""Corridors from OpenStreetMap data, offline: route along a named street, stop lines from its signals.

``corridors_from_osm(path, street)`` reads an OSM XML file (``.osm``, ``.osm.bz2``, ``.osm.gz``; the
standard library's ``xml.etree.ElementTree.iterparse``) or a ``.pbf`` (with the optional ``osmium``
package: ``pip install 'ecodrive[osm]'``) and returns one :class:`~spat_feed.road.corridors.Corridor` per
direction of travel. What it does, by OSM's tag meanings (https://wiki.openstreetmap.org):

1. **Ways**: vehicular ``highway=*`` ways (``ROAD_CLASSES``) whose ``name`` (or ``alt_name``,
   ``official_name``) equals ``street`` (case and spacing ignored). A name that matches nothing is an
   error listing the closest names in the file.
2. **Directions**: ``oneway=yes/true/1`` (and ``junction=roundabout``, ``highway=motorway``) allow travel
   along the way's node order only, ``oneway=-1`` against it; ``reversible``/``alternating`` ways are left
   out. Ways are chained at shared nodes; a route is the longest chain that can be driven in one direction
   without a U-turn or revisiting a node. A two-way street gives a route each way; a dual carriageway (two
   ``oneway`` ways) gives one route per carriageway. Routes are named by their compass direction
   (``westbound``, ...), the route from the first to the last node.
3. **Signals**: nodes on the route tagged ``highway=traffic_signals``. With ``traffic_signals:direction``
   (``forward``/``backward``, relative to the way) a node applies only to travel in that direction, and is
   taken as mapped at the stop line. Without it, a node that is a junction with another road (shared by a
   way of another street) is the intersection's centre: the stop line is placed
   ``crossing half-width + STOP_LINE_GAP_M`` before it (half the crossing road's ``width``, or its ``lanes``
   x ``LANE_WIDTH_M``, ``DEFAULT_LANES`` if untagged); a node that is no junction is taken as the stop line.
   A signal tagged only on the other carriageway of a crossing dual carriageway counts for the route's
   junction with that cross street when a crossing way links them within ``MERGE_M``. Signal nodes within
   ``MERGE_M`` of each other along the route (the two nodes of a dual-carriageway crossing) are one
   intersection: one stop line, at the first. Pedestrian-crossing signals (``highway=crossing`` +
   ``crossing=traffic_signals``) are left out (push-button, no fixed plan). Intersection ids: one per
   physical intersection, the same in both directions, counting up (1, 2, ...) along the first route (the
   longest; of two as long, the one heading north or east), so the opposite route meets them counting down;
   an intersection only the opposite route has is numbered where it lies along the first. The order of the
   file's nodes and ways changes nothing. Signal group 2 for the first route and 6 for the opposite one
   (NEMA main-street through phases). Replace them with the operator's J2735 ids to use a live SPaT feed.
4. **Speed limits** per way from ``maxspeed`` (``maxspeed:forward``/``:backward`` by direction):
   ``"50"`` km/h, ``"25 mph"``, ``"50 km/h"``, ``"walk"``, country codes (``"US:urban"``, ``"DE:rural"``,
   ... the zone part mapped by ``ZONE_LIMITS_KMH``), ``"none"`` and anything unreadable -> the default of
   the way's class (``CLASS_LIMITS_KMH`` / ``CLASS_LIMITS_MPH`` by units); several values ``"50;30"``: the
   lowest. Grades from numeric ``incline`` tags (``"5%"``), signed by direction.
5. **Units** (spoken advice): ``imperial`` when a ``maxspeed`` is in mph, or the route lies in the USA or the
   UK (coarse bounding boxes), else ``metric``; ``units=`` overrides.
"""

from __future__ import annotations

import bz2
import difflib
import gzip
import math
import re
import xml.etree.ElementTree as ET
from collections import defaultdict
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

from spat_feed.road.corridors import (
    SCHEMA_VERSION,
    WGS84,
    Corridor,
    IntersectionSpec,
    LatLon,
    RoadSource,
    RoutePoint,
    Segment,
    SignalGroupSpec,
)

MPH = 0.44704
KMH = 1 / 3.6

ROAD_CLASSES = frozenset({
    "motorway", "trunk", "primary", "secondary", "tertiary", "unclassified", "residential", "living_street", "service", "road",
    "motorway_link", "trunk_link", "primary_link", "secondary_link", "tertiary_link",
})  # fmt: skip
"""``highway=*`` values a car drives on (OSM wiki, Key:highway); paths, footways and the like are left out."""

CLASS_LIMITS_KMH = {
    "motorway": 110, "trunk": 70, "primary": 50, "secondary": 50, "tertiary": 50, "unclassified": 50, "residential": 30,
    "living_street": 20, "service": 20, "road": 50,
}  # fmt: skip
"""Default limits where a way has no usable ``maxspeed`` (metric countries). Signalised corridors lie in
built-up areas: the common urban limit (50 km/h; 30 on residential streets, 20 in living streets and
service roads, as in many European cities), motorways 110. Our choice; documented in docs/CORRIDORS.md. [km/h]"""

CLASS_LIMITS_MPH = {
    "motorway": 65, "trunk": 45, "primary": 35, "secondary": 30, "tertiary": 25, "unclassified": 25, "residential": 25,
    "living_street": 15, "service": 15, "road": 25,
}  # fmt: skip
"""Same for imperial countries (US urban practice: 25 mph on residential and business streets, the
California prima facie limit; 30-35 mph on arterials). [mph]"""

ZONE_LIMITS_KMH = {"urban": 50, "rural": 90, "motorway": 130, "trunk": 110, "living_street": 20, "walk": 7, "zone30": 30, "zone20": 20}
"""Implicit limits named by country codes (``DE:urban``...), by zone, for metric countries (the OSM wiki's
"Default speed limits" table, most common value). [km/h]"""
ZONE_LIMITS_MPH = {"urban": 25, "rural": 55, "motorway": 65, "trunk": 55, "living_street": 15, "walk": 4, "nsl_single": 60, "nsl_dual": 70}
"""Same for US/UK codes (``US:urban`` 25 mph; ``GB:nsl_single`` 60, ``GB:nsl_dual`` 70 mph). [mph]"""

LANE_WIDTH_M = 3.3
"""Width of a lane where a crossing road's ``width`` is not tagged (between the usual 3.0 and 3.6 m). [m]"""
DEFAULT_LANES = 2
"""Lanes of a crossing road without a ``lanes`` tag (one each way; a oneway road: 1). [-]"""
STOP_LINE_GAP_M = 4.0
"""Stop line to the crossing road's edge: a 3 m crosswalk plus the 1.2 m (4 ft) set-back of MUTCD 3B.16. [m]"""
MERGE_M = 30.0
"""Signal nodes closer than this along the route are one intersection (dual-carriageway crossings). [m]"""
MIN_APPROACH_M = 1.0
"""A stop line must lie at least this far inside the route (else the light is left out, with a note). [m]"""

IMPERIAL_BOXES = (
    (24.4, 49.5, -125.0, -66.9),  # contiguous USA
    (51.0, 71.5, -180.0, -129.9),  # Alaska
    (18.8, 22.3, -160.3, -154.7),  # Hawaii
    (49.8, 60.9, -8.7, 1.8),  # United Kingdom
)
"""(lat min, lat max, lon min, lon max) where spoken speeds default to mph: a coarse guess; ``units=`` overrides."""


class OsmError(ValueError):
    """An OSM file or street that cannot give a corridor; the message says why."""


@dataclass
class OsmData:
    """What the import needs from a file: the street's ways, the ways touching them, their nodes."""

    street_ways: list[tuple[int, list[int], dict[str, str]]] = field(default_factory=list)
    other_ways: list[tuple[int, list[int], dict[str, str]]] = field(default_factory=list)  # roads touching the street
    nodes: dict[int, tuple[float, float]] = field(default_factory=dict)  # id -> (lat, lon)
    node_tags: dict[int, dict[str, str]] = field(default_factory=dict)
    names: set[str] = field(default_factory=set)  # every road name in the file (for suggestions)


def _norm(name: str) -> str:
    return " ".join(name.casefold().split())


def _names(tags: dict[str, str]) -> list[str]:
    return [tags[k] for k in ("name", "alt_name", "official_name") if k in tags]


def _is_road(tags: dict[str, str]) -> bool:
    return tags.get("highway") in ROAD_CLASSES and tags.get("area") != "yes"


def _open(path: Path):
    name = path.name.lower()
    if name.endswith(".bz2"):
        return bz2.open(path, "rb")
    if name.endswith(".gz"):
        return gzip.open(path, "rb")
    return path.open("rb")


def _xml_elements(path: Path) -> Iterator[tuple[str, dict[str, str], list[int], dict[str, str]]]:
    """(kind, attributes, node refs, tags) of every node and way of an OSM XML file, streamed."""
    try:
        with _open(path) as fh:
            for _event, elem in ET.iterparse(fh, events=("end",)):
                if elem.tag in ("node", "way"):
                    tags = {t.get("k"): t.get("v") for t in elem.iter("tag")}
                    refs = [int(nd.get("ref")) for nd in elem.iter("nd")] if elem.tag == "way" else []
                    yield elem.tag, dict(elem.attrib), refs, tags
                    elem.clear()
                elif elem.tag in ("relation",):
                    elem.clear()
    except ET.ParseError as exc:
        raise OsmError(f"{path}: not valid OSM XML ({exc})") from None
    except (OSError, EOFError) as exc:
        raise OsmError(f"{path}: cannot read ({exc})") from None


def _pbf_elements(path: Path) -> Iterator[tuple[str, dict[str, str], list[int], dict[str, str]]]:
    try:
        import osmium
    except ImportError:
        raise OsmError(f"{path}: reading .pbf needs the optional 'osmium' package (pip install 'ecodrive[osm]'), or convert to .osm.bz2") from None
    for obj in osmium.FileProcessor(str(path)):
        tags = {t.k: t.v for t in obj.tags}
        if obj.is_node():
            yield "node", {"id": str(obj.id), "lat": str(obj.location.lat), "lon": str(obj.location.lon)}, [], tags
        elif obj.is_way():
            yield "way", {"id": str(obj.id)}, [n.ref for n in obj.nodes], tags


def _elements(path: Path):
    return _pbf_elements(path) if path.name.lower().endswith(".pbf") else _xml_elements(path)


def read_osm(path: str | Path, street: str) -> OsmData:
    """Two passes over the file: the street's ways first, then their nodes, the signal nodes and the roads
    that touch them (so a city extract needs little memory)."""
    path = Path(path)
    if not path.is_file():
        raise OsmError(f"{path}: no such file")
    want = _norm(street)
    data = OsmData()
    for kind, _attrs, refs, tags in _elements(path):
        if kind != "way" or not _is_road(tags):
            continue
        data.names.update(_names(tags))
        if any(_norm(n) == want for n in _names(tags)):
            data.street_ways.append((int(_attrs["id"]), refs, tags))
    if not data.street_ways:
        close = difflib.get_close_matches(street, sorted(data.names), n=5, cutoff=0.5)
        hint = f"; closest names: {', '.join(close)}" if close else f"; the file has {len(data.names)} named roads"
        raise OsmError(f"{path}: no road named {street!r}{hint}")
    on_street = {n for _, refs, _ in data.street_ways for n in refs}
    street_ids = {w for w, _, _ in data.street_ways}
    for kind, attrs, refs, tags in _elements(path):
        if kind == "node":
            nid = int(attrs["id"])
            if nid in on_street or tags.get("highway") == "traffic_signals":
                data.nodes[nid] = (float(attrs["lat"]), float(attrs["lon"]))
                if tags:
                    data.node_tags[nid] = tags
        elif _is_road(tags) and int(attrs["id"]) not in street_ids and on_street.intersection(refs):
            data.other_ways.append((int(attrs["id"]), refs, tags))
    missing = on_street - data.nodes.keys()
    if missing:
        raise OsmError(f"{path}: {len(missing)} node(s) of {street!r} are missing from the file (an extract cut without complete ways?)")
    return data


# --------------------------------------------------------------------------------------------------
# Tags


def parse_maxspeed(value: str | None, highway: str, imperial: bool) -> tuple[float, str]:
    """Speed limit [m/s] and how it was read, from a ``maxspeed`` value (module docstring, step 4).

    Examples
    --------
    >>> [round(parse_maxspeed(v, "secondary", False)[0], 3) for v in ("50", "25 mph", "30 km/h", "50;30", "walk")]
    [13.889, 11.176, 8.333, 8.333, 1.944]
    >>> round(parse_maxspeed("US:urban", "secondary", True)[0], 3), parse_maxspeed("none", "primary", False)[1]
    (11.176, 'maxspeed=none: primary default 50 km/h')
    """
    default_kmh, default_unit = (CLASS_LIMITS_MPH.get(highway, 25) * MPH, "mph") if imperial else (CLASS_LIMITS_KMH.get(highway, 50) * KMH, "km/h")

    def fallback(why: str) -> tuple[float, str]:
        shown = default_kmh / (MPH if default_unit == "mph" else KMH)
        return default_kmh, f"{why}: {highway} default {shown:.0f} {default_unit}"

    if value is None or not value.strip():
        return fallback("no maxspeed")
    found = []
    for part in value.split(";"):
        part = part.strip().lower()
        m = re.fullmatch(r"(\d+(?:\.\d+)?)\s*(mph|km/h|kmh|kph|knots)?", part)
        if m:
            number = float(m.group(1))
            unit = m.group(2) or "km/h"
            found.append(number * (MPH if unit == "mph" else 0.514444 if unit == "knots" else KMH))
        elif part == "walk":
            found.append(ZONE_LIMITS_KMH["walk"] * KMH)
        elif ":" in part:
            country, zone = part.split(":", 1)
            table, unit = (ZONE_LIMITS_MPH, MPH) if country in ("us", "gb", "uk") else (ZONE_LIMITS_KMH, KMH)
            if zone in table:
                found.append(table[zone] * unit)
    if not found or value.strip().lower() in ("none", "signals", "variable"):
        return fallback(f"maxspeed={value}")
    return min(found), f"maxspeed={value}"


def _incline_frac(value: str | None) -> float:
    """A numeric ``incline`` (``"5%"``, ``"-3 %"``, ``"4°"``) as rise over run along the way; else 0."""
    if not value:
        return 0.0
    m = re.fullmatch(r"\s*(-?\d+(?:\.\d+)?)\s*(%|°)?\s*", value)
    if not m:
        return 0.0
    x = float(m.group(1))
    return math.tan(math.radians(x)) if m.group(2) == "°" else x / 100.0


def _direction(tags: dict[str, str]) -> tuple[bool, bool] | None:
    """(forward allowed, backward allowed) along the way's node order; None if unusable."""
    oneway = tags.get("oneway", "").lower()
    if oneway in ("reversible", "alternating"):
        return None
    if oneway in ("yes", "true", "1"):
        return True, False
    if oneway in ("-1", "reverse"):
        return False, True
    if oneway in ("no", "false", "0"):
        return True, True
    implied = tags.get("junction") in ("roundabout", "circular") or tags.get("highway") == "motorway"
    return (True, False) if implied else (True, True)


def _width_m(tags: dict[str, str]) -> float:
    """Carriageway width of a road: ``width`` if numeric, else lanes x ``LANE_WIDTH_M``. [m]"""
    m = re.fullmatch(r"\s*(\d+(?:\.\d+)?)\s*(m)?\s*", tags.get("width", ""))
    if m:
        return float(m.group(1))
    try:
        lanes = int(tags["lanes"])
    except (KeyError, ValueError):
        lanes = 1 if _direction(tags) in ((True, False), (False, True)) else DEFAULT_LANES
    return max(lanes, 1) * LANE_WIDTH_M


# --------------------------------------------------------------------------------------------------
# Routes


@dataclass(frozen=True)
class Edge:
    u: int
    v: int
    way: int
    forward: bool  # along the way's node order


@dataclass
class Route:
    """A drivable chain of the street's ways: nodes in travel order and the edge into each."""

    nodes: list[int]
    edges: list[Edge]
    length_m: float


def _dist_m(a: tuple[float, float], b: tuple[float, float]) -> float:
    return float(WGS84.inv(a[1], a[0], b[1], b[0])[2])


def _azimuth(a: tuple[float, float], b: tuple[float, float]) -> float:
    return float(WGS84.inv(a[1], a[0], b[1], b[0])[0]) % 360.0


def compass(azimuth_deg: float) -> str:
    """``northbound``, ``eastbound``, ``southbound`` or ``westbound`` for a direction of travel.

    Examples
    --------
    >>> compass(280.0), compass(10.0), compass(135.1)
    ('westbound', 'northbound', 'southbound')
    """
    return ("northbound", "eastbound", "southbound", "westbound")[int(((azimuth_deg + 45.0) % 360.0) // 90.0)]


def street_routes(data: OsmData, max_steps: int = 200_000) -> list[Route]:
    """The longest drivable route along the street, and the longest one in the opposite direction (if any).

    Longest simple path over the street's directed edges, no U-turns, found by depth-first search from
    every node where a route can begin (no way in, or an end of the street), over chains contracted
    between branch nodes; ``max_steps`` bounds the search on odd networks (the best found is kept).
    """
    nodes = data.nodes
    out_edges: dict[int, list[Edge]] = defaultdict(list)
    und: dict[int, set[int]] = defaultdict(set)
    for way, refs, tags in data.street_ways:
        allowed = _direction(tags)
        if allowed is None:
            continue
        for a, b in zip(refs, refs[1:]):
            if a == b:
                continue
            und[a].add(b)
            und[b].add(a)
            if allowed[0]:
                out_edges[a].append(Edge(a, b, way, True))
            if allowed[1]:
                out_edges[b].append(Edge(b, a, way, False))
    if not out_edges:
        raise OsmError("the street has no way a car may drive along")
    length = {}
    for edges in out_edges.values():
        for e in edges:
            length[(e.u, e.v, e.way)] = _dist_m(nodes[e.u], nodes[e.v])
    has_in = {e.v for edges in out_edges.values() for e in edges}
    starts = [n for n in und if n in out_edges and (n not in has_in or len(und[n]) == 1)] or list(out_edges)
    best: list[tuple[float, list[Edge]]] = []
    steps = 0
    for s in starts:
        stack: list[tuple[int, list[Edge], float, frozenset[int]]] = [(s, [], 0.0, frozenset({s}))]
        while stack and steps < max_steps:
            steps += 1
            n, path, dist, seen = stack.pop()
            nxt = [e for e in out_edges.get(n, ()) if e.v not in seen and not (path and e.v == path[-1].u)]
            if not nxt:
                if path:
                    best.append((dist, path))
                continue
            for e in nxt:
                stack.append((e.v, path + [e], dist + length[(e.u, e.v, e.way)], seen | {e.v}))
    if not best:
        raise OsmError("the street's ways do not chain into a route")
    # longest first; of two as long (a two-way street: the same nodes both ways), the one heading north or
    # east first, then by node ids: the same first route whatever order the file lists its nodes and ways in
    def heading_back(path: list[Edge]) -> bool:
        return not 0.0 <= _azimuth(nodes[path[0].u], nodes[path[-1].v]) < 180.0

    best.sort(key=lambda bp: (-round(bp[0], 1), heading_back(bp[1]), [e.u for e in bp[1]]))
    routes = []

    def to_route(dist: float, path: list[Edge]) -> Route:
        return Route([path[0].u] + [e.v for e in path], path, dist)

    first = to_route(*best[0])
    routes.append(first)
    az1 = _azimuth(nodes[first.nodes[0]], nodes[first.nodes[-1]])
    for dist, path in best[1:]:
        r = to_route(dist, path)
        az = _azimuth(nodes[r.nodes[0]], nodes[r.nodes[-1]])
        if abs((az - az1 + 180.0) % 360.0 - 180.0) > 90.0:
            routes.append(r)
            break
    return routes


# --------------------------------------------------------------------------------------------------
# Signals and the corridor


@dataclass
class _Light:
    station_m: float
    node: int
    stop_m: float
    how: str


def _signal_applies(tags: dict[str, str], edge_forward: bool) -> bool:
    d = tags.get("traffic_signals:direction", "").lower()
    if d == "forward":
        return edge_forward
    if d == "backward":
        return not edge_forward
    return True


def _route_lights(data: OsmData, route: Route, stations: list[float]) -> tuple[list[_Light], list[str]]:
    """Stop lines of one route (module docstring, step 3) and notes on what was merged or left out."""
    notes: list[str] = []
    street_nodes = {n for _, refs, _ in data.street_ways for n in refs}
    crossing: dict[int, list[dict[str, str]]] = defaultdict(list)  # route node -> tags of other roads through it
    for _, refs, tags in data.other_ways:
        for n in refs:
            if n in street_nodes:
                crossing[n].append(tags)
    # signals tagged only on another carriageway, linked to a route node by a short crossing way
    linked: dict[int, int] = {}
    on_route = set(route.nodes)
    for _, refs, _tags in data.other_ways:
        sig = [n for n in refs if data.node_tags.get(n, {}).get("highway") == "traffic_signals" and n not in on_route]
        for j in (n for n in refs if n in on_route):
            for s in sig:
                if _dist_m(data.nodes[s], data.nodes[j]) <= MERGE_M:
                    linked[j] = s
    found: list[_Light] = []
    for i, n in enumerate(route.nodes):
        tags = data.node_tags.get(n, {})
        edge = route.edges[i - 1] if i > 0 else route.edges[0]
        if tags.get("highway") == "traffic_signals":
            if not _signal_applies(tags, edge.forward):
                notes.append(f"signal node {n} applies to the other direction (traffic_signals:direction={tags['traffic_signals:direction']})")
                continue
            directional = "traffic_signals:direction" in tags
        elif n in linked and n in crossing:
            directional = False
            notes.append(f"junction node {n}: signal tagged on the other carriageway (node {linked[n]})")
        else:
            continue
        if directional:
            setback, how = 0.0, "node at the stop line (traffic_signals:direction)"
        elif n in crossing:
            half = max(_width_m(t) for t in crossing[n]) / 2.0
            setback, how = half + STOP_LINE_GAP_M, f"junction node: {half:.1f} m half-width of the crossing road + {STOP_LINE_GAP_M:g} m"
        else:
            setback, how = 0.0, "node at the stop line (no junction)"
        found.append(_Light(stations[i], n, stations[i] - setback, how))
    lights: list[_Light] = []
    for light in found:
        if lights and light.station_m - lights[-1].station_m < MERGE_M:
            notes.append(f"signal node {light.node} merged with node {lights[-1].node} ({light.station_m - lights[-1].station_m:.0f} m apart: one intersection)")
            continue
        lights.append(light)
    kept = []
    for light in lights:
        if not MIN_APPROACH_M <= light.stop_m < stations[-1] - MIN_APPROACH_M:
            notes.append(f"signal node {light.node} left out: its stop line ({light.stop_m:.0f} m) is not inside the route")
            continue
        if kept and light.stop_m <= kept[-1].stop_m:
            notes.append(f"signal node {light.node} left out: its stop line is not after the previous one")
            continue
        kept.append(light)
    return kept, notes


def _units(data: OsmData, route_nodes: list[int]) -> str:
    if any("mph" in tags.get(k, "") for _, _, tags in data.street_ways for k in tags if k.startswith("maxspeed")):
        return "imperial"
    lat, lon = data.nodes[route_nodes[len(route_nodes) // 2]]
    inside = any(a <= lat <= b and c <= lon <= d for a, b, c, d in IMPERIAL_BOXES)
    return "imperial" if inside else "metric"


def _slug(text: str) -> str:
    return re.sub(r"[^a-z0-9]+", "_", text.casefold()).strip("_")


@dataclass
class ImportResult:
    corridors: list[Corridor]
    notes: list[str]


def _station_along(data: OsmData, route: Route, stations: list[float], point: tuple[float, float]) -> float:
    """Station of the point of ``route`` nearest to ``point`` (lat, lon), in a local flat frame. [m]"""
    lat0 = math.radians(point[0])
    best = (math.inf, 0.0)
    for (a, b), s0, s1 in zip(zip(route.nodes, route.nodes[1:]), stations, stations[1:]):
        (ya, xa), (yb, xb) = data.nodes[a], data.nodes[b]
        ax, ay = (xa - point[1]) * math.cos(lat0), ya - point[0]
        dx, dy = (xb - xa) * math.cos(lat0), yb - ya
        f = min(max(-(ax * dx + ay * dy) / max(dx * dx + dy * dy, 1e-30), 0.0), 1.0)
        d2 = (ax + f * dx) ** 2 + (ay + f * dy) ** 2
        if d2 < best[0]:
            best = (d2, s0 + f * (s1 - s0))
    return best[1]


def corridors_from_osm(
    path: str | Path, street: str, *, name: str | None = None, units: str | None = None, direction: str | None = None, first_id: int = 1
) -> ImportResult:
    """Corridors along ``street`` in the OSM file ``path``, one per direction of travel (module docstring).

    ``name``: corridor name prefix (default: the street's, e.g. ``7th_street``), suffixed with the
    direction; ``units``: ``metric``/``imperial`` (default: guessed); ``direction``: keep only that one
    (``westbound``...). Raises :class:`OsmError` with the reason.
    """
    path = Path(path)
    data = read_osm(path, street)
    routes = street_routes(data)
    ways = {w: (refs, tags) for w, refs, tags in data.street_ways}
    results: list[tuple[Route, list[float], list[_Light]]] = []
    notes: list[str] = []
    for route in routes:
        stations = [0.0]
        for a, b in zip(route.nodes, route.nodes[1:]):
            stations.append(stations[-1] + _dist_m(data.nodes[a], data.nodes[b]))
        lights, route_notes = _route_lights(data, route, stations)
        heading = compass(_azimuth(data.nodes[route.nodes[0]], data.nodes[route.nodes[-1]]))
        notes += [f"{heading}: {n}" for n in route_notes]
        results.append((route, stations, lights))
    # one id per physical intersection, shared by both directions, counting up along the first route (the
    # opposite route meets them counting down); one only the other route has is numbered where it lies
    # along the first (before: by each one's rank on either route, 1, 3, 4, 2 one way and 2, 4, 3, 1 back)
    centres: list[tuple[float, float]] = []
    along: list[float] = []
    ids: list[list[int]] = []
    for _route, _stations, lights in results:
        row = []
        for light in lights:
            here = data.nodes[light.node]
            match = next((k for k, c in enumerate(centres) if _dist_m(c, here) <= 2 * MERGE_M), None)
            if match is None:
                centres.append(here)
                along.append(light.station_m if not ids else _station_along(data, results[0][0], results[0][1], here))
                match = len(centres) - 1
            row.append(match)
        ids.append(row)
    order = sorted(range(len(centres)), key=lambda k: (along[k], k))
    number = {k: first_id + n for n, k in enumerate(order)}
    out: list[Corridor] = []
    for r_index, ((route, stations, lights), row) in enumerate(zip(results, ids)):
        heading_deg = _azimuth(data.nodes[route.nodes[0]], data.nodes[route.nodes[-1]])
        bound = compass(heading_deg)
        if direction is not None and bound != direction:
            continue
        group = 2 if r_index == 0 else 6
        polyline = [RoutePoint(station_m=round(s, 3), lat_deg=data.nodes[n][0], lon_deg=data.nodes[n][1]) for n, s in zip(route.nodes, stations)]
        length_m = polyline[-1].station_m
        imperial = (units or _units(data, route.nodes)) == "imperial"
        segments: list[Segment] = []
        for e, s0, s1 in zip(route.edges, stations, stations[1:]):
            refs, tags = ways[e.way]
            key = "maxspeed:forward" if e.forward else "maxspeed:backward"
            limit, source = parse_maxspeed(tags.get(key) or tags.get("maxspeed"), tags.get("highway", "road"), imperial)
            limit = round(limit, 4)
            grade = _incline_frac(tags.get("incline")) * (1 if e.forward else -1)
            grade = max(-0.3, min(0.3, grade))
            label = tags.get("name", "")
            if segments and segments[-1].speed_limit_mps == limit and segments[-1].grade_frac == grade and segments[-1].source == source:
                segments[-1] = segments[-1].model_copy(update={"end_m": round(s1, 3)})
            else:
                segments.append(Segment(start_m=round(s0, 3), end_m=round(s1, 3), speed_limit_mps=limit, grade_frac=grade, name=label, source=source))
        segments[-1] = segments[-1].model_copy(update={"end_m": length_m})
        intersections = []
        for light, k in zip(lights, row):
            stop = round(light.stop_m, 2)
            i = next(j for j, s in enumerate(stations) if s >= light.stop_m) if light.stop_m > 0 else 1
            i = max(i, 1)
            az = _azimuth(data.nodes[route.nodes[i - 1]], data.nodes[route.nodes[i]])
            frac = (light.stop_m - stations[i - 1]) / max(stations[i] - stations[i - 1], 1e-9)
            lon, lat, _ = WGS84.fwd(data.nodes[route.nodes[i - 1]][1], data.nodes[route.nodes[i - 1]][0], az, frac * (stations[i] - stations[i - 1]))
            cross = sorted({t.get("name", "") for _, refs, t in data.other_ways if light.node in refs and t.get("name")})
            label = f"{street} & {' / '.join(cross)}" if cross else f"{street} signal {number[k] - first_id + 1}"
            intersections.append(IntersectionSpec(
                id=number[k], name=label, stop_line_m=stop, lat_deg=round(lat, 7), lon_deg=round(lon, 7), approach_heading_deg=round(az, 2) % 360.0,
                signal_groups=(SignalGroupSpec(id=group, name=f"{bound} through"),)))  # fmt: skip
        corridor_name = f"{name or _slug(street)}_{bound}"
        start, end = data.nodes[route.nodes[0]], data.nodes[route.nodes[-1]]
        out.append(Corridor(
            schema_version=SCHEMA_VERSION,
            name=corridor_name,
            description=f"{street}, {bound}: {len(intersections)} signalised intersection(s), {length_m:.0f} m, imported from OpenStreetMap ({path.name}).",
            road=RoadSource(
                name=f"{street}, {bound}", start=LatLon(lat_deg=start[0], lon_deg=start[1]), end=LatLon(lat_deg=end[0], lon_deg=end[1]),
                source=f"OpenStreetMap data (c) OpenStreetMap contributors, ODbL; file {path.name}; ways {', '.join(str(w) for w in dict.fromkeys(e.way for e in route.edges))}",
                note="Route = the street's ways chained in travel order; stop lines from highway=traffic_signals nodes "
                     "(docs/CORRIDORS.md: placement and merging); speed limits from maxspeed or class defaults. "
                     "Intersection ids count up along the first route imported (down along the opposite one): use the operator's J2735 ids for a live SPaT feed.",
            ),
            units="imperial" if imperial else "metric",
            length_m=length_m,
            segments=tuple(segments),
            polyline=tuple(polyline),
            intersections=tuple(intersections),
        ))  # fmt: skip
    if not out:
        raise OsmError(f"{path}: no {direction} route along {street!r} (routes: {', '.join(compass(_azimuth(data.nodes[r.nodes[0]], data.nodes[r.nodes[-1]])) for r in routes)})")
    return ImportResult(out, notes)
