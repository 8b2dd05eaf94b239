"""Scale-out: the trip store's cost per fix, fixes/s with 1 and 2 workers on Redis against the in-process
baseline, and Redis memory per open trip. Starts its own ``redis-server`` (Debian package; see
scripts/system-deps.sh) on a free loopback port in a temporary folder. Prints, in one run:

1. **Store latency per fix** (in this process, no HTTP): the same drive of ``--lat-trips`` trips applied fix by
   fix (``Engine.apply_fix``) with the in-process store and with Redis: the whole fix p50/p99 for each, and
   the store's own time per fix (``authorize`` = load + rate limit, ``save``) on Redis, p50/p99 (target
   p99 < 2 ms); once with the worker's cache warm (a WebSocket, or one worker) and once with every fix
   reloading the trip's state (REST round robin over workers: the state changed elsewhere). Then the CPU per
   fix with 200 trips' fixes applied at once (the event loop never idle, one write to Redis for them all): the
   store's own work per fix, without the wake-ups and cold caches of a server whose fixes come one at a time;
   and with the same fixes applied one at a time, each waiting for its answer as a phone's stream does: the
   CPU of the kernel in it and the involuntary context switches per fix (Redis, woken by the write, preempting
   the worker on its core: the cache it leaves behind is paid by the worker's next Python).
2. **HTTP fixes/s**: ``--conns`` keep-alive clients (default 200, one trip each, one fix in flight each) POST
   fixes for ``--http-s`` each to: the in-process store (1 worker), Redis with 1 worker, Redis with
   ``--workers 2``; fixes/s, p50/p99, the ratio 2 workers / 1 worker, and beside each run the CPU (of one
   core) of the workers, Redis and the load generator, the machine's CPU taken by other jobs, stolen by the
   hypervisor and idle, and the load average. The load generator (``bench/_loadgen.py``) is its own process,
   lean (~50 us of CPU per fix): on 2 cores the second worker needs the CPU that other jobs do not take.
   ``--rounds N`` repeats the three runs.
3. **Memory**: ``--trips`` (default 20,000) open trips with ``--fixes`` fixes each in Redis (``used_memory``
   before and after): bytes per trip, and per further fix (the score samples, 24 bytes).

    .venv/bin/python bench/bench_scaleout.py [--conns 200] [--http-s 8] [--rounds 1] [--trips 20000] [--fixes 5]
                                             [--parts latency,http,memory]

Figures on a shared 2-core machine are indicative: the workers, Redis and the load generator share the cores
with whatever else runs (the "others" column says how much).
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import gc
import json
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

import httpx
import numpy as np
from tqdm import tqdm

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from bench._procs import cpu_seconds, free_port, machine_cpu_s, tree_counters  # noqa: E402
from bench.bench_server import CORRIDOR, create_trips, pct_ms  # noqa: E402
from server.advising import Engine  # noqa: E402
from server.config import Settings  # noqa: E402
from server.gps import Fix  # noqa: E402
from server.schemas import TripCreate  # noqa: E402
from spat_feed.road.corridors import load_corridor  # noqa: E402
from tests.procs import RedisServer  # noqa: E402

OPEN = {"ECO_RATE_PER_S": "1000000", "ECO_RATE_BURST": "1000000", "ECO_CREATE_RATE_PER_S": "1000000", "ECO_CREATE_BURST": "1000000",
        "ECO_MAX_CONNECTIONS_PER_CLIENT": "0", "ECO_WS_MAX_PER_CLIENT": "0", "ECO_MAX_TRIPS_PER_CLIENT": "0",
        "ECO_CREATE_RATE_PER_CLIENT_PER_S": "1000000", "ECO_CREATE_BURST_PER_CLIENT": "1000000", "ECO_MAX_TRIPS": "100000"}  # fmt: skip
"""Limits off: one client address makes every request here."""


def settings(store_url: str | None, prefix: str = "eco") -> Settings:
    env = {k[4:].lower(): v for k, v in OPEN.items()}
    return Settings(corridors=(CORRIDOR,), default_corridor=CORRIDOR, tables=False, speech=False, store_url=store_url, store_prefix=prefix, **env)


class Timed:
    """Wraps a store's ``authorize`` and ``save`` to record their durations."""

    def __init__(self, store) -> None:
        self.times: list[float] = []
        self._pending = 0.0
        for name in ("authorize", "save"):
            setattr(store, name, self._wrap(getattr(store, name), name == "save"))

    def _wrap(self, fn, last: bool):
        async def timed(*a, **k):
            t0 = time.perf_counter()
            try:
                return await fn(*a, **k)
            finally:
                self._pending += time.perf_counter() - t0
                if last:
                    self.times.append(self._pending)
                    self._pending = 0.0

        return timed


