"""The advice's own cost per fix, deterministic and in process: the advisor's calls of ``bench/same_answers.py``'s drive
(8 trips on two corridors, the shared SPaT and trips' own timings), recorded through the app, then replayed.

The fixes of the drive go through the app (in process, REST, queue-aware advice off, DP tables as the benches'); every
call of ``advise`` and of ``observation`` the service makes is recorded with its arguments (they are pure), then
replayed ``--repeat`` times: the cost of each per fix (the least of the replays' means), hot (the calls back to back) and, with ``--cold``, with the
processor's caches flushed between two fixes (a 32 MB buffer read), as a worker that sleeps between fixes meets them.
``--profile`` prints where the hot advice goes, per function (cProfile's own time per fix; cProfile adds its own cost to
every call, so read the shares, not the sums).

    PYTHONPATH=. .venv/bin/python bench/profile_advice.py [--repeat 20] [--cold] [--profile]
"""

from __future__ import annotations

import argparse
import cProfile
import pstats
import signal
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

import server.advising as advising  # noqa: E402
from bench import same_answers  # noqa: E402


def recorded(tables_dir: Path) -> tuple[list[tuple], list[tuple]]:
    """The ``advise`` and ``observation`` calls (positional and keyword arguments) of the drive, in order."""
    advise_calls: list[tuple] = []
    observe_calls: list[tuple] = []
    advise, observation = advising.advise, advising.observation

    def advise_spy(*args, **kwargs):
        advise_calls.append((args, kwargs))
        return advise(*args, **kwargs)

    def observation_spy(*args, **kwargs):
        observe_calls.append((args, kwargs))
        return observation(*args, **kwargs)

    advising.advise, advising.observation = advise_spy, observation_spy
    try:
        same_answers.answers(None, "http", False, tables_dir)
    finally:
        advising.advise, advising.observation = advise, observation
    return advise_calls, observe_calls


SAMPLE_S = 0.0002
"""CPU time between two samples of the cold replay's stacks (``ITIMER_PROF``, rounded up to the kernel's tick). [s]"""


class Sampler:
    """The innermost frames of a replay's timed calls, sampled on CPU time (as ``bench/_sampled_server.py``): a sample
    is taken where the interpreter next runs Python, so time in C (numpy, a numba dispatch) counts to its caller."""

    def __init__(self) -> None:
        self.on = False
        self.frames: Counter = Counter()

    def _sample(self, signum, frame) -> None:
        if self.on and frame is not None:
            code = frame.f_code
            self.frames[f"{Path(code.co_filename).name}:{code.co_firstlineno}:{code.co_name}"] += 1

    def __enter__(self) -> Sampler:
        signal.signal(signal.SIGPROF, self._sample)
        signal.setitimer(signal.ITIMER_PROF, SAMPLE_S, SAMPLE_S)
        return self

    def __exit__(self, *exc) -> None:
        signal.setitimer(signal.ITIMER_PROF, 0, 0)


def per_call_us(fn, calls: list[tuple], repeat: int, flush: np.ndarray | None, sampler: Sampler | None = None) -> float:
    """Time of ``fn`` per call over ``calls``, replayed ``repeat`` times: the least of the replays' means (the machine is
    shared: another job's slice counts to the replay it lands in); with ``flush``, the caches flushed before each call;
    with ``sampler``, the calls (not the flushes) sampled. [us]"""
    best = np.inf
    for _ in range(repeat):
        total = 0.0
        for args, kwargs in calls:
            if flush is not None:
                flush.sum()  # (reads the whole buffer: the caches hold it, not the advisor's data)
            t0 = time.perf_counter()
            if sampler is not None:
                sampler.on = True
            fn(*args, **kwargs)
            if sampler is not None:
                sampler.on = False
            total += time.perf_counter() - t0
        best = min(best, total / max(len(calls), 1))
    return 1e6 * best


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeat", type=int, default=20, help="replays of the recorded calls (default 20)")
    ap.add_argument("--cold", action="store_true", help="also time each call after flushing the caches")
    ap.add_argument("--profile", action="store_true", help="print cProfile's own time per fix of each function of the advice")
    ap.add_argument("--tables-dir", type=Path, default=Path(tempfile.gettempdir()) / "ecodrive-bench-tables", help="the DP tables' cache (as the benches')")
    args = ap.parse_args()
    advise_calls, observe_calls = recorded(args.tables_dir)
    advise, observation = advising.advise, advising.observation
    per_call_us(advise, advise_calls, 2, None)  # warm-up (numba dispatch, caches)
    flush = np.ones(4 * 1024 * 1024) if args.cold else None
    print(f"profile_advice: {len(advise_calls)} advise and {len(observe_calls)} observation calls of bench/same_answers.py's drive, {args.repeat} replays")
    print(f"  advise:      hot {per_call_us(advise, advise_calls, args.repeat, None):6.1f} us per fix"
          + (f", cold {per_call_us(advise, advise_calls, max(args.repeat // 4, 1), flush):6.1f} us" if flush is not None else ""))
    print(f"  observation: hot {per_call_us(observation, observe_calls, args.repeat, None):6.1f} us per fix"
          + (f", cold {per_call_us(observation, observe_calls, max(args.repeat // 4, 1), flush):6.1f} us" if flush is not None else ""))
    if args.profile and flush is not None:
        with Sampler() as sampler:
            cold_us = per_call_us(advise, advise_calls, max(args.repeat // 4, 1), flush, sampler)
        n = sum(sampler.frames.values())
        print(f"  sampled, advise cold ({cold_us:.1f} us per fix, {n} samples): us per fix by innermost Python frame:")
        for where, k in sampler.frames.most_common(25):
            print(f"    {cold_us * k / n:6.2f} us  {where}")
    if args.profile:
        prof = cProfile.Profile()
        prof.enable()
        for _ in range(args.repeat):
            for a, kw in advise_calls:
                advise(*a, **kw)
        prof.disable()
        stats = pstats.Stats(prof).stats
        n = args.repeat * len(advise_calls)
        rows = sorted(((tt, nc, f"{Path(file).name}:{line}:{name}") for (file, line, name), (_, nc, tt, _, _) in stats.items()), reverse=True)
        whole = sum(tt for tt, _, _ in rows)
        calls = sum(nc for _, nc, _ in rows)
        print(f"  cProfile, advise: {1e6 * whole / n:.1f} us per fix under the profiler, {calls / n:.1f} calls per fix (Python functions and builtins);"
              " own time per fix, calls per fix, function:")
        for tt, nc, where in rows[:25]:
            print(f"    {1e6 * tt / n:6.2f} us  {nc / n:5.2f}  {where}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
