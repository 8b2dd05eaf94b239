"""`replay` end to end as a user runs it: process start, reading, map matching, scoring (target < 1 s).

Three traces, each run as a subprocess of the installed ``replay`` script:

* a 1-hour 1 Hz **speed** CSV (3600 rows): the throughput part;
* a 1-hour 1 Hz **GPS** CSV (3600 fixes, with speed) on a straight 80 km corridor without lights, written
  to a temporary JSON: reading + map matching + scoring;
* the shipped **field-test** GPS trace with the comparison (regular driver + DP optimum).

Warm: the numba cache filled by a first run, then the median of 5 runs. Cold: ``NUMBA_CACHE_DIR``
pointed at an empty temporary folder, so every kernel compiles (one run).
"""

from __future__ import annotations

import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from spat_feed.road.corridors import StraightRoad, straight_corridor  # noqa: E402

REPLAY = Path(sys.executable).with_name("replay")
TARGET_S = 1.0
N = 3600


def speed_profile(n: int = N) -> np.ndarray:
    """Stop-and-go: 90 s cycles of accelerate, cruise at 10-25 m/s, brake, 10 s stand. [m/s]"""
    rng = np.random.default_rng(1)
    v = np.zeros(n)
    k = 0
    while k < n:
        top = rng.uniform(10, 25)
        ramp = np.concatenate([np.linspace(0, top, 12), np.full(50, top), np.linspace(top, 0, 18), np.zeros(10)])
        v[k : k + ramp.size] = ramp[: n - k]
        k += ramp.size
    return v


def write_traces(folder: Path) -> dict[str, list[str]]:
    t = np.arange(N, dtype=float)
    v = speed_profile()
    speed_csv = folder / "hour_speed.csv"
    speed_csv.write_text("t_s,speed_mps\n" + "\n".join(f"{a:.0f},{b:.3f}" for a, b in zip(t, v, strict=True)) + "\n")
    road = StraightRoad("bench road", (40.0, -100.0), (40.0, -98.9), "synthetic", "synthetic", 0.0)
    x = np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]))])
    corridor = straight_corridor("bench_straight", road, [], float(np.ceil(x[-1] / 100) * 100 + 100))
    cor_json = folder / "bench_straight.json"
    cor_json.write_text(corridor.model_dump_json())
    rng = np.random.default_rng(2)
    rows = []
    for k in range(N):
        lat, lon = corridor.position(float(x[k]))
        rows.append(f"{1_700_000_000 + k},{lat + rng.normal(0, 2e-5):.7f},{lon + rng.normal(0, 2e-5):.7f},{max(v[k] + rng.normal(0, 0.2), 0):.2f}")
    gps_csv = folder / "hour_gps.csv"
    gps_csv.write_text("t_unix_s,lat,lon,speed_mps\n" + "\n".join(rows) + "\n")
    return {
        "1 h speed CSV (3600 rows)": [str(speed_csv), "--json"],
        "1 h GPS CSV (3600 fixes, 80 km corridor)": [str(gps_csv), "--corridor", str(cor_json), "--json"],
        "field-test GPS trace + regular + DP": [str(REPO / "replay" / "data" / "field_test_advised.csv"), "--json"],
    }


def run(args: list[str], env: dict[str, str]) -> float:
    t0 = time.perf_counter()
    out = subprocess.run([str(REPLAY), *args], capture_output=True, text=True, env=env, timeout=300)
    wall = time.perf_counter() - t0
    if out.returncode not in (0, 1):
        raise SystemExit(f"replay {args} failed ({out.returncode}):\n{out.stderr}")
    return wall


def main() -> None:
    with tempfile.TemporaryDirectory() as tmp:
        cases = write_traces(Path(tmp))
        env = dict(os.environ)
        print(f"replay end to end (subprocess: {REPLAY}), median of 5 warm runs; target < {TARGET_S} s")  # noqa: T201
        worst = 0.0
        for name, args in cases.items():
            run(args, env)  # fills the numba cache if needed
            warm = statistics.median(run(args, env) for _ in range(5))
            with tempfile.TemporaryDirectory() as cache:
                cold = run(args, {**env, "NUMBA_CACHE_DIR": cache})
            worst = max(worst, warm)
            print(f"  {name:<42} warm {warm:6.3f} s   cold (empty numba cache) {cold:6.3f} s")  # noqa: T201
        print(f"worst warm: {worst:.3f} s -> {'OK' if worst < TARGET_S else 'OVER TARGET'}")  # noqa: T201


if __name__ == "__main__":
    main()
