"""server.storage.redispipe: one pipelined connection to a real ``redis-server`` on loopback. Concurrent calls get their
own replies (checked against values each call alone determines), a cancelled call does not shift the others,
scripts unknown to Redis are sent whole, error replies raise, a silent Redis fails calls (TimeoutError) and a
dead one fails them (ConnectionError), and the next call after a restart reconnects. Every wait is bounded."""

from __future__ import annotations

import asyncio
import os
import signal

import hiredis
import pytest
from redis.exceptions import ConnectionError, ResponseError, TimeoutError

from server.storage.redispipe import RedisPipe, Script


def test_concurrent_calls_share_one_connection_and_get_their_own_replies(store):
    async def run() -> None:
        pipe = RedisPipe(store.url, 10.0)
        n = 600
        replies = await asyncio.gather(*(pipe.call("SET", f"k{i}", f"v{i}") for i in range(n)))
        assert replies == [b"OK"] * n
        calls = [asyncio.ensure_future(pipe.call("GET", f"k{i}")) for i in range(n)]
        for i in range(0, n, 7):
            calls[i].cancel()  # callers that went away: the others still get their own replies
        await asyncio.wait(calls)
        for i, call in enumerate(calls):
            assert call.cancelled() if i % 7 == 0 else call.result() == f"v{i}".encode()
        clients = (await pipe.call("CLIENT", "LIST")).decode().strip().splitlines()
        assert len(clients) == 1  # this one connection
        assert await pipe.call("INCRBY", "n", 5) == 5 and await pipe.call("GET", "missing") is None
        with pytest.raises(ResponseError, match="WRONGTYPE|not an integer"):
            await pipe.call("INCR", "k1")  # an error reply raises, the connection goes on
        assert await pipe.call("GET", "k1") == b"v1"
        await pipe.close()

    asyncio.run(run())


def test_a_call_alone_leaves_at_once_and_a_turns_calls_behind_it_leave_together(store):
    """A lone call is written before ``call`` first yields (no loop turn, and its poll, before the write); the calls
    made while it is in flight leave in one write at the end of the turn; the replies keep their order."""

    async def run() -> None:
        pipe = RedisPipe(store.url, 10.0)
        assert await pipe.call("PING") == b"PONG"  # connected
        conn = pipe._conn
        writes: list[bytes] = []
        write = conn.transport.write
        conn.transport.write = lambda data: (writes.append(data), write(data))[1]
        first = asyncio.ensure_future(pipe.call("INCR", "n"))
        await asyncio.sleep(0)  # the call runs to its first await: written there, not queued
        assert len(writes) == 1 and b"INCR" in writes[0] and not conn.out
        rest = [asyncio.ensure_future(pipe.call("INCR", "n")) for _ in range(40)]
        assert await asyncio.gather(first, *rest) == list(range(1, 42))
        assert len(writes) == 2 and writes[1].count(b"INCR") == 40, [w.count(b"INCR") for w in writes]
        await pipe.close()

    asyncio.run(run())


def test_scripts_are_sent_whole_when_redis_does_not_know_them(store):
    script = Script("return {KEYS[1], ARGV[1] + 1}")

    async def run() -> None:
        pipe = RedisPipe(store.url, 10.0)
        assert await pipe.run(script, keys=["a"], args=[41]) == [b"a", 42]
        await pipe.call("SCRIPT", "FLUSH")  # as after a Redis restart (scripts are not persisted)
        await pipe.call("CONFIG", "RESETSTAT")
        replies = await asyncio.gather(*(pipe.run(script, keys=[f"b{i}"], args=[i]) for i in range(50)))
        assert replies == [[f"b{i}".encode(), i + 1] for i in range(50)]
        stats = (await pipe.call("INFO", "commandstats")).decode()
        assert "cmdstat_script|load:calls=1," in stats and "cmdstat_eval:" not in stats  # a burst of NOSCRIPT: one load
        await pipe.close()

    asyncio.run(run())


