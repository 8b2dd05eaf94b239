"""Overload shedding (``server.admission.overload``): a worker refuses what it cannot serve in time with 503 ``overloaded`` and
``Retry-After``, at once, instead of queueing it, and serves again as soon as the load falls.

The in-flight bound on a real ``python -m server`` worker with its trips in a real ``redis-server``, paused
(SIGSTOP) so that a fix stays in flight; the loop-lag signal on a real event loop blocked for a known time. Every
wait is bounded; nothing asserts on speed (a blocked loop's timer can only be late, never early).
"""

from __future__ import annotations

import asyncio
import os
import signal
import time
from concurrent.futures import ThreadPoolExecutor

import httpx
import pytest

from server.admission.overload import ShedMiddleware, Shedder
from tests.procs import RedisServer, redis_server_path
from tests.server.conftest import service_proc


def test_one_late_probe_sheds_nothing_two_in_a_row_shed_one_on_time_serves_again():
    shedder = Shedder(max_in_flight=10, max_lag_s=0.2)
    shedder.observe(0.9)  # one pause of the process (another job ran): not a queue
    assert shedder.refusal() is None
    shedder.observe(0.5)
    assert shedder.lag_s == 0.5 and shedder.refusal() == "loop_lag"
    shedder.observe(0.001)  # the load fell
    assert shedder.refusal() is None
    shedder.in_flight = 10
    assert shedder.refusal() == "in_flight"
    assert shedder.shed == {"in_flight": 1, "loop_lag": 1}


def test_a_loop_blocked_twice_sheds_with_retry_after_health_still_answers_and_it_recovers():
    """The real probe on a real loop: right after each of two probes the loop is blocked for 0.8 s (a worker whose
    turns take that long), so the next probe, due 0.5 s later, comes >= 0.3 s late; then the loop is left free."""
    served = []

    async def app(scope, receive, send):
        served.append(scope["path"])
        await send({"type": "http.response.start", "status": 200, "headers": []})
        await send({"type": "http.response.body", "body": b"{}"})

    async def run() -> None:
        shedder = Shedder(max_in_flight=100, max_lag_s=0.25)
        observed = []
        observe = shedder.observe
        shedder.observe = lambda late_s: (observe(late_s), observed.append(late_s))
        client = httpx.AsyncClient(transport=httpx.ASGITransport(ShedMiddleware(app, shedder)), base_url="http://test")
        probe = asyncio.create_task(shedder.watch(probe_s=0.5))

        async def next_probe() -> None:
            n, deadline = len(observed), time.monotonic() + 30
            while len(observed) == n and time.monotonic() < deadline:
                await asyncio.sleep(0.001)

        try:
            await next_probe()
            for _ in range(2):
                time.sleep(0.8)  # the probe's timer, due in 0.5 s, fires when this turn ends
                await next_probe()
            assert shedder.lag_s >= 0.3
            r = await client.post("/v1/trips/t/fixes", content=b"{}")
            assert r.status_code == 503 and r.headers["retry-after"] == "1"
            assert r.json()["error"] == "overloaded" and "retry in 1 s" in r.json()["message"]
            assert (await client.get("/health")).status_code == 200  # exempt: a busy worker is alive
            await next_probe()  # the load fell: one probe on time
            assert shedder.refusal() is None
            assert (await client.post("/v1/trips/t/fixes", content=b"{}")).status_code == 200
            assert served == ["/health", "/v1/trips/t/fixes"]
        finally:
            probe.cancel()
            await client.aclose()

    asyncio.run(run())


def test_in_flight_bound_on_a_worker_with_redis_paused_503_overloaded_then_served(tmp_path, s200):
    """ECO_MAX_IN_FLIGHT=1: a fix waits for a paused Redis (alive, silent, well within the store timeout); the next
    request is refused at once with 503 overloaded + Retry-After, not queued behind it nor answered "store
    unreachable"; Redis resumed, the waiting fix is accepted and the next one served."""
    if redis_server_path() is None:
        pytest.skip("redis-server is not installed and scripts/system-deps.sh could not install it (needs root and apt-get)")
    (tmp_path / "redis").mkdir()
    redis = RedisServer(tmp_path / "redis").start()
    proc = service_proc(tmp_path, ECO_STORE_URL=redis.url, ECO_MAX_IN_FLIGHT="1", ECO_STORE_TIMEOUT_S="60", ECO_TABLES="false").start()
    paused = False
    try:
        with httpx.Client(base_url=proc.base_url, timeout=60) as c, ThreadPoolExecutor(1) as pool:
            r = c.post("/v1/trips", json={})
            assert r.status_code == 201, r.text
            trip_id, auth = r.json()["trip_id"], {"Authorization": f"Bearer {r.json()['token']}"}
            lat, lon = s200.position(10.0)

            def fix(k: int) -> httpx.Response:
                return httpx.post(f"{proc.base_url}/v1/trips/{trip_id}/fixes", headers=auth, timeout=60,
                                  json={"t_unix_s": time.time(), "lat_deg": lat, "lon_deg": lon + 1e-5 * k, "speed_mps": 10.0})  # fmt: skip

            assert fix(0).status_code == 200
            os.kill(redis.proc.pid, signal.SIGSTOP)
            paused = True
            waiting = pool.submit(fix, 1)
            deadline = time.monotonic() + 30
            while "ecodrive_in_flight 1.0" not in c.get("/metrics").text:  # /metrics is exempt, and needs no Redis
                assert time.monotonic() < deadline and not waiting.done(), "the fix never reached the store"
                time.sleep(0.05)
            refused = fix(2)
            assert refused.status_code == 503, refused.text
            assert refused.json()["error"] == "overloaded" and refused.headers["retry-after"] == "1"
            os.kill(redis.proc.pid, signal.SIGCONT)
            paused = False
            assert waiting.result(timeout=60).status_code == 200
            assert fix(3).status_code == 200
            shed = [line for line in c.get("/metrics").text.splitlines() if line.startswith("ecodrive_shed_total")]
            assert shed == ['ecodrive_shed_total{reason="in_flight"} 1.0', 'ecodrive_shed_total{reason="loop_lag"} 0.0']
    finally:
        if paused:
            os.kill(redis.proc.pid, signal.SIGCONT)
        proc.kill()
        redis.kill()


def test_a_websocket_fix_while_shedding_gets_an_overloaded_error_and_the_stream_goes_on(s200):
    from fastapi.testclient import TestClient

    from server.app import create_app
    from server.config import Settings

    with TestClient(create_app(Settings(corridors=("paper_s200",), default_corridor="paper_s200", tables=False, speech=False))) as c:
        trip = c.post("/v1/trips", json={}).json()
        shedder = c.app.state.shedder
        lat, lon = s200.position(10.0)
        with c.websocket_connect(f"/v1/trips/{trip['trip_id']}/stream?token={trip['token']}") as ws:
            shedder.observe = lambda late_s: None  # the app's own probe is muted: the lag is set here
            shedder.lag_s = 1.0  # the loop a second late (at two probes in a row)
            ws.send_json({"t_unix_s": time.time(), "lat_deg": lat, "lon_deg": lon, "speed_mps": 10.0})
            refused = ws.receive_json()
            assert refused["status"] == 503 and refused["error"] == "overloaded" and "retry in 1 s" in refused["message"]
            shedder.lag_s = 0.0  # on time again
            ws.send_json({"t_unix_s": time.time(), "lat_deg": lat, "lon_deg": lon, "speed_mps": 10.0})
            assert ws.receive_json()["seq"] == 1  # the refused fix changed nothing
        assert shedder.shed["loop_lag"] == 1