async def _trips_and_fixes(engine: Engine, n_trips: int, n_fixes: int, corridor) -> tuple[list, list[Fix]]:
    """``n_trips`` new trips on ``engine`` and the ``n_fixes`` fixes of a car driving the corridor at 15 m/s, up to now."""
    now = time.time()
    trips = [await engine.create_trip(TripCreate(corridor=CORRIDOR, timing="15_15", entry_unix_s=now - n_fixes - 5)) for _ in range(n_trips)]
    return trips, [Fix(now - n_fixes + k, *corridor.position(min(15.0 * k, corridor.length_m)), 15.0, None, 4.0) for k in range(n_fixes)]


async def drive(engines: list[Engine], n_trips: int, n_fixes: int, corridor, progress: str) -> list[float]:
    """``n_trips`` trips created on ``engines[0]``, each driven fix by fix, fix k applied by ``engines[k % len]``;
    the duration of each ``apply_fix``."""
    trips, fixes = await _trips_and_fixes(engines[0], n_trips, n_fixes, corridor)
    out = []
    for k in tqdm(range(n_fixes), desc=progress, leave=False):
        fix = fixes[k]
        for trip in trips:
            t0 = time.perf_counter()
            await engines[k % len(engines)].apply_fix(trip.id, trip.token, lambda: fix)
            out.append(time.perf_counter() - t0)
    return out


async def latency_part(redis_url: str, n_trips: int, n_fixes: int) -> None:
    corridor = load_corridor(CORRIDOR)
    corridors = {CORRIDOR: corridor}
    mem = Engine(settings(None), corridors)
    await drive([mem], 5, 5, corridor, "warm-up")
    t_mem = await drive([mem], n_trips, n_fixes, corridor, "in-process store")
    red = Engine(settings(redis_url, "lat"), corridors)
    timed = Timed(red.trips)
    t_red = await drive([red], n_trips, n_fixes, corridor, "Redis, cache warm")
    s_warm = timed.times[:]
    other = Engine(settings(redis_url, "lat"), corridors)
    timed.times.clear()
    timed_other = Timed(other.trips)
    t_rr = await drive([red, other], n_trips, n_fixes, corridor, "Redis, round robin")
    s_rr = timed.times + timed_other.times
    print(f"1. Per fix, in this process, {n_trips} trips x {n_fixes} fixes, one at a time (no HTTP)")
    print(f"   in-process store        apply_fix p50 {pct_ms(t_mem, 50):6.3f} ms  p99 {pct_ms(t_mem, 99):6.3f} ms")
    print(f"   Redis, cache warm       apply_fix p50 {pct_ms(t_red, 50):6.3f} ms  p99 {pct_ms(t_red, 99):6.3f} ms   store (load + save) p50 {pct_ms(s_warm, 50):.3f} ms  p99 {pct_ms(s_warm, 99):.3f} ms  (target p99 < 2 ms)")
    print(f"   Redis, 2 workers alt.   apply_fix p50 {pct_ms(t_rr, 50):6.3f} ms  p99 {pct_ms(t_rr, 99):6.3f} ms   store (load + save) p50 {pct_ms(s_rr, 50):.3f} ms  p99 {pct_ms(s_rr, 99):.3f} ms  (every fix reloads the state)")
    print(f"   added per fix by Redis (p50 of apply_fix): {pct_ms(t_red, 50) - pct_ms(t_mem, 50):.3f} ms warm, {pct_ms(t_rr, 50) - pct_ms(t_mem, 50):.3f} ms round robin")
    hot_mem, hot_red = Engine(settings(None), corridors), Engine(settings(redis_url, "hot"), corridors)  # no timing wrappers
    gc.freeze()  # as the service does after start-up: collections skip what is already here
    for at_once, how in ((True, f"{HOT_TRIPS} trips' fixes at once (the loop never idle, the write to Redis shared: the work itself)"),
                         (False, f"{HOT_TRIPS} trips' fixes one at a time, each waiting for its answer (a phone's stream)")):  # fmt: skip
        best_mem = best_red = (float("inf"), 0.0, 0.0)
        for _ in range(3):
            best_mem = min(best_mem, await cpu_per_fix(hot_mem, HOT_TRIPS, 10, corridor, at_once))
            best_red = min(best_red, await cpu_per_fix(hot_red, HOT_TRIPS, 10, corridor, at_once))
        print(f"   CPU per fix, {how}, best of 3: in-process store {1e6 * best_mem[0]:.1f} us, Redis {1e6 * best_red[0]:.1f} us"
              f" (+{1e6 * (best_red[0] - best_mem[0]):.1f} us; of it in the kernel {1e6 * best_mem[1]:.1f} / {1e6 * best_red[1]:.1f} us;"
              f" involuntary context switches per fix {best_mem[2]:.2f} / {best_red[2]:.2f})")  # fmt: skip
    for e in (red, other, hot_red):
        await e.trips.close()


