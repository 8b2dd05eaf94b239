"""The service through a real uvicorn process on 127.0.0.1: trips, fixes, WebSocket, audio, score, bad input.

Every wait is bounded; nothing asserts on speed.
"""

from __future__ import annotations

import asyncio
import json
import random
import time

import httpx
import pytest
import websockets

from server.schemas import AdviceOut
from spat_feed.road.corridors import WGS84

from tests.server.conftest import new_trip, service_proc

MAX_STATUS = 500


@pytest.fixture
def client(service):
    with httpx.Client(base_url=service.base_url, timeout=10.0) as c:
        yield c


def check_advice(a: dict) -> dict:
    """The advisory is exactly the documented response model (the service builds it as a plain dict)."""
    assert set(a) == set(AdviceOut.model_fields), set(a) ^ set(AdviceOut.model_fields)
    AdviceOut.model_validate(a)
    return a


def fix_at(corridor, station_m: float, t: float, speed: float | None = 20.0, **extra) -> dict:
    lat, lon = corridor.position(station_m)
    body = {"t_unix_s": t, "lat_deg": lat, "lon_deg": lon, **extra}
    if speed is not None:
        body["speed_mps"] = speed
    return body


def test_health_corridors_openapi(client):
    h = client.get("/health").json()
    assert h["status"] == "ok" and h["spat"] == "in-process simulation" and "paper_s200" in h["tables"]
    names = [c["name"] for c in client.get("/v1/corridors").json()]
    assert names == ["paper_s200", "paper_s400"]
    ix = client.get("/v1/corridors/paper_s400/intersections").json()
    assert [i["stop_line_m"] for i in ix] == [100.0, 500.0]
    assert client.get("/v1/corridors/nowhere").status_code == 404
    spec = client.get("/openapi.json").json()
    assert "/v1/trips/{trip_id}/fixes" in spec["paths"] and "/metrics" in spec["paths"]
    assert all(client.get(page).status_code == 200 for page in ("/docs", "/redoc"))  # served last, still served


def test_drive_the_corridor_with_noise_dropouts_duplicates(client, s200):
    trip_id, auth, created = new_trip(client, corridor="paper_s200", timing="15_15", entry_unix_s=time.time() - 30)  # fixes in the past: none ahead of the server's clock
    t0 = created["entry_unix_s"]
    before = check_advice(client.get(f"/v1/trips/{trip_id}/advice", headers=auth).json())
    assert before["reason"] == "no_fix" and before["seq"] == 0
    rng = random.Random(7)
    seen = []
    for k in range(20):
        if k in (6, 7):  # dropout
            continue
        station = 20.0 * k
        lat, lon = s200.position(station)
        lon, lat, _ = WGS84.fwd(lon, lat, rng.uniform(0, 360), abs(rng.gauss(0, 3.0)))  # ~3 m noise
        body = {"t_unix_s": t0 + k, "lat_deg": lat, "lon_deg": lon, "accuracy_m": 5.0}
        if k % 2 == 0:
            body["speed_mps"] = 20.0  # every other fix without speed: derived from positions
        r = client.post(f"/v1/trips/{trip_id}/fixes", json=body, headers=auth)
        assert r.status_code == 200, r.text
        seen.append(r.json())
        if k == 3:  # duplicate and out-of-order: tolerated, state unchanged
            dup = client.post(f"/v1/trips/{trip_id}/fixes", json=body, headers=auth).json()
            old = client.post(f"/v1/trips/{trip_id}/fixes", json={**body, "t_unix_s": t0 + 1}, headers=auth).json()
            assert dup["fix_status"] == "duplicate" and old["fix_status"] == "out_of_order"
            assert dup["seq"] == old["seq"] == seen[-1]["seq"]
            check_advice(dup), check_advice(old)
    assert all(check_advice(a)["on_route"] for a in seen)
    assert [a["seq"] for a in seen] == list(range(1, 19))
    assert seen[1]["speed_source"] == "positions" and seen[1]["speed_mps"] == pytest.approx(20.0, abs=8.0)
    assert seen[0]["action"] in ("cruise", "ease_off", "coast", "slow_down", "brake_to", "accelerate", "stop") and seen[0]["message"]
    for a in seen:
        if a["target_speed_mps"] is not None:
            assert a["target_speed_mps"] <= 24.6
    latest = client.get(f"/v1/trips/{trip_id}/advice", headers=auth).json()
    assert check_advice(latest)["seq"] == 18 and latest["fix_status"] == "none"
    spat = client.get(f"/v1/trips/{trip_id}/spat", headers=auth).json()
    assert [i["id"] for i in spat["intersections"]] == [1, 2]
    score = client.post(f"/v1/trips/{trip_id}/end", headers=auth).json()
    assert score["regular"]["energy_kwh"] > 0 and score["driven"]["energy_kwh"] > 0 and score["n_fixes"] in (17, 18)  # inside the zone (the first at ~0 m +- noise)
    assert set(score["savings_frac"]) == {"energy", "wear", "cost"}
    assert client.get(f"/v1/trips/{trip_id}/advice", headers=auth).status_code == 404  # ended


