"""``server.web.fastlane.FixLane`` answers every fix request exactly as the router does (independent answer: the same
app with the lane taken out): advisories, each error's status, body and headers, and the request metrics."""

from __future__ import annotations

from fastapi.testclient import TestClient

from server.app import create_app
from server.config import Settings
from server.web.fastlane import FixLane
from spat_feed.road.corridors import load_corridor
from tests.server.conftest import FIX_ERROR_STATUSES, fix_errors

NOW = 1_800_000_000.0


def _app(lane: bool):
    app = create_app(Settings(corridors=("paper_s200",), default_corridor="paper_s200", tables=False, speech=False, max_body_bytes=1024), clock=lambda: NOW)
    if not lane:  # the middleware stack is built on the first request: the lane is gone before it
        app.user_middleware = [m for m in app.user_middleware if m.cls is not FixLane]
    return app


def _answers(lane: bool) -> list:
    s200 = load_corridor("paper_s200")
    out = []
    with TestClient(_app(lane)) as c:
        trip = c.post("/v1/trips", json={}).json()
        other = c.post("/v1/trips", json={}).json()
        tid, auth = trip["trip_id"], {"Authorization": f"Bearer {trip['token']}"}
        url = f"/v1/trips/{tid}/fixes"

        def fix(k: int, **extra) -> dict:
            lat, lon = s200.position(12.0 * k)
            return {"t_unix_s": NOW - 20 + k, "lat_deg": lat, "lon_deg": lon, "speed_mps": 12.0, **extra}

        requests = [
            (url, {"json": fix(0)}, auth),
            (url, {"json": fix(1)}, auth),
            (url, {"json": fix(1)}, auth),  # duplicate
            *fix_errors(url, fix(2), auth, {"Authorization": f"Bearer {other['token']}"}, 1024),
            (url, {"json": fix(3)}, auth),
            (f"/v1/trips/{tid}/fixes/", {"json": fix(4)}, auth),  # not the lane: the router redirects it
        ]
        for path, body, headers in requests:
            r = c.post(path, headers={**headers, "content-type": "application/json"}, **body)
            data = r.json() if r.headers.get("content-type") == "application/json" else r.text
            if isinstance(data, dict):
                data = {k: v for k, v in data.items() if k != "trip_id"}
            out.append((r.status_code, data, {k: r.headers.get(k) for k in ("content-type", "retry-after", "www-authenticate", "content-length")}))
        metrics = c.get("/metrics").text
        out.append(sorted(line.replace(tid, "ID") for line in metrics.splitlines() if line.startswith("ecodrive_http_requests_total") and "fixes" in line))
    return out


def test_the_lane_answers_as_the_router():
    with_lane, without = _answers(True), _answers(False)
    assert with_lane == without
    statuses = [a[0] for a in with_lane[:-1]]
    assert statuses == [200, 200, 200, *FIX_ERROR_STATUSES, 200, statuses[-1]]
    assert any('route="/v1/trips/{trip_id}/fixes",status="200"} 5.0' in line for line in with_lane[-1])
