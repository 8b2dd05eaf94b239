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

A phone's fix arrives as one small masked text frame in one read. :meth:`StreamProtocol.data_received` takes such a
read without the ``websockets`` parser (its generator coroutines, frame object, checks and event list: the largest
part of reading a streamed fix, issue 30) when the parser stands where a new frame begins, with nothing buffered and
nothing it would treat otherwise (no extension, no fragmented message open, within the size limits, not closing,
no debug log): the payload unmasked as it unmasks it (``websockets.frames.apply_mask``) goes to the app exactly as
uvicorn hands it over. Anything else (a frame split over reads, two in one, binary, control or continuation frames,
compressed ones, 64-bit lengths, reserved bits, a size over the limit) goes to the parser as before. An answer (a
text message) is framed the same way without building a ``websockets`` frame (:meth:`StreamProtocol.send`): the bytes
``Frame.serialize`` writes for a server's final text frame, written where uvicorn would write them.
"""

from __future__ import annotations

import struct

from uvicorn.protocols.websockets.websockets_sansio_impl import WebSocketsSansIOProtocol
from websockets.frames import apply_mask
from websockets.protocol import Protocol, State
from websockets.streams import StreamReader

IMPLEMENTATION = "server.ws:StreamProtocol"
"""What ``ecodrive serve --ws ecodrive`` gives uvicorn (an import string: uvicorn's worker processes build it)."""


_AT_FRAME_START, _FRAMES = StreamReader.at_eof.__code__, Protocol.parse.__code__
"""Where the ``websockets`` parser waits between frames: ``Protocol.parse``'s ``yield from self.reader.at_eof()`` (a
server's parser runs it once the handshake is done; after a close it is ``discard``, which waits in ``at_eof`` too)."""


class StreamProtocol(WebSocketsSansIOProtocol):
    """uvicorn's sans-I/O WebSocket protocol; reading pauses at ``MAX_QUEUED`` messages waiting, not at one; a read that
    is one whole small text frame is taken without the parser (:meth:`one_text_frame`)."""

    MAX_QUEUED = 4
    """Messages read ahead of the app before reading pauses (uvicorn: 1). [-]"""

    def data_received(self, data: bytes) -> None:
        payload = self.one_text_frame(data)
        if payload is None:
            super().data_received(data)
            return
        self.curr_msg_data_type = "text"  # as uvicorn's handle_text for a final text frame
        self.frames = [payload]
        self.send_receive_event_to_app()

    def one_text_frame(self, data: bytes) -> bytes | None:
        """The unmasked payload when ``data`` is exactly one final, masked text frame without reserved bits, of a 7- or
        16-bit length within the size limits, read where the parser would start a new frame with nothing buffered, on an
        open connection without extensions or an unfinished fragmented message; None otherwise (the parser's)."""
        n = len(data)
        if n < 6 or data[0] != 0x81:  # FIN, no RSV bits, opcode 1 (text)
            return None
        length, start = data[1] ^ 0x80, 6  # the mask bit must be set (a client's frame): else > 127, refused below
        if length == 126:
            if n < 8:
                return None
            length, start = int.from_bytes(data[2:4], "big"), 8
        elif length > 125:
            return None
        conn = self.conn
        if n != start + length or conn.state is not State.OPEN or conn.current_size is not None or conn.extensions or conn.debug:
            return None
        if (conn.max_message_size is not None and length > conn.max_message_size) or (conn.max_fragment_size is not None and length > conn.max_fragment_size):
            return None
        reader = conn.reader
        if reader.buffer or reader.eof:
            return None
        outer, inner = None, conn.parser  # the innermost generator the parser waits in, and the one that waits for it
        while (g := getattr(inner, "gi_yieldfrom", None)) is not None:
            outer, inner = inner, g
        if getattr(inner, "gi_code", None) is not _AT_FRAME_START or getattr(outer, "gi_code", None) is not _FRAMES:
            return None
        return apply_mask(data[start:], data[start - 4 : start])

    async def send(self, message) -> None:
        if not self.send_text_frame(message):
            await super().send(message)

    def send_text_frame(self, message) -> bool:
        """What uvicorn's ``send`` does with a text message on an open stream with nothing else to write (no extension,
        no fragmented message of the app's open, no debug log), done here: the frame written (FIN and opcode 1, the 7-,
        16- or 64-bit length, unmasked: RFC 6455 5.2, as ``websockets`` frames it); False for anything else (uvicorn's)."""
        text = message.get("text") if message["type"] == "websocket.send" and message.get("bytes") is None else None
        conn = self.conn
        if (text is None or not self.handshake_complete or self.close_sent or self.initial_response is not None or self.disconnected
                or not self.writable.is_set() or conn.state is not State.OPEN or conn.expect_continuation_frame or conn.extensions or conn.debug
                or conn.writes):  # fmt: skip
            return False
        data = text.encode()
        n = len(data)
        self.transport.write((bytes((0x81, n)) if n < 126 else struct.pack("!BBH", 0x81, 126, n) if n < 65536 else struct.pack("!BBQ", 0x81, 127, n)) + data)
        return True

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
