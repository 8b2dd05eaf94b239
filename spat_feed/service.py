"""The simulated SPaT feed: FastAPI app with a snapshot route and a 10 Hz WebSocket stream.

Routes
------
``GET /health``            liveness, with the feed's clock
``GET /corridors``         shipped corridor names; ``GET /corridors/{name}`` one corridor file
``GET /timings``           timing presets
``GET /spat``              the SPaT message now (``format=j2735`` for TimeMarks)
``WS  /spat/stream``       the SPaT message pushed at ``rate_hz``

``/spat`` and ``/spat/stream`` take the scenario as query parameters, all optional, defaulting to the
feed's settings: ``corridor``, ``timing`` (a preset, or ``trip`` to pick one of the paper's 16 from the
entry time), ``entry_unix_s`` (the trip's zone-entry instant: the timing is relative to it),
``early_s``/``late_s``/``confidence`` (actuated-style change windows).

Streaming: subscribers with the same scenario share one group; each tick builds that group's message
once (its ``timestamp`` is the build instant) and wakes the subscribers, each of which sends the latest
text. A slow subscriber skips to the newest message instead of queueing old ones.

The clock (Unix seconds) is injected: ``create_app(settings, clock=...)``; ``time.time`` by default.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import time
from collections.abc import AsyncIterator
from dataclasses import dataclass, field
from typing import Annotated, Any

from fastapi import Depends, FastAPI, HTTPException, Query, WebSocket, WebSocketDisconnect
from fastapi.responses import JSONResponse

from spat_feed.corridors import TIMING_PRESETS, load_corridor, preset_names
from spat_feed.messages import from_unix_s, to_j2735
from spat_feed.scenarios import FeedScenario, Uncertainty, make_scenario, spat_message_at
from spat_feed.source import Clock

log = logging.getLogger("spat_feed.service")


@dataclass(frozen=True, slots=True)
class FeedSettings:
    """Deployment settings of the feed. ``entry_unix_s=None``: the feed's start instant."""

    corridor: str = "paper_s400"
    timing: str = "15_15"
    entry_unix_s: float | None = None
    early_s: float = 0.0
    late_s: float = 0.0
    confidence_frac: float = 1.0
    rate_hz: float = 10.0
    n_events: int = 3
    fault_every: int = 0
    """Test hook: every ``fault_every``-th streamed message is corrupted (0: never); see :func:`_corrupt`."""

    def __post_init__(self) -> None:
        if not 0 < self.rate_hz <= 100:
            raise ValueError("rate_hz must be in (0, 100]")
        if self.fault_every < 0 or self.n_events < 1:
            raise ValueError("fault_every must be >= 0 and n_events >= 1")


class _Group:
    """Subscribers of one scenario: the latest message text and a wake-up event."""

    def __init__(self, scenario: FeedScenario) -> None:
        self.scenario = scenario
        self.subscribers = 0
        self.seq = 0
        self.text = ""
        self._event = asyncio.Event()

    def publish(self, text: str) -> None:
        self.text, self.seq = text, self.seq + 1
        event, self._event = self._event, asyncio.Event()
        event.set()

    async def next(self, last_seq: int) -> tuple[str, int]:
        """Wait for a message newer than ``last_seq``; returns (text, seq)."""
        while self.seq == last_seq:
            await self._event.wait()
        return self.text, self.seq


