"""Pure ASGI middleware (cheap on the hot path): request-body size limit, request metrics, and clients that
go away mid-request (one log line and status 499 in the metrics, nginx's "client closed request": not a 5xx,
as the server did nothing wrong)."""

from __future__ import annotations

import json
import logging
import time

from fastapi import HTTPException
from starlette.requests import ClientDisconnect

from server.web.metrics import Metrics
from server.web.protocol import READ_TIMED_OUT

log = logging.getLogger("server")
CLIENT_CLOSED = 499


def _too_large(limit: int) -> HTTPException:
    return HTTPException(413, f"request body larger than {limit} bytes")


class GuardMiddleware:
    """Refuses bodies over ``max_body_bytes`` with 413 (by Content-Length, or while reading a chunked body)
    and counts every HTTP request by method, route template and status."""

    def __init__(self, app, max_body_bytes: int, metrics: Metrics) -> None:
        self.app = app
        self.max_body_bytes = max_body_bytes
        self.metrics = metrics

    async def __call__(self, scope, receive, send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        limit = self.max_body_bytes
        for name, value in scope.get("headers", ()):
            if name == b"content-length":
                try:
                    too_big = int(value) > limit
                except ValueError:
                    too_big = False
                if too_big:
                    await _send_json(send, 413, {"error": "payload_too_large", "message": f"request body larger than {limit} bytes", "detail": None})
                    self._count(scope, 413, 0.0)
                    return
                break
        seen = 0
        gone = False  # the client went away before it was answered

        async def limited_receive():
            nonlocal seen, gone
            message = await receive()
            if message["type"] == "http.request":
                seen += len(message.get("body", b""))
                if seen > limit:
                    raise _too_large(limit)
            elif message["type"] == "http.disconnect" and status == 500:
                gone = True
            return message

        status = 500
        started = time.perf_counter()

        async def counting_send(message) -> None:
            nonlocal status
            if message["type"] == "http.response.start":
                status = message["status"]
            await send(message)

        try:
            await self.app(scope, limited_receive, counting_send)
        except ClientDisconnect:
            gone = True
        finally:
            if scope.get(READ_TIMED_OUT):  # answered 408 and logged by the protocol (server.web.protocol)
                status = 408
            elif gone:  # whatever the app made of it (FastAPI answers a body it could not read with 400), nobody heard it
                status = CLIENT_CLOSED
                client = scope.get("client") or ("?",)
                log.info("%s: client disconnected before its %s %s request was complete", client[0], scope.get("method", ""), scope.get("path", ""))
            self._count(scope, status, time.perf_counter() - started)

    def _count(self, scope, status: int, seconds: float) -> None:
        route = scope.get("route")
        path = getattr(route, "path", None) or "unmatched"
        self.metrics.count(self.metrics.requests, scope.get("method", ""), path, str(status))
        if seconds:
            self.metrics.request_s.observe(seconds, path)


async def _send_json(send, status: int, body: dict) -> None:
    data = json.dumps(body).encode()
    await send({"type": "http.response.start", "status": status, "headers": [(b"content-type", b"application/json"), (b"content-length", str(len(data)).encode()), (b"connection", b"close")]})
    await send({"type": "http.response.body", "body": data})
