"""``python bench/_floor_app.py --port P [--redis URL] [--ws IMPL]``: the floor under a fix, for ``bench/bench_floor.py``.

One uvicorn worker with the service's HTTP protocol (``server.web.protocol``), uvloop and httptools, serving a minimal ASGI
app that speaks the phones' part of the API and nothing else: ``POST /v1/trips`` (a trip id and token), a fix by
``POST /v1/trips/{id}/fixes`` (the body read, 600 bytes of JSON answered) or on ``/v1/trips/{id}/stream`` (each
message answered with the same 600 bytes); with ``--redis``, each fix first writes 1.6 kB (a trip's state) to Redis
with one pipelined ``SET`` (``server.storage.redispipe``) and is answered once Redis has it. No parsing, advice or store.
"""

from __future__ import annotations

import argparse
import json
import sys
import uuid
from pathlib import Path

import uvicorn

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from server.web.protocol import protocol_class  # noqa: E402
from server.storage.redispipe import RedisPipe  # noqa: E402
from server.web.ws import IMPLEMENTATION  # noqa: E402

STATE = b"s" * 1600
"""What a fix writes to Redis: the size of a trip's state. [bytes]"""


def answer(trip_id: str) -> bytes:
    """600 bytes of JSON beginning as an advisory of ``trip_id`` does (the phones check that)."""
    head = '{"trip_id":"%s","pad":"' % trip_id
    return (head + "x" * (598 - len(head)) + '"}').encode()


def make_app(redis: RedisPipe | None):
    async def body(receive) -> bytes:
        chunks = []
        while True:
            message = await receive()
            chunks.append(message.get("body", b""))
            if not message.get("more_body"):
                return b"".join(chunks)

    async def respond(send, status: int, data: bytes) -> None:
        await send({"type": "http.response.start", "status": status, "headers": [(b"content-type", b"application/json"), (b"content-length", b"%d" % len(data))]})
        await send({"type": "http.response.body", "body": data})

    async def app(scope, receive, send) -> None:
        if scope["type"] == "lifespan":
            while (await receive())["type"] != "lifespan.shutdown":
                await send({"type": "lifespan.startup.complete"})
            await send({"type": "lifespan.shutdown.complete"})
            return
        path = scope["path"]
        trip_id = path.split("/")[3] if path.count("/") >= 4 else ""
        if scope["type"] == "websocket":
            assert (await receive())["type"] == "websocket.connect"
            await send({"type": "websocket.accept"})
            text = answer(trip_id).decode()
            while (await receive())["type"] == "websocket.receive":
                if redis is not None:
                    await redis.call("SET", f"floor:{trip_id}", STATE)
                await send({"type": "websocket.send", "text": text})
            return
        await body(receive)
        if path == "/v1/trips":
            await respond(send, 201, json.dumps({"trip_id": uuid.uuid4().hex, "token": "t"}).encode())
        elif path == "/health":
            await respond(send, 200, b'{"status":"ok"}')
        else:
            if redis is not None:
                await redis.call("SET", f"floor:{trip_id}", STATE)
            await respond(send, 200, answer(trip_id))

    return app


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--port", type=int, required=True)
    ap.add_argument("--redis", help="Redis URL: one pipelined SET per fix")
    ap.add_argument("--ws", default=IMPLEMENTATION, help="uvicorn WebSocket implementation (default: the service's, server.web.ws)")
    args = ap.parse_args()
    redis = RedisPipe(args.redis, 10.0) if args.redis else None
    config = uvicorn.Config(make_app(redis), port=args.port, log_level="warning", access_log=False, ws=args.ws, http=protocol_class(60.0, 0, 0),
                            ws_per_message_deflate=False, timeout_keep_alive=60, loop="uvloop", interface="asgi3")  # fmt: skip
    uvicorn.Server(config).run()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
