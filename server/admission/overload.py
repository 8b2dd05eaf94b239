"""Overload shedding: a worker refuses, at once and cheaply, the work it cannot do in time, instead of queueing it.

A worker is one event loop. When requests come faster than it can serve them, those it has read wait for the rest
of the loop's turn, the next turns grow, and every answer is late: at 2,000 phones sending a fix a second to 2
workers on 2 shared cores the answers took seconds and the workers' own backlog timed out their Redis calls (526 ×
503 ``store_unavailable`` while Redis sat idle; issue 30). :class:`Shedder` answers ``503 overloaded`` with
``Retry-After: 1`` (a phone sends its next fix in a second anyway) to every request but ``/health`` and
``/metrics``, and an error message to a WebSocket fix, while either

* ``max_in_flight`` requests are inside the app already (awaiting Redis or a trip's turn): the bound on the work
  in progress, whatever holds it up; or
* the event loop ran late by more than ``max_lag_s`` at two probes in a row (one every ``PROBE_S``): the requests
  read in a turn wait for the whole turn, so a late loop is a queue. Two in a row: one pause of the process (the
  machine's other jobs) is not a queue and sheds nothing.

Both signals fall as soon as the load does, so a worker serves again within a probe or two of the load falling.
Refusing costs ~1/5 of serving a fix, so a refused request frees the time for those accepted. The same idea as
Envoy's overload manager and NGINX's ``limit_conn``/``limit_req``: shed early, say when to retry, never let a queue
grow unbounded.
"""

from __future__ import annotations

import asyncio
import json

from prometheus_client.core import CounterMetricFamily, GaugeMetricFamily

PROBE_S = 0.05
"""How often the event loop's lateness is measured. [s]"""
RETRY_AFTER_S = 1
"""What a refused client is told to wait (one fix period). [s]"""
EXEMPT_PATHS = frozenset({"/health", "/metrics"})
"""Never shed: a health check must see a busy worker as alive, and monitoring must see why it sheds."""


class Shedder:
    """Admission for one worker (see the module docstring): ``refusal()`` before a request or WebSocket fix is
    served, ``in_flight`` counted by :class:`ShedMiddleware`, :meth:`watch` run as a task for the loop's lateness."""

    def __init__(self, max_in_flight: int, max_lag_s: float) -> None:
        self.max_in_flight = max_in_flight
        self.max_lag_s = max_lag_s
        self.in_flight = 0
        self.lag_s = 0.0
        """The loop's standing lateness: the smaller of the last two probes'. [s]"""
        self._last_late_s = 0.0
        self.shed = {"in_flight": 0, "loop_lag": 0}

    def observe(self, late_s: float) -> None:
        """One probe: the loop ran its timer ``late_s`` after it was due."""
        self.lag_s = min(late_s, self._last_late_s)
        self._last_late_s = late_s

    def refusal(self) -> str | None:
        """Why the next request must be refused (``in_flight`` or ``loop_lag``, counted), or None: serve it."""
        if self.in_flight >= self.max_in_flight:
            reason = "in_flight"
        elif self.lag_s > self.max_lag_s:
            reason = "loop_lag"
        else:
            return None
        self.shed[reason] += 1
        return reason

    def error_body(self, reason: str) -> dict:
        why = f"{self.in_flight} requests in progress" if reason == "in_flight" else f"its queue is {1e3 * self.lag_s:.0f} ms long"
        return {"error": "overloaded", "message": f"this server is overloaded ({why}); retry in {RETRY_AFTER_S} s", "detail": None}

    async def watch(self, probe_s: float = PROBE_S) -> None:
        """Measure the loop's lateness every ``probe_s``, for ever (cancel the task to stop)."""
        loop = asyncio.get_running_loop()
        while True:
            due = loop.time() + probe_s
            await asyncio.sleep(probe_s)
            self.observe(max(0.0, loop.time() - due))


class ShedMiddleware:
    """Pure ASGI: HTTP requests (but :data:`EXEMPT_PATHS`) pass the :class:`Shedder` or get 503 ``overloaded``
    with ``Retry-After`` without reaching the app; those served are counted in flight."""

    def __init__(self, app, shedder: Shedder) -> None:
        self.app = app
        self.shedder = shedder

    async def __call__(self, scope, receive, send) -> None:
        if scope["type"] != "http" or scope["path"] in EXEMPT_PATHS:
            await self.app(scope, receive, send)
            return
        shedder = self.shedder
        reason = shedder.refusal()
        if reason is not None:
            data = json.dumps(shedder.error_body(reason)).encode()
            headers = [(b"content-type", b"application/json"), (b"content-length", b"%d" % len(data)), (b"retry-after", b"%d" % RETRY_AFTER_S)]
            await send({"type": "http.response.start", "status": 503, "headers": headers})
            await send({"type": "http.response.body", "body": data})
            return
        shedder.in_flight += 1
        try:
            await self.app(scope, receive, send)
        finally:
            shedder.in_flight -= 1


class ShedCollector:
    """The shedder in ``/metrics`` (read when scraped: nothing on the hot path): ``ecodrive_shed_total`` by reason,
    ``ecodrive_in_flight`` and ``ecodrive_loop_lag_seconds``."""

    def __init__(self, shedder: Shedder) -> None:
        self.shedder = shedder

    def collect(self):
        s = self.shedder
        shed = CounterMetricFamily("ecodrive_shed", "requests and WebSocket fixes refused as overload (503 overloaded), by reason", labels=["reason"])
        for reason, n in s.shed.items():
            shed.add_metric([reason], n)
        yield shed
        yield GaugeMetricFamily("ecodrive_in_flight", "requests being served by this worker", value=s.in_flight)
        yield GaugeMetricFamily("ecodrive_loop_lag_seconds", "this worker's event loop lateness (the smaller of the last two probes)", value=s.lag_s)
