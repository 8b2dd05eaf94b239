"""Open-loop load: phones sending one GPS fix per period, whatever the service answers (run as its own process
by ``bench/bench_redis_load.py``, so its CPU is measured apart from the workers').

Each phone is one keep-alive connection and one trip (``bench/_loadgen.py``'s :class:`Car` does the HTTP). Phone
``i`` ticks every ``period_s`` at its own offset (any first k phones spread evenly over the period). At a tick an
active phone sends its fix; if its previous answer is still out, the fix is sent as soon as that answer is in, and
its latency still counts from the tick (no coordinated omission: a slow service is not hidden by phones waiting
for it); a tick that finds a fix already waiting is counted as ``late`` (the phone could not send it) and dropped.

Reads a JSON job on stdin: ``{"port", "trips": [[id, token], ...], "positions": [[lat, lon], ...], "period_s",
"phases": [[seconds, n_active], ...], "out"}``: phase k keeps the first ``n_active`` phones sending for
``seconds``. Writes ``mark`` to stdout at the start of each phase and at the end of the last (the caller samples
CPU there), then ``done`` once ``out`` holds ``{"marks": [t...], "cpu_s": [...], "late": n, "lost": n, "t": [...],
"lat_s": [...], "status": [...], "kind": [...]}``: per answer its tick (seconds since the run began), latency,
HTTP status and kind (0 ok, 1 shed: ``overloaded``, 2 ``store_unavailable``, 3 any other error).
"""

from __future__ import annotations

import asyncio
import json
import sys
import time
from collections import deque

import websockets
from _loadgen import SPEED_MPS, Car, Run, cpu_s, main

GOLDEN = (5**0.5 - 1) / 2
"""Phone i ticks at (i x GOLDEN) mod 1 of the period: any first k phones are spread evenly (a low-discrepancy sequence)."""
KINDS = {b'"overloaded"': 1, b'"store_unavailable"': 2}


class Phone(Car):
    """A :class:`Car` that sends on its ticks instead of as soon as it is answered."""

    def __init__(self, run: OpenRun, i: int, trip_id: str, token: str) -> None:
        super().__init__(run, i, trip_id, token)
        self.busy = False
        self.owed: float | None = None  # the tick of a fix waiting for the answer in flight

    def tick(self, due: float) -> None:
        if self.transport is None or self.transport.is_closing():  # closed by the service: a phone connects again
            if not self.busy:
                self.busy = True
                asyncio.get_running_loop().create_task(self.reconnect(due))
            return
        if self.busy:
            if self.owed is not None:
                self.run.late += 1
            self.owed = due
            return
        self.send_at(due)

    def send_at(self, due: float) -> None:
        self.busy = True
        self.send()
        self.sent = due  # latency from the tick

    async def reconnect(self, due: float) -> None:
        self.buf, self.need = b"", -1
        try:
            await asyncio.get_running_loop().create_connection(lambda: self, "127.0.0.1", self.run.job["port"])
        except OSError:
            self.busy = False
            return
        self.send_at(due)

    def connection_made(self, transport) -> None:
        self.transport = transport
        if not self.run.all_connected.is_set():
            super().connection_made(transport)

    def connection_lost(self, exc) -> None:
        if not self.run.stopping:
            self.run.lost += 1
            if self.busy:  # the fix in flight is lost: an error
                self.status, self.busy = 0, False
                self.run.answered(self, b"", time.perf_counter())
        self.transport = None

    def answered(self) -> bool:
        self.busy = False
        self.run.answered(self, self.body, time.perf_counter())
        if self.owed is not None and not self.run.stopping:
            due, self.owed = self.owed, None
            self.send_at(due)
        return True


class OpenRun(Run):
    """:class:`Run`'s connections and counters, the phones' schedule and per-answer records."""

    car_class = Phone

    def __init__(self, job: dict) -> None:
        super().__init__(job)
        self.late = 0
        self.t0 = 0.0
        self.t: list[float] = []
        self.status: list[int] = []
        self.kind: list[int] = []

    def answered(self, car: Phone, body: bytes, now: float) -> None:
        self.t.append(car.sent - self.t0)
        self.lat.append(now - car.sent)
        self.status.append(car.status)
        kind = 0
        if car.status != 200:
            kind = next((k for word, k in KINDS.items() if word in body), 3)
        self.kind.append(kind)

    async def connect(self) -> None:
        loop = asyncio.get_running_loop()
        for car in self.cars:
            await loop.create_connection(lambda c=car: c, "127.0.0.1", self.job["port"])
        await asyncio.wait_for(self.all_connected.wait(), 60)

    async def close(self) -> None:
        for car in self.cars:
            if car.transport is not None:
                car.transport.close()

    async def main(self) -> dict:
        loop = asyncio.get_running_loop()
        await self.connect()
        period = self.job["period_s"]
        n = len(self.cars)
        self.t0 = start = time.perf_counter() + 0.2
        marks, cpu = [], []
        active = 0

        def tick(i: int, due: float) -> None:
            if self.stopping:
                return
            if i < active:
                self.cars[i].tick(due)
            loop.call_at(loop.time() + (due + period - time.perf_counter()), tick, i, due + period)

        for i in range(n):
            due = start + period * ((i * GOLDEN) % 1.0)  # the first k phones spread evenly over the period, whatever k
            loop.call_at(loop.time() + (due - time.perf_counter()), tick, i, due)
        at = start
        for seconds, n_active in self.job["phases"]:
            await asyncio.sleep(max(0.0, at - time.perf_counter()))
            active = n_active
            print("mark", flush=True)
            marks.append(time.perf_counter() - self.t0)
            cpu.append(cpu_s())
            at += seconds
        await asyncio.sleep(max(0.0, at - time.perf_counter()))
        print("mark", flush=True)
        marks.append(time.perf_counter() - self.t0)
        cpu.append(cpu_s())
        self.stopping = True
        await asyncio.sleep(1.0)  # the answers in flight come back before the connections close
        await self.close()
        return {"marks": marks, "cpu_s": cpu, "late": self.late, "lost": self.lost, "t": self.t, "lat_s": self.lat, "status": self.status, "kind": self.kind}


