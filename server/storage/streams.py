"""Who holds the open WebSocket streams: at most ``ECO_WS_MAX_PER_TRIP`` per trip, ``ECO_WS_MAX_PER_CLIENT`` per
client address; counted in this process (:class:`StreamCounts`) or, with Redis, across every worker
(:class:`RedisStreams`). Both answer ``open(trip_id, client, per_trip, per_client, on_replaced)`` and ``close(handle)``.

**The newest stream of a trip wins**: a trip whose streams are all taken gets its new one all the same, and the
stream opened first is replaced (``on_replaced`` is called: the route tells it why and closes it with 4409). The
phone holding a trip's token is the one reconnecting; what it left behind (a connection hanging half-open
after a network change, a lease of a worker that crashed) never locks it out, and one token still never holds
more than ``per_trip`` streams. The per-address cap refuses (429) as before.

**With Redis** each stream holds a lease of ``ECO_WS_LEASE_S`` (15 s) in the trip's and the address's sorted
sets, renewed every third of it by its worker for all its streams in one call (not by the stream's messages:
a silent stream keeps counting while its worker lives); a killed worker's streams stop counting within a lease,
and a stream replaced on another worker is found at that worker's next renewal and closed.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import uuid
from collections.abc import Callable

from server.web.errors import ApiError
from server.storage.redispipe import Script
from server.storage.store import REACH, RedisTrips

log = logging.getLogger("server")


class StreamHandle:
    """One open stream. ``on_replaced()`` is called once if a newer stream of its trip replaces it."""

    __slots__ = ("trip_id", "client", "member", "on_replaced", "replaced", "closed")

    def __init__(self, trip_id: str, client: str, member: str, on_replaced: Callable[[], None] | None) -> None:
        self.trip_id, self.client, self.member, self.on_replaced = trip_id, client, member, on_replaced
        self.replaced = self.closed = False

    def replace(self) -> None:
        if self.replaced or self.closed:
            return
        self.replaced = True
        if self.on_replaced is not None:
            self.on_replaced()


def client_full(per_client: int) -> ApiError:
    return ApiError(429, "too_many_streams", f"this client address already has {per_client} open streams")


class StreamCounts:
    """Open streams per trip (oldest first) and per client address in this process (bounded: entries leave at zero)."""

    def __init__(self) -> None:
        self.by_trip: dict[str, list[StreamHandle]] = {}
        self.by_client: dict[str, int] = {}

    async def open(self, trip_id: str, client: str, per_trip: int, per_client: int, on_replaced: Callable[[], None] | None = None) -> StreamHandle:
        if per_client and self.by_client.get(client, 0) >= per_client:
            raise client_full(per_client)
        mine = self.by_trip.setdefault(trip_id, [])
        while len(mine) >= per_trip:
            oldest = mine[0]
            self._drop(oldest)
            oldest.replace()
        handle = StreamHandle(trip_id, client, "", on_replaced)
        self.by_trip.setdefault(trip_id, []).append(handle)
        self.by_client[client] = self.by_client.get(client, 0) + 1
        return handle

    def _drop(self, handle: StreamHandle) -> None:
        mine = self.by_trip.get(handle.trip_id, [])
        if handle in mine:
            mine.remove(handle)
            left = self.by_client.get(handle.client, 1) - 1
            if left > 0:
                self.by_client[handle.client] = left
            else:
                self.by_client.pop(handle.client, None)
        if not mine:
            self.by_trip.pop(handle.trip_id, None)

    async def close(self, handle: StreamHandle) -> None:
        handle.closed = True
        self._drop(handle)

    async def aclose(self) -> None:
        return None


# A member is "<opened, Unix ms>|<stream id>|<client address>": the oldest opened is replaced first, and its
# address names the set it also leaves.
# KEYS: the trip's and the client's stream sets. ARGV: now, member, per trip, per client (0: none), lease_s, prefix.
# -> {0, replaced members...} opened, {2} the client's streams are full
_STREAM_OPEN = Script("""
local now, lease = tonumber(ARGV[1]), tonumber(ARGV[5])
redis.call('ZREMRANGEBYSCORE', KEYS[1], '-inf', now)
redis.call('ZREMRANGEBYSCORE', KEYS[2], '-inf', now)
if tonumber(ARGV[4]) > 0 and redis.call('ZCARD', KEYS[2]) >= tonumber(ARGV[4]) then return {2} end
local out = {0}
while redis.call('ZCARD', KEYS[1]) >= tonumber(ARGV[3]) do
  local oldest, first = nil, nil
  for _, m in ipairs(redis.call('ZRANGE', KEYS[1], 0, -1)) do
    local t = tonumber(string.match(m, '^(%d+)|')) or 0  -- 0: a lease in an older format (no address), replaced first
    if oldest == nil or t < first then oldest, first = m, t end
  end
  redis.call('ZREM', KEYS[1], oldest)
  local address = string.match(oldest, '^%d+|%x+|(.*)$')
  if address then redis.call('ZREM', ARGV[6] .. ':ws:c:' .. address, oldest) end
  out[#out + 1] = oldest
end
for i = 1, 2 do
  redis.call('ZADD', KEYS[i], now + lease, ARGV[2])
  redis.call('PEXPIRE', KEYS[i], math.ceil(lease * 1000))
end
return out
""")

# KEYS: the trip's and the client's stream sets of each stream, in pairs. ARGV: now, lease_s, the members in
# the same order. A stream still in its trip's set has its lease renewed in both; one no longer there (a newer
# stream replaced it) leaves its client's set too. -> the positions (1-based) of the replaced ones
_STREAM_RENEW = Script("""
local expiry, ms, gone = tonumber(ARGV[1]) + tonumber(ARGV[2]), math.ceil(tonumber(ARGV[2]) * 1000), {}
for i = 1, #ARGV - 2 do
  local trip, client, m = KEYS[2 * i - 1], KEYS[2 * i], ARGV[i + 2]
  if redis.call('ZSCORE', trip, m) then
    redis.call('ZADD', trip, expiry, m)
    redis.call('ZADD', client, expiry, m)
    redis.call('PEXPIRE', trip, ms)
    redis.call('PEXPIRE', client, ms)
  else
    redis.call('ZREM', client, m)
    gone[#gone + 1] = i
  end
end
return gone
""")

# KEYS: the trip's and the client's stream sets. ARGV: member.
_STREAM_CLOSE = Script("""
redis.call('ZREM', KEYS[1], ARGV[1])
redis.call('ZREM', KEYS[2], ARGV[1])
return 0
""")


class RedisStreams:
    """Open streams counted in Redis across every worker, each holding a lease renewed by its worker (module
    docstring); ``lease_s``: ``ECO_WS_LEASE_S``."""

    RENEW_BATCH = 500
    """Streams renewed per script call (a worker with more makes several). [-]"""

    def __init__(self, store: RedisTrips, lease_s: float) -> None:
        self.store = store
        self.lease_s = lease_s
        self._live: dict[str, StreamHandle] = {}  # member -> handle, this worker's open streams
        self._renewer: asyncio.Task | None = None

    def _keys(self, trip_id: str, client: str) -> list[str]:
        return [f"{self.store.p}:ws:t:{trip_id}", f"{self.store.p}:ws:c:{client}"]

    async def open(self, trip_id: str, client: str, per_trip: int, per_client: int, on_replaced: Callable[[], None] | None = None) -> StreamHandle:
        """A handle for :meth:`close`; 429 ``too_many_streams`` beyond the address's cap."""
        now = self.store.clock()
        member = f"{int(now * 1000)}|{uuid.uuid4().hex}|{client}"
        with REACH:
            r = await self.store.redis.run(_STREAM_OPEN, keys=self._keys(trip_id, client), args=[repr(now), member, per_trip, per_client, self.lease_s, self.store.p])
        if int(r[0]) == 2:
            raise client_full(per_client)
        handle = self._live[member] = StreamHandle(trip_id, client, member, on_replaced)
        for gone in r[1:]:  # replaced: if this worker holds it, at once; else its worker finds out when renewing
            old = self._live.pop(gone.decode() if isinstance(gone, bytes) else gone, None)
            if old is not None:
                old.replace()
        if self._renewer is None or self._renewer.done():
            self._renewer = asyncio.get_running_loop().create_task(self._renew_forever())
        return handle

    async def close(self, handle: StreamHandle) -> None:
        handle.closed = True
        if self._live.pop(handle.member, None) is None:
            return  # replaced: already out of the sets
        with contextlib.suppress(ApiError):
            with REACH:
                await self.store.redis.run(_STREAM_CLOSE, keys=self._keys(handle.trip_id, handle.client), args=[handle.member])

    async def renew(self) -> None:
        """Renew the leases of this worker's streams; those a newer stream replaced are told so."""
        handles = list(self._live.values())
        for k in range(0, len(handles), self.RENEW_BATCH):
            batch = handles[k : k + self.RENEW_BATCH]
            keys = [key for h in batch for key in self._keys(h.trip_id, h.client)]
            with REACH:
                gone = await self.store.redis.run(_STREAM_RENEW, keys=keys, args=[repr(self.store.clock()), self.lease_s, *(h.member for h in batch)])
            for i in gone:
                h = batch[int(i) - 1]
                if self._live.pop(h.member, None) is not None:
                    h.replace()

    async def _renew_forever(self) -> None:
        period_s = self.lease_s / 3
        while self._live:
            await asyncio.sleep(period_s)
            try:
                await self.renew()
            except ApiError:
                pass  # Redis unreachable: logged by REACH; the next round tries again
            except Exception:  # never let the renewal die silently: the leases would lapse under live streams
                log.exception("renewing the WebSocket stream leases failed")

    async def aclose(self) -> None:
        if self._renewer is not None:
            self._renewer.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._renewer
