"""Within one worker, the fixes of one trip on the Redis store are applied one after the other (``RedisTrips.hold``),
each exactly once, and the per-trip locks are gone once nobody holds or waits for them, a cancelled waiter included.
Real ``redis-server`` on loopback; independent answer: the same fixes one at a time on the in-process store."""

from __future__ import annotations

import asyncio
import time

import pytest

from server.advising import Engine
from server.config import Settings
from server.gps import Fix
from server.schemas import TripCreate
from spat_feed.road.corridors import load_corridor
from tests.procs import RedisServer, redis_server_path

CORRIDOR = "paper_s200"


def _settings(store_url: str | None) -> Settings:
    return Settings(corridors=(CORRIDOR,), default_corridor=CORRIDOR, tables=False, speech=False, store_url=store_url, rate_burst=100)


def test_concurrent_fixes_of_one_trip_are_serialised_and_each_applied_once(tmp_path):
    if redis_server_path() is None:
        pytest.skip("redis-server is not installed and scripts/system-deps.sh could not install it (needs root and apt-get)")
    server = RedisServer(tmp_path).start()
    corridor = load_corridor(CORRIDOR)
    now = time.time()
    fixes = [Fix(now - 20 + k, *corridor.position(12.0 * k), 12.0, None, 4.0) for k in range(12)]

    async def run() -> tuple[list[dict], list[dict], dict, int]:
        red = Engine(_settings(server.url), {CORRIDOR: corridor})
        mem = Engine(_settings(None), {CORRIDOR: corridor})
        body = TripCreate(corridor=CORRIDOR, entry_unix_s=now - 25)
        trip, ref = await red.create_trip(body), await mem.create_trip(body)
        # all at once, in order: each waits for the one before it (a task per fix, as uvicorn makes per request)
        tasks = [asyncio.ensure_future(red.apply_fix(trip.id, trip.token, lambda f=f: f)) for f in fixes]
        await asyncio.sleep(0)  # every task started: the first awaits Redis, the others wait for the trip
        assert red.trips._locks[trip.id][1] == len(fixes)
        tasks[5].cancel()  # a waiter given up: its fix is never applied, the others go on
        outs = [await t for t in tasks if t is not tasks[5]]
        expected = [mem.apply_fix(ref.id, ref.token, lambda f=f: f) for i, f in enumerate(fixes) if i != 5]
        expected = [await e for e in expected]
        locks = dict(red.trips._locks)
        stored = await red.trips.authorize(trip.id, trip.token)
        await red.trips.close()
        return outs, expected, locks, stored.n_fixes

    try:
        outs, expected, locks, n_fixes = asyncio.run(run())
    finally:
        server.kill()
    assert [o["seq"] for o in outs] == list(range(1, 12))
    assert n_fixes == 11
    drop = ("trip_id",)
    assert [{k: v for k, v in o.items() if k not in drop} for o in outs] == [{k: v for k, v in e.items() if k not in drop} for e in expected]
    assert locks == {}
