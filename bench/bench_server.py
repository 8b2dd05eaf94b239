"""Advisory service under load: POST-fix throughput vs a trivial endpoint, WebSocket trips at 1 Hz, memory per trip.

Starts ``python -m server`` on 127.0.0.1 (pinned to CPU 0 when there are two or more CPUs; the embedded
simulated SPaT, lookup tables for paper_s400, speech off, rate limits raised), runs the clients in this
process (pinned to CPU 1), and prints:

1. **HTTP**: ``--conns`` keep-alive connections (default 200) hammer ``GET /health`` then ``POST
   /v1/trips/{id}/fixes`` (one trip per connection, a car moving along the corridor) for ``--http-s`` each;
   requests/s of each, the ratio fixes/health, and p50/p99 latency. The load generator is a minimal
   HTTP/1.1 client on raw asyncio streams, so the server is the bottleneck.
2. **WebSocket**: ``--ws-trips`` trips (default 2,000), each a WebSocket sending one fix a second
   (phases spread over the second); round-trip latency fix -> advisory, p50/p99/max, after a warm-up.
3. **Memory**: server RSS before and after creating the trips (per trip, no fixes), and after the
   WebSocket run (per trip with its fixes, advisor memory and an open WebSocket).

    .venv/bin/python bench/bench_server.py [--conns 200] [--http-s 8] [--ws-trips 2000] [--ws-s 20]
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import httpx
import numpy as np
from websockets.asyncio.client import connect

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from bench._procs import cpu_seconds, free_port, rss_mib  # noqa: E402,F401

from spat_feed.road.corridors import load_corridor  # noqa: E402

CORRIDOR = "paper_s400"


def start_service(port: int, log_path: Path) -> subprocess.Popen:
    env = {**os.environ, "ECO_CORRIDORS": CORRIDOR, "ECO_DEFAULT_CORRIDOR": CORRIDOR, "ECO_SPEECH": "false",
           "ECO_RATE_PER_S": "1000000", "ECO_RATE_BURST": "1000000", "ECO_CREATE_RATE_PER_S": "1000000",
           "ECO_CREATE_BURST": "1000000", "ECO_TABLES_DIR": "/tmp/ecodrive-bench-tables",
           # one client address opens every connection here: the per-client caps and quotas are off
           "ECO_MAX_CONNECTIONS_PER_CLIENT": "0", "ECO_WS_MAX_PER_CLIENT": "0", "ECO_MAX_TRIPS_PER_CLIENT": "0",
           "ECO_CREATE_RATE_PER_CLIENT_PER_S": "1000000", "ECO_CREATE_BURST_PER_CLIENT": "1000000"}  # fmt: skip
    cpus = sorted(os.sched_getaffinity(0))
    pre = (lambda: os.sched_setaffinity(0, {cpus[0]})) if len(cpus) >= 2 else None
    cmd = [sys.executable, "-m", "server", "--port", str(port), "--log-level", "warning", "--no-access-log"]
    proc = subprocess.Popen(cmd, cwd=REPO, env=env, stdout=log_path.open("wb"), stderr=subprocess.STDOUT, preexec_fn=pre)
    deadline = time.monotonic() + 90
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            raise RuntimeError(log_path.read_text())
        try:
            if httpx.get(f"http://127.0.0.1:{port}/health", timeout=1).status_code == 200:
                return proc
        except httpx.HTTPError:
            pass
        time.sleep(0.1)
    proc.kill()
    raise RuntimeError("service did not start")


class RawHttp:
    """One keep-alive HTTP/1.1 connection with a minimal request/response loop."""

    def __init__(self, port: int) -> None:
        self.port = port

    async def open(self) -> None:
        self.reader, self.writer = await asyncio.open_connection("127.0.0.1", self.port)

    async def request(self, method: str, path: str, body: bytes = b"", headers: str = "") -> tuple[int, bytes]:
        head = f"{method} {path} HTTP/1.1\r\nHost: bench\r\n{headers}"
        if body or method == "POST":
            head += f"Content-Type: application/json\r\nContent-Length: {len(body)}\r\n"
        self.writer.write(head.encode() + b"\r\n" + body)
        raw = await self.reader.readuntil(b"\r\n\r\n")
        status = int(raw[9:12])
        length = 0
        for line in raw.split(b"\r\n"):
            if line[:15].lower() == b"content-length:":
                length = int(line[15:])
        return status, await self.reader.readexactly(length)

    def close(self) -> None:
        self.writer.close()


async def create_trips(port: int, n: int) -> list[tuple[str, str]]:
    conns = [RawHttp(port) for _ in range(min(50, n))]
    for c in conns:
        await c.open()
    out: list[tuple[str, str]] = []

    async def worker(c: RawHttp, count: int) -> None:
        for _ in range(count):
            while True:
                status, body = await c.request("POST", "/v1/trips", json.dumps({"corridor": CORRIDOR, "timing": "15_15"}).encode())
                if status != 503 or b'"overloaded"' not in body:
                    break
                await asyncio.sleep(1.0)  # a loaded machine: the service sheds (Retry-After: 1), as a phone would, wait
            assert status == 201, body
            d = json.loads(body)
            out.append((d["trip_id"], d["token"]))

    per = [n // len(conns) + (1 if i < n % len(conns) else 0) for i in range(len(conns))]
    await asyncio.gather(*(worker(c, k) for c, k in zip(conns, per)))
    for c in conns:
        c.close()
    return out


def fix_body(corridor, positions, k: int, t: float) -> bytes:
    lat, lon = positions[k % len(positions)]
    return f'{{"t_unix_s":{t:.3f},"lat_deg":{lat:.7f},"lon_deg":{lon:.7f},"speed_mps":18.0,"accuracy_m":4.0}}'.encode()


async def http_phase(port: int, conns: int, seconds: float, kind: str, trips, positions) -> tuple[float, np.ndarray, int]:
    clients = [RawHttp(port) for _ in range(conns)]
    for c in clients:
        await c.open()
    lat: list[float] = []
    errors = 0
    stop_at = time.perf_counter() + seconds

    async def worker(i: int, c: RawHttp) -> None:
        nonlocal errors
        k = i * 7
        if kind == "fix":
            trip_id, token = trips[i]
            path, hdr = f"/v1/trips/{trip_id}/fixes", f"Authorization: Bearer {token}\r\n"
        while time.perf_counter() < stop_at:
            t0 = time.perf_counter()
            if kind == "health":
                status, _ = await c.request("GET", "/health")
            else:
                status, _ = await c.request("POST", path, fix_body(None, positions, k, time.time()), hdr)
                k += 1
            lat.append(time.perf_counter() - t0)
            if status != 200:
                errors += 1

    t_start = time.perf_counter()
    await asyncio.gather(*(worker(i, c) for i, c in enumerate(clients)))
    elapsed = time.perf_counter() - t_start
    for c in clients:
        c.close()
    return len(lat) / elapsed, np.array(lat), errors


async def ws_phase(port: int, trips, positions, warmup_s: float, seconds: float) -> tuple[np.ndarray, int, int]:
    lat: list[float] = []
    errors = 0
    measuring = False
    stop = asyncio.Event()
    connected = 0

    async def one(i: int, trip_id: str, token: str, ready: asyncio.Event) -> None:
        nonlocal errors, connected
        url = f"ws://127.0.0.1:{port}/v1/trips/{trip_id}/stream?token={token}"
        async with connect(url, open_timeout=60, compression=None, max_queue=4) as ws:
            connected += 1
            await ready.wait()
            await asyncio.sleep((i % 1000) / 1000.0)  # spread the 1 Hz phases over the second
            k = i
            next_t = time.perf_counter()
            while not stop.is_set():
                t0 = time.perf_counter()
                await ws.send(fix_body(None, positions, k, time.time()).decode())
                reply = await ws.recv()
                if measuring:
                    lat.append(time.perf_counter() - t0)
                    if '"error"' in reply[:12]:
                        errors += 1
                k += 1
                next_t += 1.0
                await asyncio.sleep(max(0.0, next_t - time.perf_counter()))

    ready = asyncio.Event()
    tasks = []
    for i, (trip_id, token) in enumerate(trips):
        tasks.append(asyncio.create_task(one(i, trip_id, token, ready)))
        if i % 100 == 99:
            await asyncio.sleep(0.05)  # do not flood the accept queue
    deadline = time.monotonic() + 60
    while connected < len(trips) and time.monotonic() < deadline and not any(t.done() for t in tasks):
        await asyncio.sleep(0.1)
    n_conn = connected
    ready.set()
    await asyncio.sleep(warmup_s)
    measuring = True
    await asyncio.sleep(seconds)
    measuring = False
    stop.set()
    await asyncio.wait(tasks, timeout=10)
    for t in tasks:
        t.cancel()
    return np.array(lat), errors, n_conn


def pct_ms(samples_s, q: float) -> float:
    """The ``q`` percentile of latencies in seconds, in milliseconds (nan when there are none)."""
    a = np.asarray(samples_s)
    return float(np.percentile(a, q) * 1e3) if a.size else float("nan")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--conns", type=int, default=200)
    ap.add_argument("--http-s", type=float, default=8.0)
    ap.add_argument("--ws-trips", type=int, default=2000)
    ap.add_argument("--ws-warmup-s", type=float, default=5.0)
    ap.add_argument("--ws-s", type=float, default=20.0)
    args = ap.parse_args()

    cpus = sorted(os.sched_getaffinity(0))
    port = free_port()
    log = Path("/tmp") / f"bench_server_{port}.log"
    proc = start_service(port, log)
    if len(cpus) >= 2:
        os.sched_setaffinity(0, {cpus[1]})
    corridor = load_corridor(CORRIDOR)
    positions = [corridor.position(s) for s in np.arange(0.0, corridor.length_m, 9.0)]
    positions += positions[::-1]  # there and back in 9 m steps: no fix is an implausible jump (those skip the advisor)
    try:
        rss0 = rss_mib(proc.pid)

        async def run():
            trips = await create_trips(port, args.conns)
            await http_phase(port, 20, 1.0, "health", trips, positions)  # warm-up
            await http_phase(port, 20, 1.0, "fix", trips, positions)
            c0 = cpu_seconds(proc.pid)
            h_rps, h_lat, h_err = await http_phase(port, args.conns, args.http_s, "health", trips, positions)
            c1 = cpu_seconds(proc.pid)
            f_rps, f_lat, f_err = await http_phase(port, args.conns, args.http_s, "fix", trips, positions)
            c2 = cpu_seconds(proc.pid)
            print(f"HTTP, {args.conns} concurrent keep-alive clients, {args.http_s:g} s each (server on 1 core, client on another)")
            print(f"  GET /health         {h_rps:8.0f} req/s  p50 {pct_ms(h_lat, 50):6.1f} ms  p99 {pct_ms(h_lat, 99):6.1f} ms  server CPU {100 * (c1 - c0) / args.http_s:4.0f} %  errors {h_err}")
            print(f"  POST .../fixes      {f_rps:8.0f} req/s  p50 {pct_ms(f_lat, 50):6.1f} ms  p99 {pct_ms(f_lat, 99):6.1f} ms  server CPU {100 * (c2 - c1) / args.http_s:4.0f} %  errors {f_err}")
            print(f"  ratio fixes / health: {f_rps / h_rps:.2f}  (target >= 0.7)")
            base = rss_mib(proc.pid)
            ws_trips = await create_trips(port, args.ws_trips)
            after_create = rss_mib(proc.pid)
            c3 = cpu_seconds(proc.pid)
            me3 = cpu_seconds(os.getpid())
            t3 = time.perf_counter()
            lat, errors, n_conn = await ws_phase(port, ws_trips, positions, args.ws_warmup_s, args.ws_s)
            wall = time.perf_counter() - t3
            cpu = 100 * (cpu_seconds(proc.pid) - c3) / wall
            cpu_me = 100 * (cpu_seconds(os.getpid()) - me3) / wall
            after_ws = rss_mib(proc.pid)
            print(f"WebSocket: {n_conn} of {args.ws_trips} trips connected, one fix/s each, {args.ws_s:g} s measured after {args.ws_warmup_s:g} s warm-up")
            print(f"  {lat.size / args.ws_s:7.0f} advisories/s  RTT p50 {pct_ms(lat, 50):.1f} ms  p90 {pct_ms(lat, 90):.1f} ms  p99 {pct_ms(lat, 99):.1f} ms  max {pct_ms(lat, 100):.1f} ms  errors {errors}  server CPU {cpu:.0f} %, client CPU {cpu_me:.0f} % (of one core each, averaged over the phase incl. connecting)")
            print(f"Memory (server RSS): at start {rss0:.0f} MiB; before WS trips {base:.0f} MiB")
            print(f"  per trip, just created: {(after_create - base) * 1024 / args.ws_trips:.1f} KiB;  per trip with ~{args.ws_s + args.ws_warmup_s:.0f} fixes and an open WebSocket: {(after_ws - base) * 1024 / args.ws_trips:.1f} KiB")

        asyncio.run(run())
    finally:
        proc.kill()
        proc.wait(timeout=10)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
