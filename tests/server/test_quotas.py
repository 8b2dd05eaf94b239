"""Who may create trips and how many, across two workers on one Redis (issue 30, item 5): an API key's own trip
quota, a per-device limit inside it, trips created without a key shed newest first when the service is full,
and a worker crash never locks a phone out of its WebSocket stream.

Real ``redis-server`` and real ``python -m server`` processes on loopback, the settings given to them only
(not the suite's generous per-client ones: the defaults are what is tested). Anonymous clients connect from
127.0.0.2-127.0.0.9 (Linux routes all of 127/8 to loopback), so per-address quotas can be told apart. Every
wait is bounded; nothing asserts on speed.
"""

from __future__ import annotations

import asyncio
import hashlib
import json
import time

import httpx
import pytest
import redis
import websockets
from fastapi.testclient import TestClient

from server.app import create_app
from server.config import Settings
from server.web.errors import ApiError
from tests.procs import Proc, RedisServer, redis_server_path

ENV = {
    "ECO_CORRIDORS": "paper_s200", "ECO_DEFAULT_CORRIDOR": "paper_s200", "ECO_TABLES": "false", "ECO_SPEECH": "false",
    "ECO_API_KEYS": "k-app,k-fleet,k-small", "ECO_API_KEY_QUOTAS": json.dumps({"k-small": {"max_trips": 3}}),
    "ECO_ANONYMOUS_TRIPS": "true", "ECO_MAX_TRIPS": "50", "ECO_MAX_CONNECTIONS_PER_CLIENT": "0",
}  # fmt: skip
"""Three keys (k-small with a quota of 3 open trips), trips without a key allowed besides them, 50 open trips in all;
every other limit at its default."""


def worker(folder, url: str, **env: str) -> Proc:
    return Proc(["-m", "server", "--log-level", "warning", "--no-access-log"], folder / "service.log", {**ENV, "ECO_STORE_URL": url, **env})


@pytest.fixture(scope="module")
def store(tmp_path_factory):
    if redis_server_path() is None:
        pytest.skip("redis-server is not installed and scripts/system-deps.sh could not install it (needs root and apt-get)")
    server = RedisServer(tmp_path_factory.mktemp("redis")).start()
    yield server
    server.kill()


@pytest.fixture(scope="module")
def workers(store, tmp_path_factory):
    procs = [worker(tmp_path_factory.mktemp(f"worker{i}"), store.url).start() for i in range(2)]
    yield procs
    for p in procs:
        p.kill()


@pytest.fixture
def empty(store):
    """Each test starts with no trip open."""
    with redis.Redis(port=store.port) as r:
        r.flushdb()


def create(base_url: str, key: str | None = None, source: str | None = None, **body) -> httpx.Response:
    headers = {"X-API-Key": key} if key else {}
    transport = httpx.HTTPTransport(local_address=source) if source else None
    with httpx.Client(transport=transport, timeout=10) as c:
        return c.post(base_url + "/v1/trips", json=body, headers=headers)


def auth(created: httpx.Response) -> dict[str, str]:
    return {"Authorization": f"Bearer {created.json()['token']}"}


def test_forty_phones_sharing_one_app_key_each_get_a_trip_and_a_device_its_limit(workers, empty):
    """Finding: a key's quota was that of one client (1 trip/s, burst 20): 40 phones of one app got 20 x 429."""
    a, b = workers
    made = [create((a, b)[k % 2].base_url, "k-app") for k in range(40)]  # an app that names no device: the key's quota alone
    assert [r.status_code for r in made] == [201] * 40, [r.text for r in made if r.status_code != 201][:2]
    # one device: ECO_MAX_TRIPS_PER_DEVICE (2) open trips, wherever they were created; its neighbours are not held up
    first = create(a.base_url, "k-app", device_id="phone-00")
    assert create(b.base_url, "k-app", device_id="phone-00").status_code == 201
    third = create(a.base_url, "k-app", device_id="phone-00")
    assert third.status_code == 429 and third.json()["error"] == "too_many_trips_for_device" and int(third.headers["retry-after"]) >= 1
    assert create(a.base_url, "k-app", device_id="phone-41").status_code == 201
    assert httpx.post(f"{b.base_url}/v1/trips/{first.json()['trip_id']}/end", headers=auth(first), timeout=60).status_code == 200
    assert create(a.base_url, "k-app", device_id="phone-00").status_code == 201  # an ended trip frees the device's slot
    # a key's own quota (ECO_API_KEY_QUOTAS): k-small holds 3 open trips, whatever the devices; k-app goes on
    small = [create((a, b)[k % 2].base_url, "k-small", device_id=f"van-{k:04d}").status_code for k in range(4)]
    assert small == [201, 201, 201, 429]
    r = create(b.base_url, "k-small", device_id="van-0009")
    assert r.json()["error"] == "too_many_trips_for_client" and "3 open trips" in r.json()["message"]
    assert create(b.base_url, "k-app", device_id="phone-42").status_code == 201


