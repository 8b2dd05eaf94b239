"""One pipelined connection to Redis per worker: the trip store's client (``server.storage.store.RedisTrips``).

Every call of the worker goes over the same connection. A command made while nothing else is in flight leaves at
once (the common case at a phone's fix a second: no extra turn of the event loop, and its poll, before the write);
the commands made while others are in flight, during one turn of the event loop, leave together at its end, in
one write; Redis answers in order, so the replies resolve the calls in the order they were sent (hiredis parses
them). Under 200 concurrent trips redis-py's pool cost the worker about 130 us of CPU per
call (a connection per call in flight, a write per command, health checks and retries); this costs about 12 us,
and Redis reads many commands per read too. Redis runs one command at a time, so one connection loses nothing.

Failures: a call made while the connection is down reconnects first (one attempt, bounded by ``timeout_s``);
when the connection is lost every call in flight fails with ``redis.exceptions.ConnectionError``; a reply
later than ``timeout_s`` after the command was written drops the connection and fails every call in flight with ``redis.exceptions.TimeoutError``. The
caller decides what a failure means (the trip store answers 503 + ``Retry-After``).
"""

from __future__ import annotations

import asyncio
import functools
import hashlib
from collections import deque

import hiredis
from redis.asyncio.connection import parse_url
from redis.exceptions import BusyLoadingError, ConnectionError, NoScriptError, ResponseError
from redis.exceptions import TimeoutError as ReplyTimeout


class Script:
    """A Lua script, called by its SHA-1 (``EVALSHA``; loaded once when Redis does not know it yet)."""

    def __init__(self, source: str) -> None:
        self.source = source
        self.sha = hashlib.sha1(source.encode()).hexdigest()

    def head(self, keys: list, args: list) -> tuple[int, bytes]:
        """This script's ``EVALSHA`` for ``keys`` and its first ``args`` packed once, for calls that send them again and
        again (a trip's fixes): :meth:`command` adds the rest. (How many arguments, the packed ones without the count.)"""
        packed = hiredis.pack_command(("EVALSHA", self.sha, len(keys), *keys, *args))
        return 3 + len(keys) + len(args), packed[packed.index(b"\r\n") + 2 :]

    @staticmethod
    def command(head: tuple[int, bytes], tail: tuple[bytes, ...]) -> bytes:
        """The whole command: :meth:`head`'s and then the arguments ``tail``, already bytes (as ``hiredis.pack_command``
        writes them: numbers as their ``repr``), for :meth:`RedisPipe.run_packed`."""
        return b"".join([b"*%d\r\n" % (head[0] + len(tail)), head[1], *[b"$%d\r\n%b\r\n" % (len(a), a) for a in tail]])


class _Connection(asyncio.Protocol):
    """The socket: a request written at once when none is in flight, else queued and written once per loop turn
    (with ``window_s``: always queued, written ``window_s`` after the first one waiting); replies matched in order."""

    def __init__(self, window_s: float = 0.0) -> None:
        self.window_s = window_s  # commands wait this long to leave together (0: at once when alone, else at the end of the loop turn)
        self.loop = asyncio.get_running_loop()
        self.transport: asyncio.Transport | None = None
        self.reader = hiredis.Reader()
        self.pending: deque[list] = deque()  # [call, loop time when written (0.0: not yet)], in order
        self.out: list[bytes] = []
        self.unsent: list[list] = []  # the entries of pending whose commands are in out
        self.failure: Exception | None = None  # why the connection is unusable
        self._flush = None

    def connection_made(self, transport) -> None:
        self.transport = transport

    def data_received(self, data: bytes) -> None:
        if self.failure is not None:
            return
        self.reader.feed(data)
        try:
            while (reply := self.reader.gets()) is not False:
                future = self.pending.popleft()[0]
                if not future.done():  # a cancelled caller: its reply is dropped, the order kept
                    future.set_result(reply)
        except (hiredis.ProtocolError, IndexError) as exc:
            self.fail(ConnectionError(f"unexpected data from Redis ({exc!r})"))

    def connection_lost(self, exc: Exception | None) -> None:
        self.fail(self.failure or ConnectionError(f"connection to Redis lost ({exc!r})" if exc else "connection to Redis closed"))

    def fail(self, failure: Exception) -> None:
        """The connection is unusable: every call in flight fails with ``failure``."""
        self.failure = self.failure or failure
        while self.pending:
            future = self.pending.popleft()[0]
            if not future.done():
                future.set_exception(self.failure)
        if self.transport is not None:
            self.transport.abort()

    def send(self, packed: bytes) -> asyncio.Future:
        loop = self.loop
        future = loop.create_future()
        if self.failure is not None:
            future.set_exception(self.failure)
            return future
        if not self.pending and not self.window_s:  # alone: written now (nothing queued can be overtaken)
            self.pending.append([future, loop.time()])
            self.transport.write(packed)
            return future
        entry = [future, 0.0]
        self.pending.append(entry)
        self.unsent.append(entry)
        self.out.append(packed)
        if self._flush is None:
            self._flush = loop.call_later(self.window_s, self.flush) if self.window_s else loop.call_soon(self.flush)
        return future

    def flush(self) -> None:
        self._flush = None
        if self.out and self.failure is None:
            self.transport.write(b"".join(self.out))
            now = self.loop.time()
            for entry in self.unsent:
                entry[1] = now
        self.out.clear()
        self.unsent.clear()