HOT_TRIPS = 200
"""Trips whose fixes :func:`cpu_per_fix` applies at once."""


async def cpu_per_fix(engine: Engine, n_trips: int, n_fixes: int, corridor, at_once: bool = True) -> tuple[float, float, float]:
    """This thread's CPU per ``apply_fix`` (all, of it in the kernel) and its involuntary context switches per fix when
    ``n_trips`` trips' k-th fixes are applied k by k, at once or (``at_once`` False) one after the other, each waiting
    for its answer (on Redis: the worker writes, Redis runs, often on the worker's core, and replies). [s, s, -]"""
    trips, fixes = await _trips_and_fixes(engine, n_trips, n_fixes, corridor)
    r0 = resource.getrusage(resource.RUSAGE_THREAD)
    for fix in fixes:
        if at_once:
            await asyncio.gather(*(engine.apply_fix(trip.id, trip.token, lambda f=fix: f) for trip in trips))
        else:
            for trip in trips:
                await engine.apply_fix(trip.id, trip.token, lambda f=fix: f)
    r1 = resource.getrusage(resource.RUSAGE_THREAD)
    n = n_trips * n_fixes
    return (r1.ru_utime + r1.ru_stime - r0.ru_utime - r0.ru_stime) / n, (r1.ru_stime - r0.ru_stime) / n, (r1.ru_nivcsw - r0.ru_nivcsw) / n


def start_service(port: int, log_path: Path, env: dict[str, str], workers: int) -> subprocess.Popen:
    env = {**os.environ, "ECO_CORRIDORS": CORRIDOR, "ECO_DEFAULT_CORRIDOR": CORRIDOR, "ECO_SPEECH": "false",
           "ECO_TABLES_DIR": str(Path(tempfile.gettempdir()) / "ecodrive-bench-tables"), **OPEN, **env}  # fmt: skip
    cmd = [sys.executable, "-m", "server", "--port", str(port), "--log-level", "warning", "--no-access-log", "--workers", str(workers)]
    proc = subprocess.Popen(cmd, cwd=REPO, env=env, stdout=log_path.open("wb"), stderr=subprocess.STDOUT)
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            raise RuntimeError(log_path.read_text())
        try:
            if httpx.get(f"http://127.0.0.1:{port}/health", timeout=1).status_code == 200:
                if workers > 1:
                    time.sleep(5.0)  # the other workers finish their start-up too
                return proc
        except httpx.HTTPError:
            pass
        time.sleep(0.2)
    proc.kill()
    raise RuntimeError("service did not start")


@contextlib.contextmanager
def running_service(port: int, log_path: Path, env: dict[str, str], workers: int) -> Iterator[subprocess.Popen]:
    """:func:`start_service`, stopped (terminated, killed after 20 s) when the block ends."""
    proc = start_service(port, log_path, env, workers)
    try:
        yield proc
    finally:
        proc.terminate()
        with contextlib.suppress(subprocess.TimeoutExpired):
            proc.wait(timeout=20)
        if proc.poll() is None:
            proc.kill()


@contextlib.contextmanager
def bench_redis(unix_socket: bool = False) -> Iterator[tuple[Path, RedisServer]]:
    """A temporary folder and a ``redis-server`` in it (``appendfsync everysec``, as deployed; with ``unix_socket`` also
    on a Unix socket there), killed at the end."""
    with tempfile.TemporaryDirectory(prefix="ecodrive-bench-") as tmp:
        folder = Path(tmp)
        (folder / "redis").mkdir()
        redis = RedisServer(folder / "redis", fsync="everysec", unix_socket=unix_socket).start()
        try:
            yield folder, redis
        finally:
            redis.kill()


