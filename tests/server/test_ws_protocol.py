"""The service's WebSocket protocol (``server.web.ws.StreamProtocol``): uvicorn's, reading a few messages ahead.

A real uvicorn server on loopback in a thread (an echo app that can be held still) and a real ``python -m server``
(its default ``--ws``), both spoken to by the ``websockets`` client; every wait bounded, nothing timed.
"""

from __future__ import annotations

import asyncio
import json
import socket
import struct
import threading
import time

import httpx
import pytest
import uvicorn
import websockets

from uvicorn.protocols.websockets.websockets_sansio_impl import WebSocketsSansIOProtocol
from websockets.frames import apply_mask

from server.web.ws import IMPLEMENTATION, StreamProtocol
from tests.server.conftest import SERVICE_ENV, Proc, free_port


class _EchoServer:
    """uvicorn with ``StreamProtocol`` serving an echo app that reads nothing until ``release`` is set."""

    def __init__(self, ws=IMPLEMENTATION, max_size: int = 16 * 1024 * 1024) -> None:
        self.release = threading.Event()
        self.port = free_port()
        config = uvicorn.Config(self.app, host="127.0.0.1", port=self.port, ws=ws, ws_max_size=max_size, log_level="critical", lifespan="off", interface="asgi3")
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


def _frame(payload: bytes, opcode: int = 1, fin: bool = True, rsv: int = 0, masked: bool = True, long: bool = False) -> bytes:
    """One client frame (RFC 6455 5.2): masked with a fixed key, a 64-bit length with ``long``."""
    n = len(payload)
    head = bytes([(0x80 if fin else 0) | rsv << 4 | opcode])
    m = 0x80 if masked else 0
    head += bytes([m | 127]) + struct.pack("!Q", n) if long or n >= 65536 else bytes([m | n]) if n < 126 else bytes([m | 126]) + struct.pack("!H", n)
    key = b"\x37\xfa\x21\x3d"
    return head + (key + apply_mask(payload, key) if masked else payload)


CLOSE = _frame(struct.pack("!H", 1000), opcode=8)
LIMIT = 70_000  # the servers' ws_max_size [bytes]
SCRIPTS = {  # name: the client's writes after the handshake and how many frames the server answers each with
    "small texts, one a read": [(_frame(b'{"t_unix_s":1714557600.1,"lat_deg":37.8}'), 1), (_frame("é 漢字".encode()), 1), (_frame(b""), 1), (CLOSE, 1)],
    "16- and 64-bit lengths, at the limit": [(_frame(b"x" * 126), 1), (_frame(b"y" * 65535), 1), (_frame(b"z" * 65536), 1), (_frame(b"z" * LIMIT), 1), (CLOSE, 1)],
    "over the limit": [(_frame(b"a"), 1), (_frame(b"z" * (LIMIT + 1)), 1)],
    "two frames in one read, a frame over two writes": [(_frame(b"one") + _frame(b"two"), 2), (_frame(b"three")[:3], 0), (_frame(b"three")[3:], 1), (CLOSE, 1)],
    "fragmented text, then a text": [(_frame(b"frag", fin=False), 0), (_frame(b"mented", opcode=0), 1), (_frame(b"after"), 1), (CLOSE, 1)],
    "a text inside a fragmented message": [(_frame(b"frag", fin=False), 0), (_frame(b"text"), 1)],
    "binary, ping, 64-bit length": [(_frame(b"\x00\x01", opcode=2), 1), (_frame(b"p", opcode=9), 1), (_frame(b"long", long=True), 1), (_frame(b"next"), 1), (CLOSE, 1)],
    "invalid UTF-8": [(_frame(b"ok"), 1), (_frame(b"\xff\xfe"), 1)],
    "unmasked": [(_frame(b"plain", masked=False), 1)],
    "reserved bit": [(_frame(b"rsv", rsv=4), 1)],
    "text after the close": [(CLOSE, 1), (_frame(b"late"), 0)],
}


def _frames_in(data: bytes) -> int:
    """Whole server frames (unmasked) at the start of ``data``."""
    n = i = 0
    while i + 2 <= len(data):
        length, i = data[i + 1] & 0x7F, i + 2
        if length >= 126:
            size = 2 if length == 126 else 8
            if i + size > len(data):
                break
            length, i = int.from_bytes(data[i : i + size], "big"), i + size
        if i + length > len(data):
            break
        n, i = n + 1, i + length
    return n


def _exchange(port: int, writes: list[tuple[bytes, int]]) -> bytes:
    """The bytes the server sends after its handshake response to ``writes``, each written once the server has answered
    the ones before (so that each is a read of its own), until the server closes."""
    with socket.create_connection(("127.0.0.1", port), timeout=10) as sock:
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        key = "dGhlIHNhbXBsZSBub25jZQ=="
        sock.sendall(f"GET / HTTP/1.1\r\nHost: x\r\nUpgrade: websocket\r\nConnection: Upgrade\r\nSec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n\r\n".encode())
        data = b""
        while b"\r\n\r\n" not in data:
            chunk = sock.recv(65536)
            assert chunk, data
            data += chunk
        head, _, out = data.partition(b"\r\n\r\n")
        assert head.startswith(b"HTTP/1.1 101"), head
        expected = 0
        for w, answers in writes:
            try:
                sock.sendall(w)
            except OSError:  # closed by the server already
                break
            expected += answers
            while _frames_in(out) < expected and (chunk := _recv(sock)):
                out += chunk
        while chunk := _recv(sock):
            out += chunk
        return out


def _recv(sock: socket.socket) -> bytes:
    try:
        return sock.recv(65536)
    except ConnectionResetError:
        return b""


def test_raw_frames_are_answered_as_uvicorns_own_protocol_answers_them():
    """Raw frames (one or two a read, split, fragmented, binary, control, 64-bit lengths, over the size limit, invalid
    UTF-8, unmasked, reserved bits, after a close) to an echo app: the same bytes back, the same closes, from
    ``StreamProtocol`` (reading a few messages ahead) as from uvicorn's own protocol (one message at a time)."""
    got = {}
    for ws in (WebSocketsSansIOProtocol, StreamProtocol):
        with _EchoServer(ws, max_size=LIMIT) as echo:
            echo.release.set()
            got[ws] = {name: _exchange(echo.port, writes) for name, writes in SCRIPTS.items()}
    for name in SCRIPTS:
        assert got[StreamProtocol][name] == got[WebSocketsSansIOProtocol][name], name
    assert got[StreamProtocol]["small texts, one a read"].startswith(b"\x81\x28{")  # echoed
    over = got[StreamProtocol]["over the limit"]
    assert over.startswith(b"\x81\x01a\x88") and over[5:7] == b"\x03\xf1", over  # the echo of "a", then a close 1009
