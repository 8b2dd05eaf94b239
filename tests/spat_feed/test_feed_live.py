"""Against real ``python -m spat_feed`` processes on 127.0.0.1: snapshot, stream, death, stale, bad data.

Every wait is bounded (``wait_for``); no assertion is about how fast anything was.
"""

from __future__ import annotations

import asyncio
import logging
import math
import time
from datetime import datetime, timezone

import pytest

from spat_feed.transport.client import SpatClient, fetch_spat
from spat_feed.timing.messages import CONFIDENCE_FRAC, from_j2735, to_unix_s
from spat_feed.timing.plans import MovementPhaseState, seconds_to_next_green, seconds_to_next_red

STALE_S = 0.6  # short, so the tests are quick
FAST = dict(stale_after_s=STALE_S, backoff_initial_s=0.05, backoff_max_s=0.4, seed=1)
WAIT_S = 20.0  # generous bound on every wait


async def wait_for(predicate, timeout_s: float = WAIT_S, poll_s: float = 0.02, what: str = "condition"):
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if value := predicate():
            return value
        await asyncio.sleep(poll_s)
    raise AssertionError(f"timed out waiting for {what}")


def test_snapshot_over_http(shared_feed):
    parsed = fetch_spat(shared_feed.base_url, {"timing": "field_test"})
    assert not parsed.errors and [ix.id for ix in parsed.intersections] == [1, 2]
    assert abs(parsed.timestamp_unix_s - time.time()) < 60  # the feed runs on the real clock


def test_stream_serves_fresh_data(shared_feed):
    async def run():
        async with SpatClient(shared_feed.base_url, {"timing": "15_15"}, **FAST) as client:
            await client.wait_fresh(1, WAIT_S)
            await client.wait_fresh(2, WAIT_S)
            n0 = client.stats.messages
            await wait_for(lambda: client.stats.messages >= n0 + 5, what="five more messages")
            reading = client.reading(2)
            assert reading.fresh and reading.age_s <= STALE_S
            assert client.stats.rejected == 0 and client.connected

    asyncio.run(run())


def test_uncertain_windows_end_to_end(shared_feed):
    params = {"timing": "15_15", "early_s": 2.0, "late_s": 5.0, "confidence": 0.8}

    async def run():
        async with SpatClient(shared_feed.base_url, params, **FAST) as client:
            state = await client.wait_fresh(1, WAIT_S)
            now_s = to_unix_s(state.timestamp)
            plan = client.reading(1).plan(2)
            for fn in (seconds_to_next_green, seconds_to_next_red):
                ttc = fn(plan, now_s)
                assert ttc.min_s <= ttc.likely_s <= ttc.max_s
                if ttc.likely_s > 0:  # a change still to come: its window is the published one
                    assert ttc.max_s - ttc.min_s <= 7.0 + 1e-3 and ttc.confidence_frac == CONFIDENCE_FRAC[7]
            timing = state.states[0].state_time_speed[1].timing  # a future event: full window
            assert (to_unix_s(timing.max_end_time) - to_unix_s(timing.min_end_time)) == pytest.approx(7.0, abs=1e-3)

    asyncio.run(run())


def test_feed_dies_and_comes_back(start_feed):
    feed = start_feed()

    async def run():
        async with SpatClient(feed.base_url, **FAST) as client:
            await client.wait_fresh(1, WAIT_S)
            feed.kill()
            # never stale served as fresh: whenever fresh() answers, the reading is young
            killed_at = time.monotonic()
            while time.monotonic() - killed_at < STALE_S + 0.5:
                reading = client.reading(1)
                if client.fresh(1) is not None:
                    assert reading.age_s <= STALE_S
                await asyncio.sleep(0.02)
            assert client.fresh(1) is None and client.fresh(2) is None
            stale = client.reading(1)
            assert stale is not None and not stale.fresh and stale.age_s > STALE_S  # kept, flagged
            assert not client.connected and client.stats.disconnects == 1
            feed.start()  # same port
            await client.wait_fresh(1, WAIT_S)
            await client.wait_fresh(2, WAIT_S)
            assert client.stats.connects == 2

    asyncio.run(run())


