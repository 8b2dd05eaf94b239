"""The trip store under open-loop load: phones sending one fix a second, in-process store against Redis, in one run.

For each service (the in-process store with 1 worker, Redis with ``--workers`` workers; Redis started here, a
``redis-server`` on a free loopback port with ``appendfsync everysec`` as deployed) the same phones
(``bench/_phones.py``, its own process: each phone one keep-alive connection and one trip, one fix per second at
its own offset, latency counted from the second it was due) run through four phases:

1. warm-up, ``--low`` phones (not reported);
2. ``--low`` phones (default 500): p50 / p99 latency (target p99 <= 100 ms), errors, and the workers' CPU per fix;
3. ``--high`` phones (default 2,000): what was answered, accepted and shed (503 ``overloaded`` + Retry-After),
   any 503 ``store_unavailable`` (must be 0 while Redis is idle), p99 of the accepted and of the shed, and
   the fixes phones could not send because their previous one was still unanswered (the service's queue);
4. ``--low`` phones again: the recovery time, from the drop until every later half second has no error and a
   p99 <= 100 ms (target <= 5 s).

Beside each service: the CPU (of one core) of the workers, Redis and the load generator over phase 2, the
machine's CPU taken by other jobs, and the 1-minute load average. The machine is shared: compare the services
within one run, not across runs. Then what the workers did per fix in phase 2 (/proc): their CPU in user and kernel
mode, how often they slept (voluntary context switches: one per wake-up) and were preempted (involuntary), their
read and write system calls, and with Redis the commands Redis ran per fix (``INFO commandstats``): work done per
connection or per trip in the background (lease renewals, pings, SPaT, metrics) shows there, besides the fix's own.

``--queue-aware on`` runs each service with queue-aware advice (``ECO_QUEUE_AWARE=1``: every fix a probe of the
corridor's traffic; with Redis every worker's probes shared, ``server/storage/queue_store.py``), ``both`` each service with it
off, then on, in one run.

``--transport ws`` sends the same fixes on each trip's WebSocket stream, as the app does (``bench/_phones.py``
``StreamPhone``: a real ``websockets`` client, every answer checked as a REST one); ``both`` runs REST, then the
stream, on the same service.

``--redis-over unix``: the workers reach Redis over a Unix socket (a Redis on the same machine) instead of loopback TCP.

    .venv/bin/python bench/bench_redis_load.py [--low 500] [--high 2000] [--seconds 10] [--workers 2] [--queue-aware off|on|both] [--transport http|ws|both]
                                               [--redis-over tcp|unix]
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from bench._procs import cpu_seconds, free_port, machine_cpu_s, tree_counters  # noqa: E402
from bench.bench_scaleout import bench_redis, running_service  # noqa: E402
from bench.bench_server import CORRIDOR, create_trips  # noqa: E402
from spat_feed.road.corridors import load_corridor  # noqa: E402
from tests.procs import RedisServer  # noqa: E402

TARGET_P99_S = 0.100
"""Latency target at the low load, and what "recovered" means after the high load. [s]"""
WINDOW_S = 0.5
"""Recovery is judged on windows of this many seconds of ticks. [s]"""
TRANSPORTS = {"http": ("http",), "ws": ("ws",), "both": ("http", "ws")}
"""``--transport``: how the phones send their fixes, in the order run (``both``: REST then WebSocket, same service)."""


def pct_ms(a, q: float) -> float:
    a = np.asarray(a)
    return float(np.percentile(a, q) * 1e3) if a.size else float("nan")


def run_phones(port: int, trips, positions, phases, out: Path, mark, transport: str = "http") -> dict:
    job = {"port": port, "trips": trips, "positions": positions, "period_s": 1.0, "phases": phases, "out": str(out)}
    gen = subprocess.Popen([sys.executable, str(REPO / "bench" / "_phones.py"), json.dumps(transport)], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    gen.stdin.write(json.dumps(job))
    gen.stdin.close()
    for line in gen.stdout:
        if line.strip() == "mark":
            mark()
        elif line.strip() == "done":
            gen.wait(timeout=30)
            return json.loads(out.read_text())
    raise RuntimeError(f"the phones' generator exited with {gen.wait()}")


def recovery_s(t, lat, ok, drop_s: float, end_s: float, before_p99_s: float) -> float:
    """Seconds from ``drop_s`` until every later window of ticks has no error and a p99 within the target or within
    what the same phones had before the overload (``before_p99_s``: the machine's other jobs, not the service, set
    that one); inf: never."""
    limit = max(TARGET_P99_S, before_p99_s)
    edges = np.arange(drop_s, end_s - WINDOW_S / 2, WINDOW_S)
    good_from = None
    for a in edges:
        sel = (t >= a) & (t < a + WINDOW_S)
        good = bool(sel.any()) and bool(ok[sel].all()) and np.percentile(lat[sel], 99) <= limit
        if not good:
            good_from = None
        elif good_from is None:
            good_from = a
    return float("inf") if good_from is None else good_from - drop_s


def one_service(name: str, env: dict, workers: int, redis: RedisServer, args, folder: Path, positions) -> None:
    """Start the service, create ``--high`` trips, then run the phases once per transport of ``--transport`` on it."""
    port = free_port()
    with running_service(port, folder / f"service-{workers}-{'ECO_STORE_URL' in env}.log", env, workers) as proc:
        trips = asyncio.run(create_trips(port, args.high))
        for transport in TRANSPORTS[args.transport]:
            marks = []
            load_avg = os.getloadavg()[0]
            phases = [[3.0, args.low], [args.seconds, args.low], [args.seconds, args.high], [args.seconds, args.low]]
            commands = redis_commands(redis) if "ECO_STORE_URL" in env else dict
            out = run_phones(port, trips, positions, phases, folder / "phones.json",
                             lambda: marks.append((tree_counters(proc.pid), cpu_seconds(redis.proc.pid), machine_cpu_s(), time.perf_counter(), commands())), transport)  # fmt: skip
            report(f"{name}, {'REST' if transport == 'http' else 'WebSocket'}", out, marks, load_avg, workers, args)


def redis_commands(redis: RedisServer):
    """A function giving the commands ``redis`` has run so far, by name (``INFO commandstats``: calls)."""
    import redis as redis_py

    client = redis_py.Redis.from_url(redis.url)
    return lambda: {name.removeprefix("cmdstat_"): stats["calls"] for name, stats in client.info("commandstats").items()}


def per_fix(before: dict, after: dict, n: int) -> str:
    """What the workers did per fix between two marks (:func:`bench._procs.tree_counters`, ``n`` fixes)."""
    d = {k: (after[k] - before[k]) / max(n, 1) for k in before}
    return (f"user {1e6 * d['user_s']:.0f} us, kernel {1e6 * d['system_s']:.0f} us; woke {d['voluntary']:.2f}, preempted {d['involuntary']:.2f};"
            f" reads {d['reads']:.2f}, writes {d['writes']:.2f}")


def report(name: str, out: dict, marks: list, load_avg: float, workers: int, args) -> None:
    """Print one run of the phases (``out``: the phones' records; ``marks``: CPU samples at the phases' edges)."""
    if os.environ.get("BENCH_KEEP"):
        Path(os.environ["BENCH_KEEP"]).with_suffix(f".{workers}.json").write_text(json.dumps(out))
    t, lat = np.asarray(out["t"]), np.asarray(out["lat_s"])
    status, kind = np.asarray(out["status"]), np.asarray(out["kind"])
    m = out["marks"]

    def phase(k: int):
        return (t >= m[k]) & (t < m[k + 1])

    def usage(k: int) -> tuple[float, float, float, float, float]:
        (t0, r0, m0, w0, _), (t1, r1, m1, w1, _) = marks[k], marks[k + 1]
        c0, c1 = t0["user_s"] + t0["system_s"], t1["user_s"] + t1["system_s"]
        wall = w1 - w0
        gen = (out["cpu_s"][k + 1] - out["cpu_s"][k]) / wall
        others = (m1["busy"] - m0["busy"]) / wall - (c1 - c0) / wall - (r1 - r0) / wall - gen
        return (c1 - c0), (c1 - c0) / wall, (r1 - r0) / wall, gen, others

    lo = phase(1)
    cpu_lo, w_lo, r_lo, g_lo, o_lo = usage(1)
    n_lo = int(lo.sum())
    print(f"   {name}  (load avg {load_avg:.2f} before; during the {args.low} phones: others {100 * o_lo:.0f} %, workers {100 * w_lo:.0f} %,"
          f" Redis {100 * r_lo:.0f} %, generator {100 * g_lo:.0f} % of a core)")  # fmt: skip
    print(f"     {args.low:5d} phones: {n_lo / args.seconds:6.0f} fixes/s  p50 {pct_ms(lat[lo], 50):6.1f} ms  p99 {pct_ms(lat[lo], 99):6.1f} ms"
          f"  errors {int((status[lo] != 200).sum())}  worker CPU {1e3 * cpu_lo / max(n_lo, 1):.3f} ms/fix")  # fmt: skip
    commands = {name: (calls - marks[1][4].get(name, 0)) / max(n_lo, 1) for name, calls in marks[2][4].items()}
    print(f"       per fix, the workers: {per_fix(marks[1][0], marks[2][0], n_lo)}"
          + (f"; Redis ran {', '.join(f'{name} {k:.2f}' for name, k in sorted(commands.items(), key=lambda c: -c[1]) if k >= 0.005)}" if commands else ""))  # fmt: skip
    hi = phase(2)
    cpu_hi, w_hi, _, _, o_hi = usage(2)
    acc, shed, unreach = hi & (status == 200), hi & (kind == 1), hi & (kind == 2)
    other = hi & (kind == 3)
    print(f"     {args.high:5d} phones: {hi.sum() / args.seconds:6.0f} answers/s, accepted {acc.sum() / args.seconds:6.0f}/s (p50 {pct_ms(lat[acc], 50):.1f} ms,"
          f" p99 {pct_ms(lat[acc], 99):.1f} ms), shed {int(shed.sum())} (p99 {pct_ms(lat[shed], 99):.1f} ms), store_unavailable {int(unreach.sum())},"
          f" other errors {int(other.sum())}; ticks not sent (answer still out) {out['late']}; worker CPU {1e3 * cpu_hi / max(int(hi.sum()), 1):.3f} ms/answer,"
          f" workers {100 * w_hi:.0f} %, others {100 * o_hi:.0f} %")  # fmt: skip
    after = t >= m[3]
    windows = [(t >= a) & (t < a + WINDOW_S) for a in np.arange(m[1], m[2] - WINDOW_S / 2, WINDOW_S)]
    before = max(np.percentile(lat[w], 99) for w in windows if w.any())
    rec = recovery_s(t[after], lat[after], status[after] == 200, m[3], m[4], before)
    last_error = t[after & (status != 200)].max() - m[3] if (after & (status != 200)).any() else float("nan")
    print(f"     back to {args.low}: recovered in {rec:.1f} s (target <= 5 s: from then on every {WINDOW_S:g} s has no error and a p99 <= {1e3 * TARGET_P99_S:.0f} ms"
          f" or <= the worst {WINDOW_S:g} s before the overload, {1e3 * before:.0f} ms); last error {last_error:.1f} s after the drop;"
          f" p99 from then on {pct_ms(lat[t >= m[3] + min(rec, args.seconds)], 99):.1f} ms; connections lost {out['lost']}")  # fmt: skip


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--low", type=int, default=500)
    ap.add_argument("--high", type=int, default=2000)
    ap.add_argument("--seconds", type=float, default=10.0, help="length of each measured phase [s]")
    ap.add_argument("--workers", type=int, default=2, help="Redis: worker processes")
    ap.add_argument("--only", choices=["memory", "redis"], help="run one service only")
    ap.add_argument("--transport", choices=sorted(TRANSPORTS), default="http", help="fixes as REST POSTs (default), on each trip's WebSocket stream "
                    "as the app sends them, or both, one after the other on the same service")  # fmt: skip
    ap.add_argument("--redis-over", choices=["tcp", "unix"], default="tcp", help="the workers reach Redis over loopback TCP (default) or a Unix socket "
                    "(same machine: ECO_STORE_URL=unix:///path/redis.sock)")  # fmt: skip
    ap.add_argument("--queue-aware", choices=["off", "on", "both"], help="queue-aware advice (ECO_QUEUE_AWARE) off, on, or each service both ways; "
                    "default: as the environment says (off)")  # fmt: skip
    args = ap.parse_args()
    if shutil.which("redis-server") is None:
        print("redis-server is not installed: sh scripts/system-deps.sh (as root) installs it")
        return 1
    corridor = load_corridor(CORRIDOR)
    there = [corridor.position(float(s)) for s in range(int(corridor.length_m))]
    positions = there + there[::-1]
    print(f"bench_redis_load: {os.cpu_count()} CPUs, shared with other jobs (their load is printed beside each service); phones send 1 fix/s ({args.transport})")
    with bench_redis(unix_socket=args.redis_over == "unix") as (folder, redis):
        idle = {"ECO_KEEP_ALIVE_S": "60", "ECO_READ_TIMEOUT_S": "60"}  # the phones beyond --low wait, connected, through two phases
        over = (" (Unix socket)", redis.unix_url) if args.redis_over == "unix" else ("", redis.url)
        services = [("in-process store, 1 worker", idle, 1), (f"Redis{over[0]}, {args.workers} workers", {**idle, "ECO_STORE_URL": over[1]}, args.workers)]
        queue = {None: [None], "off": ["0"], "on": ["1"], "both": ["0", "1"]}[args.queue_aware]
        for name, env, workers in services:
            if args.only and (args.only == "redis") != ("ECO_STORE_URL" in env):
                continue
            for aware in queue:
                label = name if aware is None else f"{name}, queue-aware advice {'on' if aware == '1' else 'off'}"
                one_service(label, env if aware is None else {**env, "ECO_QUEUE_AWARE": aware}, workers, redis, args, folder, positions)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
