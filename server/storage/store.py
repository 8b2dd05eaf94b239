"""Where open trips live: in this process (:class:`MemoryTrips`, the default) or in Redis (:class:`RedisTrips`,
``ECO_STORE_URL=redis://host:6379/0``), shared by any number of workers.

Both answer the same calls, all ``async``:

* ``admit(client)``: may this client create a trip now? The per-client and service-wide creation buckets
  and the open-trip caps (per client, in all); 429 / 503 with ``Retry-After`` otherwise.
* ``add(trip)``: the new trip is open (the caps checked again, atomically).
* ``authorize(trip_id, token, take)``: the trip if ``token`` is its token (404 unknown or expired, 401, 403),
  its idle clock reset; ``take``: one token of the trip's request bucket too (429 when empty).
* ``save(trip)``: after :meth:`server.advising.Engine.on_fix`, the new state and the new score samples
  (False: another worker changed the trip meanwhile; reload and apply again). With Redis, ``for_fix`` gives
  the trip a fix applies to (this worker's copy when it has one) and ``save`` also checks the token, takes
  the bucket's token and resets the idle clock: a fix on a trip this worker served last is one round trip.
* ``samples(trip)``: the trip's score samples ``(t, v, x)``; ``remove(trip_id)``: the trip is ended.

**Redis layout** (prefix ``ECO_STORE_PREFIX``, default ``eco``), every key expiring ``trip_idle_ttl_s`` after
the trip's last request (up to ``touch_every_s`` later: the idle clock is reset at most that often):

* ``eco:t:<id>``, a hash: ``meta`` (JSON, written once: corridor, timing, entry time, vehicle, units, client;
  any worker rebuilds the trip and its SPaT view from it), ``state`` (JSON, rewritten per fix, ~1-2 kB:
  track, advisor memory, last advice, counters), ``v`` (version, +1 per write), ``tok`` (SHA-256 of the
  token), ``client``, ``dev`` (the device id it was created with, or ''), ``bt``/``bs`` (the trip's request
  bucket: tokens, stamp), ``ts`` (the idle clock's last reset);
* ``eco:t:<id>:tr``: the score samples, 24 bytes per accepted fix (``t, v, x`` as little-endian doubles)
  appended per fix, at most ``max_trace_fixes`` of them;
* ``eco:k:<token hash>`` -> id (tells "another trip's token", 403, from an invalid one, 401);
* ``eco:open``, ``eco:c:<client>`` and ``eco:d:<client>:<device>``: sorted sets of open trips by last request
  (the caps: in all, per API key or address, per device; members idle longer than the TTL are dropped when
  counted);
* ``eco:anon``: the open trips created without an API key, by creation time: when the service is full, a keyed
  trip takes the place of the newest (``server.admission.quotas``); members of expired trips are dropped by ``sweep``;
* ``eco:rl:create`` and ``eco:rl:c:<client>``: the creation buckets;
* ``eco:ws:t:<id>`` and ``eco:ws:c:<address>``: open WebSocket streams (:class:`server.storage.streams.RedisStreams`, leases).
* ``eco:q:p:<corridor>`` and ``eco:q:red``: the queue board's probes and red starts, with queue-aware advice
  (:class:`server.storage.queue_store.SharedBoard`, over this store's connection).

Each call is one round trip (a Lua script, atomic in Redis; a fix's write is 3 commands in it) over the worker's
one pipelined connection (:class:`server.storage.redispipe.RedisPipe`: a call alone written at once, the calls of one event-loop turn behind it in one write). A worker keeps the trips it served in a small
cache (:class:`RedisTrips` ``_cache``): a fix on a cached trip is applied to the copy and written with the
version it was computed from (one round trip); a trip not cached, or whose version moved (another worker
served it), is read first (two). Within a worker, fixes of one trip are serialised (:meth:`RedisTrips.hold`);
across workers a write carries the version it was computed from, and if the trip moved meanwhile it is
refused and the current state comes back instead, on which the fix is applied again (``save``).
A fix is accepted (answered 200) only once Redis has it: a worker killed at any instant loses no accepted
fix. Redis unreachable: 503 ``store_unavailable`` with ``Retry-After`` (never 404: the trip is not gone).
"""

from __future__ import annotations

import asyncio
import contextlib
import hmac
import logging
import math
import struct
import time
from collections.abc import Awaitable, Callable

import numpy as np
from pydantic_core import from_json, to_json
from redis.exceptions import BusyLoadingError
from redis.exceptions import ConnectionError as RedisConnectionError
from redis.exceptions import TimeoutError as RedisTimeoutError

from server.config import Settings
from server.web.errors import ApiError
from server.admission.quotas import Creator, Quota
from server.admission.ratelimit import KeyedBuckets, TokenBucket
from server.storage.redispipe import RedisPipe, Script
from server.trips import Trip, token_hash

log = logging.getLogger("server")

RETRY_AFTER_S = 1
"""What a phone is told to wait when the store is unreachable or a trip is busy. [s]"""


