"""The phone app at ``/app``: static files shipped in the package (``server/static``), and the demo drive's trace.

No build step, no CDN: plain ES modules and CSS, served from the same origin as the API (so no CORS).
The demo drive plays the shipped field-test trace (``replay/data/field_test_advised.csv``, package data of
``replay``) through the same trip, socket and rendering as a real drive (docs/APP.md).
"""

from __future__ import annotations

from importlib.resources import files
from pathlib import Path

from fastapi import APIRouter, Response
from fastapi.responses import FileResponse, RedirectResponse
from starlette.routing import Match, Mount
from starlette.staticfiles import StaticFiles

STATIC_DIR = Path(__file__).resolve().parents[1] / "static"
DEMO_TRACE = Path(str(files("replay") / "data" / "field_test_advised.csv"))
"""The demo drive: a closed-loop advised drive on ``paper_s400`` with 1 Hz GPS noise (replay/data/README.md).
Its header lines carry corridor, timing preset, zone-entry instant and vehicle."""

router = APIRouter(tags=["app"])


class AppFiles(StaticFiles):
    """Static files that the browser revalidates on every load (ETag -> 304), so an upgraded service never
    runs with yesterday's JavaScript."""

    async def get_response(self, path: str, scope) -> Response:
        response = await super().get_response(path, scope)
        response.headers["Cache-Control"] = "no-cache"
        return response


@router.get("/app", include_in_schema=False)
async def app_root() -> RedirectResponse:
    """``/app`` -> ``/app/`` (relative, so a reverse proxy's path prefix is kept)."""
    return RedirectResponse("app/", status_code=307)


@router.get("/app/demo/field_test_advised.csv", include_in_schema=False)
async def demo_trace() -> FileResponse:
    return FileResponse(DEMO_TRACE, media_type="text/csv; charset=utf-8", headers={"Cache-Control": "no-cache"})


class AppMount(Mount):
    """The files' mount, named in the request metrics as ``/app`` (a plain Mount leaves them "unmatched")."""

    def matches(self, scope) -> tuple[Match, dict]:
        match, child_scope = super().matches(scope)
        if match is not Match.NONE:
            child_scope["route"] = self
        return match, child_scope


router.routes.append(AppMount("/app", app=AppFiles(directory=STATIC_DIR, html=True), name="app"))