def test_a_command_packed_in_two_parts_is_hiredis_packing_of_the_whole_and_runs_after_a_flush(store):
    """``Script.head`` + ``Script.command`` (a trip's save: the same keys and first arguments at every fix) give the
    bytes ``hiredis.pack_command`` gives for the whole command, numbers written as hiredis writes them; Redis
    having lost the script, ``run_packed`` loads it and gets the reply."""
    script = Script("return {KEYS[1], KEYS[2], ARGV[1], ARGV[2], ARGV[3], ARGV[4], ARGV[5], ARGV[6]}")
    keys, first = ["eco:t:ab", "eco:t:ab:tr"], [b"\x00\r\n\xff", 1810.0, 0.1, "eco"]
    tail = (b"%r" % 1796021301.264423, b"%d" % -1, b"", b'{"a":[1.5e-07,null]}')
    command = Script.command(script.head(keys, first), tail)
    assert command == hiredis.pack_command(("EVALSHA", script.sha, 2, *keys, *first, 1796021301.264423, -1, b"", b'{"a":[1.5e-07,null]}'))

    async def run() -> None:
        pipe = RedisPipe(store.url, 10.0)
        want = [b"eco:t:ab", b"eco:t:ab:tr", b"\x00\r\n\xff", b"1810.0", b"0.1", b"eco", b"1796021301.264423", b"-1"]
        assert await pipe.run_packed(script, command) == want
        await pipe.call("SCRIPT", "FLUSH")
        assert await pipe.run_packed(script, command) == want
        await pipe.close()

    asyncio.run(run())


def test_a_silent_redis_times_out_a_dead_one_fails_and_a_restarted_one_serves(store):
    async def run() -> None:
        pipe = RedisPipe(store.url, 0.5)
        assert await pipe.call("SET", "k", "1") == b"OK"
        os.kill(store.proc.pid, signal.SIGSTOP)  # alive, silent
        try:
            with pytest.raises(TimeoutError):
                await asyncio.wait_for(pipe.call("GET", "k"), 30)
        finally:
            os.kill(store.proc.pid, signal.SIGCONT)
        assert await asyncio.wait_for(pipe.call("GET", "k"), 30) == b"1"  # a new connection
        store.kill()
        with pytest.raises(ConnectionError):
            await asyncio.wait_for(pipe.call("GET", "k"), 30)
        with pytest.raises(ConnectionError):  # refused while down
            await asyncio.wait_for(pipe.call("GET", "k"), 30)
        store.start()  # same port and folder: the append-only file brings the key back
        assert await asyncio.wait_for(pipe.call("GET", "k"), 30) == b"1"
        await pipe.close()

    asyncio.run(run())


def test_password_and_database_from_the_url_and_a_wrong_password_is_unreachable(store):
    async def run() -> None:
        admin = RedisPipe(store.url, 10.0)
        await admin.call("CONFIG", "SET", "requirepass", "s3cret")
        good = RedisPipe(f"redis://:s3cret@127.0.0.1:{store.port}/2", 10.0)
        assert await good.call("SET", "k", "in db 2") == b"OK"
        assert b" db=2 " in await good.call("CLIENT", "INFO")
        bad = RedisPipe(f"redis://:wrong@127.0.0.1:{store.port}/0", 10.0)
        with pytest.raises(ConnectionError, match="set-up"):
            await bad.call("GET", "k")
        await good.call("CONFIG", "SET", "requirepass", "")
        for pipe in (admin, good, bad):
            await pipe.close()

    asyncio.run(run())



def test_a_busy_worker_is_not_an_unreachable_store(store):
    """The worker's loop turn lasts longer than the timeout after its calls were made (a CPU-bound turn, as under
    load): the one written at once is answered in the turn's poll, and the one queued behind it is not written before
    the turn's end, so Redis has not even been asked yet: both must get their replies, not a TimeoutError (issue 30:
    526 "store unreachable" at 2,000 phones while Redis sat idle). On uvloop, which runs due timers before the rest of
    the ready callbacks of the next turn."""
    import time

    uvloop = pytest.importorskip("uvloop")

    async def run() -> None:
        pipe = RedisPipe(store.url, 0.3)
        assert await pipe.call("SET", "k", "v") == b"OK"  # connected
        calls = [asyncio.ensure_future(pipe.call("GET", "k")) for _ in range(2)]
        await asyncio.sleep(0)  # both calls' tasks ran in this turn: the first written, the second queued for the turn's end
        time.sleep(1.0)  # the rest of this turn takes 1 s (other requests' work)
        assert await asyncio.wait_for(asyncio.gather(*calls), 30) == [b"v", b"v"]
        await pipe.close()

    uvloop.run(run())