def _shed(worker_: Proc) -> float:
    text = httpx.get(worker_.base_url + "/metrics", headers={"X-API-Key": "k-app"}).text
    return sum(float(line.rsplit(" ", 1)[1]) for line in text.splitlines() if line.startswith('ecodrive_trips_closed_total{how="shed"}'))


def test_trips_without_a_key_are_shed_newest_first_so_they_cannot_lock_out_keyed_fleets(workers, store, empty):
    """Finding: in open mode 1,000 addresses filled the 20,000-trip cap in 100 s and then nobody got a trip."""
    a, b = workers
    shed_before = _shed(a) + _shed(b)
    anonymous = []  # 50 trips (the cap) from 5 addresses, 10 each, oldest first
    for k in range(50):
        r = create((a, b)[k % 2].base_url, source=f"127.0.0.{2 + k % 5}", device_id=f"anon-{k:03d}")
        assert r.status_code == 201, r.text
        anonymous.append(r)
    full = create(a.base_url, source="127.0.0.8")
    assert full.status_code == 503 and full.json()["error"] == "too_many_trips" and "retry-after" in full.headers
    keyed = [create((b, a)[k % 2].base_url, "k-fleet", device_id=f"bus-{k:04d}") for k in range(5)]
    assert [r.status_code for r in keyed] == [201] * 5  # each took the place of the newest trip without a key

    def alive(r: httpx.Response, via: Proc) -> int:
        return httpx.get(f"{via.base_url}/v1/trips/{r.json()['trip_id']}", headers=auth(r), timeout=10).status_code

    assert [alive(r, a) for r in anonymous[-5:]] == [404] * 5
    gone = httpx.get(f"{b.base_url}/v1/trips/{anonymous[-1].json()['trip_id']}", headers=auth(anonymous[-1]), timeout=10).json()
    assert gone["error"] == "unknown_trip" and "shed" in gone["message"]
    assert [alive(r, (a, b)[k % 2]) for k, r in enumerate(anonymous[:-5])] == [200] * 45
    assert _shed(a) + _shed(b) - shed_before == 5
    assert create(b.base_url, source="127.0.0.9").status_code == 503  # still full for trips without a key
    # keyed trips are never shed: the service full of them, a keyed one is refused
    with redis.Redis(port=store.port) as r:
        assert r.zcard("eco:open") == 50
        r.flushdb()
    more = [create((a, b)[k % 2].base_url, "k-fleet") for k in range(51)]
    assert [r.status_code for r in more[:50]] == [201] * 50
    assert more[50].status_code == 503 and more[50].json()["error"] == "too_many_trips"
    assert _shed(a) + _shed(b) - shed_before == 5


async def _advised(url: str, headers: dict, fix: dict) -> dict:
    async with websockets.connect(url, additional_headers=headers, open_timeout=10) as ws:
        await ws.send(json.dumps(fix))
        return json.loads(await asyncio.wait_for(ws.recv(), 10))


def test_two_worker_crashes_never_lock_a_phone_out_of_its_stream(workers, empty):
    """Finding: two worker crashes within 60 s locked a phone out of its WebSocket for ~60 s (each dead worker's
    stream kept its lease, and two leases filled the trip's ECO_WS_MAX_PER_TRIP = 2). Now the phone's first
    reconnect after each crash is served."""
    a, b = workers
    try:
        r = create(a.base_url, "k-app", device_id="phone-ws", entry_unix_s=time.time() - 10)
        headers, trip_id = auth(r), r.json()["trip_id"]
        t0 = time.time()

        def fix(k: int) -> dict:
            return {"t_unix_s": t0 + k, "lat_deg": 0.0, "lon_deg": 0.0}

        def url(w: Proc) -> str:
            return f"ws://127.0.0.1:{w.port}/v1/trips/{trip_id}/stream"

        async def drive() -> list[dict]:
            replies = []
            ws = await websockets.connect(url(a), additional_headers=headers, open_timeout=10)
            await ws.send(json.dumps(fix(0)))
            replies.append(json.loads(await asyncio.wait_for(ws.recv(), 10)))
            a.kill()  # crash 1: the stream's worker dies with it
            with pytest.raises(websockets.ConnectionClosed):
                await asyncio.wait_for(ws.recv(), 10)
            ws = await websockets.connect(url(b), additional_headers=headers, open_timeout=10)
            await ws.send(json.dumps(fix(1)))
            replies.append(json.loads(await asyncio.wait_for(ws.recv(), 10)))
            b.kill()  # crash 2, seconds later
            with pytest.raises(websockets.ConnectionClosed):
                await asyncio.wait_for(ws.recv(), 10)
            a.start()
            replies.append(await _advised(url(a), headers, fix(2)))  # the first reconnect is served
            return replies

        replies = asyncio.run(drive())
        assert [m.get("seq") for m in replies] == [1, 2, 3], replies
    finally:
        for w in (a, b):
            if w.proc is None:
                w.start()


