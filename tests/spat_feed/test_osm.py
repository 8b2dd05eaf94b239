"""OpenStreetMap import: small synthetic extracts for the edge cases, and the shared West Oakland extract."""

from __future__ import annotations

import bz2
import json
from pathlib import Path

import pytest

from ecodrive.corridor import main as corridor_cli
from spat_feed.road.corridors import WGS84, load_corridor
from spat_feed.road.osm import MERGE_M, STOP_LINE_GAP_M, LANE_WIDTH_M, OsmError, compass, corridors_from_osm, parse_maxspeed
from tests.conftest import SHARED_DATA

LAT = 37.80
DLON = 1e-4  # ~8.8 m at this latitude
OAKLAND = SHARED_DATA / "osm" / "west-oakland.osm.bz2"


def osm_xml(nodes: dict[int, tuple[float, float, dict]], ways: list[tuple[int, list[int], dict]]) -> str:
    out = ['<?xml version="1.0" encoding="UTF-8"?>', '<osm version="0.6" generator="test">']
    for nid, (lat, lon, tags) in nodes.items():
        body = "".join(f'<tag k="{k}" v="{v}"/>' for k, v in tags.items())
        out.append(f'<node id="{nid}" lat="{lat:.7f}" lon="{lon:.7f}">{body}</node>')
    for wid, refs, tags in ways:
        body = "".join(f'<nd ref="{r}"/>' for r in refs) + "".join(f'<tag k="{k}" v="{v}"/>' for k, v in tags.items())
        out.append(f'<way id="{wid}">{body}</way>')
    out.append("</osm>")
    return "\n".join(out)


def write_osm(tmp_path: Path, nodes, ways, name="x.osm.bz2") -> Path:
    path = tmp_path / name
    text = osm_xml(nodes, ways).encode()
    path.write_bytes(bz2.compress(text) if name.endswith(".bz2") else text)
    return path


def main_street(tmp_path):
    """A two-way 'Main Street' east-west in three ways (the middle one drawn westwards), 101 nodes 8.8 m
    apart: a junction signal with a 4-lane 'Oak Avenue' at node 30, a signal for eastbound traffic only at
    node 70 (traffic_signals:direction=forward on an eastward way), and two signal nodes 13 m apart at
    nodes 85/86 with no junction (one intersection)."""
    nodes = {i: (LAT, -122.30 + i * DLON, {}) for i in range(101)}
    nodes[30] = (LAT, nodes[30][1], {"highway": "traffic_signals"})
    nodes[70] = (LAT, nodes[70][1], {"highway": "traffic_signals", "traffic_signals:direction": "forward"})
    nodes[85] = (LAT, nodes[85][1], {"highway": "traffic_signals"})
    nodes[86] = (LAT + 1.2e-4 * 0, nodes[85][1] + 1.5 * DLON, {"highway": "traffic_signals"})
    nodes[200] = (LAT + 5e-4, nodes[30][1], {})
    nodes[201] = (LAT - 5e-4, nodes[30][1], {})
    ways = [
        (1, list(range(0, 41)), {"highway": "secondary", "name": "Main Street", "maxspeed": "30 mph"}),
        (2, list(range(60, 39, -1)), {"highway": "secondary", "name": "Main Street", "maxspeed": "50"}),
        (3, [*range(60, 86), 86, *range(87, 101)], {"highway": "residential", "name": "Main  street"}),
        (4, [200, 30, 201], {"highway": "tertiary", "name": "Oak Avenue", "lanes": "4"}),
        (5, [0, 200], {"highway": "footway", "name": "Main Street"}),  # not a road: left out
    ]
    return write_osm(tmp_path, nodes, ways)


