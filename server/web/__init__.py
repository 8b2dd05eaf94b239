"""The web layer below the routes: the HTTP and WebSocket protocols uvicorn runs (read deadline, connection caps,
reading paused only when the app falls behind), pure ASGI middleware, the fix lane served without the router,
strict JSON bodies, the API's errors and their one JSON shape, metrics, and the OpenAPI pages."""