@dataclass
class _Hub:
    settings: FeedSettings
    clock: Clock
    groups: dict[tuple, _Group] = field(default_factory=dict)
    ticks: int = 0

    def join(self, scenario: FeedScenario) -> _Group:
        group = self.groups.get(scenario.key)
        if group is None:
            group = self.groups[scenario.key] = _Group(scenario)
        group.subscribers += 1
        if group.seq == 0:
            group.publish(self.render(group, self.clock()))
        return group

    def leave(self, group: _Group) -> None:
        group.subscribers -= 1
        if group.subscribers <= 0:
            self.groups.pop(group.scenario.key, None)

    def render(self, group: _Group, now_unix_s: float) -> str:
        msg = spat_message_at(group.scenario, now_unix_s, self.settings.n_events)
        text = msg.model_dump_json(by_alias=True, exclude_none=True)
        every = self.settings.fault_every
        if every and (group.seq + 1) % every == 0:
            text = _corrupt(text, (group.seq + 1) // every)
        return text

    def tick(self) -> None:
        now = self.clock()
        for group in list(self.groups.values()):
            group.publish(self.render(group, now))
        self.ticks += 1

    async def run(self) -> None:
        loop = asyncio.get_running_loop()
        period_s = 1.0 / self.settings.rate_hz
        next_s = loop.time()
        while True:
            next_s += period_s
            delay_s = next_s - loop.time()
            if delay_s < -period_s:  # fell behind by more than a tick: skip, do not burst
                next_s = loop.time()
                delay_s = 0.0
            await asyncio.sleep(max(delay_s, 0.0))
            try:
                self.tick()
            except Exception:  # pragma: no cover - keep the feed alive, log the bug
                log.exception("tick failed")


def _corrupt(text: str, n: int) -> str:
    """Test hook: odd ``n``, a text that is not JSON; even ``n``, the first intersection made invalid."""
    if n % 2 == 1:
        return text[: len(text) // 2]
    data = json.loads(text)
    if data["intersections"]:
        data["intersections"][0]["states"][0]["stateTimeSpeed"][0]["eventState"] = "purple"
    return json.dumps(data)


def _scenario(settings: FeedSettings, default_entry_s: float, params: dict[str, Any]) -> FeedScenario:
    entry_s = params.get("entry_unix_s")
    if entry_s is None:
        entry_s = settings.entry_unix_s if settings.entry_unix_s is not None else default_entry_s
    u = Uncertainty(
        early_s=params.get("early_s") if params.get("early_s") is not None else settings.early_s,
        late_s=params.get("late_s") if params.get("late_s") is not None else settings.late_s,
        confidence_frac=params.get("confidence") if params.get("confidence") is not None else settings.confidence_frac,
    )
    corridor = params.get("corridor") or settings.corridor
    if corridor != settings.corridor and corridor not in preset_names():  # never read a path from a query
        raise HTTPException(status_code=404, detail=f"no corridor preset {corridor!r}")
    try:
        return make_scenario(corridor, params.get("timing") or settings.timing, entry_s, u)
    except KeyError as exc:
        raise HTTPException(status_code=404, detail=str(exc)) from exc
    except ValueError as exc:
        raise HTTPException(status_code=422, detail=str(exc)) from exc


def create_app(settings: FeedSettings | None = None, clock: Clock = time.time) -> FastAPI:
    """The feed app. ``clock`` returns Unix seconds; every timestamp the feed writes comes from it."""
    settings = settings or FeedSettings()
    for_validation = make_scenario(settings.corridor, settings.timing, 0.0)  # fail at start-up on bad presets
    del for_validation
    started_s = clock()
    hub = _Hub(settings, clock)

    @contextlib.asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        task = asyncio.create_task(hub.run())
        try:
            yield
        finally:
            task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await task

    app = FastAPI(title="ecodrive SPaT feed (simulated)", lifespan=lifespan)
    app.state.hub = hub

    def scenario_params(
        corridor: str | None = None,
        timing: str | None = None,
        entry_unix_s: float | None = None,
        early_s: Annotated[float | None, Query(ge=0, le=60)] = None,
        late_s: Annotated[float | None, Query(ge=0, le=60)] = None,
        confidence: Annotated[float | None, Query(ge=0, le=1)] = None,
    ) -> dict[str, Any]:
        return dict(corridor=corridor, timing=timing, entry_unix_s=entry_unix_s, early_s=early_s, late_s=late_s, confidence=confidence)

    @app.get("/health")
    def health() -> dict[str, Any]:
        now = clock()
        return {"status": "ok", "now": from_unix_s(now).isoformat().replace("+00:00", "Z"), "subscribers": sum(g.subscribers for g in hub.groups.values())}

    @app.get("/corridors")
    def corridors() -> list[str]:
        return preset_names()

    @app.get("/corridors/{name}")
    def corridor(name: str) -> JSONResponse:
        if name not in preset_names():
            raise HTTPException(status_code=404, detail=f"no corridor {name!r}")
        return JSONResponse(load_corridor(name).model_dump(mode="json"))

    @app.get("/timings")
    def timings() -> dict[str, dict[str, Any]]:
        return {k: {"red_starts_s": list(t.red_starts_s), "red_s": t.red_s, "green_s": t.green_s, "description": t.description} for k, t in TIMING_PRESETS.items()}

    @app.get("/spat")
    def spat(
        format: Annotated[str, Query(pattern="^(json|j2735)$")] = "json",
        params: dict[str, Any] = Depends(scenario_params),  # noqa: B008 (a local dependency: no Annotated alias)
    ) -> JSONResponse:
        msg = spat_message_at(_scenario(settings, started_s, params), clock(), settings.n_events)
        body = to_j2735(msg) if format == "j2735" else msg.model_dump(mode="json", by_alias=True, exclude_none=True)
        return JSONResponse(body)

    @app.websocket("/spat/stream")
    async def stream(
        ws: WebSocket,
        corridor: str | None = None,
        timing: str | None = None,
        entry_unix_s: float | None = None,
        early_s: Annotated[float | None, Query(ge=0, le=60)] = None,
        late_s: Annotated[float | None, Query(ge=0, le=60)] = None,
        confidence: Annotated[float | None, Query(ge=0, le=1)] = None,
    ) -> None:
        try:
            scenario = _scenario(settings, started_s, scenario_params(corridor, timing, entry_unix_s, early_s, late_s, confidence))
        except HTTPException as exc:
            await ws.close(code=1008, reason=str(exc.detail)[:120])
            return
        await ws.accept()
        group = hub.join(scenario)
        seq = 0
        try:
            while True:
                text, seq = await group.next(seq)
                await ws.send_text(text)
        except (WebSocketDisconnect, RuntimeError, OSError) as exc:
            log.debug("subscriber left: %r", exc)
        finally:
            hub.leave(group)

    return app
