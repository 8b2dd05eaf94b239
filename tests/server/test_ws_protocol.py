"""The service's WebSocket protocol (``server.ws.StreamProtocol``): uvicorn's, reading a few messages ahead.

A real uvicorn server on loopback in a thread (an echo app that can be held still) and a real ``python -m server``
(its default ``--ws``), both spoken to by the ``websockets`` client; every wait bounded, nothing timed.
"""

from __future__ import annotations

import asyncio
import json
import threading
import time

import httpx
import pytest
import uvicorn
import websockets

from server.ws import IMPLEMENTATION, StreamProtocol
from tests.server.conftest import SERVICE_ENV, Proc, free_port


class _EchoServer:
    """uvicorn with ``StreamProtocol`` serving an echo app that reads nothing until ``release`` is set."""

    def __init__(self) -> None:
        self.release = threading.Event()
        self.port = free_port()
        config = uvicorn.Config(self.app, host="127.0.0.1", port=self.port, ws=IMPLEMENTATION, log_level="warning", lifespan="off", interface="asgi3")
        self.server = uvicorn.Server(config)
        self.thread = threading.Thread(target=self.server.run, daemon=True)

    async def app(self, scope, receive, send) -> None:
        assert scope["type"] == "websocket"
        assert (await receive())["type"] == "websocket.connect"
        await send({"type": "websocket.accept"})
        await asyncio.to_thread(self.release.wait, 20)
        while True:
            message = await receive()
            if message["type"] == "websocket.disconnect":
                return
            await send({"type": "websocket.send", "text": message["text"]} if "text" in message else {"type": "websocket.send", "bytes": message["bytes"]})

    def streams(self) -> list[StreamProtocol]:
        return [c for c in self.server.server_state.connections if isinstance(c, StreamProtocol)]

    def __enter__(self) -> _EchoServer:
        self.thread.start()
        deadline = time.monotonic() + 20
        while not self.server.started:
            assert time.monotonic() < deadline and self.thread.is_alive(), "uvicorn did not start"
            time.sleep(0.02)
        return self

    def __exit__(self, *exc) -> None:
        self.release.set()
        self.server.should_exit = True
        self.thread.join(20)


def _wait_for(condition, limit_s: float = 10.0) -> bool:
    deadline = time.monotonic() + limit_s
    while not condition():
        if time.monotonic() > deadline:
            return False
        time.sleep(0.01)
    return True


def test_reading_pauses_only_when_messages_wait_and_every_one_is_answered_in_order():
    n = 3 * StreamProtocol.MAX_QUEUED + 5
    with _EchoServer() as echo:

        async def client() -> tuple[list[str], bool, int, bool]:
            async with websockets.connect(f"ws://127.0.0.1:{echo.port}/", open_timeout=10, compression=None) as ws:
                assert _wait_for(lambda: len(echo.streams()) == 1)
                stream = echo.streams()[0]
                await ws.send("m0")  # one message waiting: reading goes on (uvicorn's own protocol pauses here)
                assert await asyncio.to_thread(_wait_for, lambda: stream.queue.qsize() == 1)
                one_paused = stream.read_paused
                for k in range(1, n):
                    await ws.send(f"m{k}")
                assert await asyncio.to_thread(_wait_for, lambda: stream.read_paused), "reading never paused with the app held"
                queued = stream.queue.qsize()
                echo.release.set()
                out = [await asyncio.wait_for(ws.recv(), 10) for _ in range(n)]
                await ws.ping()  # control frames still answered by the protocol
                return out, one_paused, queued, stream.read_paused

        out, one_paused, queued, paused_after = asyncio.run(client())
    assert out == [f"m{k}" for k in range(n)]  # nothing lost, nothing reordered
    assert not one_paused and queued >= StreamProtocol.MAX_QUEUED and not paused_after, (one_paused, queued, paused_after)


def test_fragmented_binary_and_invalid_text_messages_as_uvicorn_treats_them():
    with _EchoServer() as echo:
        echo.release.set()

        async def client() -> tuple[str, bytes, int]:
            async with websockets.connect(f"ws://127.0.0.1:{echo.port}/", open_timeout=10, compression=None) as ws:
                await ws.send(iter(["frag", "mented"]))  # one message in two frames
                joined = await asyncio.wait_for(ws.recv(), 10)
                await ws.send(b"\x00\x01binary")
                binary = await asyncio.wait_for(ws.recv(), 10)
                await ws.send(b"\xff\xfe not UTF-8", text=True)
                with pytest.raises(websockets.ConnectionClosed) as closed:
                    await asyncio.wait_for(ws.recv(), 10)
                return joined, binary, closed.value.rcvd.code

        joined, binary, code = asyncio.run(client())
    assert (joined, binary, code) == ("fragmented", b"\x00\x01binary", 1007)


def test_the_service_answers_a_burst_of_fixes_one_by_one_in_order(start_proc, tmp_path, s200):
    """A phone that sends many fixes at once (back from a tunnel) gets one advisory per fix, in its order."""
    svc = start_proc(Proc(["-m", "server", "--log-level", "warning", "--no-access-log"], tmp_path / "service.log",
                          {**SERVICE_ENV, "ECO_TABLES": "false", "ECO_SPEECH": "false"}))  # fmt: skip
    trip = httpx.post(svc.base_url + "/v1/trips", json={}, timeout=10).json()
    t0 = time.time()
    fixes = []
    for k in range(3 * StreamProtocol.MAX_QUEUED + 3):
        lat, lon = s200.position(5.0 + 3.0 * k)
        fixes.append({"t_unix_s": round(t0 - 0.2 * (20 - k), 3), "lat_deg": lat, "lon_deg": lon, "speed_mps": 15.0})

    async def stream() -> list[dict]:
        url = svc.base_url.replace("http", "ws") + f"/v1/trips/{trip['trip_id']}/stream"
        async with websockets.connect(url, additional_headers={"Authorization": f"Bearer {trip['token']}"}, open_timeout=10) as ws:
            for fix in fixes:
                await ws.send(json.dumps(fix))
            return [json.loads(await asyncio.wait_for(ws.recv(), 10)) for _ in fixes]

    answers = asyncio.run(stream())
    assert [a.get("t_unix_s") for a in answers] == [f["t_unix_s"] for f in fixes], [a.get("error") or a.get("message") or a.get("t_unix_s") for a in answers][-6:]
    assert [a["seq"] for a in answers] == list(range(1, len(fixes) + 1)) and {a["fix_status"] for a in answers} == {"ok"}, answers[:3]
