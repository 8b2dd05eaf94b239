"""Piecewise-constant-acceleration trajectories: exact knots, fine sampling, stop-line crossing times."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True, slots=True)
class Trajectory:
    """Knots of a drive: times [s], positions [m], speeds [m/s]; constant acceleration between knots.

    Arrays have shape (n_knots,); ``accel_mps2`` (n_knots - 1,) is derived.
    """

    t_s: np.ndarray
    x_m: np.ndarray
    v_mps: np.ndarray

    @property
    def accel_mps2(self) -> np.ndarray:
        return np.diff(self.v_mps) / np.diff(self.t_s)

    @property
    def duration_s(self) -> float:
        return float(self.t_s[-1] - self.t_s[0])

    def sample(self, max_dt_s: float = 0.1) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Samples (t, x, v) containing every knot, no step longer than ``max_dt_s``. [s], [m], [m/s]"""
        t0, t1 = self.t_s[:-1], self.t_s[1:]
        n = np.maximum(1, np.ceil((t1 - t0) / max_dt_s - 1e-9).astype(np.int64))  # steps per segment
        seg = np.repeat(np.arange(n.size), n)
        k = np.arange(seg.size) - np.repeat(np.cumsum(n) - n, n) + 1  # 1..n within each segment
        t = k * ((t1 - t0) / n)[seg] + t0[seg]  # as np.linspace(t0, t1, n + 1)[1:] computes it
        t[np.cumsum(n) - 1] = t1  # segment ends exactly on the knots
        t = np.concatenate([self.t_s[:1], t])
        return t, self.position_at(t), self.speed_at(t)

    def _segment(self, t_s):
        t = np.asarray(t_s, dtype=float)
        k = np.clip(np.searchsorted(self.t_s, t, side="right") - 1, 0, len(self.t_s) - 2)
        return t, k, t - self.t_s[k]

    def speed_at(self, t_s):
        t, k, tau = self._segment(t_s)
        return self.v_mps[k] + self.accel_mps2[k] * tau

    def position_at(self, t_s):
        t, k, tau = self._segment(t_s)
        return self.x_m[k] + self.v_mps[k] * tau + 0.5 * self.accel_mps2[k] * tau * tau

    def crossing_time_s(self, position_m: float) -> float:
        """First instant the car reaches ``position_m`` (inf if it never does). [s]"""
        k = int(np.searchsorted(self.x_m, position_m, side="left"))
        if k >= len(self.x_m):
            return float("inf")
        if k == 0 or self.x_m[k] == position_m:
            return float(self.t_s[k])
        k -= 1
        v0, a, d = self.v_mps[k], self.accel_mps2[k], position_m - self.x_m[k]
        tau = d / v0 if abs(a) < 1e-12 else (-v0 + np.sqrt(max(v0 * v0 + 2.0 * a * d, 0.0))) / a
        return float(self.t_s[k] + tau)