def tree_cpu_s(pid: int) -> float:
    """CPU seconds of a process and its children (uvicorn's workers)."""
    c = tree_counters(pid)
    return c["user_s"] + c["system_s"]


def load(port: int, trips, positions, warmup_s: float, seconds: float, mark, out: Path) -> dict:
    """Run the load generator (``bench/_loadgen.py``, its own process) against ``port``; ``mark()`` is called
    when its measured window opens and when it closes (the caller samples CPU there); ``out``: its results."""
    job = {"port": port, "trips": trips, "positions": positions, "warmup_s": warmup_s, "seconds": seconds, "out": str(out)}
    gen = subprocess.Popen([sys.executable, str(REPO / "bench" / "_loadgen.py")], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    gen.stdin.write(json.dumps(job))
    gen.stdin.close()
    for line in gen.stdout:
        if line.strip() in ("start", "stop"):
            mark()
        elif line.strip() == "done":
            gen.wait(timeout=30)
            return json.loads(out.read_text())
    raise RuntimeError(f"the load generator exited with {gen.wait()}")


def http_part(redis: RedisServer, conns: int, seconds: float, folder: Path, rounds: int) -> None:
    """``rounds`` times the three services one after the other; each round's ratio, and the round whose runs
    had the least CPU taken by other jobs on the machine."""
    corridor = load_corridor(CORRIDOR)
    there = [corridor.position(float(s)) for s in range(int(corridor.length_m))]
    positions = there + there[::-1]  # 1 m apart, there and back
    results = []
    for k in range(rounds):
        if rounds > 1:
            print(f"   round {k + 1} of {rounds}")
        results.append(http_round(redis, conns, seconds, folder, positions))
    if rounds > 1:
        ratios = ", ".join(f"{r2 / r1:.2f}" for (_, (r1, _, _), (r2, _, _)) in results)
        quiet = min(results, key=lambda rows: max(rows[1][2], rows[2][2]))
        (_, _, _), (r1, _, o1), (r2, _, o2) = quiet
        print(f"   ratios 2 workers / 1 worker, by round: {ratios}; in the round with the least other CPU ({100 * o1:.0f} % and {100 * o2:.0f} % of a core"
              f" taken by other jobs during the two Redis runs): {r2 / r1:.2f}")  # fmt: skip


def http_round(redis: RedisServer, conns: int, seconds: float, folder: Path, positions) -> list[tuple[float, float, float]]:
    """The in-process store, Redis with 1 worker and with 2: (fixes/s, workers' CPU, others' CPU) each, printed."""
    rows = []
    for name, env, workers in (("in-process store, 1 worker", {}, 1), ("Redis, 1 worker", {"ECO_STORE_URL": redis.url}, 1),
                               ("Redis, 2 workers", {"ECO_STORE_URL": redis.url}, 2)):  # fmt: skip
        port = free_port()
        with running_service(port, folder / f"service-{workers}-{bool(env)}.log", env, workers) as proc:
            trips = asyncio.run(create_trips(port, conns))
            marks = []
            load_avg = os.getloadavg()[0]
            out = load(port, trips, positions, 2.0, seconds, lambda: marks.append((time.perf_counter(), tree_cpu_s(proc.pid), cpu_seconds(redis.proc.pid), machine_cpu_s())),
                       folder / "load.json")  # fmt: skip
        (t0, c0, r0, m0), (t1, c1, r1, m1) = marks
        rps, lat, wall = out["n"] / out["elapsed_s"], out["lat_s"], t1 - t0
        cpu, cpu_redis, cpu_gen = (c1 - c0) / wall, (r1 - r0) / wall, out["cpu_s"] / out["elapsed_s"]
        machine = {k: (m1[k] - m0[k]) / wall for k in m0}
        others = machine["busy"] - cpu - cpu_redis - cpu_gen
        rows.append((rps, cpu, others))
        print(f"   {name:27s} {rps:6.0f} fixes/s  p50 {pct_ms(lat, 50):6.1f} ms  p99 {pct_ms(lat, 99):6.1f} ms  errors {out['errors']}  "
              f"CPU: workers {100 * cpu:3.0f} %, Redis {100 * cpu_redis:3.0f} %, generator {100 * cpu_gen:3.0f} % ({1e6 * cpu_gen / max(rps, 1):.0f} us/fix), "
              f"{1e3 * cpu / max(rps, 1):.2f} worker-ms/fix;  machine: others {100 * others:3.0f} %, steal {100 * machine['steal']:3.0f} %, "
              f"idle {100 * machine['idle']:3.0f} %;  load avg {load_avg:.2f}")  # fmt: skip
    (_, _, _), (r1, c1, _), (r2, c2, _) = rows
    print(f"   ratio 2 workers / 1 worker on Redis: {r2 / r1:.2f}  (issue target >= 1.6 on 2 free cores); Redis 1 worker / in-process: {r1 / rows[0][0]:.2f}")
    print(f"   the workers' CPU, 2 / 1: {c2 / c1:.2f}; fixes per worker-CPU-second, 2 / 1: {(r2 / c2) / (r1 / c1):.2f} (1.00: a second worker costs nothing per fix)")
    print(f"   CPU %: of one core, over the measured window (others: the machine's busy time not ours; steal: taken by the hypervisor);"
          f" load avg: 1-minute, just before the run ({os.cpu_count()} CPUs)")
    return rows


async def memory_part(redis_url: str, n_trips: int, n_fixes: int) -> None:
    import redis.asyncio as aioredis

    corridor = load_corridor(CORRIDOR)
    r = aioredis.Redis.from_url(redis_url)
    await r.flushdb()
    before = (await r.info("memory"))["used_memory"]
    engine = Engine(settings(redis_url, "mem"), {CORRIDOR: corridor})
    engine.trips.CACHE_IDLE_S = 0.0
    now = time.time()
    fixes = []
    for k in range(n_fixes):
        lat, lon = corridor.position(15.0 * k)
        fixes.append(Fix(now - n_fixes + k, lat, lon, 15.0, None, 4.0))

    async def one() -> None:
        trip = await engine.create_trip(TripCreate(corridor=CORRIDOR, timing="15_15", entry_unix_s=now - n_fixes - 5))
        for fix in fixes:
            await engine.apply_fix(trip.id, trip.token, lambda f=fix: f)
        engine.trips._forget(trip.id)  # keep this process's cache small: the trips live in Redis

    batch = 200
    for _ in tqdm(range(0, n_trips, batch), desc=f"{n_trips} trips in Redis", leave=False):
        await asyncio.gather(*(one() for _ in range(batch)))
    after = (await r.info("memory"))["used_memory"]
    keys = await r.dbsize()
    per = (after - before) / n_trips
    print(f"3. Redis memory: {n_trips} open trips with {n_fixes} fixes each: {(after - before) / 2**20:.1f} MiB, {per:.0f} bytes per trip ({keys} keys);")
    print(f"   each further fix with a speed adds a 24-byte score sample: a 10-minute drive (600 fixes) ~{(per + 24 * (600 - n_fixes)) / 1024:.1f} KiB")
    await r.flushdb()
    await engine.trips.close()
    await r.aclose()


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--conns", type=int, default=200)
    ap.add_argument("--http-s", type=float, default=8.0)
    ap.add_argument("--lat-trips", type=int, default=50)
    ap.add_argument("--lat-fixes", type=int, default=30)
    ap.add_argument("--trips", type=int, default=20_000)
    ap.add_argument("--fixes", type=int, default=5)
    ap.add_argument("--rounds", type=int, default=1, help="HTTP part: the three runs this many times (the machine's other jobs come and go)")
    ap.add_argument("--parts", default="latency,http,memory", help="which parts to run (comma-separated)")
    args = ap.parse_args()
    parts = set(args.parts.split(","))
    if shutil.which("redis-server") is None:
        print("redis-server is not installed: sh scripts/system-deps.sh (as root) installs it")
        return 1
    print(f"bench_scaleout: {os.cpu_count()} CPUs (shared: figures are indicative)")
    with bench_redis() as (folder, redis):
        if "latency" in parts:
            asyncio.run(latency_part(redis.url, args.lat_trips, args.lat_fixes))
        if "http" in parts:
            print(f"2. HTTP, {args.conns} keep-alive clients (one trip each, one fix in flight each), {args.http_s:g} s each after 2 s warm-up;"
                  " load generator: bench/_loadgen.py, its own process")
            http_part(redis, args.conns, args.http_s, folder, args.rounds)
        if "memory" in parts:
            asyncio.run(memory_part(redis.url, args.trips, args.fixes))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
