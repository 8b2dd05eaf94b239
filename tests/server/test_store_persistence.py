"""A trip store on a Redis without its append-only file says so at start: a restart of that Redis loses every open
trip (issue 30). Real ``redis-server`` on loopback, switched with CONFIG SET."""

from __future__ import annotations

import asyncio

import pytest

from server.config import Settings
from server.storage.store import Limits, RedisTrips
from tests.procs import RedisServer, redis_server_path


def test_a_redis_without_append_only_file_is_reported_one_with_it_is_not(tmp_path):
    if redis_server_path() is None:
        pytest.skip("redis-server is not installed and scripts/system-deps.sh could not install it (needs root and apt-get)")
    server = RedisServer(tmp_path).start()  # --appendonly yes, as compose and the docs run it

    async def run() -> tuple[str | None, str | None, str | None]:
        settings = Settings(corridors=("paper_s200",), default_corridor="paper_s200", store_url=server.url)
        store = RedisTrips(settings, Limits(settings), build=None)
        kept = await store.volatile()
        await store.redis.call("CONFIG", "SET", "appendonly", "no")
        lost = await store.volatile()
        server.kill()
        unreachable = await store.volatile()  # cannot ask: the service starts all the same
        await store.close()
        return kept, lost, unreachable

    try:
        kept, lost, unreachable = asyncio.run(run())
    finally:
        server.kill()
    assert kept is None and unreachable is None
    assert "loses every open trip" in lost and "--appendonly yes" in lost
