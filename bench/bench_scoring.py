"""Scoring throughput after JIT: samples per second of score_trace (target >= 10 million/s; a long trace is scored
in parallel chunks, so on all of numba's threads).

Also prints the ratio against the same model written as whole-array numpy (tests/test_scoring.py's
reference), measured in the same run.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numba
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from advisory.physics.params import model_params  # noqa: E402
from advisory.evaluation.scoring import CHUNK_STEPS, score_trace  # noqa: E402
from tests.test_scoring import numpy_reference  # noqa: E402
from bench._procs import best_of  # noqa: E402


def main() -> None:
    n = 5_000_000
    rng = np.random.default_rng(0)
    t = np.arange(n, dtype=float)
    v = np.clip(15 + np.cumsum(rng.normal(0, 0.5, n)) % 20, 0, 35)
    grade = 0.02 * np.sin(t / 200)
    params = model_params()
    for k in (100, CHUNK_STEPS + 2):  # JIT / cache load: one pass, and the parallel chunks of a long trace
        score_trace(t[:k], v[:k], params, grade[:k])
    kernel_s = best_of(lambda: score_trace(t, v, params, grade), repeats=5)
    numpy_s = best_of(lambda: numpy_reference(t, v, params, grade), repeats=3)
    print(f"score_trace: {n:,} samples in {kernel_s * 1e3:.0f} ms = {n / kernel_s / 1e6:.1f} M samples/s on {numba.get_num_threads()} threads ({numba.threading_layer()}) "
          f"(target >= 10)")
    print(f"plain numpy : {n / numpy_s / 1e6:.1f} M samples/s; numba/numpy speed ratio {numpy_s / kernel_s:.1f}x")


if __name__ == "__main__":
    main()
