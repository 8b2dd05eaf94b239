"""Where the queue board (:class:`server.queue.QueueBoard`) keeps its probes and red starts and ends when the trips are
in Redis: every worker's, shared through the trip store's Redis, with no Redis call on a fix's path.

The board reads and writes three kinds of table as plain dicts: per corridor, trip -> ``(t_unix_s, station_m,
speed_mps)`` of its last fix (a *probe*), intersection -> when its current red was first seen, and intersection -> its
last red that has ended, ``(start, end, jam_m)`` (its queue goes on discharging after the end). With the in-process
store they are dicts of this worker. With the Redis store they are :class:`Noted` dicts: a write by this worker is
also appended to a log of its changes (a dict's cost, no I/O), and :class:`SharedBoard` runs beside the service, every
``ECO_QUEUE_SYNC_S`` (default 0.25 s), one Lua script over the worker's one pipelined connection (``server.storage.redispipe``)
that applies the worker's changes since the last call to Redis and answers every worker's current tables, which then
replace this worker's copy (the changes made while the call was out applied again on top). A fix on worker A thus
sees a car that worker B serves from at most two intervals after B's fix, as it would see its own.

**Redis layout** (prefix ``ECO_STORE_PREFIX``, default ``eco``; each key expiring ``KEY_TTL_S`` after the last call):

* ``eco:q:p:<corridor>``, a hash: trip id -> its probe, three little-endian doubles (t, station, speed); a newer probe
  of a trip replaces an older one, whichever worker wrote it (a REST trip moves between workers), a withdrawal (the
  trip left the route or ended) removes it unless a newer one has come; probes older than ``KEEP_S`` by the worker's
  clock are dropped. Whatever is kept, the board counts a probe only while it is at most ``MAX_AGE_S`` older than the
  fix it advises (``server.queue``): a stale probe never counts.
* ``eco:q:red``, a hash: intersection id -> when its current red was first seen (a double): the earliest of the
  workers' first sightings; removed when a worker sees the light not red.
* ``eco:q:end``, a hash: intersection id -> its last red that has ended, three little-endian doubles (start, end, the
  queue in metres that the worker ending it last saw published in it, NaN: none), written by the worker that first saw
  the light off after the red (its start the shared one); a later red (a later start) replaces it, another worker's
  record of the same red does not. Kept until the key expires (the board counts the red's queue only while it is still
  discharging: ``advisory.advice.queue.past_queue``).

**Redis unreachable** (down, silent for ``ECO_STORE_TIMEOUT_S``, refusing the script): the call fails in the
background, nothing on a fix's path waits for it or fails because of it; the board goes on with this worker's own
probes (the other workers' copies age out within ``MAX_AGE_S``) and its own red starts and ends; the changes kept for the next
call (the last per trip and per light). ``/health`` (``queue_board``) and ``/metrics`` (``ecodrive_queue_board_shared``,
``ecodrive_queue_board_sync_failures_total``) say so; the first successful call brings the shared tables back.
"""

from __future__ import annotations

import asyncio
import logging
import struct
from collections.abc import Callable, Iterable
from typing import Any

from redis.exceptions import RedisError

from server.storage.redispipe import RedisPipe, Script

log = logging.getLogger("server")

KEEP_S = 6.0
"""Redis keeps a probe this long after its fix, by the writing worker's clock (twice ``server.queue.MAX_AGE_S``: a
fix's time may trail the server's clock a little; the board itself never counts a probe past ``MAX_AGE_S``). [s]"""
KEY_TTL_S = 60.0
"""The board's keys expire this long after the last worker's call (a service stopped leaves nothing behind). [s]"""

_PROBE = struct.Struct("<3d")
_RED = struct.Struct("<d")
_ENDED = struct.Struct("<3d")

# KEYS: red starts, red ends, then each corridor's probes (only these are pruned by age). ARGV: oldest probe stamp kept, keys' TTL [ms], then per change
# (in the order made): key index, field, rule ('n' the newer stamp wins, 'e' the earlier wins, 'w' withdraw unless a
# newer one is stored), value (its first double is its stamp). -> each key's fields and values, flat.
_SYNC = Script("""
local oldest, ttl = tonumber(ARGV[1]), tonumber(ARGV[2])
for i = 3, #ARGV, 4 do
  local key, field, rule, value = KEYS[tonumber(ARGV[i])], ARGV[i + 1], ARGV[i + 2], ARGV[i + 3]
  local t = struct.unpack('<d', value)
  local stored = redis.call('HGET', key, field)
  local s = stored and struct.unpack('<d', stored)
  if rule == 'w' then
    if s and s <= t then redis.call('HDEL', key, field) end
  elseif not s or (rule == 'n' and s < t) or (rule == 'e' and s > t) then
    redis.call('HSET', key, field, value)
  end
end
local out = {}
for k = 1, #KEYS do
  local all = redis.call('HGETALL', KEYS[k])
  if k > 2 then
    local kept = {}
    for j = 1, #all, 2 do
      if struct.unpack('<d', all[j + 1]) < oldest then
        redis.call('HDEL', KEYS[k], all[j])
      else
        kept[#kept + 1] = all[j]
        kept[#kept + 1] = all[j + 1]
      end
    end
    all = kept
  end
  if #all > 0 then redis.call('PEXPIRE', KEYS[k], ttl) end
  out[k] = all
end
return out
""")


def _stamp(value: Any) -> float:
    """A table value's stamp: a probe's fix time, an ended red's start, or a red start itself. [s]"""
    return value[0] if isinstance(value, tuple) else value


