"""Independent trajectory checker shared by the regular-driver and DP tests.

It looks only at a trajectory's knots and the lights' plans, never at a solver's bookkeeping.
"""

from __future__ import annotations

import numpy as np

from advisory.signals import Scenario
from advisory.trajectory import Trajectory

TOL = 1e-6


def violations(traj: Trajectory, scenario: Scenario, accel_max=2.0, brake_max=4.0) -> list[str]:
    out = []
    t, x, v = traj.t_s, traj.x_m, traj.v_mps
    if np.any(np.diff(t) <= 0):
        out.append("time does not increase")
    if v.min() < -TOL or v.max() > scenario.speed_limit_mps + TOL:
        out.append(f"speed outside [0, limit]: {v.min():.4f}..{v.max():.4f}")
    a = traj.accel_mps2
    if a.max() > accel_max + TOL or a.min() < -brake_max - TOL:
        out.append(f"acceleration outside [-{brake_max}, {accel_max}]: {a.min():.4f}..{a.max():.4f}")
    if np.any(np.diff(x) < -TOL):
        out.append("moves backwards")
    if x[-1] < scenario.zone_length_m - TOL:
        out.append("does not reach the zone end")
    for i, light in enumerate(scenario.signals):
        t_cross = traj.crossing_time_s(light.position_m)
        # at or past the stop line while red: the first instant it reaches the line must be green
        for start, end in light.red_intervals(0.0, t[-1]):
            if start + TOL < t_cross < end - TOL:
                out.append(f"light {i + 1}: reaches the stop line at {t_cross:.3f} s, red [{start:g}, {end:g})")
    # never stands on a stop line while it is red (halting exactly on it during green is legal)
    for light in scenario.signals:
        on_line = (v <= TOL) & (np.abs(x - light.position_m) <= TOL)
        if np.any(light.is_red(t[on_line] - TOL) & light.is_red(t[on_line] + TOL)):
            out.append(f"stands on the stop line at {light.position_m:g} m during red")
    return out