def test_two_way_street_in_several_ways_gives_both_directions(tmp_path):
    result = corridors_from_osm(main_street(tmp_path), "main street")
    east, west = sorted(result.corridors, key=lambda c: c.name)
    assert (east.name, west.name) == ("main_street_eastbound", "main_street_westbound")
    assert east.length_m == pytest.approx(west.length_m) and east.length_m == pytest.approx(100 * 8.79, rel=0.01)
    assert east.units == "imperial"  # a maxspeed in mph
    step = east.length_m / 100
    junction_setback = 4 * LANE_WIDTH_M / 2 + STOP_LINE_GAP_M
    # eastbound: junction (set back), the forward-only signal (at its node), the 85/86 pair (one, at 85)
    assert [ix.stop_line_m for ix in east.intersections] == pytest.approx([30 * step - junction_setback, 70 * step, 85 * step], abs=0.05)
    assert east.intersections[0].name == "Main street & Oak Avenue" or "Oak Avenue" in east.intersections[0].name
    # westbound: no forward-only signal; the pair 86/85 first met at 86; the junction
    assert [ix.stop_line_m for ix in west.intersections] == pytest.approx([(100 - 86.5) * step, (100 - 30) * step - junction_setback], abs=0.5)
    # the same physical intersection keeps its id both ways; signal groups 2 and 6
    assert {east.intersections[0].id} == {west.intersections[-1].id} and east.intersections[2].id == west.intersections[0].id
    assert {ix.signal_groups[0].id for ix in east.intersections} | {ix.signal_groups[0].id for ix in west.intersections} == {2, 6}
    assert east.intersections[0].approach_heading_deg == pytest.approx(90.0, abs=0.5) and compass(west.intersections[0].approach_heading_deg) == "westbound"
    # limits per way: 30 mph, 50 km/h, then the residential default (imperial: 25 mph)
    assert [round(s.speed_limit_mps, 2) for s in east.segments] == [13.41, 13.89, 11.18]
    assert [round(s.end_m / step) for s in east.segments] == [40, 60, 100]
    assert any("merged" in n for n in result.notes) and any("other direction" in n for n in result.notes)


def test_dual_carriageway_gives_one_route_per_carriageway_and_one_stop_line_each(tmp_path):
    """Northern carriageway westbound, southern eastbound (oneway ways, 22 m apart), a cross street over
    both with a signal node on each carriageway; a second crossing whose signal is tagged on the southern
    carriageway only, linked to the northern one by the cross street."""
    nodes = {}
    for i in range(60):
        nodes[1000 + i] = (LAT + 2e-4, -122.30 + i * DLON, {})  # north
        nodes[2000 + i] = (LAT, -122.30 + i * DLON, {})  # south
    for i in (20, 45):
        nodes[2000 + i] = (LAT, nodes[2000 + i][1], {"highway": "traffic_signals"})
    nodes[1020] = (LAT + 2e-4, nodes[1020][1], {"highway": "traffic_signals"})
    ways = [
        (10, [1000 + i for i in range(59, -1, -1)], {"highway": "primary", "name": "Broad Way", "oneway": "yes", "maxspeed": "US:urban"}),
        (20, [2000 + i for i in range(60)], {"highway": "primary", "name": "Broad Way", "oneway": "yes", "maxspeed": "40 km/h"}),
        (30, [1020, 2020], {"highway": "residential", "name": "First Street"}),
        (31, [1045, 2045], {"highway": "residential", "name": "Second Street"}),
    ]
    result = corridors_from_osm(write_osm(tmp_path, nodes, ways, "dual.osm"), "Broad Way", units="metric")
    by_dir = {c.name.rsplit("_", 1)[1]: c for c in result.corridors}
    assert set(by_dir) == {"westbound", "eastbound"}
    west, east = by_dir["westbound"], by_dir["eastbound"]
    assert len(west.intersections) == 2 and len(east.intersections) == 2
    assert {ix.name for ix in west.intersections} == {"Broad Way & First Street", "Broad Way & Second Street"}
    ids_w = {ix.name: ix.id for ix in west.intersections}
    ids_e = {ix.name: ix.id for ix in east.intersections}
    assert ids_w == ids_e  # one id per physical intersection
    assert west.units == "metric" and west.segments[0].speed_limit_mps == pytest.approx(25 * 0.44704)  # US:urban
    assert east.segments[0].speed_limit_mps == pytest.approx(40 / 3.6)
    assert any("other carriageway" in n for n in result.notes)
    only_west = corridors_from_osm(tmp_path / "dual.osm", "Broad Way", direction="westbound")
    assert [c.name for c in only_west.corridors] == ["broad_way_westbound"]


