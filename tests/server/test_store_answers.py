"""The same fixes get the same answers, byte for byte, from the in-process store and from Redis (a real
``redis-server`` on loopback), with Redis commands written at the end of each loop turn or held back in a write
window (``store_write_window_s``): advisories, ignored fixes, and every 4xx's status, body and headers. Independent
answer: the in-process store, which has no Redis path at all."""

from __future__ import annotations

import pytest
from fastapi.testclient import TestClient

from server.app import create_app
from server.config import Settings
from spat_feed.road.corridors import load_corridor
from tests.server.conftest import FIX_ERROR_STATUSES, RedisServer, fix_errors, redis_server_path

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


def test_redis_over_a_unix_socket_answers_the_same_bytes(tmp_path):
    """``ECO_STORE_URL=unix:///path/redis.sock`` (a Redis on the same machine: no TCP stack per command)."""
    if redis_server_path() is None:
        pytest.skip("redis-server is not installed")
    server = RedisServer(tmp_path, unix_socket=True).start()
    try:
        assert _answers(server.unix_url) == _answers(None)
    finally:
        server.kill()


def test_a_trips_state_json_and_its_advisory_are_encoded_once_byte_for_byte():
    """``Trip.state_json`` (what a shared store writes per fix) is ``to_json(Trip.state())`` and the advisory sliced out
    of it (``Trip.last_json``, the answer) is ``to_json`` of the advisory, over a drive on live SPaT (its observed
    phases in the state): stops at reds, speeches, held plans, a restore from the JSON."""
    import asyncio

    from pydantic_core import from_json, to_json

    from server.advising import Engine
    from server.gps import Fix
    from server.schemas import TripCreate
    from server.spat import SpatHub
    from spat_feed.transport.scenarios import make_scenario, spat_message_at

    corridor = load_corridor("paper_s200")
    cfg = Settings(corridors=("paper_s200",), default_corridor="paper_s200", spat_simulate=False, tables=False, speech=False, rate_burst=1000)
    clock = {"now": NOW}
    hub = SpatHub(cfg, {corridor.name: corridor}, lambda: clock["now"])
    scenario = make_scenario(corridor, "15_15", NOW - 40.0)
    engine = Engine(cfg, {corridor.name: corridor}, spat=hub, clock=lambda: clock["now"])

    async def drive() -> int:
        trip = await engine.create_trip(TripCreate(corridor=corridor.name), client="a")
        assert trip.observed is not None and trip.state_json() == to_json(trip.state())
        x, v, spoken = -30.0, 12.0, 0
        for k in range(90):
            clock["now"] = t = NOW + k
            for ix in spat_message_at(scenario, t).intersections:
                hub.store.offer(ix)
            out = engine.on_fix(trip, Fix(t, *corridor.position(min(max(x, 0.0), corridor.length_m)), speed_mps=v if k % 5 else None, accuracy_m=4.0))
            target = out["target_speed_mps"]
            v = 0.0 if out["action"] == "stop" and out["distance_to_line_m"] < 15 else max(v - 1.5, target) if target is not None else 12.0
            x += v
            spoken += out["speak"]
            data = trip.state_json()
            assert data == to_json(trip.state()), k
            assert trip.last_json() == to_json(out)
            copy = await engine.trip_from_meta(trip.meta())
            copy.restore(from_json(data))
            assert copy.state_json() == data
        assert trip.observed.runs and trip.memory.spoken is not None and trip.memory.spoken is not trip.memory.last
        return spoken

    assert asyncio.run(drive()) >= 3  # the advice changed and was spoken several times: the remembered advice moved
