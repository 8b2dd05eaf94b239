"""The same fixes get the same answers, byte for byte, from the in-process store and from Redis (a real
``redis-server`` on loopback), with Redis commands written at the end of each loop turn or held back in a write
window (``store_write_window_s``): advisories, ignored fixes, and every 4xx's status, body and headers. Independent
answer: the in-process store, which has no Redis path at all."""

from __future__ import annotations

from fastapi.testclient import TestClient

from server.app import create_app
from server.config import Settings
from spat_feed.road.corridors import load_corridor
from tests.server.conftest import FIX_ERROR_STATUSES, fix_errors

NOW = 1_800_000_000.0
HEADERS = ("content-type", "content-length", "retry-after", "www-authenticate")


def _answers(store_url: str | None, window_s: float = 0.0) -> list:
    s200 = load_corridor("paper_s200")
    settings = Settings(corridors=("paper_s200",), default_corridor="paper_s200", tables=False, speech=False, max_body_bytes=1024, rate_burst=100,
                        store_url=store_url, store_write_window_s=window_s)  # fmt: skip
    out = []
    with TestClient(create_app(settings, clock=lambda: NOW)) as c:
        trip = c.post("/v1/trips", json={"corridor": "paper_s200", "timing": "15_15", "entry_unix_s": NOW - 30}).json()
        other = c.post("/v1/trips", json={}).json()
        tid, auth = trip["trip_id"], {"Authorization": f"Bearer {trip['token']}"}
        url = f"/v1/trips/{tid}/fixes"

        def fix(k: int, **extra) -> dict:
            lat, lon = s200.position(11.0 * k)
            return {"t_unix_s": NOW - 25 + k, "lat_deg": lat, "lon_deg": lon, "accuracy_m": 4.0, **({"speed_mps": 11.0} if k % 3 else {}), **extra}

        requests = [(url, {"json": fix(k)}, auth) for k in range(20)]
        requests[5:5] = [(url, {"json": fix(4)}, auth), (url, {"json": fix(2)}, auth)]  # a duplicate, an older fix
        requests += [*fix_errors(url, fix(21), auth, {"Authorization": f"Bearer {other['token']}"}, 1024), (url, {"json": fix(21)}, auth),
                     (f"/v1/trips/{tid}/advice", None, auth)]  # fmt: skip
        for path, body, headers in requests:
            if body is None:
                r = c.get(path, headers=headers)
            else:
                r = c.post(path, headers={**headers, "content-type": "application/json"}, **body)
            out.append((r.status_code, r.content.replace(tid.encode(), b"ID"), [r.headers.get(k) for k in HEADERS]))
    return out


def test_memory_and_redis_answer_the_same_bytes(store):
    ref = _answers(None)
    assert _answers(store.url) == ref
    assert _answers(store.url, window_s=0.002) == ref
    statuses = [a[0] for a in ref]
    assert statuses == [200] * 22 + FIX_ERROR_STATUSES + [200, 200]
    assert b'"fix_status":"duplicate"' in ref[5][1] and b'"fix_status":"out_of_order"' in ref[6][1]
    assert any(b'"action":"cruise"' not in a[1] and b'"action":"none"' not in a[1] for a in ref[:22])  # the drive met a light