def test_off_route_pauses_and_says_so(client, s200):
    trip_id, auth, created = new_trip(client, corridor="paper_s200")
    lat, lon = s200.position(50.0)
    lon, lat, _ = WGS84.fwd(lon, lat, 25.5, 300.0)
    a = client.post(f"/v1/trips/{trip_id}/fixes", json={"t_unix_s": time.time(), "lat_deg": lat, "lon_deg": lon, "speed_mps": 10.0}, headers=auth).json()
    assert check_advice(a)["on_route"] is False and a["action"] == "none" and a["reason"] == "off_route" and "Off the route" in a["message"]
    assert a["offset_m"] > 250
    weak = client.post(f"/v1/trips/{trip_id}/fixes", json={**fix_at(s200, 50.0, time.time() + 1), "accuracy_m": 500.0}, headers=auth).json()
    assert check_advice(weak)["reason"] == "poor_gps" and weak["action"] == "none"


def test_tokens_are_scoped_to_their_trip(client, s200):
    a_id, a_auth, _ = new_trip(client)
    b_id, b_auth, _ = new_trip(client)
    body = fix_at(s200, 10.0, time.time())
    assert client.post(f"/v1/trips/{a_id}/fixes", json=body, headers=b_auth).status_code == 403
    assert client.post(f"/v1/trips/{a_id}/fixes", json=body).status_code == 401
    assert client.post(f"/v1/trips/{a_id}/fixes", json=body, headers={"Authorization": "Bearer nope"}).status_code == 401
    assert client.post(f"/v1/trips/{a_id}/fixes", json=body, headers=a_auth).status_code == 200
    # B untouched by the refused requests
    assert client.get(f"/v1/trips/{b_id}/advice", headers=b_auth).json()["seq"] == 0


BAD_FIXES = [
    ("not json", b"{not json", "malformed_json"),
    ("truncated", b'{"t_unix_s": 1', "malformed_json"),
    ("array", b"[1, 2]", "validation_error"),
    ("missing lat", {"t_unix_s": "NOW", "lon_deg": 2.3}, "validation_error"),
    ("NaN speed", b'{"t_unix_s": NOW, "lat_deg": 48.87, "lon_deg": 2.31, "speed_mps": NaN}', "validation_error"),
    ("Infinity lat", b'{"t_unix_s": NOW, "lat_deg": Infinity, "lon_deg": 2.31}', "validation_error"),
    ("1e999 time", b'{"t_unix_s": 1e999, "lat_deg": 48.87, "lon_deg": 2.31}', "validation_error"),
    ("lat 91", {"t_unix_s": "NOW", "lat_deg": 91.0, "lon_deg": 2.31}, "validation_error"),
    ("lon -181", {"t_unix_s": "NOW", "lat_deg": 48.0, "lon_deg": -181.0}, "validation_error"),
    ("negative speed", {"t_unix_s": "NOW", "lat_deg": 48.87, "lon_deg": 2.31, "speed_mps": -1.0}, "validation_error"),
    ("speed 500", {"t_unix_s": "NOW", "lat_deg": 48.87, "lon_deg": 2.31, "speed_mps": 500.0}, "validation_error"),
    ("heading 400", {"t_unix_s": "NOW", "lat_deg": 48.87, "lon_deg": 2.31, "heading_deg": 400.0}, "validation_error"),
    ("string lat", {"t_unix_s": "NOW", "lat_deg": "north", "lon_deg": 2.31}, "validation_error"),
    ("extra field", {"t_unix_s": "NOW", "lat_deg": 48.87, "lon_deg": 2.31, "turbo": 3}, "validation_error"),
    ("future fix", {"t_unix_s": "FUTURE", "lat_deg": 48.87, "lon_deg": 2.31}, "time_out_of_range"),
    ("ancient fix", {"t_unix_s": 1000.0, "lat_deg": 48.87, "lon_deg": 2.31}, "time_out_of_range"),
]


