"""The API a mobile developer can pick up (issue 15, "API"): one test per finding, in-process (injected clock).

What needs a real server (timeouts, connection caps, logs) is in ``test_hardening.py``.
"""

from __future__ import annotations

import ast
import asyncio
import re
import sys
from pathlib import Path

import numpy as np
import pytest
from fastapi.testclient import TestClient
from starlette.websockets import WebSocketDisconnect
from hypothesis import given, settings as hsettings, strategies as st

from advisory.advice import advisor, views
from advisory.advice.advisor import advise
from advisory.advice.views import AdvisorMemory, LightView, Observation
from server.app import create_app
from server.config import Settings
from server.schemas import AdviceOut
from server.storage.store import Limits
from spat_feed.road.corridors import load_corridor

NOW = 1_800_000_000.0


def make(**kw) -> TestClient:
    base = dict(corridors=("paper_s200",), default_corridor="paper_s200", tables=False, speech=False)
    return TestClient(create_app(Settings(**{**base, **kw}), clock=lambda: NOW))


@pytest.fixture(scope="module")
def client():
    with make() as c:
        yield c


def trip(client, **body):
    r = client.post("/v1/trips", json=body)
    assert r.status_code == 201, r.text
    d = r.json()
    return d, {"Authorization": f"Bearer {d['token']}"}


def fix(station_m=20.0, t=NOW, **kw):
    lat, lon = load_corridor("paper_s200").position(station_m)
    return {"t_unix_s": t, "lat_deg": lat, "lon_deg": lon, "speed_mps": 13.9, **kw}


# -- every action and reason is in the schema -------------------------------------------------------------


def _advice_literals() -> tuple[set[str], set[str]]:
    """String literals the advisor module passes as action / reason: ``Advice("x", "y", ...)`` and the
    action-mapping dicts (independent of the exported constants)."""
    tree = ast.parse(Path(advisor.__file__).read_text())
    actions, reasons = set(), set()

    def strings(node) -> set[str]:
        return {n.value for n in ast.walk(node) if isinstance(n, ast.Constant) and isinstance(n.value, str)}

    for node in ast.walk(tree):
        if isinstance(node, ast.Call) and getattr(node.func, "id", None) == "Advice" and len(node.args) >= 2:
            first = node.args[0]
            if isinstance(first, ast.Constant) or isinstance(first, ast.IfExp):
                actions |= strings(first)
            reasons |= strings(node.args[1])
        if isinstance(node, ast.Assign) and any(getattr(t, "id", None) == "action" for t in node.targets):
            value = node.value
            if isinstance(value, ast.Call) and isinstance(value.func, ast.Attribute) and isinstance(value.func.value, ast.Dict):
                actions |= {v.value for v in value.func.value.values} | strings(ast.Tuple(elts=value.args[1:]))
            elif isinstance(value, ast.Constant):
                actions.add(value.value)
    return actions, reasons


def test_every_action_and_reason_the_advisor_writes_is_in_the_schema():
    """Finding: `action` took values the schema did not list (coast, slow_down, brake_to)."""
    from server.schemas import Action, Reason

    actions, reasons = _advice_literals()
    assert {"coast", "slow_down", "brake_to", "stop", "none"} <= actions  # the scan finds them
    assert actions <= {a.value for a in Action} and reasons - {"last"} <= {r.value for r in Reason}, (actions, reasons)
    schema = AdviceOut.model_json_schema()
    assert set(schema["$defs"]["Action"]["enum"]) == set(views.ACTIONS)


@hsettings(max_examples=150, deadline=None)
@given(
    st.floats(0.0, 25.0), st.floats(5.0, 700.0), st.floats(5.0, 700.0), st.floats(-40.0, 40.0), st.floats(-40.0, 40.0),
    st.booleans(), st.floats(0.0, 1.0), st.integers(1, 4),
)
def test_whatever_the_advisor_answers_validates(v, d1, d2, r1, r2, fresh, conf, steps):
    from server.schemas import Action, Reason

    memory = AdvisorMemory()
    for k in range(steps):
        lights = (
            LightView(1, d1 - 10 * k, fresh, conf, ((r1, r1 + 30.0), (r1 + 60, r1 + 90))),
            LightView(2, d1 + d2 - 10 * k, True, 1.0, ((r2, r2 + 30.0),)),
        )
        a, memory = advise(Observation(v, 24.6, tuple(lt for lt in lights if lt.distance_m > 0), position_m=100.0), memory)
        Action(a.action), Reason(a.reason)


