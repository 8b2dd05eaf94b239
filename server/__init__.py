"""The advisory web service (FastAPI): ``create_app`` in ``server.app``.

At the top: the app and its wiring (``app``, ``main``, ``config``, ``deps``, ``schemas``, ``routes/``) and what the
service does for a trip (``advising``: a fix to an advisory; ``trips``, ``gps`` map matching, ``queue`` the queue
board, ``spat`` the shared SPaT hub, ``score``, ``audio``). Below them: ``web/`` (protocols, middleware, the fix lane,
bodies, errors, metrics, OpenAPI), ``storage/`` (trips, streams and queue probes in memory or Redis) and
``admission/`` (quotas, rate limits, overload shedding).
"""