@pytest.mark.parametrize("name,body,error", BAD_FIXES, ids=[b[0] for b in BAD_FIXES])
def test_bad_fixes_get_a_clear_4xx_and_leave_the_trip_alone(client, s200, name, body, error):
    trip_id, auth, _ = new_trip(client, corridor="paper_s200")
    good = fix_at(s200, 10.0, time.time())
    assert client.post(f"/v1/trips/{trip_id}/fixes", json=good, headers=auth).status_code == 200
    before = client.get(f"/v1/trips/{trip_id}/advice", headers=auth).json()
    now = time.time() + 0.5
    if isinstance(body, dict):
        body = {k: (now if v == "NOW" else now + 3600 if v == "FUTURE" else v) for k, v in body.items()}
        content = json.dumps(body).encode()
    else:
        content = body.replace(b"NOW", str(now).encode())
    r = client.post(f"/v1/trips/{trip_id}/fixes", content=content, headers={**auth, "content-type": "application/json"})
    assert r.status_code == 422, r.text
    err = r.json()
    assert err["error"] == error and err["message"]
    after = client.get(f"/v1/trips/{trip_id}/advice", headers=auth).json()
    assert after == before


def test_other_bad_requests(client, s200):
    trip_id, auth, _ = new_trip(client)
    r = client.post(f"/v1/trips/{trip_id}/fixes", content=b"{" + b" " * 40_000 + b"}", headers={**auth, "content-type": "application/json"})
    assert r.status_code == 413 and r.json()["error"] == "payload_too_large"
    # chunked (no Content-Length): the body is read in pieces, joined, and still cut off at the limit
    body = json.dumps(fix_at(s200, 10.0, time.time())).encode()
    r = client.post(f"/v1/trips/{trip_id}/fixes", content=iter([body[:7], body[7:30], body[30:]]), headers={**auth, "content-type": "application/json"})
    assert r.status_code == 200 and r.json()["seq"] == 1
    r = client.post(f"/v1/trips/{trip_id}/fixes", content=iter([b"{"] + [b" " * 1000] * 40 + [b"}"]), headers={**auth, "content-type": "application/json"})
    assert r.status_code == 413 and r.json()["error"] == "payload_too_large"
    r = client.post("/v1/trips/0000/fixes", json=fix_at(s200, 1.0, time.time()), headers=auth)
    assert r.status_code == 404 and r.json()["error"] == "unknown_trip"
    for body, error in (({"corridor": "moon"}, "unknown_corridor"), ({"timing": "9_9"}, "unknown_timing"), ({"vehicle": "tank"}, "unknown_vehicle"),
                        ({"entry_unix_s": 1.0}, "time_out_of_range"), ({"colour": "red"}, "validation_error")):  # fmt: skip
        r = client.post("/v1/trips", json=body)
        assert r.status_code == 422 and r.json()["error"] == error, r.text
    assert client.delete(f"/v1/trips/{trip_id}/fixes", headers=auth).status_code == 405


