"""Corridor files and the paper's presets on a real straight road."""

from __future__ import annotations

import json

import numpy as np
import pytest

from advisory.signals import PAPER_SPACINGS_M
from spat_feed.road.corridors import (
    CHAMPS_ELYSEES,
    PAPER_CORRIDOR_NAMES,
    WGS84,
    corridor_from_json,
    load_corridor,
    paper_corridor,
    preset_names,
)
from spat_feed.timing.paper import TIMING_PRESETS, timing_for_trip


@pytest.fixture(scope="module", params=PAPER_SPACINGS_M)
def corridor(request):
    return load_corridor(f"paper_s{request.param:g}")


def test_presets_are_shipped():
    assert set(PAPER_CORRIDOR_NAMES) <= set(preset_names())


@pytest.mark.parametrize("spacing_m", PAPER_SPACINGS_M)
def test_shipped_file_equals_generated(spacing_m):
    assert load_corridor(f"paper_s{spacing_m:g}") == paper_corridor(spacing_m)


def test_paper_geometry(corridor):
    s = corridor.length_m - 200.0
    assert [ix.stop_line_m for ix in corridor.intersections] == [100.0, 100.0 + s]
    assert [ix.id for ix in corridor.intersections] == [1, 2]
    assert corridor.polyline[0].station_m == 0 and corridor.polyline[-1].station_m == corridor.length_m


def test_stations_are_geodesic_distances(corridor):
    st = np.array([p.station_m for p in corridor.polyline])
    lat = np.array([p.lat_deg for p in corridor.polyline])
    lon = np.array([p.lon_deg for p in corridor.polyline])
    _, _, seg_m = WGS84.inv(lon[:-1], lat[:-1], lon[1:], lat[1:])
    np.testing.assert_allclose(seg_m, np.diff(st), atol=0.02)  # 1e-7 deg rounding ~ 1 cm
    for ix in corridor.intersections:
        _, _, d_m = WGS84.inv(lon[0], lat[0], ix.lon_deg, ix.lat_deg)
        assert d_m == pytest.approx(ix.stop_line_m, abs=0.02)


def test_route_is_straight_and_on_the_road(corridor):
    (lat_a, lon_a), (lat_b, lon_b) = CHAMPS_ELYSEES.a, CHAMPS_ELYSEES.b
    az_ab, _, len_ab = WGS84.inv(lon_a, lat_a, lon_b, lat_b)
    assert len_ab > 1300.0  # the issue asks for >= 1.3 km of straight road
    for p in corridor.polyline:
        az, _, d = WGS84.inv(lon_a, lat_a, p.lon_deg, p.lat_deg)
        assert abs(d * np.sin(np.radians(az - az_ab))) < 0.05  # cross-track from the axis [m]
    assert 48.86 < corridor.road.start.lat_deg < 48.88 and 2.29 < corridor.road.start.lon_deg < 2.33
    for ix in corridor.intersections:
        assert ix.approach_heading_deg == pytest.approx(295.5, abs=0.2)  # west-north-west


def test_project_inverts_position(corridor):
    for station_m in (0.0, 37.5, 100.0, corridor.length_m - 1.0):
        lat, lon = corridor.position(station_m)
        got_m, offset_m = corridor.project(lat, lon)
        assert got_m == pytest.approx(station_m, abs=0.01) and abs(offset_m) < 0.01
    lat, lon = corridor.position(250.0)
    lon2, lat2, _ = WGS84.fwd(lon, lat, corridor.intersections[0].approach_heading_deg + 90.0, 5.0)
    got_m, offset_m = corridor.project(lat2, lon2)
    assert got_m == pytest.approx(250.0, abs=0.05) and offset_m == pytest.approx(5.0, abs=0.05)  # right of travel


def test_load_from_path(tmp_path):
    path = tmp_path / "mine.json"
    path.write_text(paper_corridor(200.0).model_copy(update={"name": "mine"}).model_dump_json(), encoding="utf-8")
    assert load_corridor(path).name == "mine"
    assert load_corridor(str(path)).intersections[1].stop_line_m == 300.0


def test_bad_corridor_files_are_rejected():
    good = json.loads(paper_corridor(200.0).model_dump_json())
    bad_order = {**good, "intersections": list(reversed(good["intersections"]))}
    bad_length = {**good, "length_m": 999.0}
    bad_lat = json.loads(json.dumps(good))
    bad_lat["polyline"][0]["lat_deg"] = 91.0
    for bad in (bad_order, bad_length, bad_lat):
        with pytest.raises(ValueError):  # spat_feed.files.FileFormatError, naming the field
            corridor_from_json(json.dumps(bad))
    with pytest.raises(KeyError):
        load_corridor("no_such_preset")


def test_timing_presets():
    paper = [t for name, t in TIMING_PRESETS.items() if name != "field_test"]
    assert len(paper) == 16
    assert {t.red_starts_s for t in paper} == {(x, y) for x in (-30.0, -15.0, 0.0, 15.0) for y in (-30.0, -15.0, 0.0, 15.0)}
    assert TIMING_PRESETS["field_test"].red_starts_s == (-15.0, 30.0)
    names = {timing_for_trip(60.0 * k).name for k in range(16)}
    assert len(names) == 16 and timing_for_trip(0.0) == timing_for_trip(16 * 60.0)


def test_project_extends_the_ends_and_matches_project_many(corridor):
    heading = corridor.intersections[0].approach_heading_deg
    start, end = corridor.polyline[0], corridor.polyline[-1]
    lon_b, lat_b, _ = WGS84.fwd(start.lon_deg, start.lat_deg, heading + 180.0, 20.0)  # 20 m before the entry
    lon_a, lat_a, _ = WGS84.fwd(end.lon_deg, end.lat_deg, heading, 15.0)  # 15 m past the exit
    assert corridor.project(lat_b, lon_b) == pytest.approx((-20.0, 0.0), abs=0.05)
    assert corridor.project(lat_a, lon_a) == pytest.approx((corridor.length_m + 15.0, 0.0), abs=0.05)
    rng = np.random.default_rng(3)
    pts = [corridor.position(s) for s in rng.uniform(-50.0, corridor.length_m + 50.0, 40)]
    lat = np.array([p[0] for p in pts]) + rng.normal(0.0, 1e-4, 40)
    lon = np.array([p[1] for p in pts]) + rng.normal(0.0, 1e-4, 40)
    st, off = corridor.project_many(lat, lon)
    one = np.array([corridor.project(a, b) for a, b in zip(lat, lon)])
    np.testing.assert_allclose(one[:, 0], st, atol=1e-9)
    np.testing.assert_allclose(one[:, 1], off, atol=1e-9)
