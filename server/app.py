"""``create_app(settings)``: the advisory service as a FastAPI app.

Start-up (``lifespan``): load the corridors, build (or load) the DP lookup tables for each, start the
speech engine and the shared SPaT hub (``server.spat``: simulator, remote feed, MQTT, log); warm the numba code
paths so the first request is not slow. A background task closes trips idle for ``trip_idle_ttl_s``.
"""

from __future__ import annotations

import asyncio
import contextlib
import gc
import inspect
import logging
import time
from collections.abc import AsyncIterator, Callable
from contextlib import asynccontextmanager
from pathlib import Path

import numpy as np
from fastapi import FastAPI
from fastapi.middleware.cors import CORSMiddleware

from advisory.advice.advisor import advise
from advisory.advice.views import AdvisorParams, LightView, Observation
from advisory.physics.params import model_params
from spat_feed.road.corridors import Corridor, load_corridor, load_corridor_dir

from server.advising import Engine
from server.audio import Speech
from server.config import Settings
from server.web.errors import install_handlers
from server.web.fastlane import FixLane
from server.web.metrics import Metrics
from server.web.middleware import GuardMiddleware
from server.web.openapi import install_docs
from server.admission.overload import ShedCollector, ShedMiddleware, Shedder
from server.routes import audio, corridors, health, stream, trips, webapp
from server.score import trip_score
from server.spat import SpatHub
from spat_feed.prediction.observe import PlanReading, observation
from spat_feed.transport.simulator import shared_scenario
from server.storage.streams import RedisStreams, StreamCounts

log = logging.getLogger("server")

DESCRIPTION = """Eco-driving advice for connected EVs at signalised intersections.

Create a trip on a corridor (`POST /v1/trips`), then send GPS fixes (`POST /v1/trips/{id}/fixes`, or the
WebSocket `/v1/trips/{id}/stream`) and receive, for each, the advisory computed at the fix's time from the
signals' SPaT. End the trip to get its energy, battery wear and cost against the paper's regular driver.
Every error is JSON: `{"error": code, "message": sentence, "detail": ...}`.
"""


NO_OTEL = {"telemetry": {"tracing": False, "metrics": False, "logs": False}} if "telemetry" in inspect.signature(FastAPI.__init__).parameters else {}
"""FastAPI's native OpenTelemetry off (FastAPI >= 0.165; the service exports Prometheus metrics, ``/metrics``): with it
on, every request looked its providers up (three environment variables): 6.1 us a request, 0.2 us off."""


def load_corridors(settings: Settings) -> dict[str, Corridor]:
    """The presets named in ``corridors``, the corridor (and plan) files of ``corridor_dir``, and
    ``corridor_file``. Errors name the file; a name defined twice is refused."""
    out = {name: load_corridor(name) for name in settings.corridors}
    extra = list(load_corridor_dir(settings.corridor_dir).values()) if settings.corridor_dir is not None else []
    if settings.corridor_file is not None:
        extra.append(load_corridor(settings.corridor_file))
    for corridor in extra:
        if corridor.name in out:
            raise ValueError(f"corridor {corridor.name!r} is defined twice (a preset and {settings.corridor_dir or settings.corridor_file})")
        out[corridor.name] = corridor
    if settings.default_corridor not in out:
        raise ValueError(f"default corridor {settings.default_corridor!r} is not among the served corridors {sorted(out)}")
    return out


def build_tables(settings: Settings, corridors: dict[str, Corridor]) -> dict[str, object]:
    """DP lookup tables per corridor for the default vehicle, for every plan its trips can run under
    (``spat_feed.road.corridor_tables``), cached as .npz in ``tables_dir`` if set.

    A corridor without any fixed-time light gets none: the advisor then uses its rules.
    """
    if not settings.tables:
        return {}
    from spat_feed.road.corridor_tables import corridor_tables

    params = model_params(settings.default_vehicle)
    out: dict[str, object] = {}
    for name, corridor in corridors.items():
        try:
            tables, report = corridor_tables(corridor, params, cache_dir=settings.tables_dir, default_limit_mps=settings.speed_limit_mps)
        except (ValueError, KeyError) as exc:
            log.warning("no lookup tables for corridor %s: %s", name, exc)
            continue
        if tables is None:
            log.info("no lookup tables for corridor %s: no light has a fixed-time plan (the rules advise)", name)
            continue
        log.info("tables %s", report.line())
        out[name] = tables
    return out


def warm_up(engine: Engine) -> None:
    """Run each numba/pyproj path once (compiles or loads the cached machine code)."""
    corridor = engine.corridors[engine.settings.default_corridor]
    scenario = shared_scenario(corridor, 0.0)
    engine.matchers[corridor.name].match(*corridor.position(10.0))
    t = np.array([0.0, 1.0, 2.0])
    v = np.array([20.0, 20.0, 20.0])
    trip_score("warm-up", scenario, engine.settings.default_vehicle, t, v, np.array([0.0, 20.0, 40.0]), engine.settings.speed_limit_mps)
    readings = {ix: PlanReading.of_plan(plan) for (ix, _), plan in scenario.fixed_plans().items()}
    for station_m in (0.0, corridor.length_m / 2):  # the advisor's kernels, with the tables and without
        obs = observation(corridor, station_m, 15.0, 30.0, readings, engine.settings.speed_limit_mps)
        for tables in (engine.tables.get(corridor.name), None):
            advise(obs, None, engine.params, tables)
    # the choice under uncertain timing (recorded, MQTT, actuated controllers): its kernels took 11 s to compile on the
    # first such fix with a cold numba cache (that fix timed out, and the event loop with it), so compile them here
    timings = tuple(((10.0 + k, 40.0 + k),) for k in range(4))
    light = LightView(0, 200.0, red_windows_s=((10.0, 43.0),), likely_red_windows_s=((11.5, 41.5),), late_red_windows_s=((13.0, 43.0),),
                      scenario_red_windows_s=timings)  # fmt: skip
    advise(Observation(15.0, engine.settings.speed_limit_mps, (light,)), None, engine.params, None)


