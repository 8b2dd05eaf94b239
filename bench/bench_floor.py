"""The floor under a fix's CPU: what one worker spends per fix with nothing but the transport (and one Redis write).

The same phones as ``bench/bench_redis_load.py`` (``bench/_phones.py``: one fix a second each, REST or the WebSocket
stream) against ``bench/_floor_app.py``: uvicorn with the service's HTTP protocol and a minimal app answering each
fix with 600 bytes of JSON, alone or after one pipelined Redis ``SET`` of 1.6 kB (``server.storage.redispipe``); on the
stream with uvicorn's own ``websockets-sansio`` protocol and with the service's (``server.web.ws``). A row is the
worker's CPU per fix over ``--seconds`` after a 3 s warm-up; ``--rounds`` repeats the rows in turn. The machine is
shared: read the rows of one round against each other (its load is printed).

    .venv/bin/python bench/bench_floor.py [--phones 500] [--seconds 10] [--rounds 1]
"""

from __future__ import annotations

import argparse
import asyncio
import os
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from bench._procs import cpu_seconds, free_port, wait_healthy  # noqa: E402
from bench.bench_redis_load import run_phones  # noqa: E402
from bench.bench_scaleout import bench_redis  # noqa: E402
from bench.bench_server import CORRIDOR, create_trips  # noqa: E402
from server.web.ws import IMPLEMENTATION  # noqa: E402
from spat_feed.road.corridors import load_corridor  # noqa: E402

ROWS = (  # (label, transport, Redis write, WebSocket implementation)
    ("REST", "http", False, None),
    ("REST + Redis SET", "http", True, None),
    ("WebSocket, uvicorn's websockets-sansio", "ws", False, "websockets-sansio"),
    ("WebSocket, server.web.ws", "ws", False, IMPLEMENTATION),
    ("WebSocket, uvicorn's websockets-sansio + Redis SET", "ws", True, "websockets-sansio"),
    ("WebSocket, server.web.ws + Redis SET", "ws", True, IMPLEMENTATION),
)


def one_row(transport: str, redis_url: str | None, ws: str | None, args, folder: Path, positions) -> tuple[float, int]:
    """Worker CPU per fix [s] and fixes answered in the measured phase."""
    port = free_port()
    cmd = [sys.executable, str(REPO / "bench" / "_floor_app.py"), "--port", str(port), *(["--redis", redis_url] if redis_url else []), *(["--ws", ws] if ws else [])]
    proc = subprocess.Popen(cmd, cwd=REPO, stdout=(folder / "floor.log").open("ab"), stderr=subprocess.STDOUT)
    try:
        wait_healthy(proc, port, folder / "floor.log", 60.0)
        trips = asyncio.run(create_trips(port, args.phones))
        marks: list[float] = []
        out = run_phones(port, trips, positions, [[3.0, args.phones], [args.seconds, args.phones]], folder / "phones.json", lambda: marks.append(cpu_seconds(proc.pid)), transport)
    finally:
        proc.terminate()
        proc.wait(timeout=20)
    m = out["marks"]
    answered = [t for t, status in zip(out["t"], out["status"]) if m[1] <= t < m[2]]
    errors = sum(1 for t, status in zip(out["t"], out["status"]) if m[1] <= t < m[2] and status != 200)
    if errors:
        raise RuntimeError(f"{errors} fixes not answered 200 by the floor app")
    return (marks[2] - marks[1]) / max(len(answered), 1), len(answered)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--phones", type=int, default=500)
    ap.add_argument("--seconds", type=float, default=10.0)
    ap.add_argument("--rounds", type=int, default=1)
    args = ap.parse_args()
    corridor = load_corridor(CORRIDOR)
    there = [corridor.position(float(s)) for s in range(int(corridor.length_m))]
    positions = there + there[::-1]
    print(f"bench_floor: {args.phones} phones at 1 fix/s, 1 worker, {args.seconds:g} s per row; worker CPU per fix")
    with bench_redis() as (folder, redis):
        for k in range(args.rounds):
            print(f"  round {k + 1} (load average {os.getloadavg()[0]:.2f} before)")
            for label, transport, write, ws in ROWS:
                cpu_s, n = one_row(transport, redis.url if write else None, ws, args, folder, positions)
                print(f"    {1e3 * cpu_s:6.3f} ms  {label}  ({n} fixes, load average {os.getloadavg()[0]:.2f})", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