# -- units, CORS, docs ------------------------------------------------------------------------------------


def test_units_per_trip_default_metric_on_the_paris_corridors(client):
    """Finding: advice only in mph (55 mph on the Champs-Elysees)."""
    d, auth = trip(client, timing="-30_-30")
    assert d["units"] == "metric"
    a = client.post(f"/v1/trips/{d['trip_id']}/fixes", json=fix(), headers=auth).json()
    assert "kilometers per hour" in a["message"] and "miles" not in a["message"], a["message"]
    d, auth = trip(client, timing="-30_-30", units="imperial")
    a = client.post(f"/v1/trips/{d['trip_id']}/fixes", json=fix(), headers=auth).json()
    assert d["units"] == "imperial" and "miles per hour" in a["message"]
    assert client.post("/v1/trips", json={"units": "furlongs"}).status_code == 422


def test_cors_is_off_by_default_and_configurable():
    """Finding: no CORS, a browser's preflight got 405."""
    pre = {"Origin": "https://app.example", "Access-Control-Request-Method": "POST", "Access-Control-Request-Headers": "authorization,content-type"}
    with make() as c:
        assert "access-control-allow-origin" not in c.options("/v1/trips", headers=pre).headers
    with make(cors_origins=("https://app.example",)) as c:
        r = c.options("/v1/trips", headers=pre)
        assert r.status_code == 200 and r.headers["access-control-allow-origin"] == "https://app.example"
        assert "authorization" in r.headers["access-control-allow-headers"].lower()
        r = c.post("/v1/trips", json={}, headers={"Origin": "https://app.example"})
        assert "location" in r.headers["access-control-expose-headers"].lower()
        assert "access-control-allow-origin" not in c.options("/v1/trips", headers={**pre, "Origin": "https://evil.example"}).headers


def test_openapi_has_security_schemes_a_valid_example_and_public_descriptions(client):
    """Findings: no security scheme, an example fix (t 0, lat -90) that always failed, implementation notes."""
    doc = client.get("/openapi.json").json()
    schemes = doc["components"]["securitySchemes"]
    assert schemes["TripToken"] == {**schemes["TripToken"], "type": "http", "scheme": "bearer"} and schemes["ApiKey"]["type"] == "apiKey"
    post_fix = doc["paths"]["/v1/trips/{trip_id}/fixes"]["post"]
    assert post_fix["security"] == [{"TripToken": []}] and doc["paths"]["/v1/trips"]["post"]["security"][0] == {"ApiKey": []}
    example = post_fix["requestBody"]["content"]["application/json"]["example"]
    d, auth = trip(client)
    r = client.post(f"/v1/trips/{d['trip_id']}/fixes", json={**example, "t_unix_s": NOW}, headers=auth)  # dated now by the live service
    assert r.status_code == 200 and r.json()["on_route"], r.text
    text = str(doc)
    for internal in ("DirectRoute", "hot path", "thread hop", "pydantic_core", "model_construct"):
        assert internal not in text, internal
    assert set(doc["components"]["schemas"]["Reason"]["enum"]) >= {"green_wave", "poor_gps", "no_fix"}


def test_docs_are_served_by_the_service_itself(client):
    """Finding: /docs was blank offline (Swagger UI from a CDN)."""
    for page in ("/docs", "/redoc"):
        html = client.get(page).text
        assert not re.findall(r"(?:src|href)=\"https?://", html), page
        for asset in re.findall(r"(?:src|href)=\"(/docs/assets/[^\"]+)\"", html):
            r = client.get(asset)
            assert r.status_code == 200 and len(r.content) > 1000, asset


