"""No client input gets a 5xx (issue 30, point 4): hypothesis over every route of the app, in process.

Each example is one request (or one WebSocket session) made straight through ASGI, so the fuzzer controls
what a real server would hand over: query strings of printable ASCII and percent-escapes of any byte, header
values of any Latin-1 byte, bodies of any bytes sent in one or two chunks, JSON with lone surrogates (escaped
and as raw bytes), huge numbers, ``NaN``/``Infinity``, deep nesting and wrong types, valid bodies with one
field spoiled, valid and wrong tokens and API keys, other methods. Asserted: no status >= 500 (but the documented ``503 speech_unavailable`` of a service
without speech), every 4xx body of the API ``{"error", "message", ...}``, and no log record at ERROR or with a
traceback. The WebSocket: every message gets one answer, none a 5xx, and the stream still serves a valid fix.
What only a real server shows (the read deadline, the WebSocket frame cap, access-log redaction) is in
``test_hardening.py``; schemathesis drives the live service from its OpenAPI schema in ``test_schemathesis.py``.

Bounded and deterministic (``derandomize=True``): 10 examples per route and method (40 where a body is read),
every field of each body replaced by each of ``NASTY``, 40 WebSocket sessions: 625 requests over 19 routes and
methods and 153 stream messages, ~3 s.
"""

from __future__ import annotations

import asyncio
import json
import logging
from urllib.parse import quote

import pytest
from fastapi.testclient import TestClient
from hypothesis import HealthCheck, given, settings as hsettings, strategies as st
from starlette.routing import Mount, Route

from server.app import create_app
from server.web.bodies import JsonBodyRoute
from server.config import Settings
from server.routes.trips import DirectRoute
from spat_feed import load_corridor  # the package's export: stable while its modules move

NOW = 1_800_000_000.0
API_KEY = "k-fuzz"
CORRIDOR = "paper_s200"
LIMIT = 16_384
FUZZ = hsettings(deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])


def _settings() -> Settings:
    lots = 1e9  # no rate limit or quota stops the fuzzer short of the handlers
    return Settings(corridors=(CORRIDOR,), default_corridor=CORRIDOR, tables=False, speech=False, api_keys=(API_KEY,), rate_per_s=lots,
                    rate_burst=lots, create_rate_per_s=lots, create_burst=lots, create_rate_per_client_per_s=lots,
                    create_burst_per_client=lots, max_trips_per_client=0, key_max_trips=0, key_create_rate_per_s=lots, key_create_burst=lots,
                    max_trips_per_device=0, max_body_bytes=LIMIT, ws_max_message_bytes=LIMIT)  # fmt: skip


class _Records(logging.Handler):
    def __init__(self) -> None:
        super().__init__(logging.DEBUG)
        self.records: list[logging.LogRecord] = []

    def emit(self, record: logging.LogRecord) -> None:
        self.records.append(record)


@pytest.fixture(scope="module")
def svc():
    records = _Records()  # at the root: what reaches a log at WARNING and above (the root's default level)
    root = logging.getLogger()
    root.addHandler(records)
    try:
        with TestClient(create_app(_settings(), clock=lambda: NOW)) as client:
            yield client, records
    finally:
        root.removeHandler(records)


# -- what a client may send ---------------------------------------------------------------------------------


class Raw(str):
    """JSON text emitted verbatim (numbers and nesting no JSON encoder writes)."""


RAW_JSON = [Raw(t) for t in ("NaN", "-Infinity", "Infinity", "1e999999", "-1e999999", "9" * 5000, "-" + "9" * 400, "1" + "0" * 400 + ".5",
                             "4e-400", "-0", "1E+2", "0x10", "01", ".5", "1.", "+1", "tru", "nul", '"\\u12"', '"\\x41"',
                             "[" * 199 + "]" * 199, "[" * 201 + "]" * 201, "[" * 5000, '{"a":' * 300 + "1" + "}" * 300, "\x00", "")]  # fmt: skip
SURROGATES = ["\ud800", "\udfff", "a\udc00b", "\ud83d", "\ud83d\ude00"[::-1]]
FIX_FIELDS = ["t_unix_s", "timestamp", "lat_deg", "lon_deg", "latitude", "longitude", "speed_mps", "speed", "heading_deg", "accuracy_m"]
TRIP_FIELDS = ["corridor", "timing", "vehicle", "entry_unix_s", "units", "device_id"]

texts = st.one_of(st.text(max_size=12), st.sampled_from(SURROGATES), st.text(st.characters(exclude_categories=()) | st.characters(min_codepoint=0xD800, max_codepoint=0xDFFF), max_size=6),
                  st.sampled_from([CORRIDOR, "15_15", "trip", "paper_54kwh", "imperial", "metric", "x" * 300]))  # fmt: skip
