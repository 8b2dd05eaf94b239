"""The feed app in-process, with an injected clock (FastAPI TestClient), and the in-process source."""

from __future__ import annotations

from datetime import datetime, timezone

import pytest
from fastapi.testclient import TestClient

from spat_feed.timing.messages import SpatMessage, from_j2735, parse_spat_text, to_unix_s
from spat_feed.timing.plans import GREEN, RED, seconds_to_next_green, state_at
from spat_feed.transport.scenarios import make_scenario
from spat_feed.transport.service import FeedSettings, create_app
from spat_feed.transport.store import InProcessSpatSource

ENTRY_S = datetime(2024, 5, 1, 12, 0, tzinfo=timezone.utc).timestamp()


class FakeClock:
    def __init__(self, t_s: float) -> None:
        self.t_s = t_s

    def __call__(self) -> float:
        return self.t_s


@pytest.fixture
def clock():
    return FakeClock(ENTRY_S + 5.0)


@pytest.fixture
def client(clock):
    with TestClient(create_app(FeedSettings(timing="-15_15", entry_unix_s=ENTRY_S), clock=clock)) as c:
        yield c


def snapshot(client, **params) -> SpatMessage:
    response = client.get("/spat", params=params)
    assert response.status_code == 200, response.text
    return SpatMessage.model_validate(response.json())


def test_health_and_catalogue(client):
    assert client.get("/health").json()["status"] == "ok"
    assert "paper_s400" in client.get("/corridors").json()
    assert client.get("/corridors/paper_s800").json()["intersections"][1]["stop_line_m"] == 900.0
    assert client.get("/timings").json()["field_test"]["red_starts_s"] == [-15.0, 30.0]


def test_snapshot_follows_the_injected_clock(client, clock):
    msg = snapshot(client)
    assert to_unix_s(msg.timestamp) == ENTRY_S + 5.0
    light1 = msg.intersections[0].states[0].state_time_speed[0]
    assert light1.event_state == RED and to_unix_s(light1.timing.min_end_time) == ENTRY_S + 15.0  # x = -15
    clock.t_s = ENTRY_S + 20.0
    assert snapshot(client).intersections[0].states[0].state_time_speed[0].event_state == GREEN


def test_scenario_is_keyed_to_the_trip_entry_time(client, clock):
    """The same timing for a trip that entered 10 s later is shifted by 10 s."""
    a = snapshot(client, timing="15_15", entry_unix_s=ENTRY_S)
    b = snapshot(client, timing="15_15", entry_unix_s=ENTRY_S + 10.0)
    ta = a.intersections[1].states[0].state_time_speed[0].timing.min_end_time
    tb = b.intersections[1].states[0].state_time_speed[0].timing.min_end_time
    assert to_unix_s(tb) - to_unix_s(ta) == pytest.approx(10.0, abs=1e-3)
    assert len(snapshot(client, corridor="paper_s800").intersections) == 2


def test_trip_timing_picks_one_of_the_sixteen(client):
    msg = snapshot(client, timing="trip", entry_unix_s=ENTRY_S + 61.0)
    assert msg.name == "paper_s400 -30_-15"


def test_bad_queries(client):
    assert client.get("/spat", params={"corridor": "nowhere"}).status_code == 404
    assert client.get("/spat", params={"corridor": "/etc/passwd"}).status_code == 404  # never a path
    assert client.get("/spat", params={"timing": "nope"}).status_code == 404
    assert client.get("/spat", params={"early_s": -1}).status_code == 422
    assert client.get("/spat", params={"format": "xml"}).status_code == 422


def test_j2735_format(client, clock):
    clock.t_s = ENTRY_S + 3599.5  # half a second before the hour: the next change is in the next hour
    j = client.get("/spat", params={"format": "j2735"}).json()
    back = from_j2735(j, ref_unix_s=clock.t_s)
    direct = snapshot(client)
    for a, b in zip(direct.intersections, back.intersections):
        ta, tb = a.states[0].state_time_speed[0].timing, b.states[0].state_time_speed[0].timing
        assert abs(to_unix_s(ta.min_end_time) - to_unix_s(tb.min_end_time)) < 0.06
        assert to_unix_s(tb.min_end_time) > clock.t_s


def test_stream_pushes_messages_stamped_by_the_clock(client, clock):
    with client.websocket_connect("/spat/stream?timing=field_test&early_s=1&late_s=2&confidence=0.9") as ws:
        first = parse_spat_text(ws.receive_text())
        clock.t_s += 0.1
        for _ in range(3):
            later = parse_spat_text(ws.receive_text())
    assert not first.errors and not later.errors
    assert first.timestamp_unix_s == ENTRY_S + 5.0 and later.timestamp_unix_s == pytest.approx(ENTRY_S + 5.1, abs=1e-3)
    assert later.intersections[0].states[0].state_time_speed[0].timing.confidence == 10


def test_stream_refuses_bad_scenarios(client):
    from starlette.websockets import WebSocketDisconnect

    with pytest.raises(WebSocketDisconnect) as exc, client.websocket_connect("/spat/stream?corridor=nowhere") as ws:
        ws.receive_text()
    assert exc.value.code == 1008


def test_in_process_source_needs_no_feed(clock):
    source = InProcessSpatSource(make_scenario("paper_s400", "-15_15", ENTRY_S), clock=clock)
    reading = source.reading(1)
    assert reading.fresh and reading.age_s == 0.0
    plan = reading.plan(2)
    assert state_at(plan, clock()) == RED
    assert seconds_to_next_green(plan, clock()).likely_s == pytest.approx(10.0, abs=1e-3)
    assert source.fresh(2) is not None and source.reading(99) is None
    assert sorted(source.readings()) == [1, 2]
