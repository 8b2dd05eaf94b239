"""The queue board's CPU per fix (``server.queue.QueueBoard.see``, queue-aware advice), with its index against the loop
over every car of the corridor it replaced (``tests/server/test_queue_index.py``'s ``LoopBoard``), in one run.

Cars spread evenly along a corridor of fixed-time lights, each fix a car's next two lights in view (as the service's
observation), fixes in random order; both boards see the same fixes and must give the same answers (checked). Three
corridors: the bench's own (``paper_s400``'s lights at 100 and 500 m, 500 cars on 600 m: every car near every other, six
times a jam's density, as ``bench_redis_load.py --queue-aware on``), and longer ones with the same cars spread out.

    .venv/bin/python bench/bench_queue_board.py [--fixes 3000]
"""

from __future__ import annotations

import argparse
import random
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from server.queue import QueueBoard  # noqa: E402
from tests.server.test_queue_index import LoopBoard, observation_at  # noqa: E402

CASES = (  # (what, cars, corridor length [m], stop lines [m])
    ("paper_s400 (600 m, 2 lights)", 500, 600.0, (100.0, 500.0)),
    ("6 km, a light every 400 m", 500, 6000.0, tuple(200.0 + 400.0 * k for k in range(15))),
    ("20 km, a light every 400 m", 2000, 20000.0, tuple(200.0 + 400.0 * k for k in range(50))),
)


def run(n_cars: int, length_m: float, stop_lines_m: tuple[float, ...], n_fixes: int) -> tuple[float, float, int]:
    """CPU per fix [s] of the indexed board and of the loop, and how many fixes were held ("follow")."""
    rng = random.Random(1)
    cars = [(f"t{i}", rng.uniform(0.0, length_m), rng.uniform(0.0, 16.0)) for i in range(n_cars)]
    fixes = [(tid, 1000.0 + 0.001 * k, observation_at(s, v, 1000.0, rng, stop_lines_m=stop_lines_m, in_view=2)) for k, (tid, s, v) in enumerate(cars)]
    fixes += [(tid, 1001.0 + k / n_fixes, obs) for k, (tid, _, obs) in enumerate(rng.choices(fixes, k=n_fixes))]
    board, loop = QueueBoard(), LoopBoard(None, 1.0)
    out, cpu = [], []
    for see in (lambda tid, t, obs: board.see("c", tid, t, obs), lambda tid, t, obs: loop.see("c", tid, t, obs)):
        answers = []
        c0 = time.process_time()
        for tid, t, obs in fixes:
            answers.append(see(tid, t, obs))
        cpu.append((time.process_time() - c0) / len(fixes))
        out.append(answers)
    assert out[0] == out[1], "the index changed an answer"
    return cpu[0], cpu[1], sum(held is not None for _, held in out[0])


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--fixes", type=int, default=3000, help="fixes after the first of each car")
    args = ap.parse_args()
    print("bench_queue_board: QueueBoard.see, CPU per fix, indexed / loop over every car (same answers, checked)")
    for what, n_cars, length_m, lines in CASES:
        indexed_s, loop_s, held = run(n_cars, length_m, lines, args.fixes)
        print(f"  {what:32s} {n_cars:5d} cars: {1e6 * indexed_s:7.1f} / {1e6 * loop_s:7.1f} us per fix (x{loop_s / indexed_s:.1f}); {held} fixes told to follow")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