scalars = st.one_of(st.none(), st.booleans(), st.integers(-(2**70), 2**70), st.floats(allow_nan=True, allow_infinity=True), texts, st.sampled_from(RAW_JSON))
json_values = st.recursive(scalars, lambda inner: st.lists(inner, max_size=4) | st.dictionaries(texts | st.sampled_from(FIX_FIELDS + TRIP_FIELDS), inner, max_size=4),
                           max_leaves=8)  # fmt: skip


def dumps(value, ascii_only: bool) -> str:
    """JSON text of ``value``; surrogates escaped (``ascii_only``) or left raw; NaN and infinities as literals."""
    if isinstance(value, Raw):
        return str(value)
    if isinstance(value, dict):
        return "{" + ",".join(dumps(str(k), ascii_only) + ":" + dumps(v, ascii_only) for k, v in value.items()) + "}"
    if isinstance(value, list):
        return "[" + ",".join(dumps(v, ascii_only) for v in value) + "]"
    return json.dumps(value, ensure_ascii=ascii_only)


NASTY = [Raw('"\\ud800"'), Raw('"a\\udfffb"'), "\ud83d", Raw("NaN"), Raw("-Infinity"), Raw("1e999999"), Raw("9" * 5000), Raw("[" * 300 + "]" * 300),
         Raw('{"a":' * 300 + "1" + "}" * 300), True, "13.9", [], {}, None, -(2**80)]  # fmt: skip
"""Values every field of every JSON body gets in turn (a lone surrogate escaped, ``\\ud800``, and as raw bytes, ED A0 BD)."""


def encode(text: str) -> bytes:
    return text.encode("utf-8", "surrogatepass")  # a raw lone surrogate is ED A0 80: invalid UTF-8


def _valid_fix() -> dict:
    lat, lon = load_corridor(CORRIDOR).position(30.0)
    return {"t_unix_s": NOW, "lat_deg": lat, "lon_deg": lon, "speed_mps": 13.9, "heading_deg": 90.0, "accuracy_m": 4.0}


@st.composite
def spoiled(draw, base: dict):
    """A valid body, or one with a field replaced, removed or added."""
    body = dict(base)
    for _ in range(draw(st.integers(0, 2))):
        how = draw(st.sampled_from(["replace", "drop", "add"]))
        if how == "replace" and body:
            body[draw(st.sampled_from(sorted(body)))] = draw(st.sampled_from(NASTY) | json_values)
        elif how == "drop" and body:
            body.pop(draw(st.sampled_from(sorted(body))))
        else:
            body[draw(texts | st.sampled_from(FIX_FIELDS + TRIP_FIELDS))] = draw(json_values)
    return body


def bodies(base: dict):
    as_json = st.builds(lambda v, a: encode(dumps(v, a)), spoiled(base), st.booleans())
    return st.one_of(
        as_json,
        as_json,
        as_json,
        st.builds(lambda v, a: encode(dumps(v, a)), json_values, st.booleans()),
        st.binary(max_size=200),
        st.sampled_from([b"", b"{}", b"[]", b"null", b"\xef\xbb\xbf{}", "{}".encode("utf-16"), b"\xff\xfe", b'{"a": 1', b"{" * (LIMIT + 1),
                         b" " * LIMIT + b"{}", encode('{"corridor": "\ud800"}'), b'{"corridor": "\\ud800"}', b'{"t_unix_s": 1e999999}']),  # fmt: skip
    )


segments = texts.map(lambda t: encode(t).decode("utf-8", "replace")).filter(lambda t: t and "/" not in t)
"""A decoded path segment, as a server hands it over (uvicorn unquotes with ``errors="replace"``: no surrogates)."""


def _mostly(value, otherwise, times: int = 6):
    """``value`` most of the time (so that examples get past authentication to the handlers), else ``otherwise``."""
    return st.integers(0, times).flatmap(lambda k: otherwise if k == times else st.just(value))


def _pct(data: bytes) -> str:
    return "".join(f"%{b:02X}" for b in data)