def test_oneway_against_the_drawing_and_a_name_that_matches_nothing(tmp_path):
    nodes = {i: (LAT + i * 1e-4, -122.30, {}) for i in range(30)}
    nodes[15] = (nodes[15][0], -122.30, {"highway": "traffic_signals"})
    ways = [(1, list(range(30)), {"highway": "tertiary", "name": "Elm Street", "oneway": "-1"})]
    path = write_osm(tmp_path, nodes, ways)
    (only,) = corridors_from_osm(path, "Elm Street").corridors
    assert only.name == "elm_street_southbound" and len(only.intersections) == 1
    assert only.units == "imperial"  # lies in the USA; no maxspeed: tertiary default 25 mph
    assert only.segments[0].speed_limit_mps == pytest.approx(25 * 0.44704)
    with pytest.raises(OsmError, match=r"no road named 'Elm Stret'; closest names: Elm Street"):
        corridors_from_osm(path, "Elm Stret")
    with pytest.raises(OsmError, match="no such file"):
        corridors_from_osm(tmp_path / "absent.osm", "Elm Street")
    (tmp_path / "bad.osm").write_text("<osm><node id='1'", encoding="utf-8")
    with pytest.raises(OsmError, match="not valid OSM XML"):
        corridors_from_osm(tmp_path / "bad.osm", "Elm Street")


@pytest.mark.parametrize(
    "value, highway, imperial, kmh",
    [("50", "primary", False, 50), ("30 mph", "primary", False, 48.28), ("60 km/h", "primary", True, 60), ("50;30", "primary", False, 30),
     ("none", "primary", False, 50), ("none", "primary", True, 56.33), ("DE:urban", "primary", False, 50), ("FR:rural", "primary", False, 90),
     ("US:urban", "secondary", True, 40.23), ("GB:nsl_single", "primary", True, 96.56), ("walk", "living_street", False, 7),
     (None, "residential", False, 30), (None, "residential", True, 40.23), ("signals", "secondary", False, 50), ("fast", "service", False, 20)],
)  # fmt: skip
def test_maxspeed_forms(value, highway, imperial, kmh):
    assert parse_maxspeed(value, highway, imperial)[0] * 3.6 == pytest.approx(kmh, abs=0.01)


def test_cli_from_osm_and_show(tmp_path, capsys):
    path = main_street(tmp_path)
    assert corridor_cli(["from-osm", str(path), "--street", "Main Street"]) == 2
    assert "gives 2 routes" in capsys.readouterr().err
    out_dir = tmp_path / "out"
    out_dir.mkdir()
    assert corridor_cli(["from-osm", str(path), "--street", "Main Street", "-o", str(out_dir)]) == 0
    assert sorted(p.name for p in out_dir.iterdir()) == ["main_street_eastbound.json", "main_street_westbound.json"]
    capsys.readouterr()
    assert corridor_cli(["show", str(out_dir / "main_street_eastbound.json"), "--json"]) == 0
    shown = json.loads(capsys.readouterr().out)
    east = next(c for c in corridors_from_osm(path, "Main Street").corridors if c.name.endswith("eastbound"))
    assert shown["length_m"] == east.length_m and [x["station_m"] for x in shown["lights"]] == [ix.stop_line_m for ix in east.intersections]
    assert len(shown["lights"]) == 3
    assert corridor_cli(["from-osm", str(path), "--street", "Nowhere Road"]) == 2
    assert "no road named 'Nowhere Road'" in capsys.readouterr().err
    assert corridor_cli(["show", str(tmp_path / "missing.json")]) == 2
    assert "missing.json: cannot read" in capsys.readouterr().err


