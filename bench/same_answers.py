"""The service's answers to a fixed set of fixes, byte for byte, to compare two versions of the code: a change meant to
make a fix cheaper must not change any answer.

About 2,000 fixes of 8 trips on two corridors (the shared SPaT and trips' own timings; seeded GPS noise, fixes without
speed, weak and off-route fixes, duplicates, late fixes, jumps, W3C names, bad bodies) go through the app
(``TestClient``, clock injected) over REST and over each trip's WebSocket stream, on the in-process store and on a
real ``redis-server`` (REST, queue-aware advice on, in process too); every answer (status, body with the trip's id
replaced by ``ID``) is written as one JSON line. Then queue-aware advice in a crowd (:func:`crowd`: 150 trips on one
corridor through the engine, 9,000 fixes, without and with the flow of the cars not connected), each answer and the
queue board's state at the end. Run it on both versions and compare the files::

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


CROWDS = ((150, 60, None, False), (150, 60, (720.0, 0.5), False), (200, 30, None, True))
"""(trips, seconds, the flow per lane [veh/h] and the connected share the board is told (None: the connected cars
alone), whether they drive as the load benches' phones)."""


def crowd(n_cars: int, seconds: int, flow: tuple[float, float] | None, stream: bool, seed: int = 7) -> list[str]:
    """Queue-aware answers in a crowd: ``n_cars`` trips on paper_s400 (its 15_15 plans published as SPaT each second)
    fixing once a second each at its own phase, through the engine (no tables): at random places and cruising speeds
    (one fix in seven nearly standing), or with ``stream`` as the load benches' phones drive (there and back at 15 m/s,
    each 7 s behind the one before: ``bench/_phones.py``); every answer (JSON, without the trip's id), then the queue
    board's state (each trip's probe, queue, cars held up, lights passed with the cars behind them, estimate; trips by
    their index)."""
    import asyncio
    import random
    from dataclasses import replace

    from server.advising import Engine
    from server.gps import Fix
    from server.schemas import TripCreate
    from server.spat import SpatHub
    from spat_feed.transport.scenarios import make_scenario, spat_message_at

    corridor = load_corridor("paper_s400")
    clock = [NOW]
    extra = {} if flow is None else {"queue_arrivals_vph": flow[0], "queue_connected_share": flow[1]}
    settings = Settings(spat_simulate=False, tables=False, speech=False, queue_aware=True, **extra)
    hub = SpatHub(settings, {corridor.name: corridor}, lambda: clock[0])
    engine = Engine(settings, {corridor.name: corridor}, spat=hub, clock=lambda: clock[0])
    plans = make_scenario(corridor, "15_15", 0.0)
    rng = random.Random(seed)
    cars = [[rng.uniform(-50.0, corridor.length_m - 20.0), rng.uniform(5.0, 16.0), i / n_cars if stream else rng.uniform(0.0, 1.0)] for i in range(n_cars)]

    async def drive() -> list[str]:
        trips = [await engine.create_trip(TripCreate(corridor=corridor.name), client=f"c{i}") for i in range(n_cars)]
        lines = []
        for second in range(seconds):
            for ix in spat_message_at(plans, NOW + second).intersections:
                hub.store.offer(ix)
            for i in sorted(range(n_cars), key=lambda i: cars[i][2]):
                station_m, cruise_mps, phase_s = cars[i]
                clock[0] = max(clock[0], NOW + second + phase_s)
                speed_mps = cruise_mps if rng.random() > 0.15 else rng.uniform(0.0, 2.0)
                if stream:  # (there and back: the way back read as the way there, as the phones' positions are)
                    speed_mps, station_m = 15.0, 15.0 * (second + phase_s + 7.0 * i) % (2.0 * corridor.length_m)
                    station_m = min(station_m, 2.0 * corridor.length_m - station_m)
                where = corridor.position(min(max(station_m, 0.0), corridor.length_m - 1.0))
                out = engine.on_fix(trips[i], Fix(NOW + second + phase_s, *where, speed_mps=speed_mps))
                lines.append(json.dumps({k: v for k, v in out.items() if k != "trip_id"}, sort_keys=True))
                cars[i][0] = station_m + speed_mps if station_m + speed_mps < corridor.length_m - 5.0 else rng.uniform(-50.0, 50.0)
        board, index = engine.queue, {trip.id: i for i, trip in enumerate(trips)}
        state = {"held": board.held, "cars": {c: sorted((index[t], p) for t, p in probes.items()) for c, probes in board._cars.items()},
                 "queued": sorted((index[t], v) for t, v in board._queued.items()),
                 "behind": sorted((index[t], repr(tuple(v))) for t, v in board._behind.items()),
                 "passed": sorted((index[t], repr([(light, tuple(behind), past) for light, behind, past in v])) for t, v in board._passed.items()),
                 "seen": sorted((index[t], repr(replace(est, behind=tuple(est.behind)))) for t, (_, est) in board._seen.items()),
                 "for_queue": sorted((index[t], v) for t, v in board._for_queue.items()), "view_m": sorted((index[t], v) for t, v in board._view_m.items()),
                 "red_since": sorted(board._red_since.items()), "red_ended": sorted(board._red_ended.items())}  # fmt: skip
        await engine.trips.close()
        return [*lines, json.dumps(state, sort_keys=True, default=str)]

    return asyncio.run(drive())


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
    with args.out.open("a") as out:
        for n_cars, seconds, flow, stream in CROWDS:
            lines = crowd(n_cars, seconds, flow, stream)
            out.write("".join(f"{line}\n" for line in lines))
            reasons: dict[str, int] = {}
            for line in lines[:-1]:
                reason = json.loads(line).get("reason")
                reasons[reason] = reasons.get(reason, 0) + 1
            print(f"crowd  {n_cars} trips, {seconds} s, flow {flow}, stream {stream}: {len(lines) - 1} answers and the board, sha256 "
                  f"{hashlib.sha256(''.join(lines).encode()).hexdigest()[:16]}, {dict(sorted(reasons.items()))}")  # fmt: skip
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
