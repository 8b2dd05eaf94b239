"""Queue-aware advice across workers (issue 28, item 3): with the Redis store every worker's queue board holds every
worker's probes and red starts (``server.storage.queue_store``), so a fix on worker B counts the cars that worker A serves.

Two engines (two workers' boards) on one real ``redis-server`` on loopback, each with its own SPaT store fed the same
SPaT; the boards' background call made explicitly (``SharedBoard.sync``), so that nothing waits on time. Independent
answer: the same fixes, in the same order, sent to one in-process service (one worker sees every trip), and, for a
car that must not count, the same car alone. Then the same through two real ``python -m server`` workers: the app
syncs the board in the background and says in ``/health`` and ``/metrics`` where its probes come from."""

from __future__ import annotations

import asyncio
import re
import time

import httpx
import pytest
import redis

from server.advising import Engine
from server.config import Settings
from server.web.errors import ApiError
from server.gps import Fix
from server.web.metrics import Metrics
from server.queue import MAX_AGE_S
from server.storage.queue_store import KEEP_S
from server.schemas import TripCreate
from server.spat import SpatHub
from spat_feed.road.corridors import load_corridor
from spat_feed.transport.scenarios import make_scenario, spat_message_at
from tests.server.conftest import service_proc

T0 = 1_714_590_030.0
"""paper_s400 under plan 15_15: light 1 (stop line at 100 m) red from :15 to :45 of the minute, so red for 15 s more."""


@pytest.fixture(scope="module")
def corridor():
    return load_corridor("paper_s400")


class Service:
    """An engine as one worker runs it (the Redis store, or in process with ``url`` None), its clock at ``now[0]``."""

    def __init__(self, corridor, url: str | None, now: list[float], **settings) -> None:
        s = Settings(spat_simulate=False, tables=False, speech=False, queue_aware=True, store_url=url, **settings)
        self.hub = SpatHub(s, {corridor.name: corridor}, lambda: now[0])
        self.corridor = corridor
        self.spat(T0)
        self.engine = Engine(s, {corridor.name: corridor}, spat=self.hub, clock=lambda: now[0])
        self.now = now
        self.trips: dict[str, object] = {}

    def spat(self, t_unix_s: float) -> None:
        """The lights' SPaT as published at ``t_unix_s`` (plan 15_15), offered to this worker's SPaT store."""
        for ix in spat_message_at(make_scenario(self.corridor, "15_15", 0.0), t_unix_s).intersections:
            self.hub.store.offer(ix)

    async def add(self, name: str) -> None:
        self.trips[name] = await self.engine.create_trip(TripCreate(corridor=self.corridor.name), client=name)

    def fix(self, name: str, station_m: float, speed_mps: float, t_unix_s: float) -> dict:
        """The fix sent at its own time (the clock moved to it)."""
        self.now[0] = max(self.now[0], t_unix_s)
        out = self.engine.on_fix(self.trips[name], Fix(t_unix_s, *self.corridor.position(station_m), speed_mps=speed_mps))
        return {k: v for k, v in out.items() if k != "trip_id"}

    async def sync(self) -> bool:
        return await self.engine.queue.shared.sync()


async def _drive(worker_of: dict[str, Service], ref: Service, fixes) -> tuple[dict, dict]:
    """Each (trip, station, speed, t) fix to the worker serving the trip and to the one-worker reference, the workers'
    boards synced (each publishes, then each loads) at each None; the last advisory of each trip from both."""
    workers = list({id(w): w for w in worker_of.values()}.values())
    got, want = {}, {}
    for f in fixes:
        if f is None:
            for w in workers + workers:
                assert await w.sync()
            continue
        name, station_m, speed_mps, t = f
        got[name] = worker_of[name].fix(name, station_m, speed_mps, t)
        want[name] = ref.fix(name, station_m, speed_mps, t)
    return got, want


async def _close(*services: Service) -> None:
    for svc in services:
        await svc.engine.trips.close()


