"""One drive, one score (issue 29, item 4): ``replay`` and the service score the same fixes alike.

The shipped demo drive (``replay/data/field_test_advised.csv``, what the app's Demo drive plays) goes through
``replay``'s Python API (``score_drive``) and through the service in-process (``POST`` every fix, then
``/end``, injected clock): the same energy, wear and cost for the drive and for the regular driver within
1 %, the same compared distance, the same savings with the same sign (positive = less than the regular
driver). A trip ended early is compared over the distance it drove, by both.
"""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from advisory.drivers.regular import regular_driver
from advisory.physics.params import model_params
from replay.drive import score_drive
from replay.trace_io import GpsTrace, read_gps_csv
from server.app import create_app
from server.config import Settings

DEMO = Path(__file__).resolve().parents[2] / "replay" / "data" / "field_test_advised.csv"


def service_score(trace: GpsTrace, n: int) -> dict:
    """The trace's first ``n`` fixes through the service, as the app sends them; the trip's score."""
    meta = trace.meta
    now = [float(trace.t_s[0])]
    settings = Settings(corridors=(meta["corridor"],), default_corridor=meta["corridor"], tables=False, speech=False,
                        rate_per_s=1000.0, rate_burst=1000.0)  # fmt: skip
    with TestClient(create_app(settings, clock=lambda: now[0])) as client:
        r = client.post("/v1/trips", json={"corridor": meta["corridor"], "timing": meta["timing"], "vehicle": meta["vehicle"], "entry_unix_s": float(meta["entry_unix_s"])})
        assert r.status_code == 201, r.text
        trip = r.json()
        auth = {"Authorization": f"Bearer {trip['token']}"}
        for i in range(n):
            now[0] = float(trace.t_s[i])
            fix = {"t_unix_s": trace.t_s[i], "lat_deg": trace.lat_deg[i], "lon_deg": trace.lon_deg[i], "speed_mps": trace.speed_mps[i], "accuracy_m": trace.accuracy_m[i]}
            assert client.post(f"/v1/trips/{trip['trip_id']}/fixes", json=fix, headers=auth).status_code == 200
        return client.post(f"/v1/trips/{trip['trip_id']}/end", headers=auth).json()


def first_fixes(trace: GpsTrace, n: int) -> GpsTrace:
    return replace(trace, **{k: getattr(trace, k)[:n] for k in ("t_s", "lat_deg", "lon_deg", "speed_mps", "accuracy_m", "lines")}, notes=list(trace.notes))


def replay_score(trace: GpsTrace):
    return score_drive(trace, model_params(trace.meta["vehicle"]))


def assert_same(result, score: dict, rel: float = 0.01) -> None:
    """Energy, wear and cost of both drivers within ``rel``; the same distance compared; the same savings."""
    for who, mine in (("driven", result.driven.score), ("regular", result.regular.score)):
        theirs = score[who]
        for key, value in (("energy_kwh", mine.energy_kwh), ("soh_lost_frac", mine.soh_lost_frac), ("wear_usd", mine.wear_usd), ("cost_usd", mine.cost_usd)):
            assert theirs[key] == pytest.approx(value, rel=rel), (who, key, theirs[key], value)
    assert score["compared_m"] == pytest.approx(result.drive.distance_m, abs=0.1)
    saved = result.savings()["driven"]
    for key in ("energy", "wear", "cost"):
        assert math.copysign(1.0, score["savings_frac"][key]) == math.copysign(1.0, saved[key])
        assert score["savings_frac"][key] == pytest.approx(saved[key], abs=0.01)  # a point at most


@pytest.fixture(scope="module")
def demo() -> GpsTrace:
    return read_gps_csv(DEMO)


def test_the_demo_drive_scores_the_same_in_replay_and_the_service(demo):
    """Finding: 139 vs 221 Wh (-37.1 %) in replay, 129 vs 220 Wh (savings 0.411) in the service and the app."""
    result = replay_score(demo)
    score = service_score(demo, demo.t_s.size)
    assert result.complete and score["complete"] and result.drive.distance_m == score["compared_m"] == 600.0
    assert_same(result, score)
    saved = result.savings()["driven"]
    assert all(saved[k] > 0.3 for k in ("energy", "wear", "cost"))  # the advised drive saves, said as a positive fraction in both


def test_a_trip_ended_early_is_compared_over_the_distance_it_drove(demo):
    """Finding: a trip ended after 55.6 m scored "52 % less energy" against a regular driver who drove 599.5 m."""
    n = next(i for i, (lat, lon) in enumerate(zip(demo.lat_deg, demo.lon_deg, strict=True)) if _station(demo, lat, lon) > 55.0) + 1
    part = first_fixes(demo, n)
    result = replay_score(part)
    score = service_score(demo, n)
    stop_m = _station(demo, part.lat_deg[-1], part.lon_deg[-1])
    assert not result.complete and not score["complete"] and result.dp is None
    assert 55.0 < score["compared_m"] < 600.0 and score["compared_m"] == pytest.approx(stop_m, abs=0.5)
    # both drivers over that distance (positions integrated from 1 Hz speeds: within a few metres), not the zone
    assert score["driven"]["distance_m"] == pytest.approx(stop_m, abs=3.0) and score["regular"]["distance_m"] == pytest.approx(stop_m, abs=3.0)
    assert result.regular.score.zone.distance_m == pytest.approx(stop_m, abs=3.0)
    assert "compared over those" in score["note"]
    assert_same(result, score)
    # the regular driver's energy over that distance is its whole-zone drive's up to there, not the whole zone's
    whole = regular_driver(result.comparison.lights)
    assert result.regular.trajectory.duration_s < 0.5 * whole.duration_s


def _station(trace: GpsTrace, lat: float, lon: float) -> float:
    from spat_feed.road.corridors import load_corridor

    return float(load_corridor(trace.meta["corridor"]).project(lat, lon)[0])
