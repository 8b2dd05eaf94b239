"""The WebSocket protocol the service runs (``ecodrive serve --ws ecodrive``, the default): uvicorn's
``websockets-sansio`` protocol, with reading paused only when the app falls behind.

uvicorn's protocol pauses reading the socket after **every** message it hands to the app and resumes it when the
app asks for the next one: backpressure, but two changes of the socket's watch in the event loop per message (on
uvloop two ``io_uring_enter`` system calls), a fixed cost on every fix a phone streams once a second (issue 30:
CPU per fix). :class:`StreamProtocol` keeps the same backpressure with room for a few messages: reading pauses
when ``MAX_QUEUED`` messages are waiting for the app (a phone sends one a second: a stream that far ahead has a
stalled app behind it) and resumes, as uvicorn's does, when the app has taken them all. The memory a stream can
hold is bounded as before: ``MAX_QUEUED`` messages of at most uvicorn's ``ws_max_size`` each. Everything else
(handshake, frames, ping and pong, close, errors) is uvicorn's.
"""

from __future__ import annotations

from uvicorn.protocols.websockets.websockets_sansio_impl import WebSocketsSansIOProtocol

IMPLEMENTATION = "server.web.ws:StreamProtocol"
"""What ``ecodrive serve --ws ecodrive`` gives uvicorn (an import string: uvicorn's worker processes build it)."""


class StreamProtocol(WebSocketsSansIOProtocol):
    """uvicorn's sans-I/O WebSocket protocol; reading pauses at ``MAX_QUEUED`` messages waiting, not at one."""

    MAX_QUEUED = 4
    """Messages read ahead of the app before reading pauses (uvicorn: 1). [-]"""

    def send_receive_event_to_app(self) -> None:
        data = self.frames[0] if len(self.frames) == 1 else b"".join(self.frames)
        self.frames = []
        if self.close_sent:  # past the app's close: dropped, reading goes on until the peer's close reply (as uvicorn)
            return
        if self.curr_msg_data_type == "text":
            try:
                self.queue.put_nowait({"type": "websocket.receive", "text": data.decode()})
            except UnicodeDecodeError:  # as uvicorn: 1007, closed
                self.logger.exception("Invalid UTF-8 sequence received from client.")
                self.conn.send_close(1007)
                self.handle_parser_exception()
                return
        else:
            self.queue.put_nowait({"type": "websocket.receive", "bytes": data})
        if not self.read_paused and self.queue.qsize() >= self.MAX_QUEUED:
            self.read_paused = True
            self.transport.pause_reading()