def test_a_car_queued_on_worker_a_holds_the_target_of_a_car_approaching_on_worker_b(store, corridor):
    """Four cars stand at light 1's red on worker A (the first seen red at T0); a car approaching at 13 m/s 120 m out
    on worker B one second later: B's advice is the one-worker service's (the queue counted, the red's start seen
    by A, the unconnected cars estimated from it: 720 veh/h, half connected), not the advice for the car alone
    (which aims at the green)."""
    now = [T0 + 1.0]
    flow = {"queue_arrivals_vph": 720.0, "queue_connected_share": 0.5}
    a, b, ref = (Service(corridor, url, now, **flow) for url in (store.url, store.url, None))
    alone = Service(corridor, None, now)  # the car alone: no flow behind it nor queue in front (a flow behind paces its glide)
    queued = [f"q{k}" for k in range(4)]

    async def go():
        for name in queued:
            await a.add(name)
            await ref.add(name)
        for w in (b, ref, alone):
            await w.add("car")
        fixes = [*((name, 98.0 - 7.5 * k, 0.0, T0) for k, name in enumerate(queued)), None, ("car", -20.0, 13.0, T0 + 1.0)]
        got, want = await _drive({**dict.fromkeys(queued, a), "car": b}, ref, fixes)
        await _close(a, b)
        return got, want, alone.fix("car", -20.0, 13.0, T0 + 1.0)

    got, want, blind = asyncio.run(go())
    assert got["car"] == want["car"]
    # alone, the car glides to the green (15 s: "Slow to 21 km/h, then coast"); behind the queue it waits for the queue
    # having crossed, later than the slowest glide advised (10 mph over 120 m, ~23 s) can wait, and no glide meets the
    # queue's tail moving (it stands until the red's end and the start-up wave reaches it), so it lifts off to stop
    # behind it (it was a glide at the slowest candidate speed, one the hard constraint had ruled out: fixed in advisor._choose).
    # The countdown is the light's own (its green), the words say the queue's clearing
    assert blind["reason"] == "green_wave" and blind["target_speed_mps"] is not None
    assert (got["car"]["reason"], got["car"]["action"]) == ("red_ahead", "coast"), got["car"]
    assert (got["car"]["light_red"], got["car"]["seconds_to_change_s"]) == (True, blind["seconds_to_change_s"])
    said = re.fullmatch(r"Queue ahead clears in (\d+) seconds\. Lift off and coast\.", got["car"]["message"])
    assert said is not None and int(said[1]) > blind["seconds_to_change_s"] + 5.0, got["car"]["message"]


def test_a_red_ended_on_worker_a_holds_a_car_on_worker_b_while_its_queue_discharges(store, corridor):
    """A's trip sees light 1's red on (from T0) and off (at its end, :45 of the minute, T0 + 15 s); B's car, 60 m before
    the line at the limit (24.6 m/s, there in 3.3 s) 1.5 s later, never saw that red: B's advice is the one-worker
    service's (the red's start and end shared: 720 veh/h, half connected, (1 - 0.5) x 0.2 x 15 = 1.5, two cars not
    connected stood in it, the last over the line 1.9-3.5 s from now), not that of a service that never saw that red
    (hold the limit into the queue)."""
    now = [T0]
    flow = {"queue_arrivals_vph": 720.0, "queue_connected_share": 0.5}
    a, b, ref, blind = (Service(corridor, url, now, **flow) for url in (store.url, store.url, None, None))
    limit = corridor.speed_limit_mps

    async def go():
        await a.add("watcher")
        await ref.add("watcher")
        for w in (b, ref, blind):
            await w.add("car")
        out = []
        for t, fixes in ((T0, [("watcher", -120.0, 13.0)]), (T0 + 15.0, [("watcher", -100.0, 13.0)]), (T0 + 16.5, [("car", 20.0, limit)])):
            now[0] = t
            for w in (a, b, ref, blind):
                w.spat(t)
            got, want = await _drive({"watcher": a, "car": b}, ref, [None, *((name, s, v, t) for name, s, v in fixes)])
            out.append((got, want))
        ended = (dict(a.engine.queue._red_ended), dict(b.engine.queue._red_ended))
        await _close(a, b)
        return out, ended, blind.fix("car", 20.0, limit, T0 + 16.5)

    out, (on_a, on_b), alone = asyncio.run(go())
    got, want = out[-1]
    assert on_a[1][:2] == on_b[1][:2] == ref.engine.queue._red_ended[1][:2] == (T0, T0 + 15.0)  # no jam published: NaN
    assert got["car"] == want["car"]
    assert alone["target_speed_mps"] == pytest.approx(limit, abs=0.5)
    assert alone["reason"] == "green_wave"  # told to hold the limit into the queue
    assert got["car"]["reason"] != "green_wave" and (got["car"]["target_speed_mps"] or 0.0) < limit - 3.0


