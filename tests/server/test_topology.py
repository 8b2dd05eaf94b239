"""Two processes, as in docker-compose.yml: the simulated SPaT feed and the service reading it by URL."""

from __future__ import annotations

import time

import httpx

from tests.server.conftest import Proc, new_trip, service_proc

WAIT_S = 20.0


def test_service_with_remote_feed_end_to_end(start_proc, tmp_path, s200):
    feed = start_proc(Proc(["-m", "spat_feed", "--n-events", "6"], tmp_path / "feed.log"))
    svc = start_proc(service_proc(tmp_path, ECO_SPAT_FEED_URL=feed.base_url, ECO_TABLES="false", ECO_SPEECH="false"))
    with httpx.Client(base_url=svc.base_url, timeout=10.0) as client:
        assert client.get("/health").json()["spat"] == f"remote {feed.base_url}"
        trip_id, auth, created = new_trip(client, corridor="paper_s200")  # no timing: the lights as the feed runs them for everyone

        def post(k: int) -> dict:
            lat, lon = s200.position(min(10.0 * k, 90.0))
            body = {"t_unix_s": time.time(), "lat_deg": lat, "lon_deg": lon, "speed_mps": 15.0}
            r = client.post(f"/v1/trips/{trip_id}/fixes", json=body, headers=auth)
            assert r.status_code == 200, r.text
            return r.json()

        deadline, k, advice = time.monotonic() + WAIT_S, 0, None
        while time.monotonic() < deadline:  # the service subscribes on trip creation; data arrives within ~0.1 s
            advice = post(k)
            k += 1
            if advice["spat_fresh"]:
                break
            time.sleep(0.1)
        assert advice is not None and advice["spat_fresh"], advice
        assert advice["reason"] not in ("no_spat", "stale_spat")
        spat = client.get(f"/v1/trips/{trip_id}/spat", headers=auth).json()
        assert [i["id"] for i in spat["intersections"]] == [1, 2] and spat["fresh"] == {"1": True, "2": True}

        feed.kill()  # the feed dies: advice must stop relying on it within stale_after_s (2 s)
        deadline = time.monotonic() + WAIT_S
        while time.monotonic() < deadline:
            advice = post(0)
            if advice["spat_fresh"] is False:
                break
            time.sleep(0.2)
        # no new speed advice on stale data: none ("out of date"), or the last advice held through a short dropout ("delayed")
        assert advice["spat_fresh"] is False and advice["reason"] == "stale_spat" and "Signal data" in advice["message"], advice
        score = client.post(f"/v1/trips/{trip_id}/end", headers=auth)
        assert score.status_code == 200