def retry_after(wait_s: float) -> tuple[int, dict[str, str]]:
    """Whole seconds to wait (HTTP's Retry-After is an integer, never 0) and the header saying so."""
    seconds = max(1, math.ceil(wait_s))
    return seconds, {"Retry-After": str(seconds)}


class Limits:
    """The errors of the limits, worded once for both stores (``s``: the settings)."""

    def __init__(self, s: Settings, on_rate_limited: Callable[[], None] | None = None) -> None:
        self.s = s
        self.on_rate_limited = on_rate_limited

    def trip_rate(self, wait_s: float) -> ApiError:
        if self.on_rate_limited is not None:
            self.on_rate_limited()
        seconds, headers = retry_after(wait_s)
        return ApiError(429, "rate_limited", f"too many requests for this trip (limit {self.s.rate_per_s:g}/s, burst {self.s.rate_burst:g}); retry in {seconds} s", headers=headers)

    def client_rate(self, wait_s: float, quota: Quota) -> ApiError:
        seconds, headers = retry_after(wait_s)
        return ApiError(429, "rate_limited", f"this client creates trips too fast (limit {quota.create_rate_per_s:g}/s, burst {quota.create_burst:g}); retry in {seconds} s", headers=headers)

    def create_rate(self, wait_s: float) -> ApiError:
        seconds, headers = retry_after(wait_s)
        return ApiError(429, "rate_limited", f"too many trips created service-wide; retry in {seconds} s", headers=headers)

    def client_full(self, quota: Quota) -> ApiError:
        return ApiError(429, "too_many_trips_for_client", f"this client already holds its maximum of {quota.max_trips} open trips; end one (POST /v1/trips/{{id}}/end) or wait for idle ones to expire",
                        headers={"Retry-After": "60"})  # fmt: skip

    def device_full(self, quota: Quota) -> ApiError:
        return ApiError(429, "too_many_trips_for_device", f"this device already holds its maximum of {quota.max_trips_per_device} open trips; end one (POST /v1/trips/{{id}}/end) or wait for idle ones to expire",
                        headers={"Retry-After": "60"})  # fmt: skip

    def service_full(self) -> ApiError:
        return ApiError(503, "too_many_trips", f"the service holds its maximum of {self.s.max_trips} open trips; end one or retry later", headers={"Retry-After": "30"})

    def refusal(self, code: int, who: Creator) -> ApiError:
        """The error of a store's refusal code: 2 the client's trips, 3 the service's, 5 the device's."""
        return {2: self.client_full, 5: self.device_full}[code](who.quota) if code != 3 else self.service_full()


def unknown_trip(trip_id: str) -> ApiError:
    return ApiError(404, "unknown_trip", f"no open trip {trip_id!r} (never created, ended, expired, or shed: a trip created without an API key "
                                         "gives its place to a keyed one when the service is full)")  # fmt: skip


def no_token() -> ApiError:
    return ApiError(401, "unauthorized", "missing bearer token: send 'Authorization: Bearer <trip token>'", headers={"WWW-Authenticate": "Bearer"})


def bad_token(other_trip: bool) -> ApiError:
    if other_trip:
        return ApiError(403, "forbidden", "this token belongs to another trip")
    return ApiError(401, "unauthorized", "invalid bearer token for this trip", headers={"WWW-Authenticate": "Bearer"})


