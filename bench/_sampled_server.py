"""``python bench/_sampled_server.py <ecodrive serve args>``: the service (one worker) with a CPU-time sampler, for
``bench/profile_worker.py``. ``SIGUSR1`` starts sampling (``ITIMER_PROF``: one sample per ``SAMPLE_S`` of this process's
CPU, rounded up by the kernel to its tick), ``SIGUSR2`` stops it and writes the stacks with their counts as JSON to
``$ECO_BENCH_SAMPLES``. A sample is taken where the interpreter next runs Python, so time in C (a system call, the event
loop) counts to the Python function that called it or that the loop calls next."""

from __future__ import annotations

import json
import os
import signal
import sys
from collections import Counter
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from server.main import main  # noqa: E402

SAMPLE_S = 0.0005
ROOT = str(Path(__file__).resolve().parents[1]) + "/"
stacks: Counter = Counter()


def _sample(signum, frame) -> None:
    names = []
    while frame is not None:
        code = frame.f_code
        names.append(f"{code.co_filename.rsplit('/site-packages/', 1)[-1].replace(ROOT, '')}:{code.co_name}")
        frame = frame.f_back
    stacks[tuple(reversed(names))] += 1


def _start(*_) -> None:
    stacks.clear()
    signal.signal(signal.SIGPROF, _sample)
    signal.setitimer(signal.ITIMER_PROF, SAMPLE_S, SAMPLE_S)


def _stop(*_) -> None:
    signal.setitimer(signal.ITIMER_PROF, 0, 0)
    Path(os.environ["ECO_BENCH_SAMPLES"]).write_text(json.dumps([[list(k), v] for k, v in stacks.items()]))


if __name__ == "__main__":
    signal.signal(signal.SIGUSR1, _start)
    signal.signal(signal.SIGUSR2, _stop)
    sys.argv[0] = "ecodrive"
    raise SystemExit(main())