query_parts = st.one_of(
    st.text(st.characters(min_codepoint=33, max_codepoint=126, exclude_characters="#"), max_size=20),  # raw printable ASCII: %, &, =, ; included
    st.builds(lambda k, v: f"{k}={v}", st.sampled_from(["token", "X-API-Key", "api_key", "corridor", "", "a"]),
              st.one_of(st.binary(max_size=8).map(_pct), st.sampled_from(["%ED%A0%80", "%FF", "%00", "%", "%zz", "%E2%82", API_KEY]))),
)  # fmt: skip
header_values = st.one_of(st.binary(max_size=30).map(lambda b: bytes(c for c in b if c >= 0x20 and c != 0x7F)), st.sampled_from([b"", b"\xff\xfe", b"\xed\xa0\x80"]))
CONTENT_TYPES = [b"application/json", b"application/json; charset=utf-8", b"application/json; charset=utf-16", b"application/vnd.x+json", b"text/plain",
                 b"application/x-www-form-urlencoded", b"multipart/form-data; boundary=x", b"multipart/form-data", b"application/json; charset=\xff", b";;", b""]  # fmt: skip


@st.composite
def headers(draw, token: str, other_token: str) -> list[tuple[bytes, bytes]]:
    out = []
    auth = draw(st.sampled_from(["token"] * 6 + ["other", "key", "none", "odd"]))
    if auth == "odd":
        out.append((b"authorization", draw(st.sampled_from([b"Bearer", b"Bearer ", b"bearer \xff\xfe", b"Basic Zm9vOmJhcg==", b"Bearer a.b.c"]) | header_values)))
    elif auth != "none":
        out.append((b"authorization", b"Bearer " + {"token": token, "other": other_token, "key": API_KEY}[auth].encode()))
    if draw(st.integers(0, 3)) == 3:
        out.append((b"x-api-key", draw(_mostly(API_KEY.encode(), st.sampled_from([b"wrong", b"\xff"]) | header_values, 2))))
    content_type = draw(_mostly(b"application/json", st.sampled_from(CONTENT_TYPES + [None]) | header_values, 3))
    if content_type is not None:
        out.append((b"content-type", content_type))
    if draw(st.booleans()):
        out.append((b"content-length", draw(st.sampled_from([b"0", b"1", b"99999999999999999999", b"-1", b"abc", b"\xd9\xa1", b" 1_0 "]) | header_values)))
    names = st.sampled_from([b"origin", b"accept", b"accept-encoding", b"cookie", b"host", b"x-forwarded-for", b"expect", b"range", b"if-none-match"])
    for _ in range(draw(st.integers(0, 2))):
        out.append((draw(names | st.binary(min_size=1, max_size=10).map(lambda b: bytes(c for c in b.lower() if 0x21 <= c < 0x7F and c != ord(":")) or b"x")),
                    draw(header_values)))  # fmt: skip
    return out


# -- driving the app through ASGI ---------------------------------------------------------------------------


def _scope(kind: str, method: str, path: str, query: bytes, hdrs: list[tuple[bytes, bytes]]) -> dict:
    scope = {"type": kind, "asgi": {"version": "3.0"}, "http_version": "1.1", "scheme": "http" if kind == "http" else "ws", "path": path,
             "raw_path": quote(path).encode(), "root_path": "", "query_string": query, "headers": hdrs, "client": ("127.0.0.1", 50000),
             "server": ("127.0.0.1", 8000), "state": {}}  # fmt: skip
    if kind == "http":
        scope["method"] = method
    return scope


async def _http(app, scope: dict, chunks: list[bytes]) -> tuple[int, bytes]:
    incoming = [{"type": "http.request", "body": c, "more_body": i < len(chunks) - 1} for i, c in enumerate(chunks)]
    done = asyncio.Event()
    status, body = [], []

    async def receive():
        if incoming:
            return incoming.pop(0)
        await done.wait()  # as a server: the client goes only once answered
        return {"type": "http.disconnect"}

    async def send(message):
        if message["type"] == "http.response.start":
            status.append(message["status"])
        elif message["type"] == "http.response.body":
            body.append(message.get("body", b""))
            if not message.get("more_body", False):
                done.set()

    await asyncio.wait_for(app(scope, receive, send), 30)
    return status[0], b"".join(body)


async def _ws(app, scope: dict, messages: list[dict]) -> list[dict]:
    """A WebSocket session: connect, each message awaiting one answer (or the close), disconnect."""
    inbox: asyncio.Queue = asyncio.Queue()
    outbox: asyncio.Queue = asyncio.Queue()
    await inbox.put({"type": "websocket.connect"})
    task = asyncio.create_task(app(scope, inbox.get, outbox.put))
    seen = [await asyncio.wait_for(outbox.get(), 30)]
    for message in messages:
        if seen[-1]["type"] == "websocket.close":
            break
        await inbox.put(message)
        seen.append(await asyncio.wait_for(outbox.get(), 30))
    if seen[-1]["type"] != "websocket.close":
        await inbox.put({"type": "websocket.disconnect", "code": 1000})
    await asyncio.wait_for(task, 30)
    while not outbox.empty():
        seen.append(outbox.get_nowait())
    return seen