class MemoryTrips:
    """Trips in this process, by id and by token hash: the embedded default (one worker; a restart loses them).
    ``release(trip)`` closes what a shed trip holds (its SPaT view); ``on_shed()`` counts it."""

    shared = False

    def __init__(self, settings: Settings, limits: Limits, release: Callable[[Trip], Awaitable[None]] | None = None) -> None:
        self.limits = limits
        self.release = release
        self.on_shed: Callable[[], None] | None = None
        self.max_trips = settings.max_trips
        self._trips: dict[str, Trip] = {}
        self._by_token: dict[bytes, str] = {}
        self._per_client: dict[str, int] = {}
        self._per_device: dict[tuple[str, str], int] = {}
        self._anonymous: dict[str, None] = {}  # trips created without a key, oldest first: the newest is shed first
        self.create_bucket = TokenBucket(settings.create_rate_per_s, settings.create_burst)
        self.client_buckets = KeyedBuckets(settings.create_rate_per_client_per_s, settings.create_burst_per_client)

    def __len__(self) -> int:
        return len(self._trips)

    async def count(self) -> int:
        return len(self._trips)

    def _check_capacity(self, who: Creator) -> None:
        q = who.quota
        if who.device and q.max_trips_per_device and self._per_device.get((who.client, who.device), 0) >= q.max_trips_per_device:
            raise self.limits.device_full(q)
        if q.max_trips and self._per_client.get(who.client, 0) >= q.max_trips:
            raise self.limits.client_full(q)
        if len(self._trips) >= self.max_trips and (who.anonymous or not self._anonymous):
            raise self.limits.service_full()

    async def admit(self, who: Creator) -> None:
        q = who.quota
        if wait_s := self.client_buckets.take(who.client, None, q.create_rate_per_s, q.create_burst):
            raise self.limits.client_rate(wait_s, q)
        self._check_capacity(who)
        if wait_s := self.create_bucket.take():
            raise self.limits.create_rate(wait_s)

    async def add(self, trip: Trip, who: Creator) -> None:
        self._check_capacity(who)
        while len(self._trips) >= self.max_trips and self._anonymous:  # a keyed trip: the newest without a key gives its place
            shed = await self.remove(next(reversed(self._anonymous)))
            if self.release is not None:
                await self.release(shed)
            if self.on_shed is not None:
                self.on_shed()
        self._trips[trip.id] = trip
        self._by_token[trip.token_hash] = trip.id
        self._per_client[trip.client] = self._per_client.get(trip.client, 0) + 1
        if trip.device:
            self._per_device[trip.client, trip.device] = self._per_device.get((trip.client, trip.device), 0) + 1
        if who.anonymous:
            self._anonymous[trip.id] = None

    def get(self, trip_id: str) -> Trip:
        trip = self._trips.get(trip_id)
        if trip is None:
            raise unknown_trip(trip_id)
        return trip

    async def authorize(self, trip_id: str, token: str | None, take: bool = False) -> Trip:
        trip = self.get(trip_id)
        if not token:
            raise no_token()
        digest = token_hash(token)
        if not hmac.compare_digest(digest, trip.token_hash):
            raise bad_token(self._by_token.get(digest) is not None)
        trip.last_seen_s = time.monotonic()
        if take and (wait_s := trip.bucket.take()):
            raise self.limits.trip_rate(wait_s)
        return trip

    async def save(self, trip: Trip, take: bool = False) -> bool:
        return True  # the trip object is the stored trip (Engine.apply_fix does not call this: on_fix is one step)

    async def samples(self, trip: Trip) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return tuple(np.frombuffer(a, dtype=np.float64).copy() for a in (trip.trace_t, trip.trace_v, trip.trace_x))  # type: ignore[return-value]

    async def remove(self, trip_id: str) -> Trip:
        trip = self.get(trip_id)
        del self._trips[trip_id]
        self._by_token.pop(trip.token_hash, None)
        self._anonymous.pop(trip_id, None)
        for table, key in ((self._per_client, trip.client), (self._per_device, (trip.client, trip.device))):
            left = table.get(key, 1) - 1
            if left > 0:
                table[key] = left
            else:
                table.pop(key, None)
        return trip

    def idle(self, ttl_s: float, now_s: float | None = None) -> list[str]:
        now = time.monotonic() if now_s is None else now_s
        return [tid for tid, trip in self._trips.items() if now - trip.last_seen_s > ttl_s]

    async def sweep(self, ttl_s: float) -> list[Trip]:
        """Remove and return the trips idle longer than ``ttl_s`` (the caller closes their SPaT)."""
        out = []
        for trip_id in self.idle(ttl_s):
            with contextlib.suppress(ApiError):
                out.append(await self.remove(trip_id))
        return out

    async def close(self) -> None:
        return None


# -- Redis ------------------------------------------------------------------------------------------------
_TAKE = """
local function take(key, fn, fs, rate, burst, now)
  local b = redis.call('HMGET', key, fn, fs)
  local n = tonumber(b[1]) or burst
  local s = tonumber(b[2]) or now
  n = math.min(burst, n + math.max(0, now - s) * rate)
  local wait = 0
  if n >= 1 then n = n - 1 else wait = (1 - n) / rate end
  redis.call('HSET', key, fn, string.format('%.17g', n), fs, string.format('%.17g', now))
  return wait
end
local function count(key, oldest)
  redis.call('ZREMRANGEBYSCORE', key, '-inf', '(' .. oldest)
  return redis.call('ZCARD', key)
end
"""

# KEYS: open, client zset, client bucket, create bucket, device zset ('' none), anonymous zset. ARGV: now, keep_s,
# max_trips, max_per_client, client rate, client burst, create rate, create burst, max_per_device, anonymous (0/1).
# -> {0} admitted, {1, wait} client rate, {2} client full, {3} service full, {4, wait} service rate, {5} device full
# (a keyed client finding the service full is admitted while a trip without a key is open: _ADD sheds it)
_ADMIT = Script(_TAKE + """
local now, ttl = tonumber(ARGV[1]), tonumber(ARGV[2])
local wait = take(KEYS[3], 'n', 's', tonumber(ARGV[5]), tonumber(ARGV[6]), now)
redis.call('PEXPIRE', KEYS[3], math.ceil(1000 * (tonumber(ARGV[6]) / tonumber(ARGV[5]) + 1)))
if wait > 0 then return {1, tostring(wait)} end
if KEYS[5] ~= '' and tonumber(ARGV[9]) > 0 and count(KEYS[5], now - ttl) >= tonumber(ARGV[9]) then return {5} end
if tonumber(ARGV[4]) > 0 and count(KEYS[2], now - ttl) >= tonumber(ARGV[4]) then return {2} end
if count(KEYS[1], now - ttl) >= tonumber(ARGV[3]) and (ARGV[10] == '1' or redis.call('ZCARD', KEYS[6]) == 0) then return {3} end
wait = take(KEYS[4], 'n', 's', tonumber(ARGV[7]), tonumber(ARGV[8]), now)
redis.call('PEXPIRE', KEYS[4], math.ceil(1000 * (tonumber(ARGV[8]) / tonumber(ARGV[7]) + 1)))
if wait > 0 then return {4, tostring(wait)} end
return {0}
""")

