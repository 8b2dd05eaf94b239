"""Hardening probed as an attacker would, against real ``python -m server`` processes on loopback (issue 15).

Every wait is bounded; nothing asserts on speed. The "attacker" connects from 127.0.0.2 (Linux routes all
of 127/8 to loopback), honest clients from 127.0.0.1, so per-address caps can be told apart.
"""

from __future__ import annotations

import asyncio
import json
import socket
import time

import httpx
import pytest
import websockets

from tests.server.conftest import SERVICE_ENV, Proc

ATTACKER = "127.0.0.2"


def _proc(tmp_path, *, access_log: bool = False, **env) -> Proc:
    args = ["-m", "server", "--log-level", "info"] + ([] if access_log else ["--no-access-log"])
    return Proc(args, tmp_path / "service.log", {**SERVICE_ENV, "ECO_CORRIDORS": "paper_s200", "ECO_DEFAULT_CORRIDOR": "paper_s200",
                                                 "ECO_TABLES": "false", "ECO_SPEECH": "false", **env})  # fmt: skip


def _sock(port: int, source: str = ATTACKER) -> socket.socket:
    s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    s.bind((source, 0))
    s.settimeout(15)
    s.connect(("127.0.0.1", port))
    return s


def _read_all(s: socket.socket, limit_s: float = 15.0) -> bytes:
    """Everything the server sends until it closes (bounded)."""
    s.settimeout(limit_s)
    out = b""
    try:
        while chunk := s.recv(65536):
            out += chunk
    except (TimeoutError, ConnectionResetError):
        pass
    return out


def test_half_sent_requests_are_timed_out_and_capped(start_proc, tmp_path):
    """Finding: 1,000 half-sent requests stayed open 40 s; with a 1,024-file limit /health failed 20 of 20."""
    svc = start_proc(_proc(tmp_path, ECO_READ_TIMEOUT_S="2", ECO_MAX_CONNECTIONS_PER_CLIENT="50"))
    half_header = [_sock(svc.port) for _ in range(30)]
    for s in half_header:
        s.sendall(b"GET /health HTTP/1.1\r\nHost: x\r\n")  # never finished
    silent = [_sock(svc.port) for _ in range(10)]  # never sends a byte
    trip = httpx.post(svc.base_url + "/v1/trips", json={}, timeout=10).json()
    half_body = _sock(svc.port)
    half_body.sendall(f"POST /v1/trips/{trip['trip_id']}/fixes HTTP/1.1\r\nHost: x\r\nAuthorization: Bearer {trip['token']}\r\n"
                      "Content-Type: application/json\r\nContent-Length: 200\r\n\r\n{\"t_unix_s\": 1".encode())  # fmt: skip
    half_create = _sock(svc.port)  # a body FastAPI reads itself (the fix route reads its own)
    half_create.sendall(b'POST /v1/trips HTTP/1.1\r\nHost: x\r\nContent-Type: application/json\r\nContent-Length: 200\r\n\r\n{"corridor": ')
    # over the per-address cap: answered 503 at once and closed
    extra = [_sock(svc.port) for _ in range(15)]
    refused = [_read_all(s, 10) for s in extra]
    assert sum(r.startswith(b"HTTP/1.1 503") for r in refused) >= 5
    # honest clients from another address are served throughout
    assert all(httpx.get(svc.base_url + "/health", timeout=10).status_code == 200 for _ in range(20))
    # the read deadline closes every half-sent request, with a 408 where nothing was answered
    answers = [_read_all(s) for s in half_header + silent + [half_body, half_create]]
    assert all(a.startswith(b"HTTP/1.1 408") for a in answers[:40]), set(a[:20] for a in answers)
    assert answers[-2].startswith(b"HTTP/1.1 408") and answers[-1].startswith(b"HTTP/1.1 408"), answers[-2:]
    for s in half_header + silent + extra + [half_body, half_create]:
        s.close()
    # the caps are released: the attacker's address may connect again, a keep-alive client works
    s = _sock(svc.port)
    s.sendall(b"GET /health HTTP/1.1\r\nHost: x\r\n\r\n")
    assert _read_all(s, 10).startswith(b"HTTP/1.1 200")
    metrics = httpx.get(svc.base_url + "/metrics", timeout=10).text
    assert 'status="500"' not in metrics and "process_open_fds" in metrics
    # a timed-out body is a 408, counted as one and logged in one line (issue 30: each was a 500 with a traceback)
    assert 'route="/v1/trips/{trip_id}/fixes",status="408"' in metrics and 'route="/v1/trips",status="408"' in metrics, metrics
    log = svc.log_path.read_text()
    assert "Traceback" not in log and "ERROR" not in log and "client disconnected" not in log, log[-3000:]
    assert log.count("request not received within 2 s") >= len(answers), log[-3000:]


