"""Several workers on one Redis (``ECO_STORE_URL``): any worker answers any call of any trip, a killed worker
loses nothing it accepted, limits hold across workers, a Redis outage is 503 (retry), not 404 (gone).

Real ``redis-server`` and real ``python -m server`` processes on loopback. Independent answer: the same drive
sent to one in-process service (the embedded default) gives the same advisories, fix by fix, and the same score.
Every wait is bounded; nothing asserts on speed.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import os
import signal
import subprocess
import time
from pathlib import Path

import httpx
import pytest
import redis
import websockets

from tests.procs import REPO, Proc, RedisServer, free_port, redis_server_path
from tests.server.conftest import service_proc

KEYS = ("k-drive", "k-quota", "k-global", "k-ws")
WORKER_ENV = {
    "ECO_CORRIDORS": "paper_s200", "ECO_DEFAULT_CORRIDOR": "paper_s200", "ECO_TABLES": "false", "ECO_SPEECH": "false",
    "ECO_API_KEYS": ",".join(KEYS), "ECO_RATE_PER_S": "0.001", "ECO_RATE_BURST": "100", "ECO_KEY_MAX_TRIPS": "5",
    "ECO_KEY_CREATE_RATE_PER_S": "0.001", "ECO_KEY_CREATE_BURST": "6", "ECO_MAX_TRIPS": "8", "ECO_WS_MAX_PER_CLIENT": "3",
}  # fmt: skip


def _redis_or_skip(folder: Path) -> RedisServer:
    if redis_server_path() is None:
        pytest.skip("redis-server is not installed and scripts/system-deps.sh could not install it (needs root and apt-get)")
    return RedisServer(folder).start()


@pytest.fixture(scope="module")
def store(tmp_path_factory):
    server = _redis_or_skip(tmp_path_factory.mktemp("redis"))
    yield server
    server.kill()


@pytest.fixture(scope="module")
def workers(store, tmp_path_factory):
    """Two workers (separate processes, as on two machines) sharing the Redis store."""
    procs = [service_proc(tmp_path_factory.mktemp(f"worker{i}"), **WORKER_ENV, ECO_STORE_URL=store.url) for i in range(2)]
    for p in procs:
        p.start()
    yield procs
    for p in procs:
        p.kill()


def drive_fixes(corridor, t0: float, n: int) -> list[dict]:
    """A car along the corridor at 12 m/s, one fix a second; every third without speed (derived from positions)."""
    out = []
    for k in range(n):
        lat, lon = corridor.position(min(12.0 * k, corridor.length_m + 30.0))
        fix = {"t_unix_s": t0 + k, "lat_deg": lat, "lon_deg": lon, "accuracy_m": 4.0}
        if k % 3:
            fix["speed_mps"] = 12.0
        out.append(fix)
    return out


def _create(base_url: str, key: str, **body) -> tuple[str, dict]:
    r = httpx.post(base_url + "/v1/trips", json=body, headers={"X-API-Key": key}, timeout=10)
    assert r.status_code == 201, r.text
    d = r.json()
    return d["trip_id"], {"Authorization": f"Bearer {d['token']}"}


def _strip(advice: dict) -> dict:
    return {k: v for k, v in advice.items() if k != "trip_id"}


def test_any_worker_answers_a_killed_worker_loses_nothing_same_advice_and_score_as_one_process(workers, s200, tmp_path):
    one = service_proc(tmp_path, **{k: v for k, v in WORKER_ENV.items()}).start()  # the in-process store
    try:
        a, b = workers
        t0 = time.time() - 120.0
        body = {"corridor": "paper_s200", "timing": "15_15", "entry_unix_s": t0}
        ref_id, ref_auth = _create(one.base_url, "k-drive", **body)
        trip_id, auth = _create(a.base_url, "k-drive", **body)
        fixes = drive_fixes(s200, t0, 40)
        ref, got = [], []
        for k, fix in enumerate(fixes):
            if k == 15:
                a.kill()  # mid-trip: b alone answers until a is back
            if k == 25:
                a.start()
            to = b if (k % 2 or a.proc is None) else a
            ref.append(httpx.post(f"{one.base_url}/v1/trips/{ref_id}/fixes", json=fix, headers=ref_auth).json())
            r = httpx.post(f"{to.base_url}/v1/trips/{trip_id}/fixes", json=fix, headers=auth)
            assert r.status_code == 200, r.text
            got.append(r.json())
            if k == 5:  # the same fix again, on the other worker: a duplicate, nothing changes
                other = a if to is b else b
                dup = httpx.post(f"{other.base_url}/v1/trips/{trip_id}/fixes", json=fix, headers=auth).json()
                assert dup["fix_status"] == "duplicate" and dup["seq"] == got[-1]["seq"]
        assert [_strip(x) for x in got] == [_strip(x) for x in ref]
        assert [x["seq"] for x in got] == list(range(1, 41))
        assert any(x["action"] not in ("none", "cruise") for x in got)  # the drive met a light: the advisor's memory mattered
        for w in (a, b):  # any worker reads the trip and its latest advice
            assert httpx.get(f"{w.base_url}/v1/trips/{trip_id}", headers=auth).json()["n_fixes"] == 40
            assert _strip(httpx.get(f"{w.base_url}/v1/trips/{trip_id}/advice", headers=auth).json()) == {**_strip(got[-1]), "fix_status": "none"}
        wrong = httpx.get(f"{b.base_url}/v1/trips/{trip_id}", headers=ref_auth)  # another (in-process) trip's token: not this one's
        assert wrong.status_code == 401
        score = httpx.post(f"{b.base_url}/v1/trips/{trip_id}/end", headers=auth, timeout=60)
        ref_score = httpx.post(f"{one.base_url}/v1/trips/{ref_id}/end", headers=ref_auth, timeout=60).json()
        assert score.status_code == 200, score.text
        assert {**score.json(), "trip_id": None} == {**ref_score, "trip_id": None}
        assert score.json()["complete"] and score.json()["driven"] is not None
        for w in (a, b):  # ended: gone on every worker
            assert httpx.get(f"{w.base_url}/v1/trips/{trip_id}", headers=auth).status_code == 404
    finally:
        one.kill()


def test_limits_hold_across_workers(workers, store):
    a, b = workers
    t0 = time.time() - 60.0
    # per trip: a burst of 100 requests across both workers, not 100 each
    trip_id, auth = _create(a.base_url, "k-global", entry_unix_s=t0)
    codes = [httpx.get(f"{(a, b)[k % 2].base_url}/v1/trips/{trip_id}/advice", headers=auth).status_code for k in range(101)]
    assert codes[:100] == [200] * 100 and codes[100] == 429
    # per client: 5 open trips, wherever they were created; then the creation bucket (burst 6) is empty
    made = [_create((a, b)[k % 2].base_url, "k-quota") for k in range(5)]
    r = httpx.post(b.base_url + "/v1/trips", json={}, headers={"X-API-Key": "k-quota"})
    assert r.status_code == 429 and r.json()["error"] == "too_many_trips_for_client"
    assert httpx.post(f"{a.base_url}/v1/trips/{made[0][0]}/end", headers=made[0][1], timeout=60).status_code == 200
    r = httpx.post(a.base_url + "/v1/trips", json={}, headers={"X-API-Key": "k-quota"})
    assert r.status_code == 429 and r.json()["error"] == "rate_limited" and int(r.headers["retry-after"]) >= 1
    # service-wide: at most 8 open trips in all
    open_now = httpx.get(a.base_url + "/health").json()["trips"]
    assert open_now == len(store_trips(store)) >= 5  # the health count is the store's
    for k in range(8 - open_now):
        _create((a, b)[k % 2].base_url, "k-global")
    r = httpx.post(b.base_url + "/v1/trips", json={}, headers={"X-API-Key": "k-global"})
    assert r.status_code == 503 and r.json()["error"] == "too_many_trips" and "retry-after" in r.headers
    with redis.Redis(port=store.port) as r:
        r.flushdb()  # room for the next tests


def store_trips(store: RedisServer) -> list[bytes]:
    with redis.Redis(port=store.port) as r:
        return [k for k in r.scan_iter("eco:t:*") if not k.endswith(b":tr")]


def test_websocket_streams_are_capped_across_workers(workers):
    """At most ECO_WS_MAX_PER_CLIENT (3) streams per client address, wherever they are opened (4429 beyond); a
    closed one frees its slot. (Per trip, a newer stream replaces the oldest: tests/server/test_quotas.py.)"""
    a, b = workers
    trips = [_create(a.base_url, "k-ws", entry_unix_s=time.time() - 10) for _ in range(2)]

    def url(w: Proc, k: int) -> str:
        return f"ws://127.0.0.1:{w.port}/v1/trips/{trips[k][0]}/stream"

    async def connect(w: Proc, k: int):
        return await websockets.connect(url(w, k), additional_headers=trips[k][1], open_timeout=10, local_addr=("127.0.0.3", 0))

    async def run() -> None:
        held = [await connect(a, 0), await connect(b, 0), await connect(b, 1)]
        extra = await connect(a, 1)
        msg = json.loads(await asyncio.wait_for(extra.recv(), 10))
        assert msg["status"] == 429 and msg["error"] == "too_many_streams"
        with pytest.raises(websockets.ConnectionClosed) as closed:
            await asyncio.wait_for(extra.recv(), 10)
        assert closed.value.rcvd.code == 4429
        await held[0].close()
        # the slot held[0] held: the server frees it when it sees the close, and its closing frame may reach the
        # client first (uvicorn answers a close before the route's ``finally`` runs): a new stream opens
        # once the slot is free, within a bound; until then it is refused with 4429, never anything else
        deadline = time.monotonic() + 20
        while True:
            try:
                async with await connect(a, 1) as ws4:
                    await ws4.send(json.dumps({"t_unix_s": time.time() - 1, "lat_deg": 0.0, "lon_deg": 0.0}))
                    reply = json.loads(await asyncio.wait_for(ws4.recv(), 10))
            except websockets.ConnectionClosed as exc:
                assert exc.rcvd is not None and exc.rcvd.code == 4429, exc
                reply = {"error": "too_many_streams"}
            if "seq" in reply or time.monotonic() > deadline:
                break
            assert reply["error"] == "too_many_streams", reply
            await asyncio.sleep(0.1)
        assert "seq" in reply, reply
        for ws in held[1:]:
            await ws.close()

    asyncio.run(run())


def test_trip_state_is_bounded_and_expires(workers, store, s200):
    a, _ = workers
    t0 = time.time() - 60.0
    trip_id, auth = _create(a.base_url, "k-drive", corridor="paper_s200", timing="15_15", entry_unix_s=t0)
    for fix in drive_fixes(s200, t0, 30):
        assert httpx.post(f"{a.base_url}/v1/trips/{trip_id}/fixes", json=fix, headers=auth).status_code == 200
    with redis.Redis(port=store.port) as r:
        h = r.hgetall(f"eco:t:{trip_id}")
        assert set(h) == {b"v", b"tok", b"client", b"dev", b"bt", b"bs", b"ts", b"meta", b"state"}
        assert auth["Authorization"].split()[1].encode() not in b"".join(h.values())  # the token's hash only
        state = json.loads(h[b"state"])
        assert state["n_fixes"] == 30 and len(state["track"][1]) <= 8 and len(h[b"state"]) < 4096
        samples = r.get(f"eco:t:{trip_id}:tr")
        assert len(samples) == 24 * state["n_trace"] and state["n_trace"] == 29  # 24 bytes a sample, per fix with a speed (not the first)
        ttl, every = 1800.0, 10.0  # the idle clock is reset at most every 10 s: the keys live TTL + 10 s after a reset
        for key in (f"eco:t:{trip_id}", f"eco:t:{trip_id}:tr"):
            assert (ttl - 60.0) * 1000 < r.pttl(key) <= (ttl + every) * 1000  # at least the TTL after the last fix (just now)


def test_the_idle_clock_is_reset_at_most_every_tenth_of_the_ttl_and_the_bucket_holds(store, s200):
    """A fix does not reset the trip's expiry and open-set scores unless they were last reset a tenth of the TTL
    ago (at most 10 s): the trip still counts as open until the TTL after its last request; the trip's request
    bucket is taken in the same write. In process (``Engine`` on the shared Redis, no HTTP), on a fake clock."""
    from server.advising import Engine
    from server.config import Settings
    from server.web.errors import ApiError
    from server.gps import Fix
    from server.schemas import TripCreate

    now = [time.time()]
    settings = Settings(corridors=("paper_s200",), default_corridor="paper_s200", tables=False, speech=False, store_url=store.url,
                        store_prefix="idle", trip_idle_ttl_s=100.0, rate_per_s=0.001, rate_burst=12.0)  # fmt: skip
    engine = Engine(settings, {"paper_s200": s200}, clock=lambda: now[0])

    def fix(k: int) -> Fix:
        lat, lon = s200.position(10.0 * k)
        return Fix(now[0], lat, lon, 10.0, None, 4.0)

    async def run() -> None:
        trip = await engine.create_trip(TripCreate(corridor="paper_s200", timing="15_15", entry_unix_s=now[0]))
        key, r = f"idle:t:{trip.id}", redis.Redis(port=store.port)
        reset = float(r.hget(key, "ts"))
        assert reset == now[0] and r.zscore("idle:open", trip.id) == reset
        for k in range(1, 10):  # 9 s: no reset
            now[0] += 1.0
            assert (await engine.apply_fix(trip.id, trip.token, lambda: fix(k)))["seq"] == k
            assert float(r.hget(key, "ts")) == reset and r.zscore("idle:open", trip.id) == reset
        last = now[0]
        now[0] = last + 100.0 - 1e-3  # the TTL after the last request, not yet passed: still open
        assert await engine.trips.count() == 1
        now[0] = last + 1.0  # 10 s after the reset: this fix resets the clock
        assert (await engine.apply_fix(trip.id, trip.token, lambda: fix(10)))["seq"] == 10
        assert float(r.hget(key, "ts")) == now[0] == r.zscore("idle:open", trip.id)
        assert r.pttl(key) > 100_000  # TTL + 10 s from the reset (real milliseconds)
        for k in (11, 12):  # the bucket (burst 12) is used up by the 12th fix
            now[0] += 1.0
            await engine.apply_fix(trip.id, trip.token, lambda: fix(k))
        now[0] += 1.0
        with pytest.raises(ApiError) as refused:
            await engine.apply_fix(trip.id, trip.token, lambda: fix(13))
        assert refused.value.status == 429 and int(r.hget(key, "v")) == 13  # nothing written: 12 fixes, version 1 + 12
        now[0] += 200.0  # idle longer than TTL + 10 s after the reset: not counted any more
        assert await engine.trips.count() == 0
        r.delete(*r.keys("idle:*"))
        await engine.trips.close()
        r.close()

    asyncio.run(run())


def test_websocket_on_a_killed_uvicorn_worker_reconnects_with_the_same_token(store, s200, tmp_path):
    """``--workers 2``: the worker holding a phone's WebSocket is killed; the phone reconnects (the other worker
    answers, uvicorn replaces the dead one) and goes on with its token; every acknowledged fix is in the trip."""
    proc = Proc(["-m", "server", "--workers", "2", "--log-level", "warning", "--no-access-log"], tmp_path / "service.log",
                {**WORKER_ENV, "ECO_STORE_URL": store.url}).start()  # fmt: skip
    try:
        t0 = time.time() - 100.0
        trip_id, auth = _create(proc.base_url, "k-ws", corridor="paper_s200", timing="15_15", entry_unix_s=t0)
        url = f"ws://127.0.0.1:{proc.port}/v1/trips/{trip_id}/stream"
        fixes = drive_fixes(s200, t0, 30)

        async def run() -> list[dict]:
            acked: list[dict] = []
            k = 0
            killed = False
            for _ in range(50):  # connections, bounded
                try:
                    async with websockets.connect(url, additional_headers=auth, open_timeout=10) as ws:
                        while k < len(fixes):
                            if k == 12 and not killed:
                                killed = True
                                os.kill(_worker_of(proc.proc.pid, ws), signal.SIGKILL)
                            await ws.send(json.dumps(fixes[k]))
                            msg = json.loads(await asyncio.wait_for(ws.recv(), 10))
                            assert "error" not in msg, msg
                            acked.append(msg)
                            k += 1
                        return acked
                except (websockets.ConnectionClosed, OSError):
                    await asyncio.sleep(0.2)  # the phone's back-off, then the same token again
            raise AssertionError("could not reconnect")

        acked = asyncio.run(run())
        assert len(_children(proc.proc.pid)) >= 1
        seqs = [m["seq"] for m in acked]
        assert seqs == list(range(1, len(seqs) + 1)) and len(seqs) == 30  # none lost, none counted twice
        assert httpx.get(f"{proc.base_url}/v1/trips/{trip_id}", headers=auth).json()["n_fixes"] == 30
        deadline = time.monotonic() + 60
        while len(_children(proc.proc.pid)) < 2 and time.monotonic() < deadline:  # uvicorn replaced the dead worker
            time.sleep(0.2)
        assert len(_children(proc.proc.pid)) == 2
    finally:
        children = _children(proc.proc.pid) if proc.proc is not None else []
        proc.kill()
        for pid in children:  # the supervisor was killed without telling its workers
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGKILL)


def _children(pid: int) -> list[int]:
    """The live worker processes of the uvicorn supervisor ``pid`` (Linux /proc: its children started by
    multiprocessing's spawn, not its resource tracker, not zombies)."""
    out = []
    for task in Path(f"/proc/{pid}/task").iterdir():
        with open(task / "children") as f:
            out += [int(c) for c in f.read().split()]
    workers = []
    for c in out:
        with contextlib.suppress(OSError):
            alive = Path(f"/proc/{c}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
            if alive and b"spawn_main" in Path(f"/proc/{c}/cmdline").read_bytes():
                workers.append(c)
    return workers


def _worker_of(supervisor_pid: int, ws) -> int:
    """The worker process holding the WebSocket ``ws``: the child with a socket whose inode is the server end
    of the client's connection (/proc/net/tcp)."""
    local_port = ws.transport.get_extra_info("sockname")[1]
    inodes = set()
    for line in Path("/proc/net/tcp").read_text().splitlines()[1:]:
        cols = line.split()
        if int(cols[2].split(":")[1], 16) == local_port:  # remote end = the client: this is the server's socket
            inodes.add(cols[9])
    for pid in _children(supervisor_pid):
        for fd in Path(f"/proc/{pid}/fd").iterdir():
            try:
                target = os.readlink(fd)
            except OSError:
                continue
            if target.startswith("socket:[") and target[8:-1] in inodes:
                return pid
    raise AssertionError("no worker holds the connection")


def _advised(worker: Proc) -> float:
    """Advisories this worker computed (its Prometheus counter)."""
    text = httpx.get(worker.base_url + "/metrics", headers={"X-API-Key": KEYS[0]}).text
    return sum(float(line.rsplit(" ", 1)[1]) for line in text.splitlines() if line.startswith("ecodrive_advice_total{"))


def test_behind_the_load_balancer_workers_come_and_go_and_the_trip_goes_on(workers, s200, tmp_path):
    """deploy/haproxy.cfg (docker compose's ``lb``) in front of the two workers on loopback: requests spread over
    both, a killed worker is passed over, none at all is 503 + Retry-After (JSON), a restarted one serves again."""
    import shutil

    if shutil.which("haproxy") is None:
        pytest.skip("haproxy is not installed (sh scripts/system-deps.sh, as root)")
    a, b = workers
    port = free_port()
    cfg = (REPO / "deploy" / "haproxy.cfg").read_text().replace("/app/deploy", str(REPO / "deploy")).replace("bind :8000", f"bind 127.0.0.1:{port}")
    cfg = cfg.replace("server-template advisory 16 advisory:8000", f"server a 127.0.0.1:{a.port}\n    server b 127.0.0.1:{b.port}")
    (tmp_path / "haproxy.cfg").write_text(cfg)
    lb = subprocess.Popen(["haproxy", "-db", "-f", str(tmp_path / "haproxy.cfg")], stdout=subprocess.DEVNULL, stderr=subprocess.STDOUT)
    base = f"http://127.0.0.1:{port}"
    try:
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline:
            with contextlib.suppress(httpx.HTTPError):
                if httpx.get(base + "/health", timeout=1).status_code == 200:
                    break
            time.sleep(0.1)
        else:
            raise AssertionError(f"haproxy did not answer on port {port} within 30 s (exit code {lb.poll()})")
        before = [_advised(w) for w in workers]
        t0 = time.time() - 100.0
        trip_id, auth = _create(base, "k-ws", corridor="paper_s200", timing="15_15", entry_unix_s=t0)
        fixes = drive_fixes(s200, t0, 40)
        with httpx.Client(base_url=base, headers=auth, timeout=10) as c:
            for fix in fixes[:10]:
                assert c.post(f"/v1/trips/{trip_id}/fixes", json=fix).status_code == 200
            assert all(_advised(w) > n for w, n in zip(workers, before))  # no sticky sessions: both served the trip
            a.kill()
            for fix in fixes[10:20]:  # passed over: the load balancer retries the other worker
                r = c.post(f"/v1/trips/{trip_id}/fixes", json=fix)
                assert r.status_code == 200, r.text
            b.kill()
            r = c.post(f"/v1/trips/{trip_id}/fixes", json=fixes[20])
            assert r.status_code == 503 and r.json()["error"] == "service_unavailable" and int(r.headers["retry-after"]) >= 1
            a.start()
            deadline = time.monotonic() + 30
            while (r := c.post(f"/v1/trips/{trip_id}/fixes", json=fixes[20])).status_code == 503 and time.monotonic() < deadline:
                time.sleep(0.2)  # the phone's retry, with the same fix and token
            assert r.status_code == 200 and r.json()["seq"] == 21
            for fix in fixes[21:]:
                assert c.post(f"/v1/trips/{trip_id}/fixes", json=fix).status_code == 200
            assert c.get(f"/v1/trips/{trip_id}").json()["n_fixes"] == 40
            score = c.post(f"/v1/trips/{trip_id}/end", timeout=60).json()
            assert score["complete"] and score["n_fixes"] >= 30
    finally:
        lb.kill()
        lb.wait(timeout=10)
        for w in workers:
            if w.proc is None:
                w.start()


def test_store_outage_is_503_retry_and_the_trip_survives_a_store_restart(s200, tmp_path):
    (tmp_path / "redis").mkdir()
    store = _redis_or_skip(tmp_path / "redis")
    worker = service_proc(tmp_path, **WORKER_ENV, ECO_STORE_URL=store.url, ECO_STORE_TIMEOUT_S="1").start()
    try:
        t0 = time.time() - 60.0
        trip_id, auth = _create(worker.base_url, "k-drive", corridor="paper_s200", timing="15_15", entry_unix_s=t0)
        fixes = drive_fixes(s200, t0, 10)
        for fix in fixes[:5]:
            assert httpx.post(f"{worker.base_url}/v1/trips/{trip_id}/fixes", json=fix, headers=auth).status_code == 200
        store.kill()
        r = httpx.post(f"{worker.base_url}/v1/trips/{trip_id}/fixes", json=fixes[5], headers=auth, timeout=30)
        assert r.status_code == 503 and r.json()["error"] == "store_unavailable" and int(r.headers["retry-after"]) >= 1
        store.start()  # same port and folder: the append-only file brings the trip back
        for fix in fixes[5:]:  # the phone retries the refused fix, then goes on
            r = httpx.post(f"{worker.base_url}/v1/trips/{trip_id}/fixes", json=fix, headers=auth, timeout=30)
            assert r.status_code == 200, r.text
        assert r.json()["seq"] == 10
        assert httpx.get(f"{worker.base_url}/v1/trips/nosuchtrip", headers=auth).status_code == 404  # unknown: 404, not 503
    finally:
        worker.kill()
        store.kill()


def test_compose_runs_workers_on_redis_behind_one_port():
    import yaml

    spec = yaml.safe_load((REPO / "docker-compose.yml").read_text())["services"]
    svc, store, lb = spec["advisory"], spec["redis"], spec["lb"]
    assert svc["environment"]["ECO_STORE_URL"] == "redis://redis:6379/0" and "--workers" in " ".join(svc["command"])
    assert "ports" not in svc and svc["deploy"]["replicas"] and svc["depends_on"]["redis"]["condition"] == "service_healthy"
    assert store["command"][0] == "redis-server" and "--appendonly" in store["command"] and "redis-cli" in store["healthcheck"]["test"]
    assert lb["ports"] == ["127.0.0.1:8000:8000"] and lb["depends_on"]["advisory"]["condition"] == "service_healthy"
    assert lb["command"][0] == "haproxy" and lb["command"][-1] == "/app/deploy/haproxy.cfg"
    cfg = (REPO / "deploy" / "haproxy.cfg").read_text()
    assert "advisory:8000" in cfg and "bind :8000" in cfg and "/app/deploy/503.http" in cfg
    docker = (REPO / "Dockerfile").read_text()
    assert "redis-server" in docker and "haproxy" in docker and "COPY deploy deploy" in docker