# Removes the trip ``id`` (its hash, samples, token key, open-set entries); h = its tok, client, dev fields.
_DROP = """
local function drop(p, id, h)
  redis.call('DEL', p .. ':t:' .. id, p .. ':t:' .. id .. ':tr', p .. ':k:' .. h[1])
  redis.call('ZREM', p .. ':open', id)
  redis.call('ZREM', p .. ':c:' .. h[2], id)
  if h[3] and h[3] ~= '' then redis.call('ZREM', p .. ':d:' .. h[2] .. ':' .. h[3], id) end
  redis.call('ZREM', p .. ':anon', id)
end
"""

# KEYS: trip, open, client zset, token key, device zset ('' none), anonymous zset. ARGV: now, keep_s, max_trips,
# max_per_client, id, token hash, client, burst, meta, state, max_per_device, device, anonymous (0/1), prefix.
# -> {0, id of the trip shed or ''} added, {2} client full, {3} service full, {5} device full.
# The service full, a keyed trip takes the place of the newest open trip created without a key (``anon``, by
# creation time; members whose trip expired are dropped on the way).
_ADD = Script(_TAKE + _DROP + """
local now, ttl, p = tonumber(ARGV[1]), tonumber(ARGV[2]), ARGV[14]
if KEYS[5] ~= '' and tonumber(ARGV[11]) > 0 and count(KEYS[5], now - ttl) >= tonumber(ARGV[11]) then return {5} end
if tonumber(ARGV[4]) > 0 and count(KEYS[3], now - ttl) >= tonumber(ARGV[4]) then return {2} end
local shed = ''
if count(KEYS[2], now - ttl) >= tonumber(ARGV[3]) then
  if ARGV[13] == '1' then return {3} end
  while shed == '' do
    local newest = redis.call('ZRANGE', KEYS[6], -1, -1)[1]
    if not newest then return {3} end
    local h = redis.call('HMGET', p .. ':t:' .. newest, 'tok', 'client', 'dev')
    if h[1] then shed = newest else redis.call('ZREM', KEYS[6], newest) end
    if h[1] then drop(p, newest, h) end
  end
end
local ms = math.ceil(ttl * 1000)
redis.call('HSET', KEYS[1], 'v', '1', 'tok', ARGV[6], 'client', ARGV[7], 'bt', ARGV[8], 'bs', ARGV[1], 'ts', ARGV[1], 'meta', ARGV[9], 'state', ARGV[10], 'dev', ARGV[12])
redis.call('PEXPIRE', KEYS[1], ms)
redis.call('SET', KEYS[4], ARGV[5], 'PX', ms)
redis.call('ZADD', KEYS[2], now, ARGV[5])
redis.call('ZADD', KEYS[3], now, ARGV[5])
redis.call('PEXPIRE', KEYS[3], ms)
if KEYS[5] ~= '' then
  redis.call('ZADD', KEYS[5], now, ARGV[5])
  redis.call('PEXPIRE', KEYS[5], ms)
end
if ARGV[13] == '1' then redis.call('ZADD', KEYS[6], now, ARGV[5]) end
return {0, shed}
""")

# KEYS: anonymous zset. ARGV: prefix. Drops the members whose trip has expired (by the TTL, not ended): the
# zset is scored by creation, not by last request. -> members dropped
_PRUNE_ANON = Script("""
local gone = 0
for _, id in ipairs(redis.call('ZRANGE', KEYS[1], 0, -1)) do
  if redis.call('EXISTS', ARGV[1] .. ':t:' .. id) == 0 then
    redis.call('ZREM', KEYS[1], id)
    gone = gone + 1
  end
end
return gone
""")