class Noted(dict):
    """A dict of the board that logs this worker's changes (``ops``: ``(key, value, kept)`` in order; ``kept`` False: a
    withdrawal) for :class:`SharedBoard`. ``newer``: of two values of one key the one with the later stamp wins
    (probes, ended reds), else the earlier (red starts). A deletion with ``del`` (the board forgetting a stale probe) is not
    logged: Redis drops stale probes itself."""

    __slots__ = ("newer", "ops", "loads")

    def __init__(self, newer: bool) -> None:
        super().__init__()
        self.newer = newer
        self.ops: list[tuple[Any, Any, bool]] = []
        self.loads = 0
        """How many times :meth:`load` replaced the table (an index over it, ``server.queue.Lane``, is then rebuilt)."""

    def __setitem__(self, key, value) -> None:
        dict.__setitem__(self, key, value)
        self.ops.append((key, value, True))

    def setdefault(self, key, default=None):
        if key in self:
            return dict.__getitem__(self, key)
        self[key] = default
        return default

    def pop(self, key, *default):
        if key not in self:
            if default:
                return default[0]
            raise KeyError(key)
        value = dict.pop(self, key)
        self.ops.append((key, value, False))
        return value

    def _apply(self, key, value, kept: bool) -> None:
        """One change merged by the rules Redis applies (a value replaces a stored one only if it wins)."""
        stored = dict.get(self, key)
        if not kept:
            if stored is not None and _stamp(stored) <= _stamp(value):
                dict.pop(self, key)
        elif stored is None or (_stamp(value) > _stamp(stored) if self.newer else _stamp(value) < _stamp(stored)):
            dict.__setitem__(self, key, value)

    def load(self, state: dict) -> None:
        """The shared table replaces this copy; the changes logged since it was asked for are applied again on top."""
        dict.clear(self)
        dict.update(self, state)
        for op in self.ops:
            self._apply(*op)
        self.loads += 1

    def take(self) -> list[tuple[Any, Any, bool]]:
        ops, self.ops = self.ops, []
        return ops

    def give_back(self, ops: list[tuple[Any, Any, bool]]) -> None:
        """Changes Redis did not get go out with the next call: the last per key (a red start withdrawn and seen again
        in one outage keeps only the second), so that an outage does not grow the log."""
        last = {key: (key, value, kept) for key, value, kept in ops + self.ops}
        self.ops = list(last.values())


class Corridors(dict):
    """corridor -> its :class:`Noted` probes; ``setdefault`` (the board's way in) hands out the shared table."""

    def setdefault(self, corridor, default=None):
        found = dict.get(self, corridor)
        return found if found is not None else dict.setdefault(self, corridor, default)


class SharedBoard:
    """The board's tables shared through Redis (see the module docstring): ``cars``, ``red_since`` and ``red_ended`` for
    :class:`server.queue.QueueBoard`, :meth:`run` in the background (:meth:`sync` once)."""

    def __init__(self, pipe: RedisPipe, prefix: str, corridors: Iterable[str], every_s: float, clock: Callable[[], float]) -> None:
        names = list(corridors)
        self.pipe = pipe
        self.every_s = every_s
        self.clock = clock
        self.red_since = Noted(newer=False)
        self.red_ended = Noted(newer=True)
        self.cars = Corridors((name, Noted(newer=True)) for name in names)
        self._tables: list[tuple[Noted, Callable, Callable, Callable]] = [  # the table, its field's type, value packed, unpacked
            (self.red_since, int, _RED.pack, lambda b: _RED.unpack(b)[0]),
            (self.red_ended, int, lambda v: _ENDED.pack(*v), _ENDED.unpack),
            *((self.cars[name], bytes.decode, lambda v: _PROBE.pack(*v), _PROBE.unpack) for name in names),
        ]
        self.keys = [f"{prefix}:q:red", f"{prefix}:q:end", *(f"{prefix}:q:p:{name}" for name in names)]
        self.down: str | None = "not synced yet"
        """Why the last call failed; None while the tables are shared."""
        self.failures = 0
        self.synced_unix_s: float | None = None

    def state(self) -> str:
        """``shared``, or ``own_trips_only`` (the last call failed: ``down`` says why)."""
        return "shared" if self.down is None else "own_trips_only"

    async def sync(self) -> bool:
        """Send this worker's changes, load every worker's tables; False (the tables left as they are) when Redis
        could not be reached."""
        sent = [table[0].take() for table in self._tables]
        args: list = [repr(self.clock() - KEEP_S), int(KEY_TTL_S * 1000)]
        for k, ((noted, _, pack, _), ops) in enumerate(zip(self._tables, sent, strict=True), 1):
            rule = "n" if noted.newer else "e"
            for key, value, kept in ops:
                args += (k, str(key), rule if kept else "w", pack(value))
        try:
            reply = await self.pipe.run(_SYNC, keys=self.keys, args=args)
        except (RedisError, OSError) as exc:
            for (noted, *_), ops in zip(self._tables, sent, strict=True):
                noted.give_back(ops)
            self.failures += 1
            if self.down is None or self.down == "not synced yet":
                log.warning("queue board: Redis unreachable (%r); each worker counts its own trips only until it is back", exc)
            self.down = type(exc).__name__
            return False
        for (noted, key, _, unpack), flat in zip(self._tables, reply, strict=True):
            noted.load({key(f): unpack(v) for f, v in zip(flat[::2], flat[1::2], strict=True)})
        if self.down is not None and self.down != "not synced yet":
            log.info("queue board: shared again through Redis")
        self.down = None
        self.synced_unix_s = self.clock()
        return True

    async def run(self) -> None:
        """:meth:`sync` every ``every_s`` until cancelled."""
        while True:
            try:
                await self.sync()
            except Exception:  # never let the board's task die (a malformed reply, a bug): say so and go on
                log.exception("queue board: sync failed")
                self.failures += 1
            await asyncio.sleep(self.every_s)