class StreamPhone:
    """A phone on the WebSocket stream (as the app sends its fixes, ``server/static/lib/api.js``): the same fixes as
    :class:`Phone`'s, a fix per tick, answers in order, several in flight when the service is slow (each one's
    latency from its own tick). Every answer is checked as a REST one is: an advisory of this trip is a 200, an
    error object gives its ``status`` and kind, anything else counts as an error (status 0). A stream the service
    closes is opened again at the next tick (the fixes then in flight are lost: errors), as the app does."""

    def __init__(self, run: StreamRun, i: int, trip_id: str, token: str) -> None:
        self.run, self.trip_id, self.token = run, trip_id, token
        self.t0 = time.time() - 7.0 * i  # where along its there-and-back this phone is (as Car.t0)
        self.ws = None
        self.opening = False
        self.advisory = ('{"trip_id":"%s",' % trip_id).encode()  # how every advisory of this trip begins
        self.pending: deque[float] = deque()  # ticks of the fixes sent, not answered yet
        self.status = 0
        self.sent = 0.0

    async def open(self) -> None:
        url = f"ws://127.0.0.1:{self.run.job['port']}/v1/trips/{self.trip_id}/stream"
        self.ws = await websockets.connect(url, additional_headers={"Authorization": f"Bearer {self.token}"}, compression=None, max_queue=None)
        asyncio.get_running_loop().create_task(self.receive(self.ws))

    async def reopen(self) -> None:
        try:
            await self.open()
        except (OSError, websockets.WebSocketException):
            pass  # tried again at the next tick
        finally:
            self.opening = False

    def tick(self, due: float) -> None:
        if self.ws is None:
            if not self.opening and not self.run.stopping:
                self.opening = True
                asyncio.get_running_loop().create_task(self.reopen())
            return
        if self.pending:
            self.run.late += 1
        now = time.time()
        lat, lon = self.run.positions[int(SPEED_MPS * (now - self.t0)) % len(self.run.positions)]
        self.pending.append(due)
        asyncio.get_running_loop().create_task(self.ws.send(b'{"t_unix_s":%.3f,"lat_deg":%.7f,"lon_deg":%.7f,"speed_mps":%.1f,"accuracy_m":4.0}' % (now, lat, lon, SPEED_MPS), text=True))

    async def receive(self, ws) -> None:
        try:
            while True:
                message = await ws.recv(decode=False)  # bytes, as a REST body
                now = time.perf_counter()
                if not self.pending:  # an answer to no fix: the service said something unasked (a replaced stream's notice)
                    continue
                self.sent = self.pending.popleft()
                if message.startswith(self.advisory):
                    self.status, body = 200, b""
                else:
                    self.status, body = _error_status(message), message
                self.run.answered(self, body, now)
        except websockets.ConnectionClosed:
            pass
        if self.ws is ws:
            self.ws = None
            if not self.run.stopping:
                self.run.lost += 1
                now = time.perf_counter()
                while self.pending:  # the fixes in flight are lost: errors
                    self.sent, self.status = self.pending.popleft(), 0
                    self.run.answered(self, b"", now)


def _error_status(message: bytes) -> int:
    """The ``status`` of a stream's error object (0: not one)."""
    try:
        out = json.loads(message)
        return int(out["status"]) if isinstance(out, dict) and "error" in out else 0
    except (ValueError, KeyError, TypeError):
        return 0


class StreamRun(OpenRun):
    """The same phones and phases on the WebSocket stream (``"transport": "ws"`` in the job)."""

    car_class = StreamPhone

    async def connect(self) -> None:
        for k in range(0, len(self.cars), 100):
            await asyncio.gather(*(car.open() for car in self.cars[k : k + 100]))

    async def close(self) -> None:
        await asyncio.gather(*(car.ws.close() for car in self.cars if car.ws is not None), return_exceptions=True)


if __name__ == "__main__":
    raise SystemExit(main(StreamRun if json.loads(sys.argv[1] if len(sys.argv) > 1 else '"http"') == "ws" else OpenRun))