def test_docs_and_metrics_access_in_api_key_mode():
    with make(api_keys=("k1",)) as c:
        assert c.get("/metrics").status_code == 401 and c.get("/metrics", headers={"X-API-Key": "k1"}).status_code == 200
        assert c.get("/docs").status_code == 200  # public by default
    with make(api_keys=("k1",), docs_access="api_key", metrics_access="public") as c:
        assert c.get("/openapi.json").status_code == 401 and c.get("/openapi.json", headers={"X-API-Key": "k1"}).status_code == 200
        assert c.get("/metrics").status_code == 200
    with make(docs_access="off", metrics_access="off") as c:
        assert c.get("/docs").status_code == 404 and c.get("/metrics").status_code == 404


def test_process_metrics(client):
    text = client.get("/metrics").text
    assert "process_resident_memory_bytes" in text and "process_open_fds" in text


# -- trips and fixes ----------------------------------------------------------------------------------------


def test_get_trip_and_location(client):
    """Findings: no GET /v1/trips/{id}, no Location on 201."""
    r = client.post("/v1/trips", json={"timing": "15_15"})
    d = r.json()
    assert r.headers["location"] == f"/v1/trips/{d['trip_id']}" == d["links"]["trip"]
    auth = {"Authorization": f"Bearer {d['token']}"}
    got = client.get(r.headers["location"], headers=auth).json()
    assert got["trip_id"] == d["trip_id"] and got["timing"] == "15_15" and got["n_fixes"] == 0 and "token" not in got
    client.post(f"/v1/trips/{d['trip_id']}/fixes", json=fix(), headers=auth)
    assert client.get(r.headers["location"], headers=auth).json()["n_fixes"] == 1
    assert client.get(r.headers["location"]).status_code == 401


def test_fields_are_rounded_as_documented(client):
    """Finding: unrounded floats (24.140160000000016)."""
    d, auth = trip(client, timing="-30_-30", units="imperial")
    a = client.post(f"/v1/trips/{d['trip_id']}/fixes", json=fix(speed_mps=20.123456789), headers=auth).json()
    assert a["target_speed_mps"] is not None
    for key, digits in (("speed_mps", 2), ("target_speed_mps", 2), ("station_m", 2), ("t_unix_s", 3), ("seconds_to_change_s", 1)):
        if a[key] is not None:
            assert a[key] == round(a[key], digits), (key, a[key])
    props = AdviceOut.model_json_schema()["properties"]
    assert "0.01" in props["target_speed_mps"]["description"] and "0.1" in props["seconds_to_change_s"]["description"]


@pytest.mark.parametrize(
    "body,ok",
    [
        ({"timestamp": NOW * 1000, "latitude": "LAT", "longitude": "LON", "speed": 13.9, "heading": 295.0, "accuracy": 5.0}, True),
        ({"timestamp": NOW * 1000, "latitude": "LAT", "longitude": "LON", "speed": None, "heading": None}, True),  # JS NaN -> null
        # a flattened GeolocationCoordinates as a phone gives it: altitude fields always there, null on most phones
        ({"timestamp": NOW * 1000, "latitude": "LAT", "longitude": "LON", "accuracy": 4.0, "altitude": None, "altitudeAccuracy": None,
          "heading": None, "speed": None}, True),  # fmt: skip
        ({"timestamp": NOW * 1000, "latitude": "LAT", "longitude": "LON", "accuracy": 4.0, "altitude": 87.4, "altitudeAccuracy": 6.0}, True),
        ({"t_unix_s": NOW, "lat_deg": "LAT", "lon_deg": "LON", "altitude_m": 87.4, "altitude_accuracy_m": 6.0}, True),
        ({"t_unix_s": NOW, "lat_deg": "LAT", "lon_deg": "LON", "altitude_m": "87"}, False),
        ({"t_unix_s": NOW, "lat_deg": "LAT", "lon_deg": "LON", "altitude_accuracy_m": -1.0}, False),
        ({"t_unix_s": NOW, "lat_deg": "LAT", "lon_deg": "LON", "speed_mps": True}, False),
        ({"t_unix_s": NOW, "lat_deg": "LAT", "lon_deg": "LON", "speed_mps": "13.9"}, False),
        ({"t_unix_s": str(NOW), "lat_deg": "LAT", "lon_deg": "LON"}, False),
        ({"t_unix_s": NOW, "timestamp": NOW * 1000, "lat_deg": "LAT", "lon_deg": "LON"}, False),
        ({"t_unix_s": NOW, "lat_deg": "LAT", "latitude": "LAT", "lon_deg": "LON"}, False),
    ],
    ids=["w3c names", "w3c nulls", "w3c coords null altitude", "w3c altitude", "our altitude names", "altitude string", "altitude accuracy < 0", "speed true", "speed string", "time string", "both times", "both latitudes"],
)
def test_w3c_names_and_strict_numbers(client, body, ok):
    """Findings: W3C Geolocation names rejected; "speed_mps": true taken as 1.0; numeric strings passed."""
    d, auth = trip(client)
    lat, lon = load_corridor("paper_s200").position(20.0)
    body = {k: lat if v == "LAT" else lon if v == "LON" else v for k, v in body.items()}
    r = client.post(f"/v1/trips/{d['trip_id']}/fixes", json=body, headers=auth)
    assert (r.status_code == 200) is ok, r.text
    if ok:
        assert r.json()["t_unix_s"] == NOW and r.json()["on_route"]
    else:
        assert r.json()["error"] == "validation_error"


