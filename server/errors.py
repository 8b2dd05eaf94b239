"""Errors the API answers with, and the handlers that give every one the same JSON shape (``ErrorOut``)."""

from __future__ import annotations

import logging
import math

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
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


def clean_errors(errors) -> list[dict]:
    """Validation errors without URLs or un-serialisable context (inputs such as NaN are shown as text)."""
    out = []
    for err in errors:
        item = {"loc": list(err.get("loc", ())), "msg": str(err.get("msg", "")), "type": str(err.get("type", ""))}
        inp = err.get("input")
        if isinstance(inp, float) and not math.isfinite(inp):
            item["input"] = str(inp)
        elif isinstance(inp, (int, float, str, bool)) and len(str(inp)) < 100:
            item["input"] = inp
        out.append(item)
    return out


def install_handlers(app: FastAPI) -> None:
    @app.exception_handler(ApiError)
    async def _api_error(request: Request, exc: ApiError) -> JSONResponse:
        return JSONResponse(exc.body(), status_code=exc.status, headers=exc.headers)

    @app.exception_handler(RequestValidationError)
    async def _validation(request: Request, exc: RequestValidationError) -> JSONResponse:
        errors = clean_errors(exc.errors())
        if any(e["type"] == "json_invalid" for e in errors):
            return JSONResponse({"error": "malformed_json", "message": "body is not valid JSON: " + validation_summary(errors), "detail": errors}, status_code=422)
        return JSONResponse({"error": "validation_error", "message": validation_summary(errors), "detail": errors}, status_code=422)

    @app.exception_handler(StarletteHTTPException)
    async def _http(request: Request, exc: StarletteHTTPException) -> JSONResponse:
        code = {404: "not_found", 405: "method_not_allowed", 413: "payload_too_large"}.get(exc.status_code, "http_error")
        return JSONResponse({"error": code, "message": str(exc.detail), "detail": None}, status_code=exc.status_code, headers=getattr(exc, "headers", None))

    @app.exception_handler(Exception)
    async def _unexpected(request: Request, exc: Exception) -> JSONResponse:  # pragma: no cover - a bug
        log.exception("unhandled error on %s %s", request.method, request.url.path)
        return JSONResponse({"error": "internal_error", "message": "internal error (logged)", "detail": None}, status_code=500)