def test_the_read_deadline_counts_from_each_request_on_a_kept_alive_connection(start_proc, tmp_path):
    """The connection keeps one timer across requests (server.web.protocol): a request begun after the first one's
    deadline would have passed gets its own full deadline, and a half-sent one is still cut off with a 408."""
    svc = start_proc(_proc(tmp_path, ECO_READ_TIMEOUT_S="2"))
    s = _sock(svc.port, "127.0.0.1")
    s.sendall(b"GET /health HTTP/1.1\r\nHost: x\r\n\r\n")
    assert s.recv(65536).startswith(b"HTTP/1.1 200")
    time.sleep(1.2)
    s.sendall(b'POST /v1/trips HTTP/1.1\r\nHost: x\r\nContent-Type: application/json\r\nContent-Length: 200\r\n\r\n{"corridor": ')  # half sent
    s.settimeout(1.3)  # until past where the first request's deadline was: nothing yet (this one's is 2 s from its start)
    with pytest.raises(TimeoutError):
        s.recv(65536)
    assert _read_all(s).startswith(b"HTTP/1.1 408")
    s.close()


def test_half_sent_headers_after_an_answered_request_get_a_408(start_proc, tmp_path):
    """On a kept-alive connection whose last request was answered, a next request whose headers never complete is cut
    off with a 408 too (before, the deadline saw the previous request's response as started and closed in silence)."""
    svc = start_proc(_proc(tmp_path, ECO_READ_TIMEOUT_S="1"))
    s = _sock(svc.port, "127.0.0.1")
    s.sendall(b"GET /health HTTP/1.1\r\nHost: x\r\n\r\n")
    assert s.recv(65536).startswith(b"HTTP/1.1 200")
    s.sendall(b"GET /health HTTP/1.1\r\nHost: x\r\n")  # the headers' end never comes
    assert _read_all(s).startswith(b"HTTP/1.1 408")
    s.close()


def test_client_disconnects_mid_body_are_not_server_errors(start_proc, tmp_path):
    """Finding: a body cut off mid-request counted as a 500 and wrote ~100 log lines."""
    svc = start_proc(_proc(tmp_path))
    trip = httpx.post(svc.base_url + "/v1/trips", json={}, timeout=10).json()
    for path, auth in ((f"/v1/trips/{trip['trip_id']}/fixes", f"Authorization: Bearer {trip['token']}\r\n"), ("/v1/trips", "")):
        s = _sock(svc.port, "127.0.0.1")
        s.sendall(f"POST {path} HTTP/1.1\r\nHost: x\r\n{auth}Content-Type: application/json\r\nContent-Length: 300\r\n\r\n{{\"a\": ".encode())
        time.sleep(0.3)
        s.close()
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline and svc.log_path.read_text().count("client disconnected") < 2:
        time.sleep(0.1)
    log = svc.log_path.read_text()
    assert log.count("client disconnected") == 2 and "Traceback" not in log and "ERROR" not in log, log[-3000:]
    metrics = httpx.get(svc.base_url + "/metrics", timeout=10).text
    assert 'status="499"' in metrics and 'status="500"' not in metrics


def test_tokens_never_reach_the_log_and_open_creation_is_announced(start_proc, tmp_path):
    """Finding: the trip token and the operator key landed in the access log (?token= on any route)."""
    svc = start_proc(_proc(tmp_path, access_log=True))
    trip = httpx.post(svc.base_url + "/v1/trips", json={}, timeout=10).json()
    token = trip["token"]
    assert httpx.get(f"{svc.base_url}/v1/trips/{trip['trip_id']}/advice?token={token}", timeout=10).status_code == 401
    assert httpx.get(f"{svc.base_url}/v1/trips/{trip['trip_id']}/advice", headers={"Authorization": f"Bearer {token}"}, timeout=10).status_code == 200
    httpx.get(f"{svc.base_url}/health?api_key=operator-secret", timeout=10)
    # issue 30: a key under any spelling of its name, on a 2xx, a 4xx and a WebSocket refused
    secrets = [f"operator-key-{i}" for i in range(5)]
    httpx.get(f"{svc.base_url}/health?X-API-Key={secrets[0]}&x%2Dapi%2Dkey={secrets[1]}&apiKey={secrets[2]}", timeout=10)
    assert httpx.post(f"{svc.base_url}/v1/trips?X-API-Key={secrets[3]}", content=b"{", headers={"Content-Type": "application/json"}, timeout=10).status_code == 422

    async def stream():
        url = svc.base_url.replace("http", "ws") + f"/v1/trips/{trip['trip_id']}/stream?token={token}"
        async with websockets.connect(url, open_timeout=10) as ws:
            await ws.send(json.dumps({"t_unix_s": time.time(), "lat_deg": 0.0, "lon_deg": 0.0}))
            return json.loads(await asyncio.wait_for(ws.recv(), 10))

    async def refused():
        url = svc.base_url.replace("http", "ws") + f"/v1/trips/{trip['trip_id']}/stream?X-Api-Key={secrets[4]}"
        async with websockets.connect(url, open_timeout=10) as ws:
            return json.loads(await asyncio.wait_for(ws.recv(), 10))

    assert asyncio.run(stream())["trip_id"] == trip["trip_id"]
    assert asyncio.run(refused())["status"] == 401
    time.sleep(0.5)
    log = svc.log_path.read_text()
    assert "/advice" in log and "stream" in log  # the lines are there, redacted
    assert token not in log and token.split(".")[1] not in log and "operator-secret" not in log and "token=***" in log
    assert not [s for s in secrets if s in log] and "X-API-Key=***" in log and "X-Api-Key=***" in log, log[-3000:]
    assert "TRIP CREATION IS OPEN" in log and "WARNING" in log