# The trip's hash is read once per call (HMGET of TRIP_FIELDS) and written once (HSET of what changed).
# ``touch``: the idle clock (the keys' expiry, the open-trip sets' scores) is reset when it was last reset
# ``every`` seconds ago or more (a tenth of the TTL, at most 10 s), not per request: 6 commands saved on most
# fixes. The keys then live ``keep`` = TTL + every after a reset, so a trip lives at least its TTL after its
# last request, and the caps count a trip until ``keep`` after its last reset (never too few).
# ``bucket``: the trip's request bucket from the fields read; its new tokens and stamp go with the write.
_TRIP = """
local function touch(key, h, keep, every, now, p, id, out)
  if now - (tonumber(h[6]) or 0) < every then return end
  local ms = math.ceil(keep * 1000)
  redis.call('PEXPIRE', key, ms)
  redis.call('PEXPIRE', key .. ':tr', ms)
  redis.call('PEXPIRE', p .. ':k:' .. h[2], ms)
  redis.call('ZADD', p .. ':open', now, id)
  redis.call('ZADD', p .. ':c:' .. h[3], now, id)
  redis.call('PEXPIRE', p .. ':c:' .. h[3], ms)
  if h[7] and h[7] ~= '' then
    redis.call('ZADD', p .. ':d:' .. h[3] .. ':' .. h[7], now, id)
    redis.call('PEXPIRE', p .. ':d:' .. h[3] .. ':' .. h[7], ms)
  end
  out[#out + 1] = 'ts'
  out[#out + 1] = string.format('%.17g', now)
end
local function bucket(h, rate, burst, now, out)
  local n = tonumber(h[4]) or burst
  local s = tonumber(h[5]) or now
  n = math.min(burst, n + math.max(0, now - s) * rate)
  if n < 1 then return (1 - n) / rate end
  out[#out + 1] = 'bt'
  out[#out + 1] = string.format('%.17g', n - 1)
  out[#out + 1] = 'bs'
  out[#out + 1] = string.format('%.17g', now)
  return 0
end
local function write(key, out)
  if #out > 0 then redis.call('HSET', key, unpack(out)) end
end
"""
TRIP_FIELDS = ("v", "tok", "client", "bt", "bs", "ts", "dev")

# KEYS: trip. ARGV: token hash, version held ('' none), meta wanted (0/1), take (0/1), now, rate, burst,
# keep_s, every_s, prefix, id.
# -> {0} unknown, {1} bad token, {2} another trip's token, {3, wait} rate limited,
#    {4, version, state or nil, meta or nil}
_LOAD = Script(_TRIP + """
local h = redis.call('HMGET', KEYS[1], 'v', 'tok', 'client', 'bt', 'bs', 'ts', 'dev')
if not h[1] then return {0} end
local p = ARGV[10]
if h[2] ~= ARGV[1] then
  if redis.call('EXISTS', p .. ':k:' .. ARGV[1]) == 1 then return {2} end
  return {1}
end
local now, out = tonumber(ARGV[5]), {}
touch(KEYS[1], h, tonumber(ARGV[8]), tonumber(ARGV[9]), now, p, ARGV[11], out)
if ARGV[4] == '1' then
  local wait = bucket(h, tonumber(ARGV[6]), tonumber(ARGV[7]), now, out)
  if wait > 0 then
    write(KEYS[1], out)
    return {3, tostring(wait)}
  end
end
write(KEYS[1], out)
local state, meta = false, false
if h[1] ~= ARGV[2] and ARGV[3] == '1' then
  local sm = redis.call('HMGET', KEYS[1], 'state', 'meta')
  state, meta = sm[1], sm[2]
elseif h[1] ~= ARGV[2] then
  state = redis.call('HGET', KEYS[1], 'state')
elseif ARGV[3] == '1' then
  meta = redis.call('HGET', KEYS[1], 'meta')
end
return {4, h[1], state, meta}
""")

# KEYS: trip, samples. ARGV: token hash, keep_s, rate, burst, prefix, id, every_s (the same for every fix of the
# trip: :meth:`RedisTrips.save` packs them once), then take (0/1), now, version computed from, state, new samples
# (bytes). The trip's token is checked, its idle clock reset, a token of its bucket taken (when asked), then the state
# written if the trip is still at the version it was computed from: 3 commands (HMGET, HSET, APPEND) on most fixes.
# -> {new version}, {0, version, state} the trip moved meanwhile, {-1} gone, {-2} not its token, {-3, wait} rate limited
_SAVE = Script(_TRIP + """
local h = redis.call('HMGET', KEYS[1], 'v', 'tok', 'client', 'bt', 'bs', 'ts', 'dev')
if not h[1] then return {-1} end
if h[2] ~= ARGV[1] then return {-2} end
local now, keep, out = tonumber(ARGV[9]), tonumber(ARGV[2]), {}
touch(KEYS[1], h, keep, tonumber(ARGV[7]), now, ARGV[5], ARGV[6], out)
if ARGV[8] == '1' then
  local wait = bucket(h, tonumber(ARGV[3]), tonumber(ARGV[4]), now, out)
  if wait > 0 then
    write(KEYS[1], out)
    return {-3, tostring(wait)}
  end
end
if h[1] ~= ARGV[10] then
  write(KEYS[1], out)
  return {0, h[1], redis.call('HGET', KEYS[1], 'state')}
end
local nv = tonumber(h[1]) + 1
out[#out + 1] = 'v'
out[#out + 1] = tostring(nv)
out[#out + 1] = 'state'
out[#out + 1] = ARGV[11]
write(KEYS[1], out)
if #ARGV[12] > 0 and redis.call('APPEND', KEYS[2], ARGV[12]) == #ARGV[12] then  -- a new key: its expiry
  redis.call('PEXPIRE', KEYS[2], math.ceil(keep * 1000))
end
return {nv}
""")