async def _expire_idle(engine: Engine, metrics: Metrics, period_s: float) -> None:
    while True:
        await asyncio.sleep(period_s)
        with contextlib.suppress(Exception):
            for trip in await engine.trips.sweep(engine.settings.trip_idle_ttl_s):
                with contextlib.suppress(Exception):
                    await trip.spat.close()
                metrics.trips_closed.labels("expired").inc()


def create_app(settings: Settings | None = None, *, clock: Callable[[], float] = time.time, advisor_params: AdvisorParams | None = None) -> FastAPI:
    """The app. ``clock`` (Unix seconds) is injected for tests; the server's real clock by default."""
    settings = settings or Settings()
    corridors_ = load_corridors(settings)

    @asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        t0 = time.perf_counter()
        tables = await asyncio.to_thread(build_tables, settings, corridors_)
        hub = SpatHub(settings, corridors_, clock)
        engine = Engine(settings, corridors_, tables, advisor_params, hub, clock)
        engine.on_advice = metrics.observe_advice
        engine.on_ignored_fix = lambda status: metrics.count(metrics.fixes, status)
        engine.on_rate_limited = metrics.rate_limited.inc
        engine.trips.on_shed = metrics.trips_closed.labels("shed").inc
        app.state.engine = engine
        if engine.trips.shared:  # WebSocket caps across workers
            app.state.streams = RedisStreams(engine.trips, settings.ws_lease_s)
            if warning := await engine.trips.volatile():
                log.warning(warning)
        await asyncio.to_thread(warm_up, engine)
        await speech.start()
        await hub.start()
        sweeper = asyncio.create_task(_expire_idle(engine, metrics, min(60.0, settings.trip_idle_ttl_s / 2)))
        lag_probe = asyncio.create_task(shedder.watch())
        tasks = [sweeper, lag_probe]
        if engine.queue is not None and engine.queue.shared is not None:  # every worker's probes (server.storage.queue_store)
            tasks.append(asyncio.create_task(engine.queue.shared.run()))
        gc.freeze()  # start-up objects (tables, corridors, numba) to the permanent generation: collections stop rescanning them
        log.info("advisory service ready in %.1f s: %d corridors, tables for %s, speech %s", time.perf_counter() - t0, len(corridors_), sorted(tables), speech.reason)
        try:
            yield
        finally:
            for task in tasks:
                task.cancel()
                with contextlib.suppress(asyncio.CancelledError):
                    await task
            await speech.stop()
            await app.state.streams.aclose()
            await engine.trips.close()
            await hub.stop()

    app = FastAPI(title="ecodrive advisory service", version="1.0.0", description=DESCRIPTION, lifespan=lifespan, docs_url=None, redoc_url=None, openapi_url=None,
                  **NO_OTEL)  # fmt: skip
    app.state.settings = settings
    speech = Speech(settings.speech, settings.audio_cache_size)
    app.state.speech = speech
    metrics = Metrics(lambda: len(app.state.engine.trips) if hasattr(app.state, "engine") else 0, lambda: app.state.engine.spat if hasattr(app.state, "engine") else None,
                      lambda: app.state.engine.queue if hasattr(app.state, "engine") else None)  # fmt: skip
    app.state.metrics = metrics
    app.state.streams = StreamCounts()
    # Routes are tried in order, a regex and some bookkeeping each, so the per-second ones (fixes, stream)
    # come early and the documentation pages last. The routers' routes go straight into the app's list
    # (each router carries its own prefix and tags; no include-level options are used): FastAPI's
    # include_router adds a nested matching level per router. Together ~25 us less per fix (docs/SERVICE.md).
    # The phone app's static files (/app) come after every API route, the documentation pages last.
    for module in (health, trips, stream, corridors, audio, webapp):
        app.router.routes.extend(r for r in module.router.routes if not (getattr(r, "path", "") == "/metrics" and settings.metrics_access == "off"))
    default = corridors_[settings.default_corridor]
    install_docs(app, default.position(min(50.0, default.length_m / 2)), default.name)
    install_handlers(app)
    shedder = app.state.shedder = Shedder(settings.max_in_flight, settings.max_loop_lag_s)  # overload: 503 + Retry-After, never a queue
    metrics.registry.register(ShedCollector(shedder))
    fix_route = next(r for r in app.router.routes if getattr(r, "path", "") == "/v1/trips/{trip_id}/fixes" and "POST" in getattr(r, "methods", ()))
    app.add_middleware(FixLane, route=fix_route, handlers=app.exception_handlers)  # a car's fix each second, without the router
    app.add_middleware(ShedMiddleware, shedder=shedder)  # inside GuardMiddleware: a refusal is counted as a 503
    app.add_middleware(GuardMiddleware, max_body_bytes=settings.max_body_bytes, metrics=metrics)
    if settings.cors_origins:  # outermost: answers browsers' preflight requests (docs/SERVICE.md, CORS)
        app.add_middleware(CORSMiddleware, allow_origins=list(settings.cors_origins), allow_methods=["GET", "POST"],
                           allow_headers=["Authorization", "Content-Type", "X-API-Key"], expose_headers=["Location", "Retry-After"], max_age=600)  # fmt: skip
    return app