def _trip(client: TestClient) -> dict:
    r = client.post("/v1/trips", json={}, headers={"X-API-Key": API_KEY})
    assert r.status_code == 201, r.text
    return r.json()


def _quiet(records: _Records, what: str) -> None:
    bad = [r for r in records.records if r.levelno >= logging.ERROR or r.exc_info]
    assert not bad, f"{what}: " + "; ".join(f"{r.levelname} {r.name} {r.getMessage()[:300]} {r.exc_info and r.exc_info[1]!r}" for r in bad)


def _http_routes() -> list[tuple[str, str]]:
    app = create_app(_settings())
    out = []
    for route in app.routes:
        if isinstance(route, Mount):
            out.append(("GET", route.path + "/{path}"))
        elif isinstance(route, Route):
            out += [(m, route.path) for m in sorted(route.methods - {"HEAD"})]
    return out


HTTP_ROUTES = _http_routes()
BODY_ROUTES = [r.path for r in create_app(_settings()).routes if getattr(r, "body_field", None) is not None or isinstance(r, DirectRoute)]


def test_every_json_body_is_parsed_strictly():
    """Every route that takes a JSON body parses it with jiter (``server.web.bodies``) or reads it raw (``DirectRoute``):
    Python's ``json.loads`` lets lone surrogates and invalid UTF-8 through (a 500 on ``POST /v1/trips``)."""
    app = create_app(_settings())
    with_body = [r for r in app.routes if getattr(r, "body_field", None) is not None]
    assert with_body and all(isinstance(r, (JsonBodyRoute, DirectRoute)) for r in with_body), [(r.path, type(r).__name__) for r in with_body]
    assert len(HTTP_ROUTES) >= 18 and ("POST", "/v1/trips") in HTTP_ROUTES and ("GET", "/docs/assets/{path}") in HTTP_ROUTES


def _check(client: TestClient, records: _Records, method: str, template: str, path: str, query: bytes, hdrs: list, body: bytes, cut: int) -> None:
    """One request through ASGI (the body in two chunks, cut at ``cut``): no 5xx, a JSON error body, no error logged."""
    records.records.clear()
    status, out = client.portal.call(_http, client.app, _scope("http", method, path, query, hdrs), [body[:cut], body[cut:]])
    what = f"{method} {path[:200]!r} ?{query!r} {hdrs!r} body {body[:200]!r}: {status} {out[:300]!r}"
    speechless = status == 503 and template.endswith("advice.wav") and json.loads(out)["error"] == "speech_unavailable"
    assert status < 500 or speechless, what
    if 400 <= status < 500 and method != "HEAD" and not template.startswith(("/app", "/docs")):  # static files: Starlette's own 400/416 for a bad Range
        err = json.loads(out)
        assert isinstance(err["error"], str) and isinstance(err["message"], str), what
    _quiet(records, what)

