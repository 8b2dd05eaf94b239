"""Connection limits uvicorn itself does not enforce: a read deadline and connection caps.

uvicorn's ``timeout_keep_alive`` only runs *between* requests: a connection that sends nothing, half a header
or a body that never ends stays open for ever (measured: 1,000 half-sent requests held 40 s and more, and
with a 1,024-file limit ``/health`` then failed every probe). No ASGI middleware can help, as the app is
only called once the headers are complete. So :func:`protocol_class` subclasses uvicorn's httptools
protocol (the documented ``http=`` class of ``uvicorn.run``):

* **read deadline** ``read_timeout_s``: from a request's first byte (or the connection's opening) until its
  body is complete; when it passes, ``408 Request Timeout`` (if nothing was answered yet) and close;
* **connection caps**: at most ``max_connections`` open in all (default: the file limit less a reserve)
  and ``max_connections_per_client`` per client address; beyond, ``503`` with ``Retry-After`` and close,
  at once, so the file descriptor is freed.

Each response leaves in one write (:class:`_OneWrite`: uvicorn writes its head and body apart).

A connection upgraded to a WebSocket leaves the per-address count here; WebSocket streams have their own caps
(``server.routes.stream``).
"""

from __future__ import annotations

import json
import logging
import resource

from uvicorn.protocols.http.httptools_impl import HttpToolsProtocol

log = logging.getLogger("server")

READ_TIMED_OUT = "ecodrive.read_timed_out"
"""Scope key set on a request the read deadline cut off (answered 408 by the protocol itself)."""

FD_RESERVE = 64
"""File descriptors kept free for the process itself (logs, tables, the SPaT feed) when capping connections."""


def file_limit(raise_soft: bool = True) -> int:
    """The process's open-file limit, first raised to the hard limit (as servers usually do)."""
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    if raise_soft and hard != resource.RLIM_INFINITY and soft < hard:
        try:
            resource.setrlimit(resource.RLIMIT_NOFILE, (hard, hard))
            soft = hard
        except (ValueError, OSError):
            pass
    return soft if soft != resource.RLIM_INFINITY else 1 << 20


def _raw_response(status: int, reason: str, body: dict, extra: str = "") -> bytes:
    data = json.dumps(body).encode()
    head = (f"HTTP/1.1 {status} {reason}\r\ncontent-type: application/json\r\ncontent-length: {len(data)}\r\n"
            f"connection: close\r\n{extra}\r\n")  # fmt: skip
    return head.encode() + data


class _OneWrite:
    """A response's view of its connection: the status line and headers are held back and written with the first
    part of the body, one ``send()`` for a whole small response (uvicorn writes them apart: two system calls per
    answer, a fix's included). A 100 Continue is never held (such a request is not given this view)."""

    __slots__ = ("transport", "head")

    def __init__(self, transport) -> None:
        self.transport = transport
        self.head: bytes | None = None

    def write(self, data: bytes) -> None:
        if self.head is None:
            self.head = data
            return
        if self.head:
            data, self.head = self.head + data, b""
        self.transport.write(data)

    def close(self) -> None:
        if self.head:
            self.transport.write(self.head)
            self.head = b""
        self.transport.close()

    def __getattr__(self, name: str):
        return getattr(self.transport, name)


