"""Errors the API answers with, and the handlers that give every one the same JSON shape (``ErrorOut``)."""

from __future__ import annotations

import logging
import math

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError, WebSocketRequestValidationError
from starlette.websockets import WebSocket
from fastapi.responses import JSONResponse
from starlette.exceptions import HTTPException as StarletteHTTPException

log = logging.getLogger("server")


class ApiError(Exception):
    """An error with an HTTP status, a code and a sentence for the client."""

    def __init__(self, status: int, error: str, message: str, headers: dict[str, str] | None = None, detail=None) -> None:
        super().__init__(message)
        self.status, self.error, self.message, self.headers, self.detail = status, error, message, headers, detail

    def body(self) -> dict:
        return {"error": self.error, "message": self.message, "detail": self.detail}


def not_found(what: str) -> ApiError:
    return ApiError(404, "not_found", what)


def validation_summary(errors: list[dict]) -> str:
    """'body.lat_deg: Input should be less than or equal to 90; ...' (first three)."""
    parts = []
    for err in errors[:3]:
        loc = ".".join(str(p) for p in err.get("loc", ()))
        parts.append(f"{loc}: {err.get('msg', 'invalid')}" if loc else str(err.get("msg", "invalid")))
    more = f" (+{len(errors) - 3} more)" if len(errors) > 3 else ""
    return "; ".join(parts) + more


UNICODE_HINT = ("the body must be UTF-8 and every \\u escape a Unicode character (a lone surrogate \\ud800-\\udfff, "
                "unpaired, is not one)")  # fmt: skip


def json_error_message(parser_message: str) -> str:
    """The JSON parser's (jiter's) sentence, with what to do when it is about invalid Unicode."""
    lowered = parser_message.lower()
    if "surrogate" in lowered or "hex escape" in lowered or "unicode" in lowered or "utf-8" in lowered:
        return f"invalid Unicode: {parser_message}; {UNICODE_HINT}"
    return parser_message


def printable(text: str) -> str:
    """``text`` as UTF-8 can carry it: any lone surrogate (only a bug could still bring one) becomes U+FFFD."""
    try:
        text.encode("utf-8")
        return text
    except UnicodeEncodeError:
        return text.encode("utf-8", "surrogatepass").decode("utf-8", "replace")


def clean_errors(errors) -> list[dict]:
    """Validation errors without URLs or un-serialisable context (inputs such as NaN are shown as text); a JSON
    error says what the parser found (FastAPI's own says only "JSON decode error")."""
    out = []
    for err in errors:
        kind = str(err.get("type", ""))
        msg = str(err.get("msg", ""))
        if kind == "json_invalid":
            ctx = err.get("ctx") or {}
            msg = json_error_message(str(ctx["error"]) if ctx.get("error") and msg == "JSON decode error" else msg)
        item = {"loc": [p if isinstance(p, int) else printable(str(p)) for p in err.get("loc", ())], "msg": printable(msg), "type": kind}
        inp = err.get("input")
        if isinstance(inp, float) and not math.isfinite(inp):
            item["input"] = str(inp)
        elif isinstance(inp, (int, float, str, bool)) and len(str(inp)) < 100:
            item["input"] = printable(inp) if isinstance(inp, str) else inp
        out.append(item)
    return out


class ErrorResponse(JSONResponse):
    """The JSON of an error: rendering it never fails (a handler that raised would turn a 4xx into a 500)."""

    def render(self, content) -> bytes:
        try:
            return super().render(content)
        except (ValueError, TypeError):  # not UTF-8-encodable text, a NaN: the code and sentence alone, made safe
            safe = {"error": str(content.get("error", "error")), "message": printable(str(content.get("message", ""))), "detail": None}
            return super().render(safe)


def install_handlers(app: FastAPI) -> None:
    @app.exception_handler(ApiError)
    async def _api_error(request: Request, exc: ApiError) -> JSONResponse:
        return ErrorResponse(exc.body(), status_code=exc.status, headers=exc.headers)

    @app.exception_handler(RequestValidationError)
    async def _validation(request: Request, exc: RequestValidationError) -> JSONResponse:
        errors = clean_errors(exc.errors())
        if any(e["type"] == "json_invalid" for e in errors):
            return ErrorResponse({"error": "malformed_json", "message": "body is not valid JSON: " + validation_summary(errors), "detail": errors}, status_code=422)
        return ErrorResponse({"error": "validation_error", "message": validation_summary(errors), "detail": errors}, status_code=422)

    @app.exception_handler(WebSocketRequestValidationError)
    async def _ws_validation(websocket: WebSocket, exc: WebSocketRequestValidationError) -> None:
        """A handshake FastAPI could not validate (a path parameter too long) is refused as every other one is:
        told why, closed with 4000 + status (FastAPI's default closes it with 1008 and the errors as the reason,
        which uvicorn answers with a bare HTTP 403)."""
        errors = clean_errors(exc.errors())
        body = {"error": "validation_error", "message": validation_summary(errors), "detail": errors, "status": 422}
        await websocket.accept()
        await websocket.send_text(ErrorResponse(body).body.decode())
        await websocket.close(code=4422, reason="validation_error")

    @app.exception_handler(StarletteHTTPException)
    async def _http(request: Request, exc: StarletteHTTPException) -> JSONResponse:
        code = {404: "not_found", 405: "method_not_allowed", 413: "payload_too_large"}.get(exc.status_code, "http_error")
        return ErrorResponse({"error": code, "message": str(exc.detail), "detail": None}, status_code=exc.status_code, headers=getattr(exc, "headers", None))

    @app.exception_handler(Exception)
    async def _unexpected(request: Request, exc: Exception) -> JSONResponse:  # pragma: no cover - a bug
        log.exception("unhandled error on %s %s", request.method, request.url.path)
        return ErrorResponse({"error": "internal_error", "message": "internal error (logged)", "detail": None}, status_code=500)