@pytest.mark.parametrize("template", BODY_ROUTES)
def test_known_nasty_bodies_on_every_body_route(svc, template):
    """Finding: a lone surrogate in a trip-creation body was a 500 every time (``json.loads`` let it through and the
    error message quoting it could not be encoded). Each field of a valid body, then the whole body, replaced by
    each of ``NASTY``."""
    client, records = svc
    trip = _trip(client)
    base = _valid_fix() if template.endswith("/fixes") else {"corridor": CORRIDOR, "timing": "15_15", "vehicle": "paper_54kwh", "entry_unix_s": NOW, "units": "metric"}
    path = template.replace("{trip_id}", trip["trip_id"])
    hdrs = [(b"authorization", b"Bearer " + (trip["token"] if "{trip_id}" in template else API_KEY).encode()), (b"content-type", b"application/json")]
    for field in [*base, "\ud800", None]:
        for value in NASTY:
            body = value if field is None else {**base, field: value}
            for ascii_only in (True, False) if isinstance(value, str) else (True,):
                data = encode(dumps(body, ascii_only))
                _check(client, records, "POST", template, path, b"", hdrs, data, len(data) // 2)


@pytest.mark.parametrize("method,template", HTTP_ROUTES, ids=[f"{m} {p}" for m, p in HTTP_ROUTES])
def test_no_client_input_gets_a_5xx(svc, method, template):
    """Hypothesis per route and method: 40 examples where a body is read, 10 elsewhere."""

    @hsettings(FUZZ, max_examples=40 if method == "POST" and template in BODY_ROUTES else 10)
    @given(data=st.data())
    def fuzz(data):
        _fuzz_request(svc, method, template, data)

    fuzz()


def _fuzz_request(svc, method: str, template: str, data) -> None:
    client, records = svc
    odd_method, path, query, hdrs, body = draw_request(data, method, template, _trip(client), _trip(client), _valid_fix())
    cut = data.draw(st.integers(0, len(body)), label="cut")
    _check(client, records, odd_method, template, path, query, hdrs, body, cut)


def draw_request(data, method: str, template: str, trip: dict, other: dict, fix: dict) -> tuple[str, str, bytes, list[tuple[bytes, bytes]], bytes]:
    """A request to the route ``method template``: (method, path, query string, headers, body), mostly with
    ``trip``'s id and token (sometimes ``other``'s, or none), a body from ``fix`` on ``/fixes``."""
    values = {
        "trip_id": _mostly(trip["trip_id"], st.sampled_from([other["trip_id"], "0" * 32, "x" * 65]) | segments),
        "name": _mostly(CORRIDOR, st.just(CORRIDOR + "x") | segments),
        "path": st.sampled_from(["index.html", "app.js", "swagger-ui.css", "..%2F..%2Fetc%2Fpasswd", "a/../../x", ".", ""]) | segments,
    }
    path = template
    for name, strategy in values.items():
        path = path.replace("{" + name + "}", data.draw(strategy, label=name))
    odd_method = data.draw(_mostly(method, st.sampled_from(["PUT", "DELETE", "PATCH", "OPTIONS", "HEAD"])), label="method")
    query = "&".join(data.draw(st.lists(query_parts, max_size=3), label="query")).encode()
    hdrs = data.draw(headers(trip["token"] if "{trip_id}" in template else API_KEY, other["token"]), label="headers")
    base = fix if template.endswith("/fixes") else {"corridor": CORRIDOR, "units": "metric"}
    body = data.draw(bodies(base), label="body") if odd_method in ("POST", "PUT", "PATCH") or data.draw(st.booleans(), label="get body") else b""
    return odd_method, path, query, hdrs, body


def _ws_messages():
    fix = _valid_fix()
    text = st.one_of(bodies(fix).map(lambda b: b.decode("utf-8", "replace")), st.just("x" * (LIMIT + 1)), st.just("é" * (LIMIT // 2 + 1)))
    frame = st.one_of(text.map(lambda t: {"type": "websocket.receive", "text": t}),
                      st.one_of(bodies(fix), st.just(b"y" * (LIMIT + 1))).map(lambda b: {"type": "websocket.receive", "bytes": b}))  # fmt: skip
    return st.lists(frame, min_size=1, max_size=4)


@hsettings(FUZZ, max_examples=40)
@given(data=st.data())
def test_no_websocket_message_gets_a_5xx_and_the_stream_goes_on(svc, data):
    client, records = svc
    trip, other = _trip(client), _trip(client)
    trip_id = data.draw(_mostly(trip["trip_id"], st.sampled_from([other["trip_id"], "0" * 32, "x" * 65]) | segments, 4), label="trip_id")
    how = data.draw(_mostly("query", st.sampled_from(["header", "other", "none"])), label="auth")
    query = f"token={trip['token']}".encode() if how == "query" else b""
    query += b"&" + "&".join(data.draw(st.lists(query_parts, max_size=2), label="query")).encode()
    hdrs = data.draw(headers(trip["token"], other["token"]), label="headers")
    hdrs = [(k, v) for k, v in hdrs if k != b"authorization"]
    if how in ("header", "other"):
        hdrs.append((b"authorization", f"Bearer {trip['token'] if how == 'header' else other['token']}".encode()))
    messages = data.draw(_ws_messages(), label="messages")
    last = {"type": "websocket.receive", "text": json.dumps({**_valid_fix(), "t_unix_s": NOW + 1.0})}
    records.records.clear()
    seen = client.portal.call(_ws, client.app, _scope("websocket", "GET", f"/v1/trips/{trip_id}/stream", query, hdrs), messages + [last])
    what = f"{trip_id[:100]!r} {how} {hdrs!r} {[str(m)[:120] for m in messages]}: {[str(s)[:200] for s in seen]}"
    answers = [json.loads(s["text"]) for s in seen if s["type"] == "websocket.send"]
    assert all(a.get("status", 200) < 500 for a in answers), what
    closes = [s for s in seen if s["type"] == "websocket.close"]
    assert all(4400 <= c.get("code", 1000) < 4500 for c in closes), what
    if seen[0]["type"] == "websocket.accept" and not closes:  # an open stream answered every message and still serves
        assert len(answers) == len(messages) + 1 and "error" not in answers[-1] and answers[-1]["trip_id"] == trip_id, what
    _quiet(records, what)
