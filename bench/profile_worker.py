"""Where a worker's CPU goes per fix, in process and on Redis, in one run: phones at one fix a second (as
``bench/bench_redis_load.py``) against one worker that samples its own CPU time (``bench/_sampled_server.py``).

For each store (in process; Redis, a ``redis-server`` started here) the worker serves ``--phones`` phones for a warm-up,
then samples its CPU over ``--seconds``; each sample is put in the part of a fix its stack is deepest in (``PARTS``: the
first rule, from the innermost frame out, that names one of its frames), and the worker's CPU per fix (from /proc) is
shared out by the samples. Read the two columns against each other: the machine is shared (its load is printed).

    .venv/bin/python bench/profile_worker.py [--phones 500] [--seconds 20] [--queue-aware off|on] [--transport http|ws|both]
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from bench._procs import cpu_seconds, free_port, wait_healthy  # noqa: E402
from bench.bench_redis_load import TRANSPORTS, run_phones  # noqa: E402
from bench.bench_scaleout import OPEN, bench_redis  # noqa: E402
from bench.bench_server import CORRIDOR, create_trips  # noqa: E402
from spat_feed.road.corridors import load_corridor  # noqa: E402

PARTS = (  # (part, frames that put a sample in it): a sample goes to the innermost frame named here
    ("HTTP: request parsed (uvicorn, httptools)", ("server/web/protocol.py:data_received", "server/web/protocol.py:on_headers_complete", "server/web/protocol.py:on_message_complete")),
    ("HTTP: response written (starlette Response, uvicorn send, socket)", ("starlette/responses.py:__call__",)),
    ("ASGI layers (uvicorn proxy headers, FastAPI, error and limit middleware, fix lane)", ("uvicorn/protocols/http/httptools_impl.py:run_asgi",)),
    ("WebSocket: message read (uvicorn websockets-sansio: frame parsed, queued)", ("uvicorn/protocols/websockets/websockets_sansio_impl.py:data_received",
                                                                                    "uvicorn/protocols/websockets/websockets_sansio_impl.py:receive",
                                                                                    "server/web/ws.py:data_received")),
    ("WebSocket: answer written (frame built, socket)", ("uvicorn/protocols/websockets/websockets_sansio_impl.py:send", "server/web/ws.py:send")),
    ("WebSocket: ASGI layers (starlette WebSocket, FastAPI wrappers)", ("starlette/websockets.py:receive", "starlette/websockets.py:send",
                                                                         "starlette/_exception_handler.py:sender")),
    ("metrics (requests, fixes, advice)", ("server/web/middleware.py:_count", "server/web/metrics.py:observe_advice")),
    ("fix body parsed (plain fix, else pydantic)", ("server/routes/trips.py:parse", "server/routes/stream.py:_parse")),
    ("store: token checked, trip loaded, held", ("server/storage/store.py:for_fix", "server/storage/store.py:authorize", "server/storage/store.py:__aenter__", "server/storage/store.py:__aexit__", "server/storage/store.py:hold")),
    ("store: state encoded, script call, reply (Python)", ("server/storage/store.py:save",)),
    ("Redis: commands written (socket send)", ("server/storage/redispipe.py:flush",)),
    ("Redis: replies read and matched", ("server/storage/redispipe.py:data_received",)),
    ("map matching", ("server/gps.py:match",)),
    ("track (order, plausibility, speed)", ("server/gps.py:order", "server/gps.py:add", "server/gps.py:implausible")),
    ("SPaT readings and observation", ("spat_feed/prediction/observe.py:observation", "server/spat.py:readings")),
    ("queue board (queue-aware advice)", ("server/queue.py:see", "server/queue.py:check")),
    ("advice (advisor)", ("advisory/advice/advisor.py:advise",)),
    ("advisory built (the response's dict, on_fix's own lines)", ("server/advising.py:on_fix",)),
    ("fix route or stream loop, apply_fix (the rest)", ("server/routes/trips.py:post_fix", "server/routes/stream.py:stream", "server/advising.py:apply_fix")),
    ("queue board shared through Redis (background sync)", ("server/storage/queue_store.py:sync",)),
)


def part_of(stack: list[str]) -> str:
    for frame in reversed(stack):
        for name, frames in PARTS:
            if frame in frames:
                return name
    return "event loop, other tasks (outside a request)"


def sample(store: str, transport: str, redis_url: str, args, folder: Path, positions) -> tuple[Counter, float, int, dict]:
    port = free_port()
    out = folder / f"samples-{store}.json"
    env = {**os.environ, "ECO_CORRIDORS": CORRIDOR, "ECO_DEFAULT_CORRIDOR": CORRIDOR, "ECO_SPEECH": "false", "ECO_BENCH_SAMPLES": str(out),
           "ECO_TABLES_DIR": str(Path(tempfile.gettempdir()) / "ecodrive-bench-tables"), **OPEN, "ECO_KEEP_ALIVE_S": "60", "ECO_READ_TIMEOUT_S": "60",
           "ECO_QUEUE_AWARE": "1" if args.queue_aware == "on" else "0", **({"ECO_STORE_URL": redis_url} if store == "redis" else {})}  # fmt: skip
    cmd = [sys.executable, str(REPO / "bench" / "_sampled_server.py"), "--port", str(port), "--log-level", "warning", "--no-access-log", "--workers", "1"]
    proc = subprocess.Popen(cmd, cwd=REPO, env=env, stdout=(folder / f"service-{store}.log").open("wb"), stderr=subprocess.STDOUT)
    try:
        wait_healthy(proc, port, folder / f"service-{store}.log")
        trips = asyncio.run(create_trips(port, args.phones))
        marks: list[tuple[float, float]] = []
        load = {}

        def mark() -> None:
            marks.append((time.perf_counter(), cpu_seconds(proc.pid)))
            if len(marks) == 2:
                load["before"] = os.getloadavg()[0]
                os.kill(proc.pid, signal.SIGUSR1)
            elif len(marks) == 3:
                os.kill(proc.pid, signal.SIGUSR2)

        res = run_phones(port, trips, positions, [[3.0, args.phones], [args.seconds, args.phones]], folder / "phones.json", mark, transport)
        deadline = time.monotonic() + 10
        while not out.exists() and time.monotonic() < deadline:
            time.sleep(0.1)
    finally:
        proc.terminate()
        proc.wait(timeout=20)
    t, m = np.asarray(res["t"]), res["marks"]
    n = int(((t >= m[1]) & (t < m[2])).sum())
    counts: Counter = Counter()
    for stack, k in json.loads(out.read_text()):
        counts[part_of(stack)] += k
    return counts, (marks[2][1] - marks[1][1]) / max(n, 1), n, load


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--phones", type=int, default=500)
    ap.add_argument("--seconds", type=float, default=20.0)
    ap.add_argument("--queue-aware", choices=["off", "on"], default="off")
    ap.add_argument("--transport", choices=sorted(TRANSPORTS), default="http", help="fixes as REST POSTs (default), on each trip's WebSocket stream, "
                    "or both (a worker per store and transport, one after the other)")  # fmt: skip
    args = ap.parse_args()
    corridor = load_corridor(CORRIDOR)
    there = [corridor.position(float(s)) for s in range(int(corridor.length_m))]
    positions = there + there[::-1]
    rows = {}
    with bench_redis() as (folder, redis):
        for transport in TRANSPORTS[args.transport]:
            for store in ("memory", "redis"):
                rows[store, transport] = sample(store, transport, redis.url, args, folder, positions)
    print(f"profile_worker: {args.phones} phones at 1 fix/s, 1 worker, queue-aware {args.queue_aware}, {args.seconds:g} s sampled per store and transport")
    for (store, transport), (counts, cpu_s, n, load) in rows.items():
        print(f"  {store:6s} {transport:4s}: {n} fixes, worker CPU {1e3 * cpu_s:.3f} ms per fix, {sum(counts.values())} samples, load average {load.get('before', float('nan')):.2f}")
    columns = list(rows)
    print(f"  {'us per fix':>10s} " + " ".join(f"{s[:5] + ' ' + ('REST' if t == 'http' else 'WS'):>10s}" for s, t in columns) + "  part")
    names = [name for name, _ in PARTS] + ["event loop, other tasks (outside a request)"]
    share = {key: {k: 1e6 * cpu_s * v / max(sum(counts.values()), 1) for k, v in counts.items()} for key, (counts, cpu_s, _, _) in rows.items()}
    for name in sorted(names, key=lambda k: -share[columns[-1]].get(k, 0.0)):
        if any(share[c].get(name) for c in columns):
            print(f"  {'':>10s} " + " ".join(f"{share[c].get(name, 0.0):10.1f}" for c in columns) + f"  {name}")
    print(f"  {'':>10s} " + " ".join(f"{sum(share[c].values()):10.1f}" for c in columns) + "  all")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