# KEYS: trip, samples. ARGV: prefix, id. -> 1 removed, 0 already gone
_REMOVE = Script(_DROP + """
local h = redis.call('HMGET', KEYS[1], 'tok', 'client', 'dev')
if not h[1] then return 0 end
drop(ARGV[1], ARGV[2], h)
return 1
""")

SAMPLE = np.dtype("<f8")
"""A score sample's fields (t, v, x) as stored: little-endian doubles, 24 bytes a fix."""
_ROW = struct.Struct("<3d")
"""A score sample packed (as :data:`SAMPLE` rows)."""


def _json(data) -> bytes:
    return to_json(data, inf_nan_mode="constants")  # advisories may hold infinite seconds


class _Reach:
    """``with REACH:`` Redis unreachable (down, silent, loading) as 503 ``store_unavailable`` (the trip is not gone: retry)."""

    def __enter__(self) -> None:
        return None

    def __exit__(self, kind, exc, tb) -> bool:
        if exc is None or not isinstance(exc, (RedisConnectionError, RedisTimeoutError, BusyLoadingError, OSError)):
            return False
        log.warning("trip store unreachable: %r", exc)
        raise ApiError(503, "store_unavailable", f"the trip store is unreachable ({type(exc).__name__}); the trip is kept: retry in {RETRY_AFTER_S} s",
                       headers={"Retry-After": str(RETRY_AFTER_S)}) from None  # fmt: skip


REACH = _Reach()


class _Hold:
    """:meth:`RedisTrips.hold`: one lock per trip while anyone holds or waits for it (``locks``: id -> [lock, holders
    and waiters]). A class, not an ``asynccontextmanager``: that one is an async generator per fix, registered with
    the event loop (a weak set's add and remove) and stepped twice."""

    __slots__ = ("locks", "trip_id", "entry")

    def __init__(self, locks: dict[str, list], trip_id: str) -> None:
        self.locks = locks
        self.trip_id = trip_id

    async def __aenter__(self) -> None:
        entry = self.entry = self.locks.get(self.trip_id) or self.locks.setdefault(self.trip_id, [asyncio.Lock(), 0])
        entry[1] += 1
        try:
            await entry[0].acquire()
        except BaseException:
            self._leave()
            raise

    async def __aexit__(self, *exc) -> None:
        self.entry[0].release()
        self._leave()

    def _leave(self) -> None:
        self.entry[1] -= 1
        if not self.entry[1]:
            del self.locks[self.trip_id]


