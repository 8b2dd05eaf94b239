"""The simulated SPaT feed: FastAPI app with a snapshot route and a 10 Hz WebSocket stream.

Routes
------
``GET /health``            liveness, with the feed's clock
``GET /corridors``         shipped corridor names; ``GET /corridors/{name}`` one corridor file
``GET /timings``           timing presets
``GET /spat``              the SPaT message now (``format=j2735`` for TimeMarks)
``WS  /spat/stream``       the SPaT message pushed at ``rate_hz``
``GET /spat/intersections``          the latest state of every intersection (simulated and played)
``WS  /spat/intersections/stream``   every intersection's new states, one message per tick, shared by all

``/spat`` and ``/spat/stream`` take the scenario as query parameters, all optional, defaulting to the
feed's settings: ``corridor``, ``timing`` (a preset, or ``trip`` to pick one of the paper's 16 from the
entry time), ``entry_unix_s`` (the trip's zone-entry instant: the timing is relative to it),
``early_s``/``late_s``/``confidence`` (actuated-style change windows).

**Per intersection** (what a city runs; the advisory service subscribes once): the simulator publishes every
intersection of the served corridors under its shared timing (``spat_feed.transport.simulator``), a recorded log plays
on the present clock (``--log``, ``spat_feed.transport.player``); each tick's states go to the shared stream, to an MQTT
broker (``--mqtt``) and to a JSON-lines recording (``--record``). One text per tick whatever the number of
subscribers. Each state goes out with every movement's predicted ``likelyTime`` and ``confidence`` where its
controller did not state them, marked as ours (``spat_feed.transport.republish``).

**Per scenario** (research and tests): ``/spat`` and ``/spat/stream`` with a scenario in the query.
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

from spat_feed.road.corridors import load_corridor, preset_names
from spat_feed.timing.paper import TIMING_PRESETS
from spat_feed.timing.messages import IntersectionState, SpatMessage, from_unix_s, to_j2735
from spat_feed.transport.mqtt import MqttPublisher
from spat_feed.transport.player import JsonlRecorder, LogPlayer, read_spat_log
from spat_feed.transport.pump import SpatPump, run_every
from spat_feed.transport.republish import Republisher
from spat_feed.transport.scenarios import FeedScenario, Uncertainty, make_scenario, spat_message_at
from spat_feed.transport.simulator import IntersectionSimulator
from spat_feed.transport.store import Clock

log = logging.getLogger("spat_feed.transport.service")


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
    corridors: tuple[str, ...] | None = None
    """Corridors whose intersections are simulated on the shared stream (None: every preset; () none)."""
    log: str | None = None
    """A recorded SPaT log (.csv[.gz] or .jsonl[.gz]) played on the shared stream."""
    speedup: float = 1.0
    loop: bool = False
    mqtt: str | None = None
    """Publish the shared stream to this broker (``mqtt://host:port[/prefix]``)."""
    record: str | None = None
    """Append the shared stream to this JSON-lines log."""

    def __post_init__(self) -> None:
        if not 0 < self.rate_hz <= 100:
            raise ValueError("rate_hz must be in (0, 100]")
        if self.fault_every < 0 or self.n_events < 1:
            raise ValueError("fault_every must be >= 0 and n_events >= 1")


class _Group:
    """Subscribers of one scenario (or of the shared stream): the latest message text (a tuple of texts for
    the shared stream: one tick's messages) and a wake-up event."""

    def __init__(self, scenario: FeedScenario | None) -> None:
        self.scenario = scenario
        self.subscribers = 0
        self.seq = 0
        self.text: str | tuple[str, ...] = ""
        self._event = asyncio.Event()

    def publish(self, text: str | tuple[str, ...]) -> None:
        self.text, self.seq = text, self.seq + 1
        event, self._event = self._event, asyncio.Event()
        event.set()

    async def next(self, last_seq: int) -> tuple[str | tuple[str, ...], int]:
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


class _Shared:
    """The per-intersection stream: producers (simulator, log player) -> latest states, subscribers, sinks."""

    def __init__(self, settings: FeedSettings, clock: Clock) -> None:
        self.clock = clock
        names = preset_names() if settings.corridors is None else list(settings.corridors)
        self.simulator = IntersectionSimulator([load_corridor(n) for n in names], settings.n_events) if names else None
        self.player = LogPlayer(read_spat_log(settings.log), clock(), settings.speedup, settings.loop) if settings.log else None
        self.republisher = Republisher()  # every movement's likelyTime and confidence, predicted where not stated
        self.latest: dict[int, IntersectionState] = {}
        self.group = _Group(None)  # type: ignore[arg-type]
        self.sinks: list = []
        self.recorder = JsonlRecorder(settings.record) if settings.record else None
        if self.recorder is not None:
            self.sinks.append(self.recorder)
        self.publisher = MqttPublisher(settings.mqtt) if settings.mqtt else None
        if self.publisher is not None:
            self.sinks.append(self.publisher)
        self.pump = SpatPump(self.produce, [self.keep, *self.sinks], settings.rate_hz, clock)

    def produce(self, now_unix_s: float) -> list[IntersectionState]:
        states = self.simulator.states_at(now_unix_s) if self.simulator is not None else []
        if self.player is not None:
            states += self.player.due(now_unix_s)
        return [self.republisher(s) for s in states]

    def keep(self, state: IntersectionState) -> None:
        self.latest[state.id] = state

    def tick(self) -> None:
        """One round: new states to the sinks and, as one tick's texts (32 intersections a message, J2735's
        limit), to every subscriber."""
        states = self.pump.tick()
        if states:
            self.group.publish(self.texts(states))

    def texts(self, states: list[IntersectionState]) -> tuple[str, ...]:
        stamp = from_unix_s(self.clock())
        return tuple(
            SpatMessage(timestamp=stamp, name="ecodrive intersections", intersections=states[i : i + 32]).model_dump_json(by_alias=True, exclude_none=True)
            for i in range(0, len(states), 32)
        )

    def start(self) -> None:
        if self.publisher is not None:
            self.publisher.start()

    def stop(self) -> None:
        if self.publisher is not None:
            self.publisher.stop()
        if self.recorder is not None:
            self.recorder.close()


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
    shared = _Shared(settings, clock)

    def tick() -> None:
        hub.tick()
        shared.tick()

    @contextlib.asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        shared.start()
        task = asyncio.create_task(run_every(settings.rate_hz, tick, "feed tick"))
        try:
            yield
        finally:
            task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await task
            shared.stop()

    app = FastAPI(title="ecodrive SPaT feed (simulated)", lifespan=lifespan)
    app.state.hub = hub
    app.state.shared = shared

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
        out: dict[str, Any] = {
            "status": "ok", "now": from_unix_s(now).isoformat().replace("+00:00", "Z"),
            "subscribers": sum(g.subscribers for g in hub.groups.values()) + shared.group.subscribers,
            "intersections": sorted(shared.latest), "states_sent": shared.pump.sent,
        }  # fmt: skip
        if shared.player is not None:
            out["log"] = {"file": settings.log, "passes": shared.player.passes, "index": shared.player.index, "done": shared.player.done}
        if shared.publisher is not None:
            out["mqtt"] = {"url": shared.publisher.url, "connected": shared.publisher.connected.is_set(), "published": shared.publisher.published}
            if not shared.publisher.connected.is_set():
                out["status"] = "degraded"
        return out

    @app.get("/spat/intersections")
    def intersections() -> JSONResponse:
        states = [shared.latest[i] for i in sorted(shared.latest)]
        return JSONResponse([json.loads(t) for t in shared.texts(states)] if states else [])

    @app.websocket("/spat/intersections/stream")
    async def intersections_stream(ws: WebSocket) -> None:
        await ws.accept()
        group = shared.group
        group.subscribers += 1
        try:
            if shared.latest:  # the latest state of each intersection first, then every tick's new ones
                for text in shared.texts([shared.latest[i] for i in sorted(shared.latest)]):
                    await ws.send_text(text)
            seq = group.seq
            while True:
                texts, seq = await group.next(seq)
                for text in texts:
                    await ws.send_text(text)
        except (WebSocketDisconnect, RuntimeError, OSError) as exc:
            log.debug("subscriber left: %r", exc)
        finally:
            group.subscribers -= 1

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
