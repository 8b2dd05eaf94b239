"""A lean HTTP/1.1 load generator for the scale-out bench, run as its own process so that its CPU is measured
apart from the workers' (and stays small: a few tens of microseconds per request).

One keep-alive connection per trip, one request in flight on each (closed loop, no pipelining): each car
POSTs its next fix as soon as the previous answer is in. The request's head (path, token) is built once per
connection; per request only the body is formatted: the fix's time is the wall clock and its position is
where a car driving the corridor there and back at ``SPEED_MPS`` is at that instant (from a table of
positions 1 m apart), so every fix is plausible, in order and goes through the whole advisor.
Plain ``asyncio.Protocol`` callbacks (no streams, no coroutine per request), on uvloop when installed.

Reads a JSON job on stdin: ``{"port", "trips": [[id, token], ...], "positions": [[lat, lon], ...] (1 m
apart, there and back), "warmup_s", "seconds", "out"}``. Writes ``start`` to stdout when the measured window
opens, ``stop`` when it closes (the caller samples the servers' CPU at those lines), then ``done`` once the
file ``out`` holds ``{"n", "errors", "elapsed_s", "cpu_s", "lat_s": [...]}`` (the requests completed in the
window, non-200 answers among them, the window's length, this process's CPU seconds in it, and each
request's latency).
"""

from __future__ import annotations

import asyncio
import json
import resource
import sys
import time

SPEED_MPS = 15.0
"""The cars' speed along the corridor (a fix's position is where such a car is at the fix's time). [m/s]"""


def cpu_s() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


class Car(asyncio.Protocol):
    """One connection, one trip: sends a fix, waits for the whole answer, sends the next."""

    def __init__(self, run: Run, i: int, trip_id: str, token: str) -> None:
        self.run = run
        self.head = (f"POST /v1/trips/{trip_id}/fixes HTTP/1.1\r\nHost: bench\r\nAuthorization: Bearer {token}\r\n"
                     "Content-Type: application/json\r\nContent-Length: ").encode()  # fmt: skip
        self.t0 = time.time() - 7.0 * i  # where along its there-and-back this car is
        self.buf = b""
        self.need = -1  # bytes of the answer still to come once its head is read (-1: reading the head)
        self.status = 0
        self.body = b""
        self.sent = 0.0
        self.transport: asyncio.Transport | None = None

    def connection_made(self, transport) -> None:
        self.transport = transport
        self.run.connected += 1
        if self.run.connected == len(self.run.cars):
            self.run.all_connected.set()

    def send(self) -> None:
        now = time.time()
        pos = self.run.positions
        lat, lon = pos[int(SPEED_MPS * (now - self.t0)) % len(pos)]
        body = b'{"t_unix_s":%.3f,"lat_deg":%.7f,"lon_deg":%.7f,"speed_mps":%.1f,"accuracy_m":4.0}' % (now, lat, lon, SPEED_MPS)
        self.sent = time.perf_counter()
        self.transport.write(b"%s%d\r\n\r\n%s" % (self.head, len(body), body))

    def data_received(self, data: bytes) -> None:
        self.buf += data
        while True:
            if self.need < 0:
                end = self.buf.find(b"\r\n\r\n")
                if end < 0:
                    return
                head = self.buf[:end].lower()
                self.status = int(head[9:12])
                at = head.find(b"content-length:")
                eol = head.find(b"\r\n", at)
                self.need = int(head[at + 15 : eol if eol >= 0 else len(head)]) if at >= 0 else 0
                self.buf = self.buf[end + 4 :]
            if len(self.buf) < self.need:
                return
            self.body = self.buf[: self.need] if self.status != 200 else b""  # an error's body says which
            self.buf = self.buf[self.need :]
            self.need = -1
            if not self.answered():
                return

    def answered(self) -> bool:
        """A whole answer is in (``status``, ``body``): counted, and the next fix sent; False: stop reading."""
        self.run.done(self, time.perf_counter())
        if self.run.stopping:
            return False
        self.send()
        return True

    def connection_lost(self, exc) -> None:
        if not self.run.stopping:
            self.run.lost += 1


class Run:
    car_class = Car

    def __init__(self, job: dict) -> None:
        self.job = job
        self.positions = job["positions"]
        self.cars = [self.car_class(self, i, tid, tok) for i, (tid, tok) in enumerate(job["trips"])]
        self.connected = 0
        self.lost = 0
        self.all_connected = asyncio.Event()
        self.measuring = False
        self.stopping = False
        self.lat: list[float] = []
        self.errors = 0

    def done(self, car: Car, t: float) -> None:
        if self.measuring:
            self.lat.append(t - car.sent)
            if car.status != 200:
                self.errors += 1

    async def main(self) -> dict:
        loop = asyncio.get_running_loop()
        port = self.job["port"]
        for car in self.cars:
            await loop.create_connection(lambda c=car: c, "127.0.0.1", port)
        await asyncio.wait_for(self.all_connected.wait(), 60)
        for car in self.cars:
            car.send()
        await asyncio.sleep(self.job["warmup_s"])
        print("start", flush=True)
        c0, t0 = cpu_s(), time.perf_counter()
        self.measuring = True
        await asyncio.sleep(self.job["seconds"])
        self.measuring = False
        c1, t1 = cpu_s(), time.perf_counter()
        print("stop", flush=True)
        self.stopping = True
        await asyncio.sleep(0.5)  # the answers in flight come back before the connections close
        for car in self.cars:
            car.transport.close()
        return {"n": len(self.lat), "errors": self.errors, "elapsed_s": t1 - t0, "cpu_s": c1 - c0, "lost": self.lost, "lat_s": self.lat}


def main(run_class=None) -> int:
    """Read the job on stdin, run it (``run_class``, default :class:`Run`) on uvloop when installed, write its results."""
    job = json.load(sys.stdin)
    try:
        import uvloop

        runner = uvloop.run
    except ImportError:
        runner = asyncio.run
    out = runner((run_class or Run)(job).main())
    with open(job["out"], "w") as f:
        json.dump(out, f)
    print("done", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
