"""A recorded drive as a trajectory: station/speed samples -> :class:`advisory.trajectory.Trajectory`.

Pure functions shared by the service's trip score (``server.score``) and the ``replay`` CLI. Positions
are integrated from the speeds (trapezoid, i.e. constant acceleration between samples), so the
trajectory is consistent with its own speeds: map-matched stations are noisy, speeds much less so.
"""

from __future__ import annotations

import numpy as np

from advisory.trajectory import Trajectory

MIN_ENTRY_SPEED_MPS = 1.0
"""Slowest speed used to extrapolate the entry instant back to station 0. [m/s]"""


def entry_instant_s(t_s: float, station_m: float, speed_mps: float) -> float:
    """When a car seen at ``station_m`` at ``t_s`` with ``speed_mps`` crossed station 0 (linear). [s]

    Examples
    --------
    >>> entry_instant_s(10.0, 20.0, 20.0)
    9.0
    """
    return float(t_s - station_m / max(speed_mps, MIN_ENTRY_SPEED_MPS))


def trajectory_from_samples(t_s, speed_mps, x0_m: float = 0.0, t0_s: float | None = None) -> Trajectory:
    """
    A trajectory through speed samples, positions integrated from the speeds.

    Parameters
    ----------
    t_s : array (n,)
        Sample times, strictly increasing. [s]
    speed_mps : array (n,)
        Speeds, >= 0. [m/s]
    x0_m : float
        Position of the first sample. [m]
    t0_s : float, optional
        Time origin of the trajectory (default: the first sample). [s]

    Returns
    -------
    Trajectory
        Knots ``(t - t0, x0 + cumulative trapezoid of v, v)``.

    Examples
    --------
    >>> traj = trajectory_from_samples([100.0, 101.0, 103.0], [10.0, 12.0, 12.0], x0_m=5.0)
    >>> traj.t_s.tolist(), traj.x_m.tolist()
    ([0.0, 1.0, 3.0], [5.0, 16.0, 40.0])
    """
    t = np.asarray(t_s, dtype=float)
    v = np.asarray(speed_mps, dtype=float)
    x = np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * np.diff(t))])
    return Trajectory(t - (t[0] if t0_s is None else t0_s), x + x0_m, v)