def test_old_data_from_a_live_feed_is_stale(start_feed):
    """A feed whose clock runs 30 s behind sends well-formed but old timing: never fresh. (Its clock starts 30 s before
    the instant it was launched, when its process starts: on a loaded machine that is later, and the data older.)"""
    launched = time.time()
    feed = start_feed("--clock-start-unix-s", str(launched - 30.0))

    async def run():
        async with SpatClient(feed.base_url, **FAST) as client:
            await wait_for(lambda: client.stats.intersections >= 4, what="messages")
            assert client.connected
            assert client.fresh(1) is None and client.fresh(2) is None
            assert 29.0 <= client.reading(1).age_s <= 30.0 + (time.time() - launched) + 1.0

    asyncio.run(run())


def test_malformed_messages_are_rejected_and_logged(start_feed, caplog):
    """Every 3rd message is bad: alternately not JSON, and JSON with intersection 1 invalid."""
    feed = start_feed("--fault-every", "3")
    caplog.set_level(logging.WARNING, logger="spat_feed.transport.client")

    async def run():
        async with SpatClient(feed.base_url, **FAST) as client:
            await wait_for(lambda: client.stats.rejected >= 4, what="rejections")
            assert client.fresh(1) is not None and client.fresh(2) is not None  # others still served
            for ix_id in (1, 2):
                for movement in client.reading(ix_id).intersection.states:
                    assert all(ev.event_state in MovementPhaseState for ev in movement.state_time_speed)
            # good data keeps flowing after the bad: more good intersections arrive (not a ratio of the two counts: the
            # feed serves each subscriber its latest message, and a subscriber slowed by a loaded machine skips some,
            # good or bad; CI read 7 good against 4 rejected once, at load ~5 on 2 cores)
            good, bad = client.stats.intersections, client.stats.rejected
            more = lambda: client.stats.intersections >= good + 4 and client.stats.rejected > bad  # noqa: E731
            await wait_for(more, what="good data after bad")
            assert client.fresh(1) is not None and client.fresh(2) is not None
            assert client.stats.connects == 1  # bad data does not drop the connection

    asyncio.run(run())
    messages = [r.getMessage() for r in caplog.records]
    assert any("not JSON" in m for m in messages)
    assert any("intersection #0 (id=1) rejected" in m and "eventState" in m for m in messages)


def test_timemark_rollover_at_the_hour_live(start_feed):
    """A feed whose clock starts 1.5 s before the top of an hour: its J2735 TimeMarks decode correctly."""
    top_s = datetime(2024, 5, 1, 13, 0, tzinfo=timezone.utc).timestamp()
    feed = start_feed("--clock-start-unix-s", str(top_s - 1.5), "--entry-unix-s", str(top_s - 15.0), "--timing", "0_15")
    import httpx

    j = httpx.get(feed.base_url + "/spat", params={"format": "j2735"}, timeout=5.0).json()
    direct = fetch_spat(feed.base_url)
    msg_s = direct.timestamp_unix_s
    back = from_j2735(j, ref_unix_s=msg_s)
    crossed = 0
    for a, b in zip(direct.intersections, back.intersections):
        for ea, eb in zip(a.states[0].state_time_speed, b.states[0].state_time_speed):
            assert ea.event_state == eb.event_state
            ta, tb = to_unix_s(ea.timing.min_end_time), to_unix_s(eb.timing.min_end_time)
            if ta > top_s and math.floor(msg_s / 3600) < math.floor(ta / 3600):
                crossed += 1
            if ta > msg_s + 1.0:  # not clipped to "now" (the two requests came at different instants)
                assert tb == pytest.approx(ta, abs=0.051)
    assert crossed >= 1  # some change times lie beyond the hour