def test_a_newer_stream_of_a_trip_replaces_the_oldest_across_workers(workers, empty):
    """At most ECO_WS_MAX_PER_TRIP (2) streams of a trip are open: a third, on any worker, replaces the oldest,
    which is told why and closed with 4409 (one token never holds more; a phone whose old connection hangs
    half-open gets in)."""
    a, b = workers
    r = create(a.base_url, "k-app", device_id="phone-3ws", entry_unix_s=time.time() - 10)
    headers, trip_id = auth(r), r.json()["trip_id"]
    t0 = time.time()

    async def run() -> None:
        urls = [f"ws://127.0.0.1:{w.port}/v1/trips/{trip_id}/stream" for w in (a, b, b)]
        ws1 = await websockets.connect(urls[0], additional_headers=headers, open_timeout=10)
        ws2 = await websockets.connect(urls[1], additional_headers=headers, open_timeout=10)
        await ws2.send(json.dumps({"t_unix_s": t0, "lat_deg": 0.0, "lon_deg": 0.0}))
        assert json.loads(await asyncio.wait_for(ws2.recv(), 10))["seq"] == 1
        reply = await _advised(urls[2], headers, {"t_unix_s": t0 + 1, "lat_deg": 0.0, "lon_deg": 0.0})
        assert reply["seq"] == 2, reply
        told = json.loads(await asyncio.wait_for(ws1.recv(), 20))  # within a lease renewal (a third of ECO_WS_LEASE_S)
        assert told["status"] == 409 and told["error"] == "stream_replaced", told
        with pytest.raises(websockets.ConnectionClosed) as closed:
            await asyncio.wait_for(ws1.recv(), 10)
        assert closed.value.rcvd.code == 4409
        await ws2.send(json.dumps({"t_unix_s": t0 + 2, "lat_deg": 0.0, "lon_deg": 0.0}))  # the other one goes on
        assert json.loads(await asyncio.wait_for(ws2.recv(), 10))["seq"] == 3
        await ws2.close()

    asyncio.run(run())


def test_the_in_process_store_holds_the_same_quotas():
    """The embedded default (one process, no Redis) answers as the workers above: a key's own quota, a device's
    limit, the newest trip without a key shed for a keyed one, never a keyed one."""
    settings = Settings(corridors=("paper_s200",), default_corridor="paper_s200", tables=False, speech=False, api_keys=("k-app", "k-small"),
                        api_key_quotas={"key-" + hashlib.sha256(b"k-small").hexdigest()[:8]: {"max_trips": 1}},  # by its id
                        anonymous_trips=True, max_trips=6)  # fmt: skip
    with TestClient(create_app(settings)) as c:
        key = {"X-API-Key": "k-app"}
        assert [c.post("/v1/trips", json={"device_id": "phone-00"}, headers=key).status_code for _ in range(3)] == [201, 201, 429]
        assert [c.post("/v1/trips", json={}, headers={"X-API-Key": "k-small"}).status_code for _ in range(2)] == [201, 429]  # quota by key id
        anonymous = [c.post("/v1/trips", json={}) for _ in range(3)]  # 6 open: full
        assert [r.status_code for r in anonymous] == [201] * 3
        assert c.post("/v1/trips", json={}).status_code == 503
        assert c.post("/v1/trips", json={}, headers=key).status_code == 201  # the newest without a key gave its place
        assert [c.get(f"/v1/trips/{r.json()['trip_id']}", headers=auth(r)).status_code for r in anonymous] == [200, 200, 404]
        assert c.post("/v1/trips", json={}, headers={"X-API-Key": "wrong"}).status_code == 403  # a key sent must be valid
        c.post("/v1/trips", json={}, headers=key)
        c.post("/v1/trips", json={}, headers=key)
        r = c.post("/v1/trips", json={}, headers=key)  # only keyed trips left: none is shed
        assert r.status_code == 503 and r.json()["error"] == "too_many_trips"
        assert 'ecodrive_trips_closed_total{how="shed"} 3.0' in c.get("/metrics", headers=key).text