def protocol_class(read_timeout_s: float, max_connections: int, max_per_client: int) -> type[HttpToolsProtocol]:
    """An ``HttpToolsProtocol`` with the limits above (``max_connections`` 0: from the file limit)."""
    limit = max_connections or max(file_limit() - FD_RESERVE, 16)

    class GuardedHttpToolsProtocol(HttpToolsProtocol):
        _deadline = None  # the connection's timer (a loop TimerHandle), kept across requests
        _due = None  # when the request being read must be complete (loop time), None between requests
        _counted = False

        def connection_made(self, transport) -> None:  # type: ignore[override]
            super().connection_made(transport)
            per_client = self.server_state.__dict__.setdefault("eco_per_client", {})
            host = self.client[0] if self.client else "unknown"
            if len(self.connections) > limit or (max_per_client and per_client.get(host, 0) >= max_per_client):
                which = "the service" if len(self.connections) > limit else "this client address"
                body = {"error": "too_many_connections", "message": f"{which} has too many open connections; retry later", "detail": None}
                transport.write(_raw_response(503, "Service Unavailable", body, "retry-after: 1\r\n"))
                transport.close()
                return
            per_client[host] = per_client.get(host, 0) + 1
            self._counted = True
            self._arm()

        def _arm(self) -> None:
            # A timer per request (call_later, then cancel) cost ~6 us of a fix's CPU (issue 30): the connection keeps
            # one, set for the first request's deadline; when it fires, a later request's deadline (_due) that has not
            # come yet sets it again for the rest, so a kept-alive phone re-arms it once per read_timeout_s, not per request.
            self._due = self.loop.time() + read_timeout_s
            if self._deadline is None:
                self._deadline = self.loop.call_at(self._due, self._on_timer)

        def _disarm(self) -> None:
            self._due = None

        def _drop_timer(self) -> None:
            self._due = None
            if self._deadline is not None:
                self._deadline.cancel()
                self._deadline = None

        def _on_timer(self) -> None:
            self._deadline = None
            if self._due is None:  # between requests: the next one sets a timer again
                return
            if self._due - self.loop.time() > 1e-3:  # (a timer may fire a clock tick early: that is the deadline)
                self._deadline = self.loop.call_at(self._due, self._on_timer)
                return
            self._read_timed_out()

        def _uncount(self) -> None:
            if self._counted:
                self._counted = False
                per_client = self.server_state.__dict__.get("eco_per_client", {})
                host = self.client[0] if self.client else "unknown"
                left = per_client.get(host, 1) - 1
                if left > 0:
                    per_client[host] = left
                else:
                    per_client.pop(host, None)

        def data_received(self, data: bytes) -> None:
            if self._due is None and self._counted and (self.cycle is None or self.cycle.response_complete):
                self._arm()  # a new request begins on a kept-alive connection
            super().data_received(data)

        def on_headers_complete(self) -> None:
            super().on_headers_complete()
            cycle = self.cycle
            if cycle is not None and cycle.transport is self.transport and not self.expect_100_continue and not cycle.response_started:
                cycle.transport = _OneWrite(self.transport)

        def on_message_complete(self) -> None:
            self._disarm()
            super().on_message_complete()

        def handle_websocket_upgrade(self) -> None:
            self._drop_timer()
            self._uncount()
            super().handle_websocket_upgrade()

        def connection_lost(self, exc) -> None:
            self._drop_timer()
            self._uncount()
            super().connection_lost(exc)

        def _read_timed_out(self) -> None:
            self._due = None
            if self.transport.is_closing():
                return
            log.info("%s: request not received within %g s: closed", self.client[0] if self.client else "?", read_timeout_s)
            # a cycle whose response is complete is the previous request's on a kept-alive connection: the one being
            # read has no cycle yet (its headers are not complete) and nothing has answered it
            cycle = None if self.cycle is None or self.cycle.response_complete else self.cycle
            if cycle is None or not cycle.response_started:
                body = {"error": "request_timeout", "message": f"the request was not received within {read_timeout_s:g} s", "detail": None}
                self.transport.write(_raw_response(408, "Request Timeout", body))
            if cycle is not None:
                # The app, if waiting for the body, hears a disconnect, and what it sends is dropped: the 408 is
                # the answer (before, its 400 went to the closed transport: a 500 and a traceback per timeout).
                # The scope says why, so the request is counted as 408 (server.web.middleware), not as a 499.
                cycle.scope[READ_TIMED_OUT] = True
                cycle.disconnected = True
                cycle.message_event.set()
            self.transport.close()

    return GuardedHttpToolsProtocol
