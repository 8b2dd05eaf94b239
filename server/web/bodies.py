"""JSON request bodies parsed as strictly as the fix route parses its own: by pydantic's JSON parser (jiter).

FastAPI parses a declared JSON body with Python's ``json.loads``, which accepts what is not JSON text in
UTF-8: a lone surrogate escape (``"\\ud800"``, a string no UTF-8 writer can then encode: every error
message quoting it was a 500 with a traceback), invalid UTF-8 bytes (decoded with ``surrogatepass``) and
UTF-16/32 bodies. :class:`JsonBodyRoute` (FastAPI's documented extension point: a custom
``APIRoute.get_route_handler`` with a custom ``Request``) parses with ``pydantic_core.from_json`` instead, the
parser ``POST .../fixes`` and the WebSocket already use: invalid Unicode, nesting deeper than 200 and numbers
of more than 4,300 digits are a 422 ``malformed_json`` that says so (``server.web.errors.json_error_message``).
A UTF-8 byte-order mark is skipped, as ``json.loads`` did. ``NaN``/``Infinity`` parse, and the models refuse
them (``allow_inf_nan=False``): 422 ``validation_error``.
"""

from __future__ import annotations

import json
import re
from typing import Any

from fastapi import Request
from fastapi.routing import APIRoute
from pydantic_core import from_json

_WHERE = re.compile(r" at line (\d+) column (\d+)$")


def parse_json(body: bytes) -> Any:
    """``body`` parsed by jiter; ``json.JSONDecodeError`` (what FastAPI turns into a 422) when it is not JSON."""
    if body.startswith(b"\xef\xbb\xbf"):
        body = body[3:]
    try:
        return from_json(body)
    except ValueError as exc:
        message = str(exc)
        try:
            body.decode("utf-8")
        except UnicodeDecodeError as bad:  # jiter may name the first token it could not read instead
            message = f"invalid UTF-8 byte 0x{body[bad.start]:02x} at byte {bad.start}: {message}"
        doc = body.decode("utf-8", "replace")
        pos = 0
        if (m := _WHERE.search(message)) is not None:  # jiter gives line and column (1-based); JSONDecodeError a position
            line, col = int(m.group(1)), int(m.group(2))
            pos = min(sum(len(text) + 1 for text in doc.split("\n")[: line - 1]) + col - 1, len(doc))
        raise json.JSONDecodeError(message, doc, pos) from None


class StrictJsonRequest(Request):
    async def json(self) -> Any:
        if not hasattr(self, "_json"):
            self._json = parse_json(await self.body())
        return self._json


class JsonBodyRoute(APIRoute):
    """An ``APIRoute`` whose JSON body is parsed by :func:`parse_json` (routes without a body are unchanged)."""

    def get_route_handler(self):
        handler = super().get_route_handler()
        if self.body_field is None:
            return handler

        async def strict_handler(request: Request):
            return await handler(StrictJsonRequest(request.scope, request.receive))

        return strict_handler
