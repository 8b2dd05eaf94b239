"""SPaT client: subscribe to a remote feed, keep the latest state per intersection, never serve stale data.

:class:`SpatClient` runs one background task on the caller's event loop. It connects to the feed's
``/spat/stream`` WebSocket, validates every message intersection by intersection (a malformed one is
logged and counted, the others are kept), and stores the newest state of each intersection in a
:class:`~spat_feed.transport.store.SpatStore` (its own, or one shared with other sources: ``store=``). When the connection drops, or goes silent for
``silence_timeout_s``, it reconnects with exponential backoff and jitter. Readers ask
``fresh(intersection_id)``, which returns ``None`` once the data is older than ``stale_after_s``
(default 2 s), whatever the connection is doing; ``reading(...)`` returns it with its age and a
``fresh`` flag.

:func:`fetch_spat` is the one-shot HTTP counterpart (``GET /spat``).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import random
import time
from dataclasses import dataclass
from typing import Any
from urllib.parse import urlencode, urlsplit, urlunsplit

import httpx
import websockets
from websockets.asyncio.client import connect

from spat_feed.timing.messages import IntersectionState, ParsedSpat, parse_spat_text
from spat_feed.transport.store import DEFAULT_STALE_AFTER_S, MAX_SPAT_BYTES, Clock, SpatReading, SpatStore, TimeRules

log = logging.getLogger("spat_feed.transport.client")


@dataclass
class ClientStats:
    """Counters since the client started."""

    messages: int = 0  # texts received
    intersections: int = 0  # intersection states accepted
    rejected: int = 0  # intersection states or whole texts rejected
    connects: int = 0
    disconnects: int = 0


def stream_url(base_url: str, params: dict[str, Any] | None = None) -> str:
    """``http://host:port`` (or ``ws://...``) plus scenario params -> ``ws://host:port/spat/stream?...``.

    Examples
    --------
    >>> stream_url("http://127.0.0.1:8765", {"timing": "15_15", "entry_unix_s": None})
    'ws://127.0.0.1:8765/spat/stream?timing=15_15'
    """
    parts = urlsplit(base_url)
    scheme = {"http": "ws", "https": "wss"}.get(parts.scheme, parts.scheme)
    path = parts.path.rstrip("/")
    if not path.endswith("/stream"):  # /spat/stream (a scenario) or /spat/intersections/stream (every intersection)
        path += "/spat/stream"
    query = urlencode({k: v for k, v in (params or {}).items() if v is not None})
    return urlunsplit((scheme, parts.netloc, path, query, ""))


def backoff_s(attempt: int, initial_s: float, max_s: float, rng: random.Random) -> float:
    """Delay before reconnect ``attempt`` (0-based): ``min(max, initial 2^attempt)`` times a jitter in [0.5, 1]. [s]"""
    return min(max_s, initial_s * 2.0**attempt) * (0.5 + 0.5 * rng.random())


class SpatClient:
    """Latest SPaT per intersection from a remote feed, stale-safe. Use as ``async with SpatClient(url) as c``.

    Parameters
    ----------
    base_url : str
        The feed, ``http://host:port`` or a full ``ws://.../spat/stream`` URL.
    params : dict, optional
        Scenario query parameters (``corridor``, ``timing``, ``entry_unix_s``, ...).
    stale_after_s : float
        Readings older than this are not fresh (see :mod:`spat_feed.transport.store` for "older"). [s]
    clock : callable
        Unix seconds; ``time.time`` by default.
    backoff_initial_s, backoff_max_s : float
        Reconnect delays: doubling from the first to the cap, with jitter. [s]
    silence_timeout_s : float, optional
        Reconnect when a connected feed sends nothing for this long; default ``max(5, 3 stale_after_s)``. [s]
    """

    def __init__(
        self,
        base_url: str,
        params: dict[str, Any] | None = None,
        *,
        stale_after_s: float = DEFAULT_STALE_AFTER_S,
        clock: Clock = time.time,
        backoff_initial_s: float = 0.2,
        backoff_max_s: float = 5.0,
        silence_timeout_s: float | None = None,
        open_timeout_s: float = 5.0,
        seed: int | None = None,
        store: SpatStore | None = None,
    ) -> None:
        if not 0 < backoff_initial_s <= backoff_max_s:
            raise ValueError("need 0 < backoff_initial_s <= backoff_max_s")
        self.url = stream_url(base_url, params)
        self.store = store if store is not None else SpatStore(TimeRules(stale_after_s), clock)
        self.stats = ClientStats()
        self.connected = False
        self._backoff = (backoff_initial_s, backoff_max_s)
        self._silence_s = silence_timeout_s if silence_timeout_s is not None else max(5.0, 3.0 * stale_after_s)
        self._open_timeout_s = open_timeout_s
        self._rng = random.Random(seed)
        self._task: asyncio.Task | None = None
        self._update = asyncio.Event()

    # reading ------------------------------------------------------------------------------------

    def reading(self, intersection_id: int) -> SpatReading | None:
        """The latest state of an intersection with its age and ``fresh`` flag; ``None`` if never seen."""
        return self.store.reading(intersection_id)

    def fresh(self, intersection_id: int) -> IntersectionState | None:
        """The latest state if it is fresh, else ``None``. The advisor should use this."""
        return self.store.fresh(intersection_id)

    def readings(self) -> dict[int, SpatReading]:
        return self.store.readings()

    async def wait_fresh(self, intersection_id: int, timeout_s: float) -> IntersectionState:
        """Wait until the intersection has fresh data; ``TimeoutError`` after ``timeout_s``."""
        loop = asyncio.get_running_loop()
        deadline_s = loop.time() + timeout_s
        while (state := self.fresh(intersection_id)) is None:
            if loop.time() >= deadline_s:
                raise TimeoutError(f"no fresh SPaT for intersection {intersection_id} within {timeout_s} s")
            self._update.clear()
            with contextlib.suppress(asyncio.TimeoutError):
                await asyncio.wait_for(self._update.wait(), 0.05)
        return state

    # lifecycle ----------------------------------------------------------------------------------

    async def start(self) -> None:
        if self._task is None:
            self._task = asyncio.create_task(self._run(), name=f"spat-client {self.url}")

    async def stop(self) -> None:
        if self._task is not None:
            self._task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._task
            self._task = None
        self.connected = False

    async def __aenter__(self) -> SpatClient:
        await self.start()
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.stop()

    # internals ----------------------------------------------------------------------------------

    def handle_text(self, text: str | bytes) -> ParsedSpat:
        """Validate one received text and store its good intersections (public for tests)."""
        self.stats.messages += 1
        if len(text) > MAX_SPAT_BYTES:  # never parsed (the WebSocket's max_size closes the stream before, 1009)
            self.stats.rejected += 1
            self.store.reject("too_large", None, f"{len(text)} bytes")
            return ParsedSpat(None, (), (f"too large: {len(text)} > {MAX_SPAT_BYTES} bytes",))
        parsed = parse_spat_text(text)
        for err in parsed.errors:
            self.stats.rejected += 1
            self.store.reject("malformed", None, err)
            log.warning("rejected SPaT data from %s: %s", self.url, err)
        if parsed.intersections:
            stored = self.store.offer_many(parsed.intersections)
            self.stats.intersections += stored
            self.stats.rejected += len(parsed.intersections) - stored
            self._update.set()
        return parsed

    async def _run(self) -> None:
        attempt = 0
        while True:
            try:
                async with connect(self.url, open_timeout=self._open_timeout_s, max_size=MAX_SPAT_BYTES, compression=None) as ws:
                    self.connected = True
                    self.stats.connects += 1
                    log.info("connected to %s", self.url)
                    while True:
                        text = await asyncio.wait_for(ws.recv(), self._silence_s)
                        if self.handle_text(text).intersections:
                            attempt = 0
            except asyncio.CancelledError:
                raise
            except websockets.exceptions.ConnectionClosed as exc:
                if exc.sent is not None and exc.sent.code == 1009:  # we closed it: a message over max_size, unread
                    self.stats.rejected += 1
                    self.store.reject("too_large", None, self.url)
                    log.warning("feed %s sent a message over %d bytes: dropped, reconnecting", self.url, MAX_SPAT_BYTES)
                else:
                    log.info("feed %s closed: %r", self.url, exc)
            except (OSError, asyncio.TimeoutError, websockets.exceptions.WebSocketException) as exc:
                log.info("feed %s unavailable: %r", self.url, exc)
            except Exception:  # keep reconnecting whatever went wrong, but say what it was
                log.exception("SPaT client error on %s", self.url)
            if self.connected:
                self.stats.disconnects += 1
            self.connected = False
            delay_s = backoff_s(attempt, *self._backoff, self._rng)
            attempt += 1
            await asyncio.sleep(delay_s)


def fetch_spat(base_url: str, params: dict[str, Any] | None = None, timeout_s: float = 5.0) -> ParsedSpat:
    """One ``GET /spat`` snapshot, validated like a streamed message (a body over ``MAX_SPAT_BYTES``: not read further,
    one ``too large`` error). Raises ``httpx.HTTPError`` on failure."""
    url = base_url.rstrip("/") + "/spat"
    with httpx.stream("GET", url, params={k: v for k, v in (params or {}).items() if v is not None}, timeout=timeout_s) as response:
        response.raise_for_status()
        body = bytearray()
        for chunk in response.iter_bytes():
            body += chunk
            if len(body) > MAX_SPAT_BYTES:
                return ParsedSpat(None, (), (f"too large: over {MAX_SPAT_BYTES} bytes",))
    return parse_spat_text(bytes(body))
