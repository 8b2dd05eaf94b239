"""The fix lane: ``POST /v1/trips/{trip_id}/fixes``, a car's request every second, served without the router.

Every other request goes through Starlette's exception middleware, the router (a regex per route until one
matches) and FastAPI's per-request wrapper (a ``Request``, two ``AsyncExitStack`` and an exception wrapper around
the endpoint): ~50 us of a fix's CPU on the shared 2-core machine, a sixth of all a worker spends on it
(issue 30, item 6: CPU per fix on the Redis path). :class:`FixLane`, a pure ASGI middleware inside
``GuardMiddleware`` and ``ShedMiddleware`` (so a fix is counted, size-limited and shed as before), recognises the
path by its prefix and suffix and calls the route's endpoint (:func:`server.routes.trips.post_fix`, a
``DirectRoute`` already: no dependencies, no response model) itself; an exception the app has a handler for
(``ApiError``, validation, HTTP errors) is answered by that handler, exactly as the exception middleware would;
any other propagates as it would have. The route stays in the router for the OpenAPI document.
"""

from __future__ import annotations

from starlette.requests import Request

PREFIX, SUFFIX = "/v1/trips/", "/fixes"


class FixLane:
    """Pure ASGI: a ``POST`` to ``/v1/trips/<id>/fixes`` goes to ``route``'s endpoint; anything else to ``app``.
    ``handlers``: the app's exception handlers by class (``FastAPI.exception_handlers``), read per exception."""

    def __init__(self, app, route, handlers: dict) -> None:
        self.app = app
        self.route = route
        self.endpoint = route.endpoint
        self.handlers = handlers

    async def __call__(self, scope, receive, send) -> None:
        path = scope.get("path", "")
        if scope["type"] != "http" or scope["method"] != "POST" or not path.endswith(SUFFIX) or not path.startswith(PREFIX):
            await self.app(scope, receive, send)
            return
        trip_id = path[len(PREFIX) : -len(SUFFIX)]
        if not trip_id or "/" in trip_id:
            await self.app(scope, receive, send)
            return
        scope["route"] = self.route  # as the router sets it: the request metrics name the route
        scope["endpoint"] = self.endpoint
        scope["path_params"] = {"trip_id": trip_id}
        request = Request(scope, receive, send)
        try:
            response = await self.endpoint(trip_id=trip_id, request=request)
        except Exception as exc:
            handler = next((self.handlers[cls] for cls in type(exc).__mro__ if cls is not Exception and cls in self.handlers), None)
            if handler is None:
                raise
            response = await handler(request, exc)
        await response(scope, receive, send)
