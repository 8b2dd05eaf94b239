"""SPaT at city scale: one feed simulating 100 intersections at 10 Hz, one service holding 5,000 trips on one corridor.

Starts ``python -m spat_feed`` (100 intersections: 10 corridors of 10 lights, written to a temporary folder) on
CPU 0 and ``python -m server`` on CPU 1, reading the feed's per-intersection stream (``ECO_SPAT_FEED_URL``),
then measures twice, with no trips and with ``--trips`` trips open: the feed's and the service's CPU share, and
the message latency p50/p99 (receive time minus the message's timestamp) at a subscriber of the same stream.
The SPaT work per tick must not grow with the trips: the service's CPU ratio (trips / none) is printed. Last,
a trip created among them posts fixes until its advice says the SPaT is fresh: that time is printed (target < 1 s).

    .venv/bin/python bench/bench_spat_city.py [--trips 5000] [--duration-s 10]
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import subprocess
import sys
import tempfile
import time
from datetime import datetime
from pathlib import Path

import httpx
import numpy as np
from websockets.asyncio.client import connect

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from bench._procs import cpu_seconds, free_port  # noqa: E402
from spat_feed.road.corridors import CHAMPS_ELYSEES, straight_corridor  # noqa: E402


def write_corridors(folder: Path, n_corridors: int = 10, lights: int = 10) -> list[Path]:
    """``n_corridors`` corridors of ``lights`` lights 100 m apart, intersection ids 101-110, 201-210, ..."""
    paths = []
    for k in range(1, n_corridors + 1):
        c = straight_corridor(f"city_{k}", CHAMPS_ELYSEES, [100.0 * (i + 1) for i in range(lights)], 100.0 * (lights + 1), first_id=100 * k + 1)
        path = folder / f"city_{k}.json"
        path.write_text(c.model_dump_json())
        paths.append(path)
    return paths


def start(cmd: list[str], cpu: int | None, env: dict[str, str], log: Path) -> subprocess.Popen:
    fh = log.open("wb")
    proc = subprocess.Popen(cmd, cwd=REPO, env={**os.environ, **env}, stdout=fh, stderr=subprocess.STDOUT,
                            preexec_fn=(lambda: os.sched_setaffinity(0, {cpu})) if cpu is not None else None)  # fmt: skip
    return proc


def wait_health(url: str, proc: subprocess.Popen, log: Path, timeout_s: float = 120.0) -> None:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            raise SystemExit(f"{url} exited:\n{log.read_text()[-3000:]}")
        try:
            if httpx.get(url + "/health", timeout=1).status_code == 200:
                return
        except httpx.HTTPError:
            pass
        time.sleep(0.2)
    raise SystemExit(f"{url} did not start:\n{log.read_text()[-3000:]}")


async def latencies(url: str, duration_s: float) -> list[float]:
    out: list[float] = []
    async with connect(url, compression=None, max_size=2**22) as ws:
        await asyncio.wait_for(ws.recv(), 10)  # the latest states first, then one message per tick
        end = time.monotonic() + duration_s
        while time.monotonic() < end:
            text = await ws.recv()
            now = time.time()
            out.append(now - datetime.fromisoformat(json.loads(text)["timestamp"].replace("Z", "+00:00")).timestamp())
    return out


def measure(feed: subprocess.Popen, svc: subprocess.Popen, stream_url: str, duration_s: float) -> dict[str, float]:
    f0, s0 = cpu_seconds(feed.pid), cpu_seconds(svc.pid)
    lat = np.array(asyncio.run(latencies(stream_url, duration_s))) * 1e3
    return {
        "feed_cpu": (cpu_seconds(feed.pid) - f0) / duration_s,
        "svc_cpu": (cpu_seconds(svc.pid) - s0) / duration_s,
        "p50_ms": float(np.percentile(lat, 50)),
        "p99_ms": float(np.percentile(lat, 99)),
        "messages_per_s": len(lat) / duration_s,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trips", type=int, default=5000)
    parser.add_argument("--duration-s", type=float, default=10.0)
    parser.add_argument("--rate-hz", type=float, default=10.0)
    args = parser.parse_args()
    cpus = sorted(os.sched_getaffinity(0))
    c_feed, c_svc = (cpus[0], cpus[1]) if len(cpus) >= 2 else (None, None)
    with tempfile.TemporaryDirectory(prefix="ecodrive-bench-") as tmp:
        folder = Path(tmp)
        paths = write_corridors(folder)
        fport, sport = free_port(), free_port()
        feed = start([sys.executable, "-m", "spat_feed", "--port", str(fport), "--rate-hz", str(args.rate_hz), "--corridors", ",".join(map(str, paths))], c_feed, {}, folder / "feed.log")
        svc = None
        try:
            wait_health(f"http://127.0.0.1:{fport}", feed, folder / "feed.log")
            n_ix = len(httpx.get(f"http://127.0.0.1:{fport}/health").json()["intersections"])
            env = {"ECO_SPAT_FEED_URL": f"http://127.0.0.1:{fport}", "ECO_CORRIDOR_DIR": str(folder), "ECO_CORRIDORS": "paper_s200", "ECO_DEFAULT_CORRIDOR": "city_1",
                   "ECO_TABLES": "false", "ECO_SPEECH": "false", "ECO_MAX_TRIPS_PER_CLIENT": "0", "ECO_CREATE_RATE_PER_CLIENT_PER_S": "100000",
                   "ECO_CREATE_BURST_PER_CLIENT": "100000", "ECO_CREATE_RATE_PER_S": "100000", "ECO_CREATE_BURST": "100000", "ECO_MAX_CONNECTIONS_PER_CLIENT": "0"}  # fmt: skip
            svc = start([sys.executable, "-m", "server", "--port", str(sport), "--log-level", "warning", "--no-access-log"], c_svc, env, folder / "service.log")
            base = f"http://127.0.0.1:{sport}"
            wait_health(base, svc, folder / "service.log")
            if c_svc is not None:
                os.sched_setaffinity(0, {c_svc})  # the bench's own client shares the service's core
            stream_url = f"ws://127.0.0.1:{fport}/spat/intersections/stream"
            time.sleep(2.0)
            none = measure(feed, svc, stream_url, args.duration_s)
            with httpx.Client(base_url=base, timeout=30) as client:
                t0 = time.perf_counter()
                for _ in range(args.trips):
                    client.post("/v1/trips", json={"corridor": "city_1"}).raise_for_status()
                create_s = time.perf_counter() - t0
                loaded = measure(feed, svc, stream_url, args.duration_s)
                lat, lon = json.loads(paths[0].read_text())["polyline"][1]["lat_deg"], json.loads(paths[0].read_text())["polyline"][1]["lon_deg"]
                t0 = time.perf_counter()
                r = client.post("/v1/trips", json={"corridor": "city_1"}).json()
                auth = {"Authorization": f"Bearer {r['token']}"}
                while True:
                    advice = client.post(f"/v1/trips/{r['trip_id']}/fixes", json={"t_unix_s": time.time(), "lat_deg": lat, "lon_deg": lon, "speed_mps": 12.0}, headers=auth).json()
                    if advice["spat_fresh"]:
                        break
                fresh_s = time.perf_counter() - t0
                health = client.get("/health").json()
            ages = [i["age_s"] for i in health["spat_health"]["intersections"] if i["age_s"] is not None]
        finally:
            for p in (svc, feed):
                if p is not None:
                    p.terminate()
                    p.wait(timeout=10)
    print(f"SPaT at city scale: feed simulating {n_ix} intersections at {args.rate_hz:g} Hz (CPU {c_feed}), service on CPU {c_svc} "
          f"reading its per-intersection stream; {len(cpus)} CPUs; {args.duration_s:g} s per measurement")
    print(f"{'':>14} {'feed CPU':>9} {'service CPU':>12} {'latency p50':>12} {'p99':>8} {'msg/s':>7}")
    for name, m in (("no trips", none), (f"{args.trips:,} trips", loaded)):
        print(f"{name:>14} {100 * m['feed_cpu']:>8.1f}% {100 * m['svc_cpu']:>11.1f}% {m['p50_ms']:>10.1f}ms {m['p99_ms']:>6.1f}ms {m['messages_per_s']:>7.1f}")
    print(f"service SPaT CPU with {args.trips:,} trips / with none: {loaded['svc_cpu'] / max(none['svc_cpu'], 1e-9):.2f} (no per-trip work per message: ~1)")
    print(f"{args.trips:,} trips created in {create_s:.1f} s; a trip created then saw fresh SPaT after {1e3 * fresh_s:.1f} ms (target < 1000 ms)")
    print(f"SPaT age at the service ({len(ages)} intersections): median {1e3 * np.median(ages):.0f} ms, max {1e3 * max(ages):.0f} ms")


if __name__ == "__main__":
    main()
