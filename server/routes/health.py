"""``/health`` (liveness, for the compose health check) and ``/metrics`` (Prometheus text format)."""

from __future__ import annotations

import time

from fastapi import APIRouter, Response

from server.deps import EngineDep, MetricsAccessDep, MetricsDep, SettingsDep, SpeechDep
from server.web.metrics import CONTENT_TYPE_LATEST
from server.schemas import HealthOut, SpatHealthOut

router = APIRouter(tags=["service"])


@router.get("/health", response_model=HealthOut)
async def health(engine: EngineDep, settings: SettingsDep, speech: SpeechDep) -> HealthOut:
    """The service is up and its tables are loaded; each SPaT source's state and each intersection's freshness."""
    spat = engine.spat.health()
    board = engine.queue.state() if engine.queue is not None else None
    return HealthOut(
        status="degraded" if board == "own_trips_only" else spat["status"],
        now_unix_s=time.time(),
        trips=await engine.trips.count(),
        spat=spat["source"],
        spat_health=SpatHealthOut.model_validate({k: v for k, v in spat.items() if k != "status"}),
        tables=sorted(engine.tables),
        speech=speech.available,
        queue_board=board,
    )


@router.get("/metrics", response_class=Response, responses={200: {"content": {CONTENT_TYPE_LATEST: {}}, "description": "Prometheus metrics"}})
async def metrics(metrics: MetricsDep, _: MetricsAccessDep) -> Response:
    """Prometheus metrics: requests, fixes, advisories, trips, WebSocket streams, process memory and open files."""
    return Response(metrics.render(), media_type=CONTENT_TYPE_LATEST)
