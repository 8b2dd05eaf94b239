"""The API's own documentation: the OpenAPI document with its security schemes and live examples, and the
Swagger UI and ReDoc pages served from the service itself (their assets ship in the ``fastapi-offline``
package: nothing is fetched from a CDN, so the pages work offline).

Access is configurable (``ECO_DOCS_ACCESS``): public (default), an API key needed when keys are set, or off.
"""

from __future__ import annotations

import copy
import time
from pathlib import Path

import fastapi_offline
from fastapi import FastAPI, Request
from fastapi.openapi.docs import get_redoc_html, get_swagger_ui_html
from fastapi.responses import HTMLResponse, JSONResponse
from fastapi.staticfiles import StaticFiles

from server.deps import check_api_key

ASSETS = Path(fastapi_offline.__file__).parent / "static"
"""swagger-ui-bundle.js, swagger-ui.css (Apache-2.0), redoc.standalone.js (MIT), favicon.png: the fastapi-offline
package (MIT) ships them."""
ASSETS_URL = "/docs/assets"

SECURITY_SCHEMES = {
    "TripToken": {"type": "http", "scheme": "bearer", "description": "the trip's token from POST /v1/trips (this trip only)"},
    "ApiKey": {"type": "apiKey", "in": "header", "name": "X-API-Key",
               "description": "an operator key (ECO_API_KEYS) to create trips; 'Authorization: Bearer <key>' works too"},
}  # fmt: skip


def _security(schema: dict, api_keys: bool, metrics_key: bool) -> None:
    schema.setdefault("components", {})["securitySchemes"] = SECURITY_SCHEMES
    for path, ops in schema.get("paths", {}).items():
        for method, op in ops.items():
            if path == "/v1/trips" and method == "post":
                op["security"] = [{"ApiKey": []}] if api_keys else [{"ApiKey": []}, {}]
            elif path.startswith("/v1/trips/{trip_id}"):
                op["security"] = [{"TripToken": []}]
            elif path == "/metrics" and metrics_key:
                op["security"] = [{"ApiKey": []}]


def install_docs(app: FastAPI, default_lat_lon: tuple[float, float], default_corridor: str) -> None:
    """Routes ``/openapi.json``, ``/docs``, ``/redoc`` and the assets, after ``app``'s other routes."""
    settings = app.state.settings
    if settings.docs_access == "off":
        return
    cached: dict = {}

    def check(request: Request) -> None:
        if settings.docs_access == "api_key":
            check_api_key(request, "the API documentation")

    def document() -> dict:
        if not cached:
            schema = copy.deepcopy(app.openapi())
            _security(schema, bool(settings.api_keys), settings.metrics_access == "api_key" and bool(settings.api_keys))
            create = schema["paths"]["/v1/trips"]["post"]["requestBody"]["content"]["application/json"]
            create["example"] = {"corridor": default_corridor, "units": "metric"}
            cached.update(schema)
        schema = dict(cached)
        # the example fix is dated now and placed on the default corridor, so "Try it out" gets an advisory
        lat, lon = default_lat_lon
        example = {"t_unix_s": round(time.time(), 3), "lat_deg": round(lat, 7), "lon_deg": round(lon, 7), "speed_mps": 13.9, "heading_deg": 295.5, "accuracy_m": 4.0}
        paths = dict(schema["paths"])
        op = copy.deepcopy(paths["/v1/trips/{trip_id}/fixes"])
        op["post"]["requestBody"]["content"]["application/json"]["example"] = example
        op["post"]["requestBody"]["content"]["application/json"]["schema"]["examples"] = [example]
        paths["/v1/trips/{trip_id}/fixes"] = op
        schema["paths"] = paths
        return schema

    async def openapi_json(request: Request) -> JSONResponse:
        check(request)
        return JSONResponse(document())

    async def swagger(request: Request) -> HTMLResponse:
        check(request)
        return get_swagger_ui_html(openapi_url="/openapi.json", title=f"{app.title} - Swagger UI", swagger_js_url=f"{ASSETS_URL}/swagger-ui-bundle.js",
                                   swagger_css_url=f"{ASSETS_URL}/swagger-ui.css", swagger_favicon_url=f"{ASSETS_URL}/favicon.png",
                                   swagger_ui_parameters={"persistAuthorization": True})  # fmt: skip

    async def redoc(request: Request) -> HTMLResponse:
        check(request)
        return get_redoc_html(openapi_url="/openapi.json", title=f"{app.title} - ReDoc", redoc_js_url=f"{ASSETS_URL}/redoc.standalone.js",
                              redoc_favicon_url=f"{ASSETS_URL}/favicon.png", with_google_fonts=False)  # fmt: skip

    app.add_route("/openapi.json", openapi_json, include_in_schema=False)
    app.add_route("/docs", swagger, include_in_schema=False)
    app.add_route("/redoc", redoc, include_in_schema=False)
    app.mount(ASSETS_URL, StaticFiles(directory=ASSETS), name="docs-assets")
