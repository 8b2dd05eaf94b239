"""The approach: a corridor whose first light is too near its entry to be met without hard braking is advised from
before the entry (issue 28: the paper's corridor, first light 100 m in at 55 mph)."""

from __future__ import annotations

import asyncio

import pytest

from advisory.advice.views import AdvisorParams
from server.advising import Engine, approach_m
from server.config import Settings
from server.gps import Fix
from server.schemas import TripCreate
from server.spat import SpatHub
from spat_feed.road.corridors import WGS84, load_corridor
from spat_feed.transport.scenarios import make_scenario, spat_message_at

T0 = 1_714_590_000.0


def _before_entry(corridor, back_m, side_m=0.0):
    """Lat/lon ``back_m`` before the entry on the line of the first stretch, ``side_m`` to its left."""
    a, b = corridor.polyline[0], corridor.polyline[1]
    az, _, _ = WGS84.inv(a.lon_deg, a.lat_deg, b.lon_deg, b.lat_deg)
    lon, lat, _ = WGS84.fwd(a.lon_deg, a.lat_deg, az, -back_m)
    if side_m:
        lon, lat, _ = WGS84.fwd(lon, lat, az - 90.0, side_m)
    return float(lat), float(lon)


def _fix_at(name, back_m, side_m=0.0, **settings):
    corridor = load_corridor(name)
    cfg = Settings(spat_simulate=False, tables=False, speech=False, **settings)
    hub = SpatHub(cfg, {corridor.name: corridor}, lambda: T0)
    for ix in spat_message_at(make_scenario(corridor, "15_15", 0.0), T0).intersections:
        hub.store.offer(ix)
    engine = Engine(cfg, {corridor.name: corridor}, spat=hub, clock=lambda: T0)

    async def go():
        trip = await engine.create_trip(TripCreate(corridor=corridor.name), client="a")
        lat, lon = _before_entry(corridor, back_m, side_m)
        return engine.on_fix(trip, Fix(T0, lat, lon, speed_mps=24.0))

    return asyncio.run(go())


def test_the_approach_is_what_a_comfortable_stop_for_the_first_light_needs_beyond_the_zone():
    params = AdvisorParams()
    paper = load_corridor("paper_s400")
    v = paper.advisory_limit_mps(0.0)
    need = v * (params.reaction_s + params.stop_lead_s) + v * v / (2 * params.comfort_decel_mps2)  # 75 m + 202 m
    assert approach_m(paper, params, 13.4) == pytest.approx(need - 100.0)
    assert approach_m(load_corridor("oakland_7th_westbound"), params, 13.4) == 0.0  # its first light is 379 m in


def test_a_fix_on_the_approach_is_on_the_route_and_advised_for_the_first_light():
    out = _fix_at("paper_s400", 150.0)
    assert out["on_route"] and out["station_m"] == pytest.approx(-150.0, abs=1.0)
    assert out["next_intersection_id"] == 1 and out["distance_to_line_m"] == pytest.approx(250.0, abs=1.0)
    assert out["reason"] != "off_route"


@pytest.mark.parametrize(("name", "back_m", "side_m", "settings"), [
    ("paper_s400", 200.0, 0.0, {}),  # beyond the approach (175 m)
    ("paper_s400", 150.0, 60.0, {}),  # beside it: another road
    ("paper_s400", 150.0, 0.0, {"approach_m": 0.0}),  # switched off
    ("oakland_7th_westbound", 100.0, 0.0, {}),  # no approach needed
])  # fmt: skip
def test_beyond_beside_or_without_the_approach_a_fix_is_off_the_route(name, back_m, side_m, settings):
    out = _fix_at(name, back_m, side_m, **settings)
    assert not out["on_route"] and out["reason"] == "off_route"