@pytest.mark.skipif(not OAKLAND.exists(), reason="shared OSM extract not present")
def test_west_oakland_7th_street(tmp_path, capsys):
    """The shared extract: 7th Street is a dual carriageway; westbound it passes both signalised
    intersections (Wood Street, mapped with a signal node on each carriageway, and one further west mapped
    as two nodes 13 m apart), eastbound only the Wood Street one (its carriageway ends before the other)."""
    result = corridors_from_osm(OAKLAND, "7th Street")
    by_dir = {c.name.rsplit("_", 1)[1]: c for c in result.corridors}
    assert set(by_dir) == {"westbound", "eastbound"}
    west, east = by_dir["westbound"], by_dir["eastbound"]
    assert len(west.intersections) == 2 and len(east.intersections) == 1
    assert west.units == east.units == "imperial"
    for c in (west, east):
        stations = [ix.stop_line_m for ix in c.intersections]
        assert stations == sorted(stations) and 0 < stations[0] and stations[-1] < c.length_m
        assert all(0 < s.speed_limit_mps <= 70 and s.source for s in c.segments)  # every stretch has a limit and says whence
        for ix in c.intersections:  # each stop line sits just before a signal node, on the route
            lat, lon = c.position(ix.stop_line_m)
            assert WGS84.inv(lon, lat, ix.lon_deg, ix.lat_deg)[2] < 0.5
    assert west.intersections[0].id == east.intersections[0].id and "Wood Street" in west.intersections[0].name
    assert west.intersections[1].stop_line_m - west.intersections[0].stop_line_m > MERGE_M
    # the shipped corridor is this import, its intersections numbered from 7001 (ids apart from the paper's 1 and 2)
    shipped = load_corridor("oakland_7th_westbound")
    again = corridors_from_osm(OAKLAND, "7th Street", name="oakland_7th", direction="westbound", first_id=7001).corridors[0]
    assert [ix.id for ix in again.intersections] == [7001, 7002]
    assert shipped.model_copy(update={"plans": ()}) == again
    assert corridor_cli(["show", "oakland_7th_westbound", "--json"]) == 0
    shown = json.loads(capsys.readouterr().out)
    assert shown["length_m"] == pytest.approx(again.length_m) and len(shown["lights"]) == 2 and shown["default_plan"] == "plausible"


def test_pbf_through_the_optional_osmium_package(tmp_path):
    """The same street from a .pbf (written by osmium from the XML) gives the same corridors; without the
    package, a clear error says how to get it."""
    xml = main_street(tmp_path)
    pbf = tmp_path / "x.osm.pbf"
    try:
        import osmium
    except ImportError:
        pbf.write_bytes(b"\x00")
        with pytest.raises(OsmError, match=r"optional 'osmium' package"):
            corridors_from_osm(pbf, "Main Street")
        return
    with osmium.SimpleWriter(str(pbf)) as writer:
        for obj in osmium.FileProcessor(str(xml)):
            writer.add_node(obj) if obj.is_node() else writer.add_way(obj) if obj.is_way() else None
    from_xml = corridors_from_osm(xml, "Main Street").corridors
    from_pbf = corridors_from_osm(pbf, "Main Street").corridors
    assert [(c.polyline, c.intersections, c.segments) for c in from_pbf] == [(c.polyline, c.intersections, c.segments) for c in from_xml]


def _shuffled_osm(tmp_path: Path, nodes: dict, ways: list, seed: int, name: str) -> Path:
    """The same extract with its nodes and ways listed in another order (as a real file lists them: by id,
    by edit, nothing to do with the street's order)."""
    import random

    rng = random.Random(seed)
    keys = list(nodes)
    rng.shuffle(keys)
    ways = list(ways)
    rng.shuffle(ways)
    return write_osm(tmp_path, {k: nodes[k] for k in keys}, ways, name)


