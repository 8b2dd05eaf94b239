"""SPaT feed fan-out: N WebSocket subscribers at 10 Hz; message latency p50/p99 and messages/s.

Starts ``python -m spat_feed`` on 127.0.0.1 (pinned to CPU 0 when there are two or more), opens N
subscribers in this process (pinned to CPU 1), waits ``--warmup-s``, then for ``--duration-s`` records,
for every message, receive time minus the ``timestamp`` the feed wrote when it built the message (the
same machine clock on both sides). The latency therefore includes building the message, the fan-out to
all subscribers, the loopback and the subscriber's own event loop.

    .venv/bin/python bench/bench_spat_feed.py [--subscribers 1000] [--rate-hz 10] [--duration-s 15]
"""

from __future__ import annotations

import argparse
import asyncio
import os
import subprocess
import sys
import time
from datetime import datetime
from pathlib import Path

import httpx
import numpy as np
from websockets.asyncio.client import connect

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from bench._procs import cpu_seconds, free_port, rss_mib  # noqa: E402,F401


def stamp_s(text: str) -> float:
    """The message's ``timestamp``: the text begins ``{"timestamp":"YYYY-MM-DDTHH:MM:SS.mmmZ"``."""
    return datetime.fromisoformat(text[14:38].replace("Z", "+00:00")).timestamp()


async def subscriber(url: str, latencies: list[float], state: dict, ready: asyncio.Event) -> None:
    async with connect(url, compression=None, max_size=2**20, open_timeout=60) as ws:
        state["connected"] += 1
        if state["connected"] == state["n"]:
            ready.set()
        async for text in ws:
            now = time.time()
            if state["recording"]:
                latencies.append(now - stamp_s(text))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--subscribers", type=int, default=1000)
    parser.add_argument("--rate-hz", type=float, default=10.0)
    parser.add_argument("--warmup-s", type=float, default=3.0)
    parser.add_argument("--duration-s", type=float, default=15.0)
    args = parser.parse_args()

    cpus = sorted(os.sched_getaffinity(0))
    port = free_port()
    cmd = [sys.executable, "-m", "spat_feed", "--port", str(port), "--rate-hz", str(args.rate_hz), "--timing", "15_15"]
    pin = len(cpus) >= 2
    feed = subprocess.Popen(cmd, cwd=REPO, preexec_fn=(lambda: os.sched_setaffinity(0, {cpus[0]})) if pin else None)
    try:
        deadline = time.monotonic() + 30
        while True:
            try:
                httpx.get(f"http://127.0.0.1:{port}/health", timeout=1).raise_for_status()
                break
            except httpx.HTTPError:
                if time.monotonic() > deadline or feed.poll() is not None:
                    raise SystemExit("feed did not start") from None
                time.sleep(0.1)
        if pin:
            os.sched_setaffinity(0, {cpus[1]})
        url = f"ws://127.0.0.1:{port}/spat/stream?timing=15_15"
        out: dict[str, float] = {}
        lat, connected = asyncio.run(run(url, args, feed.pid, out))
        lat_ms = np.array(lat) * 1e3
        expected = args.subscribers * args.rate_hz * args.duration_s
        print(f"spat_feed fan-out: {connected} WebSocket subscribers at {args.rate_hz:g} Hz, {args.duration_s:g} s measured "
              f"(feed on CPU {cpus[0] if pin else 'any'}, subscribers on CPU {cpus[1] if pin else 'any'}; {len(cpus)} CPUs)")
        print(f"messages received: {len(lat_ms):,} = {len(lat_ms) / args.duration_s:,.0f} msg/s "
              f"({100 * len(lat_ms) / expected:.1f} % of {expected / args.duration_s:,.0f} msg/s offered)")
        print(f"latency build->receive: p50 {np.percentile(lat_ms, 50):.1f} ms, p90 {np.percentile(lat_ms, 90):.1f} ms, "
              f"p99 {np.percentile(lat_ms, 99):.1f} ms, max {lat_ms.max():.1f} ms")
        print(f"feed CPU while recording: {100 * out['feed_cpu_s'] / args.duration_s:.0f} % of one core; "
              f"subscriber process CPU: {100 * out['client_cpu_s'] / args.duration_s:.0f} % of one core")
    finally:
        feed.terminate()
        try:
            feed.wait(timeout=10)
        except subprocess.TimeoutExpired:
            feed.kill()


async def run(url: str, args: argparse.Namespace, feed_pid: int, out: dict) -> tuple[list[float], int]:
    """Open the subscribers, warm up, record latencies; also the feed's and our CPU seconds while recording."""
    latencies: list[float] = []
    state = {"connected": 0, "n": args.subscribers, "recording": False}
    ready = asyncio.Event()
    tasks = []
    for i in range(args.subscribers):
        tasks.append(asyncio.create_task(subscriber(url, latencies, state, ready)))
        if i % 50 == 49:
            await asyncio.sleep(0.05)
    await asyncio.wait_for(ready.wait(), 120)
    await asyncio.sleep(args.warmup_s)
    feed0, me0 = cpu_seconds(feed_pid), time.process_time()
    state["recording"] = True
    await asyncio.sleep(args.duration_s)
    state["recording"] = False
    out["feed_cpu_s"] = cpu_seconds(feed_pid) - feed0
    out["client_cpu_s"] = time.process_time() - me0
    connected = state["connected"]
    for t in tasks:
        t.cancel()
    await asyncio.gather(*tasks, return_exceptions=True)
    return latencies, connected


if __name__ == "__main__":
    main()
