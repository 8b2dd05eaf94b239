"""The service's answers to a fixed set of fixes, byte for byte, to compare two versions of the code: a change meant to
make a fix cheaper must not change any answer.

About 2,000 fixes of 8 trips on two corridors (the shared SPaT and trips' own timings; seeded GPS noise, fixes without
speed, weak and off-route fixes, duplicates, late fixes, jumps, W3C names, bad bodies) go through the app
(``TestClient``, clock injected) over REST and over each trip's WebSocket stream, on the in-process store and on a
real ``redis-server`` (REST, queue-aware advice on, in process too); every answer (status, body with the trip's id
replaced by ``ID``) is written as one JSON line. Run it on both versions and compare the files::

    PYTHONPATH=. .venv/bin/python bench/same_answers.py --out /tmp/new.jsonl
    cd <other tree> && PYTHONPATH=. .venv/bin/python bench/same_answers.py --out /tmp/old.jsonl && cmp /tmp/old.jsonl /tmp/new.jsonl
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
import tempfile
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from fastapi.testclient import TestClient  # noqa: E402

from server.app import create_app  # noqa: E402
from server.config import Settings  # noqa: E402
from spat_feed.road.corridors import load_corridor  # noqa: E402
from tests.procs import RedisServer  # noqa: E402

NOW = 1_800_000_000.0
M_PER_DEG = 111_320.0
TRIPS = (  # (corridor, timing: None the shared SPaT, entry before NOW [s], fixes without speed, GPS noise [m])
    ("paper_s400", None, 20.0, False, 2.0),
    ("paper_s400", None, 55.0, True, 3.0),
    ("paper_s400", "15_15", 10.0, False, 1.0),
    ("paper_s400", "field_test", 40.0, True, 4.0),
    ("paper_s200", None, 30.0, False, 2.0),
    ("paper_s200", "15_15", 0.0, True, 3.0),
    ("paper_s400", None, 80.0, False, 0.5),
    ("paper_s200", None, 65.0, False, 5.0),
)
N_STEPS = 250


def at(corridor, x_m: float) -> tuple[float, float]:
    """Where station ``x_m`` is along the route, extended beyond its ends along its first and last 10 m. [deg]"""
    if 0.0 <= x_m <= corridor.length_m:
        return corridor.position(x_m)
    end = 0.0 if x_m < 0.0 else corridor.length_m
    inner = corridor.position(abs(end - 10.0))
    outer = corridor.position(end)
    k = abs(x_m - end) / 10.0
    return outer[0] + k * (outer[0] - inner[0]), outer[1] + k * (outer[1] - inner[1])


def drives(seed: int = 1) -> list[list[tuple[float, str]]]:
    """Per trip, its messages in order: (the clock when sent, the JSON text)."""
    rng = np.random.default_rng(seed)
    out = []
    for corridor_name, _, entry_s, no_speed, noise_m in TRIPS:
        corridor = load_corridor(corridor_name)
        t, x, v = NOW - entry_s - 20.0, -120.0, 12.0
        msgs = []
        for k in range(N_STEPS):
            t += 1.0
            v = float(np.clip(v + rng.normal(0.0, 1.2), 0.0, 17.0)) if rng.random() > 0.08 else 0.0
            x += v
            if x > corridor.length_m + 60.0:
                x = -80.0  # around again
            lat, lon = at(corridor, x)
            lat += rng.normal(0.0, noise_m) / M_PER_DEG
            lon += rng.normal(0.0, noise_m) / M_PER_DEG
            fix: dict = {"t_unix_s": round(t, 3), "lat_deg": round(lat, 7), "lon_deg": round(lon, 7), "accuracy_m": round(float(2 + 4 * rng.random()), 1)}
            if not no_speed or k % 7 == 0:
                fix["speed_mps"] = round(max(v + rng.normal(0.0, 0.3), 0.0), 2)
            r = rng.random()
            if r < 0.03:
                fix["accuracy_m"] = 75.0  # weak
            elif r < 0.06:
                fix["lat_deg"] = round(lat + 60.0 / M_PER_DEG, 7)  # off the route
            elif r < 0.08:
                fix["lat_deg"], fix["lon_deg"] = (round(a, 7) for a in at(corridor, x + 400.0))  # a jump of 400 m along the route
            elif r < 0.10:  # W3C names, timestamp in ms
                fix = {"timestamp": round(t * 1000.0), "latitude": fix["lat_deg"], "longitude": fix["lon_deg"], "speed": fix.get("speed_mps"), "heading": 90.0}
            msgs.append((t + 0.3, json.dumps(fix)))
            r = rng.random()
            if r < 0.03:
                msgs.append((t + 0.5, json.dumps(fix)))  # the same fix again
            elif r < 0.05:
                msgs.append((t + 0.6, json.dumps({**fix, "t_unix_s": round(t - 1.5, 3)} if "t_unix_s" in fix else fix)))  # late
            elif r < 0.06:
                msgs.append((t + 0.7, json.dumps({**fix, "lat_deg": 91.0})))  # 422
            elif r < 0.065:
                msgs.append((t + 0.7, '{"t_unix_s": 1, "lat_deg": "x"'))  # malformed
            elif r < 0.07:
                msgs.append((t + 0.7, json.dumps({**fix, "t_unix_s": t + 30.0, "timestamp": None})))  # from the future
        out.append(msgs)
    return out


def answers(store_url: str | None, transport: str, queue_aware: bool, tables_dir: Path | None) -> list[str]:
    settings = Settings(corridors=("paper_s400", "paper_s200"), default_corridor="paper_s400", tables=tables_dir is not None, tables_dir=tables_dir,
                        speech=False, rate_per_s=100.0, rate_burst=1000.0, store_url=store_url, queue_aware=queue_aware,
                        create_rate_per_client_per_s=100.0, create_burst_per_client=100, max_trips_per_client=100)  # fmt: skip
    clock = {"now": NOW - 200.0}
    lines = []
    with TestClient(create_app(settings, clock=lambda: clock["now"])) as c:
        trips = []
        for corridor, timing, entry_s, _, _ in TRIPS:
            clock["now"] = NOW - entry_s - 25.0
            body = {"corridor": corridor, "entry_unix_s": NOW - entry_s, **({"timing": timing} if timing else {})}
            r = c.post("/v1/trips", json=body)
            assert r.status_code == 201, r.text
            trips.append(r.json())
        plan = drives()
        events = sorted((t, i, j, text) for i, msgs in enumerate(plan) for j, (t, text) in enumerate(msgs))  # every trip's messages in time order
        streams = {}
        try:
            for t, i, _, text in events:
                clock["now"] = t
                tid, auth = trips[i]["trip_id"], {"Authorization": f"Bearer {trips[i]['token']}"}
                if transport == "http":
                    r = c.post(f"/v1/trips/{tid}/fixes", content=text, headers={**auth, "content-type": "application/json"})
                    status, body = r.status_code, r.text
                else:
                    if i not in streams:
                        streams[i] = c.websocket_connect(f"/v1/trips/{tid}/stream", headers=auth)
                        streams[i].__enter__()
                    streams[i].send_text(text)
                    status, body = 0, streams[i].receive_text()
                lines.append(json.dumps([i, status, body.replace(tid, "ID")]))
        finally:
            for ws in streams.values():
                ws.__exit__(None, None, None)
    return lines


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, required=True, help="JSON lines: one answer per message, per configuration")
    ap.add_argument("--tables-dir", type=Path, default=Path(tempfile.gettempdir()) / "ecodrive-bench-tables", help="the DP tables' cache (as the benches')")
    args = ap.parse_args()
    runs = [("memory", "http", False), ("memory", "ws", False), ("memory", "http", True), ("redis", "http", False), ("redis", "ws", False)]
    with tempfile.TemporaryDirectory() as folder:
        redis = RedisServer(Path(folder), fsync="everysec").start()
        try:
            with args.out.open("w") as out:
                for store, transport, queue in runs:
                    lines = answers(redis.url if store == "redis" else None, transport, queue, args.tables_dir)
                    out.write("".join(f"{line}\n" for line in lines))
                    counts: dict[str, int] = {}
                    for line in lines:
                        body = json.loads(json.loads(line)[2])
                        for kind in filter(None, (body.get("fix_status") or body.get("error"), body.get("reason"), body.get("source"))):
                            counts[kind] = counts.get(kind, 0) + 1
                    print(f"{store:6s} {transport:4s} queue-aware {'on ' if queue else 'off'}: {len(lines)} answers, sha256 "
                          f"{hashlib.sha256(''.join(lines).encode()).hexdigest()[:16]}, {dict(sorted(counts.items()))}")  # fmt: skip
        finally:
            redis.kill()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