class RedisTrips:
    """Trips in Redis, shared by every worker (see the module docstring). ``build(meta)`` makes a trip from its
    meta (``Engine.trip_from_meta``); ``release(trip)`` closes what a cached trip holds (its SPaT view)."""

    shared = True
    CACHE_IDLE_S = 120.0
    """A worker forgets a trip it has not served for this long (the trip stays in Redis). [s]"""

    def __init__(
        self, settings: Settings, limits: Limits, build: Callable[[dict], Awaitable[Trip]],
        release: Callable[[Trip], Awaitable[None]] | None = None, clock: Callable[[], float] = time.time,
    ) -> None:  # fmt: skip
        self.s = settings
        self.limits = limits
        self.build = build
        self.release = release
        self.clock = clock
        self.p = settings.store_prefix
        self.redis = RedisPipe(settings.store_url, settings.store_timeout_s, settings.store_write_window_s)  # one pipelined connection per worker
        self.touch_every_s = min(10.0, settings.trip_idle_ttl_s / 10)
        """A trip's idle clock is reset at most this often (each request did it before: 6 more commands). [s]"""
        self.keep_s = settings.trip_idle_ttl_s + self.touch_every_s
        """A trip's keys live this long after its idle clock's last reset: at least the TTL after its last request. [s]"""
        self._cache: dict[str, tuple[Trip, float]] = {}  # id -> (trip, last used, monotonic)
        self._heads: dict[str, tuple[int, bytes]] = {}  # id -> its save's packed start (_save_head), while cached
        self._locks: dict[str, list] = {}  # id -> [lock, holders and waiters]
        self._count = 0
        self.on_shed: Callable[[], None] | None = None

    def __len__(self) -> int:
        return self._count  # as of the last count() (health, sweep)

    def _key(self, trip_id: str) -> str:
        return f"{self.p}:t:{trip_id}"

    async def count(self) -> int:
        with REACH:
            await self.redis.call("ZREMRANGEBYSCORE", f"{self.p}:open", "-inf", f"({self.clock() - self.keep_s!r}")
            self._count = int(await self.redis.call("ZCARD", f"{self.p}:open"))
        return self._count

    def _quota_keys(self, who: Creator) -> tuple[str, str]:
        """The device's open-trip set ('' without a device) and the set of trips created without a key."""
        device = f"{self.p}:d:{who.client}:{who.device}" if who.device else ""
        return device, f"{self.p}:anon"

    async def admit(self, who: Creator) -> None:
        s, q = self.s, who.quota
        with REACH:
            r = await self.redis.run(
                _ADMIT, keys=[f"{self.p}:open", f"{self.p}:c:{who.client}", f"{self.p}:rl:c:{who.client}", f"{self.p}:rl:create", *self._quota_keys(who)],
                args=[repr(self.clock()), self.keep_s, s.max_trips, q.max_trips, q.create_rate_per_s, q.create_burst, s.create_rate_per_s, s.create_burst,
                      q.max_trips_per_device, 1 if who.anonymous else 0],
            )  # fmt: skip
        code = int(r[0])
        if code == 1:
            raise self.limits.client_rate(float(r[1]), q)
        if code == 4:
            raise self.limits.create_rate(float(r[1]))
        if code:
            raise self.limits.refusal(code, who)

    async def add(self, trip: Trip, who: Creator) -> None:
        s, q = self.s, who.quota
        with REACH:
            r = await self.redis.run(
                _ADD, keys=[self._key(trip.id), f"{self.p}:open", f"{self.p}:c:{trip.client}", f"{self.p}:k:".encode() + trip.token_hash, *self._quota_keys(who)],
                args=[repr(self.clock()), self.keep_s, s.max_trips, q.max_trips, trip.id, trip.token_hash, trip.client,
                      s.rate_burst, _json(trip.meta()), trip.state_json(), q.max_trips_per_device, who.device, 1 if who.anonymous else 0, self.p],
            )  # fmt: skip
        code = int(r[0])
        if code:
            raise self.limits.refusal(code, who)
        if r[1]:  # a trip without a key gave its place
            shed = r[1].decode() if isinstance(r[1], bytes) else r[1]
            self._forget(shed)
            if self.on_shed is not None:
                self.on_shed()
        trip.version = 1
        self._cache[trip.id] = (trip, time.monotonic())

    def hold(self, trip_id: str) -> _Hold:
        """``async with store.hold(trip_id)``: serialise this worker's calls on one trip (load, apply, save)."""
        return _Hold(self._locks, trip_id)

    async def authorize(self, trip_id: str, token: str | None, take: bool = False) -> Trip:
        if not token:
            if self._cache.get(trip_id) is None and not await self._exists(trip_id):
                raise unknown_trip(trip_id)
            raise no_token()
        s = self.s
        cached = self._cache.get(trip_id)
        trip = cached[0] if cached is not None else None
        digest = token_hash(token)
        with REACH:
            r = await self.redis.run(
                _LOAD, keys=[self._key(trip_id)],
                args=[digest, "" if trip is None else str(trip.version), 0 if trip is not None else 1, 1 if take else 0, repr(self.clock()),
                      s.rate_per_s, s.rate_burst, self.keep_s, self.touch_every_s, self.p, trip_id],
            )  # fmt: skip
        code = int(r[0])
        if code == 0:
            self._forget(trip_id)
            raise unknown_trip(trip_id)
        if code in (1, 2):
            raise bad_token(code == 2)
        if code == 3:
            raise self.limits.trip_rate(float(r[1]))
        version, state, meta = int(r[1]), r[2], r[3]
        if trip is None:
            trip = await self.build(from_json(meta))
            trip.token_hash = digest
        if state is not None:
            trip.restore(from_json(state))
            trip.version = version
        self._cache[trip_id] = (trip, time.monotonic())
        return trip

    async def _exists(self, trip_id: str) -> bool:
        with REACH:
            return bool(await self.redis.call("EXISTS", self._key(trip_id)))

    async def volatile(self) -> str | None:
        """A warning when this Redis keeps no append-only file, so that a restart of Redis loses every open trip;
        None when it keeps one, or cannot be asked now (the service starts all the same)."""
        try:
            with REACH:
                info = await self.redis.call("INFO", "persistence")
        except ApiError:
            return None
        fields = dict(line.split(":", 1) for line in info.decode().splitlines() if ":" in line)
        if fields.get("aof_enabled", "1") == "1":
            return None
        return ("the trip store's Redis keeps no append-only file (appendonly no): a restart of Redis loses every open trip (their phones get 404), "
                "or brings back its last RDB snapshot without the fixes since. Run it with --appendonly yes (docs/SERVICE.md, Scaling)")  # fmt: skip

    async def for_fix(self, trip_id: str, token: str | None) -> Trip:
        """The trip to apply a fix to: this worker's copy when it has one and ``token`` is its token (no round
        trip: :meth:`save` finds out whether the copy was current), else :meth:`authorize` (no bucket token)."""
        cached = self._cache.get(trip_id)
        if cached is not None and cached[0].version > 0 and token:
            trip = cached[0]
            if trip.token is not None and hmac.compare_digest(token.encode(), trip.token.encode()):
                return trip  # the token this worker already checked against the hash (no SHA-256 per fix)
            if hmac.compare_digest(token_hash(token), trip.token_hash):
                trip.token = token
                return trip
        return await self.authorize(trip_id, token)

    async def save(self, trip: Trip, take: bool = False) -> bool:
        """Write the trip's new state and samples if the store still holds the version they were computed from
        (False: another worker wrote first; the copy now holds the store's state: apply the fix again).
        ``take``: one token of the trip's bucket first (429 when empty, nothing written)."""
        n = len(trip.trace_t)
        samples = b"".join(map(_ROW.pack, trip.trace_t, trip.trace_v, trip.trace_x))  # as SAMPLE rows
        head = self._heads.get(trip.id) or self._save_head(trip)
        command = _SAVE.command(head, (b"1" if take else b"0", b"%r" % self.clock(), b"%d" % trip.version, trip.state_json(), samples))
        try:
            with REACH:
                r = await self.redis.run_packed(_SAVE, command)
        except ApiError:
            trip.version = -1  # not known to be written: the copy may be ahead of the store, reload its state
            raise
        version = int(r[0])
        if version == 0:  # another worker wrote first: the copy takes the store's state, the fix is applied again
            trip.restore(from_json(r[2]))
            trip.version = int(r[1])
            return False
        if version < 0:
            trip.version = -1  # the copy holds a fix that is not in the store
            if version == -1:
                self._forget(trip.id)
                raise unknown_trip(trip.id)
            if version == -2:
                raise bad_token(False)
            raise self.limits.trip_rate(float(r[1]))
        trip.version = version
        trip.trace_base += n
        del trip.trace_t[:], trip.trace_v[:], trip.trace_x[:]
        self._cache[trip.id] = (trip, time.monotonic())
        return True

    def _save_head(self, trip: Trip) -> tuple[int, bytes]:
        """The start of the trip's ``_SAVE`` command, the same for each of its fixes, packed once: a save's command and
        samples then cost 3.0 us, against 5.2 with hiredis packing the whole command (a 1.5 kB state; issue 30)."""
        s = self.s
        head = self._heads[trip.id] = _SAVE.head([self._key(trip.id), self._key(trip.id) + ":tr"],
                                                 [trip.token_hash, self.keep_s, s.rate_per_s, s.rate_burst, self.p, trip.id, self.touch_every_s])  # fmt: skip
        return head

    async def samples(self, trip: Trip) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        with REACH:
            data = await self.redis.call("GET", self._key(trip.id) + ":tr") or b""
        rows = np.frombuffer(data, dtype=SAMPLE)[: 3 * (len(data) // (3 * SAMPLE.itemsize))].reshape(-1, 3)
        pending = np.column_stack([np.frombuffer(a, dtype=np.float64) for a in (trip.trace_t, trip.trace_v, trip.trace_x)]).reshape(-1, 3)
        rows = np.concatenate([rows, pending]) if pending.size else rows
        return rows[:, 0].copy(), rows[:, 1].copy(), rows[:, 2].copy()

    async def remove(self, trip_id: str) -> Trip:
        cached = self._cache.get(trip_id)
        with REACH:
            gone = not await self.redis.run(_REMOVE, keys=[self._key(trip_id), self._key(trip_id) + ":tr"], args=[self.p, trip_id])
        trip = self._forget(trip_id, release=False) or (cached[0] if cached else None)  # the caller closes its SPaT
        if gone or trip is None:  # another call ended it first
            if trip is not None and self.release is not None:
                await self.release(trip)
            raise unknown_trip(trip_id)
        return trip

    def _forget(self, trip_id: str, release: bool = True) -> Trip | None:
        """Drop this worker's copy of the trip (and with ``release`` what it holds: its SPaT view)."""
        self._heads.pop(trip_id, None)
        entry = self._cache.pop(trip_id, None)
        if entry is None:
            return None
        if release and self.release is not None:
            asyncio.get_running_loop().create_task(self.release(entry[0]))
        return entry[0]

    async def sweep(self, ttl_s: float) -> list[Trip]:
        """Forget the trips this worker has not served lately (they stay in Redis until their TTL);
        refresh the open-trip count. Returns nothing to close: the caller's SPaT views are released here."""
        now = time.monotonic()
        for trip_id in [tid for tid, (_, used) in self._cache.items() if now - used > min(self.CACHE_IDLE_S, ttl_s)]:
            if trip_id not in self._locks:
                self._forget(trip_id)
        with contextlib.suppress(ApiError):
            await self.count()
            with REACH:
                await self.redis.run(_PRUNE_ANON, keys=[f"{self.p}:anon"], args=[self.p])
        return []

    async def close(self) -> None:
        for trip_id in list(self._cache):
            self._forget(trip_id)
        await self.redis.close()


def make_store(settings: Settings, limits: Limits, build, release, clock) -> MemoryTrips | RedisTrips:
    """The store ``ECO_STORE_URL`` names: Redis (``redis://``, ``rediss://``, ``unix://``), else in process."""
    if settings.store_url:
        return RedisTrips(settings, limits, build, release, clock)
    return MemoryTrips(settings, limits, release)