def test_stream_leases_are_renewed_by_their_worker_and_lapse_with_it(store, empty):
    """The lease logic on a fake clock, two workers' stream counters on the real Redis: a silent stream keeps
    counting while its worker renews it; a dead worker's stream stops counting within ECO_WS_LEASE_S (the address
    cap, 1 here, admits again); a stream replaced through the other worker is told so at its worker's renewal."""
    from server.storage.store import Limits, RedisTrips
    from server.storage.streams import RedisStreams

    now = [time.time()]
    settings = Settings(corridors=("paper_s200",), default_corridor="paper_s200", tables=False, speech=False, store_url=store.url, store_prefix="lease")

    async def build(meta):
        raise AssertionError("no trip is loaded here")

    async def run() -> None:
        trips_a, trips_b = (RedisTrips(settings, Limits(settings), build, clock=lambda: now[0]) for _ in range(2))
        a, b, c = RedisStreams(trips_a, lease_s=15.0), RedisStreams(trips_b, lease_s=15.0), RedisStreams(trips_b, lease_s=15.0)
        r = redis.Redis(port=store.port)
        try:
            told = []
            silent = await a.open("t1", "10.0.0.1", 2, 0, lambda: told.append("silent"))
            now[0] += 40.0  # no message for 40 s: its worker renews it all the same
            await a.renew()
            assert r.zscore("lease:ws:t:t1", silent.member) == pytest.approx(now[0] + 15.0)
            await b.open("t2", "10.0.0.2", 2, 1)  # worker b dies holding it: nobody renews it
            with pytest.raises(ApiError) as full:
                await a.open("t3", "10.0.0.2", 2, 1)
            assert full.value.status == 429 and full.value.error == "too_many_streams"
            now[0] += 15.0 + 1e-3  # one lease later: the address's slot is free again
            assert (await a.open("t3", "10.0.0.2", 2, 1)).member
            await a.renew()  # (every 5 s in a worker) the silent stream still counts
            await c.open("t1", "10.0.0.1", 2, 0)  # another worker: the phone's newer streams of t1 replace the silent one
            assert r.zscore("lease:ws:t:t1", silent.member) is not None
            await c.open("t1", "10.0.0.1", 2, 0)
            assert told == [] and r.zscore("lease:ws:t:t1", silent.member) is None
            await a.renew()
            assert told == ["silent"] and r.zscore("lease:ws:t:t1", silent.member) is None and r.zcard("lease:ws:t:t1") == 2
        finally:
            r.delete(*(r.keys("lease:*") or ["none"]))
            r.close()
            for streams in (a, b, c):
                await streams.aclose()
            await trips_a.close()
            await trips_b.close()

    asyncio.run(run())


def test_an_operator_sets_a_key_quota_by_the_key_or_its_id_and_mistakes_stop_the_start():
    from pydantic import ValidationError

    from server.admission.quotas import Quota, key_quotas

    base = dict(corridors=("paper_s200",), default_corridor="paper_s200", api_keys=("k-app", "k-small"), key_max_trips=100)
    small_id = "key-" + hashlib.sha256(b"k-small").hexdigest()[:8]
    for name in ("k-small", small_id):
        quotas = key_quotas(Settings(**base, api_key_quotas={name: {"max_trips": 3, "max_trips_per_device": 0}}))
        assert quotas[small_id] == Quota(max_trips=3, create_rate_per_s=10.0, create_burst=200.0, max_trips_per_device=0)
    assert key_quotas(Settings(**base))["key-" + hashlib.sha256(b"k-app").hexdigest()[:8]].max_trips == 100  # the ECO_KEY_* defaults
    for wrong in ({"api_key_quotas": {"k-other": {"max_trips": 3}}}, {"api_key_quotas": {"k-app": {"max_trip": 3}}}, {"api_key_quotas": {"k-app": {"max_trips": -1}}}):
        with pytest.raises(ValidationError) as refused:
            Settings(**base, **wrong)
        assert "k-other" not in str(refused.value)  # a key named by mistake is not echoed (it may be a secret)
    with pytest.raises(ValidationError, match="nobody could create a trip"):
        Settings(corridors=("paper_s200",), default_corridor="paper_s200", anonymous_trips=False)
