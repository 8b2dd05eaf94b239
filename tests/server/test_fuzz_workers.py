"""No client input gets a 5xx across two workers on one Redis (issue 30, point 4): the fuzz of ``test_fuzz.py``
(same strategies: any body bytes, any JSON, odd query strings and headers, valid and wrong tokens and keys, other
methods) sent over real sockets to two real ``python -m server`` processes sharing a real ``redis-server``.

What the in-process fuzz does not reach: the Redis trip store (a trip created on one worker and fuzzed on the
other, its state loaded, saved and versioned there), the WebSocket leases in Redis, uvicorn and the guarded
HTTP protocol in front of the app. Each request goes to the worker that did **not** create its trip. Asserted:
no status >= 500 (but the documented ``503 speech_unavailable`` without speech), every JSON 4xx body of the API
``{"error", "message", ...}``, every WebSocket message answered with no 5xx and the stream still serving a
valid fix, and neither worker's log holds an ERROR or a traceback. Headers that frame the request
(``Content-Length``, ``Host``, ``Connection``, ``Expect``) are the client's own here: the framing is
``test_hardening.py``'s.

Bounded and deterministic (``derandomize=True``): 6 examples per route and method (20 where a body is read), 16
WebSocket sessions: up to 142 requests (each after 2 trips created on the other worker), ~20-30 s with the
workers' start on 2 shared cores.
"""

from __future__ import annotations

import asyncio
import json
import socket
import time
from urllib.parse import quote

import httpx
import pytest
import websockets
from hypothesis import given, settings as hsettings, strategies as st

from spat_feed import load_corridor
from tests.procs import Proc, RedisServer, redis_server_path
from tests.server.test_fuzz import API_KEY, BODY_ROUTES, CORRIDOR, FUZZ, HTTP_ROUTES, LIMIT, bodies, draw_request

LOTS = "1000000000"
ENV = {
    "ECO_CORRIDORS": CORRIDOR, "ECO_DEFAULT_CORRIDOR": CORRIDOR, "ECO_TABLES": "false", "ECO_SPEECH": "false", "ECO_API_KEYS": API_KEY,
    "ECO_RATE_PER_S": LOTS, "ECO_RATE_BURST": LOTS, "ECO_CREATE_RATE_PER_S": LOTS, "ECO_CREATE_BURST": LOTS, "ECO_KEY_CREATE_RATE_PER_S": LOTS,
    "ECO_KEY_CREATE_BURST": LOTS, "ECO_KEY_MAX_TRIPS": "0", "ECO_MAX_TRIPS_PER_DEVICE": "0", "ECO_CREATE_RATE_PER_CLIENT_PER_S": LOTS,
    "ECO_CREATE_BURST_PER_CLIENT": LOTS, "ECO_MAX_TRIPS_PER_CLIENT": "0", "ECO_MAX_BODY_BYTES": str(LIMIT),
    "ECO_WS_MAX_MESSAGE_BYTES": str(LIMIT), "ECO_METRICS_ACCESS": "public",
}  # fmt: skip
"""No rate limit or quota stops the fuzzer short of the handlers (as in ``test_fuzz.py``)."""
FRAMING = {b"content-length", b"host", b"connection", b"expect", b"transfer-encoding"}


@pytest.fixture(scope="module")
def workers(tmp_path_factory):
    if redis_server_path() is None:
        pytest.skip("redis-server is not installed and scripts/system-deps.sh could not install it (needs root and apt-get)")
    store = RedisServer(tmp_path_factory.mktemp("redis"), fsync="everysec").start()
    procs = []
    try:
        for i in range(2):
            folder = tmp_path_factory.mktemp(f"worker{i}")
            procs.append(Proc(["-m", "server", "--log-level", "warning", "--no-access-log"], folder / "service.log", {**ENV, "ECO_STORE_URL": store.url}).start())
        yield procs
    finally:
        for p in procs:
            p.kill()
        store.kill()


_turn = [0]


def _pair(workers: list[Proc]) -> tuple[Proc, Proc]:
    """(the worker that creates the trips, the one the request goes to), alternating."""
    _turn[0] += 1
    return (workers[0], workers[1]) if _turn[0] % 2 else (workers[1], workers[0])


def _trip(w: Proc) -> dict:
    r = httpx.post(w.base_url + "/v1/trips", json={}, headers={"X-API-Key": API_KEY}, timeout=30)
    assert r.status_code == 201, r.text
    return r.json()