def test_a_car_closing_in_on_a_car_of_the_other_worker_is_told_to_follow_until_that_trip_ends_or_goes_silent(store, corridor):
    """A's car stands 2 m before the red light; B's car, 28 m behind at 10 m/s, is closing in on it: it is told "Queue
    ahead. Follow the car in front." as on one worker. A's trip ended: a car of B's 6 m behind where it stood, at
    6 m/s (held if A's car counted), is not held. A car of A's that stops sending counts until its last fix is
    ``MAX_AGE_S`` old, not after; Redis drops it ``KEEP_S`` after its fix."""
    now = [T0]
    a, b, ref = Service(corridor, store.url, now), Service(corridor, store.url, now), Service(corridor, None, now)
    key = f"{a.engine.settings.store_prefix}:q:p:{corridor.name}"
    silent_for = MAX_AGE_S + 0.5

    async def go():
        for w in (a, ref):
            await w.add("lead")
            await w.add("silent")
        for w in (b, ref):
            for name in ("car", "after_end", "within", "after_silence"):
                await w.add(name)
        workers = {"lead": a, "silent": a, **{name: b for name in ("car", "after_end", "within", "after_silence")}}
        out = [await _drive(workers, ref, [("lead", 98.0, 0.0, T0), None, ("car", 70.0, 10.0, T0)])]
        await a.engine.end_trip(a.trips["lead"])
        await ref.engine.end_trip(ref.trips["lead"])
        out.append(await _drive(workers, ref, [None, ("after_end", 92.0, 6.0, T0 + 1.0)]))
        out.append(await _drive(workers, ref, [("silent", 98.0, 0.0, T0 + 2.0), None, ("within", 92.0, 6.0, T0 + 2.0 + MAX_AGE_S)]))
        out.append(await _drive(workers, ref, [None, ("after_silence", 92.0, 6.0, T0 + 2.0 + silent_for)]))
        await b.sync()
        with redis.Redis.from_url(store.url) as r:
            out.append(r.hexists(key, a.trips["silent"].id))
            now[0] = T0 + 2.0 + KEEP_S + 0.1  # Redis drops it once KEEP_S old by the writer's clock
            await a.sync()
            out.append((r.hexists(key, a.trips["silent"].id), r.hexists(key, b.trips["after_silence"].id)))
        await _close(a, b)
        return out

    (got, want), (got2, want2), (got3, want3), (got4, want4), kept, (dropped, younger_kept) = asyncio.run(go())
    assert got["car"] == want["car"] and (got["car"]["reason"], got["car"]["message"]) == ("queue", "Queue ahead. Follow the car in front.")
    assert got2["after_end"] == want2["after_end"] and got2["after_end"]["reason"] != "queue"
    assert got3["within"] == want3["within"] and got3["within"]["reason"] == "queue"
    assert got4["after_silence"] == want4["after_silence"] and got4["after_silence"]["reason"] != "queue"
    assert kept and not dropped and younger_kept


def test_redis_killed_worker_b_still_advises_from_its_own_trips_and_says_so(store, corridor):
    """A's car stands at the red; B's car closing in on it is told to follow. Redis is killed: B's board cannot call
    Redis (a failure in the background: False; ``/metrics`` and ``/health`` say own trips only), and B's fixes are
    still advised (``on_fix`` never waits for the board) from its own probes: once A's last probe is stale a car of
    B's right behind where A's stood is not held by it, and a car of B's closing in on another of B's cars is held.
    The fix's write to the trip store then fails on its own (503 ``store_unavailable``, as without the board)."""
    now = [T0]
    a, b = Service(corridor, store.url, now), Service(corridor, store.url, now)
    metrics = Metrics(lambda: 0, None, lambda: b.engine.queue)
    t = T0 + MAX_AGE_S + 1.0  # A's car, last seen at T0, no longer counts then

    async def go():
        await a.add("lead")
        for name in ("first", "behind_lead", "behind_first"):
            await b.add(name)
        a.fix("lead", 98.0, 0.0, T0)
        assert await a.sync() and await b.sync()
        out = [b.fix("first", 70.0, 10.0, T0), metrics.render(), b.engine.queue.state()]
        store.kill()
        out += [await b.sync(), metrics.render(), b.engine.queue.state()]
        out += [b.fix("behind_lead", 92.0, 6.0, t), b.fix("first", 80.0, 0.0, t), b.fix("behind_first", 55.0, 10.0, t)]
        trip = b.trips["first"]
        try:
            await b.engine.apply_fix(trip.id, trip.token, lambda: Fix(t + 1.0, *corridor.position(80.0), speed_mps=0.0))
        except ApiError as exc:
            out.append((exc.status, exc.error))
        await _close(a, b)
        return out

    held, up, shared, synced, down, degraded, behind_lead, _, behind_first, refused = asyncio.run(go())
    assert held["reason"] == "queue"  # closing in on A's car
    assert b"ecodrive_queue_board_shared 1.0" in up and shared == "shared"
    assert synced is False and degraded == "own_trips_only"
    assert b"ecodrive_queue_board_shared 0.0" in down and b"ecodrive_queue_board_sync_failures_total 1.0" in down
    assert behind_lead["reason"] != "queue" and behind_first["reason"] == "queue"
    assert refused == (503, "store_unavailable")