@pytest.mark.parametrize("keys", ["k-one"])
def test_creation_needs_a_key_when_keys_are_set_and_quotas_hold_per_client(start_proc, tmp_path, keys):
    svc = start_proc(_proc(tmp_path, ECO_API_KEYS=keys, ECO_API_KEY_QUOTAS=json.dumps({keys: {"max_trips": 2}}), ECO_MAX_CONNECTIONS_PER_CLIENT="0"))
    assert httpx.post(svc.base_url + "/v1/trips", json={}, timeout=10).status_code == 401
    codes = [httpx.post(svc.base_url + "/v1/trips", json={}, headers={"X-API-Key": keys}, timeout=10).status_code for _ in range(3)]
    assert codes == [201, 201, 429]
    assert "TRIP CREATION IS OPEN" not in svc.log_path.read_text()


def test_invalid_unicode_is_one_4xx_line_and_big_websocket_messages_are_413(start_proc, tmp_path):
    """Findings (issue 30): a lone surrogate in a trip-creation body was a 500 with a traceback every time; a
    WebSocket message over 16 KiB closed the stream (1009) instead of the documented 413 error message."""
    svc = start_proc(_proc(tmp_path, access_log=True, ECO_WS_MAX_FRAME_BYTES="65536"))
    for body in (b'{"corridor": "\\ud800"}', b'{"vehicle": "a\\udc00"}', '{"corridor": "\ud800"}'.encode("utf-8", "surrogatepass"), b"\xff\xfe{}"):
        r = httpx.post(svc.base_url + "/v1/trips", content=body, headers={"Content-Type": "application/json"}, timeout=10)
        assert r.status_code == 422 and r.json()["error"] == "malformed_json" and "Unicode" in r.json()["message"], (body, r.text)
    trip = httpx.post(svc.base_url + "/v1/trips", json={}, timeout=10).json()

    async def stream():
        url = svc.base_url.replace("http", "ws") + f"/v1/trips/{trip['trip_id']}/stream?token={trip['token']}"
        async with websockets.connect(url, open_timeout=10, max_size=None) as ws:
            out = []
            for message in ("x" * 17_000, "\u00e9" * 9_000, b"y" * 60_000, json.dumps({"t_unix_s": time.time(), "lat_deg": 0.0, "lon_deg": 0.0})):
                await ws.send(message)
                out.append(json.loads(await asyncio.wait_for(ws.recv(), 10)))
            await ws.send("z" * 70_000)  # over the frame cap: not even read
            with pytest.raises(websockets.ConnectionClosed) as closed:
                await asyncio.wait_for(ws.recv(), 10)
            return out, closed.value.rcvd.code

    answers, code = asyncio.run(stream())
    assert [a.get("status") for a in answers[:3]] == [413, 413, 413] and "18000 bytes" in answers[1]["message"], answers
    assert answers[3]["trip_id"] == trip["trip_id"] and code == 1009, (answers[3], code)
    time.sleep(0.3)
    log = svc.log_path.read_text()
    assert "Traceback" not in log and "ERROR" not in log, log[-3000:]
    assert log.count('"POST /v1/trips HTTP/1.1" 422') == 4, log[-3000:]
    metrics = httpx.get(svc.base_url + "/metrics", timeout=10).text
    assert 'status="500"' not in metrics and 'route="/v1/trips",status="422"} 4.0' in metrics
