"""Trajectory sampling: every knot kept, no step longer than asked, the samples of ``np.linspace`` per segment."""

import numpy as np
import pytest

from advisory.trajectory import Trajectory


def _linspace_samples(t_s: np.ndarray, max_dt_s: float) -> np.ndarray:
    """The samples built segment by segment, independently of ``Trajectory.sample``."""
    out = [t_s[:1]]
    for t0, t1 in zip(t_s[:-1], t_s[1:], strict=True):
        n = max(1, int(np.ceil((t1 - t0) / max_dt_s - 1e-9)))
        out.append(np.linspace(t0, t1, n + 1)[1:])
    return np.concatenate(out)


@pytest.mark.parametrize("seed", range(5))
def test_sample_keeps_every_knot_and_steps_at_most_max_dt(seed):
    rng = np.random.default_rng(seed)
    # segments of random length, some exactly a multiple of the step (the rounding edge), some far shorter
    dt = rng.choice([rng.uniform(1e-6, 7.0), 0.1, 0.2, 0.30000000000000004, 1e-7], size=40)
    t = np.cumsum(np.r_[rng.uniform(0, 3), dt])
    v = rng.uniform(0, 25, t.size)
    x = np.r_[0.0, np.cumsum(0.5 * (v[:-1] + v[1:]) * np.diff(t))]
    traj = Trajectory(t, x, v)
    ts, xs, vs = traj.sample(0.1)
    assert np.array_equal(ts, _linspace_samples(t, 0.1))
    assert np.isin(t, ts).all()
    assert np.diff(ts).max() <= 0.1 + 1e-12 and (np.diff(ts) > 0).all()
    at_knots = np.searchsorted(ts, t)
    assert np.allclose(xs[at_knots], x) and np.allclose(vs[at_knots], v)