class RedisPipe:
    """A client for ``url`` (``redis://[[user]:password@]host[:port][/db]``, ``rediss://`` with TLS,
    ``unix:///path.sock[?db=N]``): :meth:`call` a command, :meth:`run` a :class:`Script`."""

    def __init__(self, url: str, timeout_s: float, write_window_s: float = 0.0) -> None:
        self.options = parse_url(url)
        self.tls = url.startswith("rediss://")
        self.timeout_s = timeout_s
        self.write_window_s = write_window_s
        self._conn: _Connection | None = None
        self._connecting: asyncio.Task | None = None
        self._watch: asyncio.TimerHandle | None = None
        self._loading: dict[str, asyncio.Future] = {}  # script SHA-1 -> its SCRIPT LOAD

    async def _connect(self) -> _Connection:
        loop = asyncio.get_running_loop()
        o = self.options
        conn = None
        try:
            async with asyncio.timeout(self.timeout_s):
                made = functools.partial(_Connection, self.write_window_s)
                if "path" in o:
                    _, conn = await loop.create_unix_connection(made, o["path"])
                else:
                    _, conn = await loop.create_connection(made, o.get("host", "localhost"), o.get("port", 6379), ssl=self.tls or None)
                if o.get("password"):
                    await self._reply(conn.send(hiredis.pack_command(("AUTH", *([o["username"]] if o.get("username") else []), o["password"]))))
                if o.get("db"):
                    await self._reply(conn.send(hiredis.pack_command(("SELECT", o["db"]))))
        except BaseException as exc:
            if conn is not None:
                conn.fail(ConnectionError("connection set-up failed"))
            if isinstance(exc, ResponseError):  # a wrong password or database: unreachable as configured
                raise ConnectionError(f"Redis refused the connection's set-up: {exc}") from None
            raise
        self._conn = conn
        return conn

    async def _connection(self) -> _Connection:
        conn = self._conn
        if conn is not None and conn.failure is None:
            return conn
        if self._connecting is None or self._connecting.done():  # one attempt at a time, shared by the callers waiting
            self._connecting = asyncio.ensure_future(self._connect())
        try:
            return await asyncio.shield(self._connecting)
        except (OSError, TimeoutError) as exc:  # refused, unreachable, or no answer within timeout_s
            raise ConnectionError(f"cannot connect to Redis ({exc!r})") from None

    @staticmethod
    def _raise(reply: hiredis.ReplyError):
        message = str(reply)
        if message.startswith("NOSCRIPT"):
            raise NoScriptError(message)
        if message.startswith("LOADING"):
            raise BusyLoadingError(message)
        raise ResponseError(message)

    @classmethod
    async def _reply(cls, future: asyncio.Future):
        reply = await future
        if isinstance(reply, hiredis.ReplyError):
            cls._raise(reply)
        return reply

    async def call(self, *args):
        """One command's reply (bytes, int, None, lists of those); Redis's error replies raised."""
        return await self._call(hiredis.pack_command(args))

    async def _call(self, packed: bytes):
        conn = self._conn
        reply = await self._send(conn if conn is not None and conn.failure is None else await self._connection(), packed)
        if isinstance(reply, hiredis.ReplyError):
            self._raise(reply)
        return reply

    def _send(self, conn: _Connection, packed: bytes) -> asyncio.Future:
        """The command ``packed`` queued on ``conn``: the future of its reply (a plain function, so that a call is one
        coroutine: a fix's save is the hot path, issue 30)."""
        future = conn.send(packed)
        if self._watch is None:
            self._watch = conn.loop.call_later(self.timeout_s, self._check)
        return future

    def _check(self) -> None:
        """Drop the connection when its oldest call in flight has waited ``timeout_s`` since it was written to the
        socket; else look again when it will have."""
        self._watch = None
        conn = self._conn
        if conn is None or conn.failure is not None or not conn.pending:
            return
        loop = asyncio.get_running_loop()
        written = conn.pending[0][1]
        # from when the command was written, not asked for: a busy worker's own queue (the calls of a long loop turn
        # wait for its end to be written) is not Redis being slow (issue 30: 526 "store unreachable", Redis idle)
        waited = loop.time() - written if written else 0.0
        if waited >= self.timeout_s:
            conn.fail(ReplyTimeout(f"no reply from Redis within {self.timeout_s:g} s"))
            return
        self._watch = loop.call_later(self.timeout_s - waited, self._check)

    async def run(self, script: Script, keys: list, args: list):
        """``script``'s reply for ``keys`` and ``args`` (``EVALSHA``; ``EVAL`` the first time Redis lacks it)."""
        return await self.run_packed(script, hiredis.pack_command(("EVALSHA", script.sha, len(keys), *keys, *args)))

    async def run_packed(self, script: Script, command: bytes):
        """:meth:`run` of the ``EVALSHA`` of ``script`` already packed (:meth:`Script.command`)."""
        conn = self._conn
        reply = await self._send(conn if conn is not None and conn.failure is None else await self._connection(), command)
        if not isinstance(reply, hiredis.ReplyError):
            return reply
        try:
            self._raise(reply)
        except NoScriptError:  # the calls of a burst all fail at once: one SCRIPT LOAD serves them all
            loading = self._loading.get(script.sha)
            if loading is None or loading.done():
                loading = self._loading[script.sha] = asyncio.ensure_future(self.call("SCRIPT", "LOAD", script.source))
            await asyncio.shield(loading)
            return await self._call(command)

    async def close(self) -> None:
        if self._watch is not None:
            self._watch.cancel()
            self._watch = None
        if self._conn is not None and self._conn.transport is not None:
            self._conn.transport.close()
        self._conn = None