def test_a_fix_made_while_the_boards_call_is_out_is_kept_and_published_by_the_next(store, corridor):
    """The board's call to Redis is asynchronous: a fix applied while it is out must neither be lost when the reply
    replaces the board's tables, nor be taken back by the older state the reply carries."""
    now = [T0]
    a, b = Service(corridor, store.url, now), Service(corridor, store.url, now)

    async def go():
        await a.add("lead")
        a.fix("lead", 60.0, 8.0, T0)
        call = asyncio.ensure_future(a.sync())  # sends the first fix
        await asyncio.sleep(0)  # the call is written, its reply not yet read
        a.fix("lead", 68.0, 8.0, T0 + 1.0)
        assert await call
        mine = dict(a.engine.queue._cars[corridor.name])
        await a.sync()
        await b.sync()
        theirs = dict(b.engine.queue._cars[corridor.name])
        await _close(a, b)
        return mine, theirs

    mine, theirs = asyncio.run(go())
    assert [p[:2] for p in mine.values()] == [(T0 + 1.0, pytest.approx(68.0))]
    assert [p[:2] for p in theirs.values()] == [(T0 + 1.0, pytest.approx(68.0))]


def test_in_process_board_is_unchanged_and_needs_no_redis(corridor):
    """The in-process store (one process): the board's tables are this worker's dicts, nothing synced."""
    svc = Service(corridor, None, [T0])
    assert svc.engine.queue.shared is None and svc.engine.queue.state() == "local"
    assert type(svc.engine.queue._cars) is dict and type(svc.engine.queue._red_since) is dict


def test_two_worker_processes_share_the_board_and_say_so(store, corridor, tmp_path):
    """Two real workers on one Redis, queue-aware: a car on worker B closing in on a car standing on worker A is told to
    follow once B's board has A's probe (polled, bounded; each sync every 0.25 s); ``/health`` says ``shared``. Redis
    killed: ``/metrics`` says the board counts B's own trips only."""
    env = {"ECO_CORRIDORS": corridor.name, "ECO_DEFAULT_CORRIDOR": corridor.name, "ECO_TABLES": "false", "ECO_SPEECH": "false",
           "ECO_QUEUE_AWARE": "1", "ECO_STORE_URL": store.url, "ECO_METRICS_ACCESS": "public"}  # fmt: skip
    workers = []
    for name in ("a", "b"):
        (tmp_path / name).mkdir()
        workers.append(service_proc(tmp_path / name, **env))
    try:
        for w in workers:
            w.start()
        trips = []
        for w in workers:
            body = httpx.post(w.base_url + "/v1/trips", json={"corridor": corridor.name, "timing": "15_15"}).json()
            trips.append((w.base_url + f"/v1/trips/{body['trip_id']}/fixes", {"Authorization": f"Bearer {body['token']}"}))

        def send(k: int, station_m: float, speed_mps: float) -> dict:
            lat, lon = corridor.position(station_m)
            r = httpx.post(trips[k][0], json={"t_unix_s": time.time(), "lat_deg": lat, "lon_deg": lon, "speed_mps": speed_mps}, headers=trips[k][1])
            assert r.status_code == 200, r.text
            return r.json()

        deadline = time.monotonic() + 20.0
        reasons = []
        while time.monotonic() < deadline and "queue" not in reasons:
            send(0, 98.0, 0.0)  # A's car stands 2 m before light 1
            reasons.append(send(1, 70.0, 10.0)["reason"])  # B's closes in on it at 10 m/s, 28 m behind
            time.sleep(0.2)
        assert reasons[-1] == "queue"
        health = httpx.get(workers[1].base_url + "/health").json()
        assert health["queue_board"] == "shared"
        assert "ecodrive_queue_board_shared 1.0" in httpx.get(workers[1].base_url + "/metrics").text
        store.kill()
        deadline = time.monotonic() + 20.0
        while time.monotonic() < deadline and "ecodrive_queue_board_shared 0.0" not in (text := httpx.get(workers[1].base_url + "/metrics").text):
            time.sleep(0.1)
        assert "ecodrive_queue_board_shared 0.0" in text
    finally:
        for w in workers:
            w.kill()