def _valid_fix() -> dict:
    lat, lon = load_corridor(CORRIDOR).position(30.0)
    return {"t_unix_s": time.time() - 1.0, "lat_deg": lat, "lon_deg": lon, "speed_mps": 13.9, "heading_deg": 90.0, "accuracy_m": 4.0}


def raw_request(port: int, method: str, target: bytes, hdrs: list[tuple[bytes, bytes]], body: bytes) -> tuple[int, dict[bytes, bytes], bytes]:
    """One request on its own connection, bytes as given (the status, the response's headers, its body)."""
    head = [method.encode() + b" " + target + b" HTTP/1.1", b"host: 127.0.0.1", b"connection: close", b"content-length: %d" % len(body)]
    head += [k + b": " + v for k, v in hdrs if k.lower() not in FRAMING]
    with socket.create_connection(("127.0.0.1", port), timeout=30) as s:
        s.sendall(b"\r\n".join(head) + b"\r\n\r\n" + body)
        chunks = []
        while chunk := s.recv(65536):
            chunks.append(chunk)
    data = b"".join(chunks)
    head_out, _, payload = data.partition(b"\r\n\r\n")
    lines = head_out.split(b"\r\n")
    fields = dict(line.split(b":", 1) for line in lines[1:] if b":" in line)
    return int(lines[0].split()[1]), {k.strip().lower(): v.strip() for k, v in fields.items()}, payload


@pytest.mark.parametrize("method,template", HTTP_ROUTES, ids=[f"{m} {p}" for m, p in HTTP_ROUTES])
def test_no_client_input_gets_a_5xx_from_either_worker(workers, method, template):
    @hsettings(FUZZ, max_examples=20 if method == "POST" and template in BODY_ROUTES else 6)
    @given(data=st.data())
    def fuzz(data):
        maker, target = _pair(workers)
        odd_method, path, query, hdrs, body = draw_request(data, method, template, _trip(maker), _trip(maker), _valid_fix())
        url = quote(path, safe="/%").encode() + (b"?" + query if query else b"")
        status, out_headers, out = raw_request(target.port, odd_method, url, hdrs, body)
        what = f"{odd_method} {url[:200]!r} {hdrs!r} body {body[:200]!r}: {status} {out[:300]!r}"
        speechless = status == 503 and template.endswith("advice.wav") and json.loads(out)["error"] == "speech_unavailable"
        assert status < 500 or speechless, what
        if 400 <= status < 500 and odd_method != "HEAD" and out_headers.get(b"content-type", b"").startswith(b"application/json"):
            err = json.loads(out)
            assert isinstance(err["error"], str) and isinstance(err["message"], str), what

    fuzz()


def _ws_messages():
    text = st.one_of(bodies(_valid_fix()).map(lambda b: b.decode("utf-8", "replace")), st.just("x" * (LIMIT + 1)), st.just("é" * (LIMIT // 2 + 1)))
    return st.lists(st.one_of(text, st.one_of(bodies(_valid_fix()), st.just(b"y" * (LIMIT + 1)))), min_size=1, max_size=4)


@hsettings(FUZZ, max_examples=16)
@given(data=st.data())
def test_no_websocket_message_gets_a_5xx_from_either_worker_and_the_stream_goes_on(workers, data):
    maker, target = _pair(workers)
    trip = _trip(maker)
    messages = data.draw(_ws_messages(), label="messages")
    url = f"ws://127.0.0.1:{target.port}/v1/trips/{trip['trip_id']}/stream"

    async def session() -> list[dict]:
        answers = []
        async with websockets.connect(url, additional_headers={"Authorization": f"Bearer {trip['token']}"}, open_timeout=30, max_size=None) as ws:
            for message in [*messages, json.dumps(_valid_fix())]:
                await ws.send(message)
                answers.append(json.loads(await asyncio.wait_for(ws.recv(), 30)))
        return answers

    answers = asyncio.run(session())
    what = f"{[str(m)[:120] for m in messages]}: {[str(a)[:200] for a in answers]}"
    assert all(a.get("status", 200) < 500 for a in answers), what
    assert "error" not in answers[-1] and answers[-1]["trip_id"] == trip["trip_id"], what


def test_neither_worker_logged_an_error(workers):
    """After the fuzz above (this module's tests run in order): every refusal was a 4xx, none logged as an error."""
    for p in workers:
        log = p.log_path.read_text(errors="replace")
        assert "Traceback" not in log and " ERROR " not in log, log[-3000:]