def test_a_javascript_millisecond_timestamp_gets_a_hint(client):
    d, auth = trip(client)
    r = client.post(f"/v1/trips/{d['trip_id']}/fixes", json=fix(t=NOW * 1000), headers=auth)
    assert r.status_code == 422 and "milliseconds" in r.json()["message"] and "timestamp" in r.json()["message"]
    r = client.post(f"/v1/trips/{d['trip_id']}/fixes", json={**fix(), "t_unix_s": None, "timestamp": NOW}, headers=auth)
    assert r.status_code == 422 and "looks like seconds" in r.json()["message"]


def test_retry_after_agrees_with_the_message():
    """Finding: Retry-After: 1 while the message said 0.1 s."""
    error = Limits(Settings(rate_per_s=10.0, rate_burst=1.0)).trip_rate(0.1)  # the finding's wait
    assert error.headers == {"Retry-After": "1"} and "retry in 1 s" in error.message
    with make(rate_per_s=0.001, rate_burst=1.0) as c:  # refills in 1000 s: the second request is refused however slow
        d, auth = trip(c)
        codes = [c.get(f"/v1/trips/{d['trip_id']}/advice", headers=auth) for _ in range(2)]
        assert [x.status_code for x in codes] == [200, 429]
        seconds = codes[1].headers["retry-after"]
        assert seconds.isdigit() and f"retry in {seconds} s" in codes[1].json()["message"]


def test_rest_refuses_a_token_in_the_query(client):
    """Finding: ?token= worked on every REST route (the docs said WebSocket only)."""
    d, auth = trip(client)
    r = client.get(f"/v1/trips/{d['trip_id']}/advice?token={d['token']}")
    assert r.status_code == 401 and r.json()["error"] == "token_in_query"


def test_a_future_dated_fix_does_not_blind_the_trip():
    """Finding: one fix dated 30 s ahead made every honest fix out_of_order for 29 s."""
    now = [NOW]
    with TestClient(create_app(Settings(corridors=("paper_s200",), default_corridor="paper_s200", tables=False, speech=False), clock=lambda: now[0])) as c:
        d, auth = trip(c)
        r = c.post(f"/v1/trips/{d['trip_id']}/fixes", json=fix(t=NOW + 30), headers=auth)
        assert r.status_code == 422 and r.json()["error"] == "time_out_of_range"
        statuses = []
        for k in range(1, 5):
            now[0] = NOW + k
            statuses.append(c.post(f"/v1/trips/{d['trip_id']}/fixes", json=fix(20.0 + 14 * k, t=NOW + k), headers=auth).json()["fix_status"])
        assert statuses == ["ok"] * 4