def test_rate_limit_per_trip(start_proc, tmp_path):
    """The burst, then 429, per trip. The bucket refills at 0.001/s, so the count does not depend on how fast
    this machine sends the requests (it did at 50/s: 80 requests that each took > 0.2 s never exceeded it)."""
    svc = start_proc(service_proc(tmp_path, ECO_RATE_PER_S="0.001", ECO_RATE_BURST="20", ECO_TABLES="false", ECO_SPEECH="false"))
    with httpx.Client(base_url=svc.base_url, timeout=10.0) as c:
        trip_id, auth, _ = new_trip(c)
        other_id, other_auth, _ = new_trip(c)
        codes = [c.get(f"/v1/trips/{trip_id}/advice", headers=auth).status_code for _ in range(21)]
        assert codes == [200] * 20 + [429]
        r = c.get(f"/v1/trips/{trip_id}/advice", headers=auth)
        assert r.status_code == 429 and r.json()["error"] == "rate_limited"
        assert int(r.headers["retry-after"]) >= 900 and f"retry in {r.headers['retry-after']} s" in r.json()["message"]
        assert c.get(f"/v1/trips/{other_id}/advice", headers=other_auth).status_code == 200  # per trip


def test_websocket_stream(service, client, s200):
    trip_id, auth, created = new_trip(client, corridor="paper_s200", timing="15_15")
    url = service.base_url.replace("http", "ws") + f"/v1/trips/{trip_id}/stream"

    async def run():
        async with websockets.connect(url + f"?token={auth['Authorization'][7:]}", open_timeout=10) as ws:
            t0 = time.time() - 20
            out = []
            for k in range(5):
                await ws.send(json.dumps(fix_at(s200, 20.0 * k, t0 + k)))
                out.append(json.loads(await asyncio.wait_for(ws.recv(), 10)))
            await ws.send("{broken")
            err = json.loads(await asyncio.wait_for(ws.recv(), 10))
            await ws.send(json.dumps({**fix_at(s200, 0.0, t0 + 9), "lat_deg": 123}))
            err2 = json.loads(await asyncio.wait_for(ws.recv(), 10))
            await ws.send(json.dumps(fix_at(s200, 100.0, t0 + 5)))  # still streaming after errors
            last = json.loads(await asyncio.wait_for(ws.recv(), 10))
            return out, err, err2, last

    out, err, err2, last = asyncio.run(run())
    assert [a["seq"] for a in out] == [1, 2, 3, 4, 5] and all(check_advice(a)["trip_id"] == trip_id for a in out)
    assert err["error"] == "malformed_json" and err["status"] == 422
    assert err2["error"] == "validation_error" and "lat_deg" in err2["message"]
    assert last["seq"] == 6

    async def refused(token: str):
        async with websockets.connect(url + f"?token={token}", open_timeout=10) as ws:
            msg = json.loads(await asyncio.wait_for(ws.recv(), 10))
            with pytest.raises(websockets.exceptions.ConnectionClosed) as info:
                await asyncio.wait_for(ws.recv(), 10)
            return msg, info.value.rcvd.code

    other_id, other_auth, _ = new_trip(client)
    msg, code = asyncio.run(refused(other_auth["Authorization"][7:]))
    assert msg["status"] == 403 and code == 4403
    msg, code = asyncio.run(refused("garbage"))
    assert msg["status"] == 401 and code == 4401


def test_audio_is_a_wav(client, s200, service):
    if not client.get("/health").json()["speech"]:
        pytest.skip("no speech engine in this environment (espeak-ng missing; scripts/system-deps.sh installs it)")
    trip_id, auth, _ = new_trip(client, corridor="paper_s200", timing="15_15")
    client.post(f"/v1/trips/{trip_id}/fixes", json=fix_at(s200, 0.0, time.time()), headers=auth)
    r = client.get(f"/v1/trips/{trip_id}/advice.wav", headers=auth)
    assert r.status_code == 200 and r.headers["content-type"] == "audio/wav"
    assert r.content[:4] == b"RIFF" and r.content[8:12] == b"WAVE" and len(r.content) > 1000


def test_metrics_count_requests_and_fixes(client, s200):
    trip_id, auth, _ = new_trip(client)
    client.post(f"/v1/trips/{trip_id}/fixes", json=fix_at(s200, 1.0, time.time()), headers=auth)
    text = client.get("/metrics").text
    assert 'ecodrive_http_requests_total{method="POST",route="/v1/trips/{trip_id}/fixes",status="200"}' in text
    assert "ecodrive_fixes_total" in text and "ecodrive_trips_open" in text and "ecodrive_advice_compute_seconds_bucket" in text