def test_ids_count_up_along_the_street_whatever_the_files_order(tmp_path):
    """Finding: on an unseen file the ids ran 1, 3, 4, 2 westbound and 2, 4, 3, 1 eastbound. Four signalised
    crossings of a dual carriageway, each carriageway drawn in three ways; node ids, ways and nodes listed out
    of street order. Ids count up along the first route (of two as long, the eastbound one), count down along
    the opposite one, one id per crossing, whatever the order in the file."""
    nodes, ways = {}, []
    ids = list(range(500, 620))
    import random

    random.Random(3).shuffle(ids)  # node ids unrelated to the street's order
    north = [ids[i] for i in range(60)]
    south = [ids[60 + i] for i in range(60)]
    for i in range(60):
        nodes[north[i]] = (LAT + 2e-4, -122.30 + i * DLON, {})
        nodes[south[i]] = (LAT, -122.30 + i * DLON, {})
    cross = {10: "Ash", 25: "Birch", 40: "Cedar", 52: "Dogwood"}
    for n, (i, street) in enumerate(cross.items()):
        for side in (north, south):
            nodes[side[i]] = (nodes[side[i]][0], nodes[side[i]][1], {"highway": "traffic_signals"})
        ways.append((900 + n, [north[i], south[i]], {"highway": "residential", "name": f"{street} Street"}))
    tags = {"highway": "primary", "name": "Elm Street", "oneway": "yes"}
    for k, (a, b) in enumerate(((0, 21), (20, 41), (40, 60))):  # three ways a carriageway, listed out of order
        ways.append((700 + k, [north[i] for i in range(b - 1, a - 1, -1)], tags))  # westbound
        ways.append((800 + k, [south[i] for i in range(a, b)], tags))  # eastbound
    names = [f"Elm Street & {s} Street" for s in cross.values()]  # west to east
    seen = []
    for seed in (1, 2, 3):
        result = corridors_from_osm(_shuffled_osm(tmp_path, nodes, ways, seed, f"elm{seed}.osm"), "Elm Street")
        by_dir = {c.name.rsplit("_", 1)[1]: c for c in result.corridors}
        east, west = by_dir["eastbound"], by_dir["westbound"]
        assert [ix.name for ix in east.intersections] == names and [ix.name for ix in west.intersections] == names[::-1]
        assert [ix.id for ix in east.intersections] == [1, 2, 3, 4] and [ix.id for ix in west.intersections] == [4, 3, 2, 1]
        assert east.intersections[0].signal_groups[0].id == 2 and west.intersections[0].signal_groups[0].id == 6
        seen.append([(c.name, [(ix.id, ix.stop_line_m) for ix in c.intersections]) for c in result.corridors])
    assert seen[0] == seen[1] == seen[2]
    # a two-way street: the same, both directions on the same ways, whatever order they come in
    path = main_street(tmp_path)
    for k, p in enumerate((path, _shuffled_osm(tmp_path, *_read_back(path), 5, "main5.osm"))):
        east, west = sorted(corridors_from_osm(p, "Main Street").corridors, key=lambda c: c.name)
        assert [ix.id for ix in east.intersections] == [1, 2, 3] and [ix.id for ix in west.intersections] == [3, 1], k


def _read_back(path: Path) -> tuple[dict, list]:
    """Nodes and ways of a file written by :func:`write_osm` (to list them again in another order)."""
    import xml.etree.ElementTree as ET

    root = ET.fromstring(bz2.decompress(path.read_bytes()) if path.suffix == ".bz2" else path.read_bytes())
    nodes = {int(n.get("id")): (float(n.get("lat")), float(n.get("lon")), {t.get("k"): t.get("v") for t in n.findall("tag")}) for n in root.findall("node")}
    ways = [(int(w.get("id")), [int(r.get("ref")) for r in w.findall("nd")], {t.get("k"): t.get("v") for t in w.findall("tag")}) for w in root.findall("way")]
    return nodes, ways