def test_per_client_trip_quota_and_creation_rate():
    """Finding: one client filled the 20,000-trip cap and locked everyone out for 30 minutes."""
    with make(max_trips_per_client=3, create_rate_per_client_per_s=1000.0) as c:
        codes = [c.post("/v1/trips", json={}).status_code for _ in range(4)]
        assert codes == [201, 201, 201, 429]
        assert c.post("/v1/trips", json={}).json()["error"] == "too_many_trips_for_client"
    with make(create_rate_per_client_per_s=0.01, create_burst_per_client=2.0) as c:
        r = [c.post("/v1/trips", json={}) for _ in range(3)]
        assert [x.status_code for x in r] == [201, 201, 429] and int(r[2].headers["retry-after"]) >= 1
    with make(api_keys=("a", "b"), key_max_trips=1) as c:  # quotas per key
        assert c.post("/v1/trips", json={}, headers={"X-API-Key": "a"}).status_code == 201
        assert c.post("/v1/trips", json={}, headers={"X-API-Key": "a"}).status_code == 429
        assert c.post("/v1/trips", json={}, headers={"Authorization": "Bearer b"}).status_code == 201


def test_websocket_messages_keep_the_trip_alive_and_streams_are_capped():
    """Findings: a streaming trip's last_seen was set only at connect (it expired mid-drive and its score was
    lost); one token opened 5,000 WebSockets."""
    with make(ws_max_per_trip=2) as c:
        d, auth = trip(c)
        engine = c.app.state.engine
        t = engine.trips.get(d["trip_id"])
        url = f"/v1/trips/{d['trip_id']}/stream?token={d['token']}"
        with c.websocket_connect(url) as ws1, c.websocket_connect(url) as ws2:
            t.last_seen_s -= 1000.0
            ws1.send_json(fix())
            ws1.receive_json()
            assert engine.trips.idle(500.0) == []  # the message refreshed it
            with c.websocket_connect(url) as ws3:  # a third replaces the oldest: never more than 2 open
                told = ws1.receive_json()
                assert told["status"] == 409 and told["error"] == "stream_replaced"
                with pytest.raises(WebSocketDisconnect) as closed:
                    ws1.receive_json()
                assert closed.value.code == 4409
                ws3.send_json(fix(30.0, NOW + 1))
                assert ws3.receive_json()["seq"] == 2
            ws2.send_json(fix(40.0, NOW + 2))
            assert ws2.receive_json()["seq"] == 3
            assert c.app.state.streams.by_trip[d["trip_id"]] == [c.app.state.streams.by_trip[d["trip_id"]][0]]  # ws2's, still counted


def test_a_streamed_fix_wakes_the_streams_own_frames_only():
    """A streamed fix wakes its task twice (its message, then Redis's reply), and a wake-up resumes every frame the
    task is suspended in: the messages are served by a task of their own (the route's task awaits it), not under the
    ~20 frames of uvicorn, Starlette, FastAPI and the middlewares (issue 30). Counted here: the frames resumed by a
    wake-up inside a fix, up to the event loop's callback, and the answers are the stream's as before."""
    with make() as c:
        d, _ = trip(c)
        engine = c.app.state.engine
        apply, depths = engine.apply_fix_json, []

        async def woken(*args):
            await asyncio.sleep(0)  # a wake-up, as for Redis's reply
            frame, n = sys._getframe(), 0
            while frame is not None and frame.f_code.co_name != "_run":  # up to asyncio.events.Handle._run, the loop's callback
                frame, n = frame.f_back, n + 1
            depths.append(n)
            return await apply(*args)

        engine.apply_fix_json = woken
        with c.websocket_connect(f"/v1/trips/{d['trip_id']}/stream?token={d['token']}") as ws:
            for k in range(3):
                ws.send_json(fix(20.0 + 14.0 * k, NOW + k))
                assert ws.receive_json()["seq"] == k + 1
    assert depths == [2, 2, 2]  # this function and the stream's message loop


def test_score_values_are_rounded(client):
    d, auth = trip(client, timing="-30_-30")
    for k in range(6):
        client.post(f"/v1/trips/{d['trip_id']}/fixes", json=fix(20.0 * k, NOW + k), headers=auth)
    s = client.post(f"/v1/trips/{d['trip_id']}/end", headers=auth).json()
    assert s["regular"]["energy_kwh"] == round(s["regular"]["energy_kwh"], 6)
    assert np.isfinite(s["entry_unix_s"])
