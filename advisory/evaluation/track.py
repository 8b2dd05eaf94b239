"""A recorded drive as a trajectory: station/speed samples -> :class:`advisory.trajectory.Trajectory`.

Pure functions shared by the service's trip score (``server.score``) and the ``replay`` CLI. Positions
are integrated from the speeds (trapezoid, i.e. constant acceleration between samples), so the
trajectory is consistent with its own speeds: map-matched stations are noisy, speeds much less so.
"""

from __future__ import annotations

from dataclasses import dataclass

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


STANDSTILL_MPS = 0.2
"""Smoothed speeds below this are taken as a standstill (receivers report small speeds at rest). [m/s]"""


def smooth_speed_mps(t_s: np.ndarray, v_mps: np.ndarray, sigma_s: float) -> np.ndarray:
    """Gaussian-weighted average of the speeds within ±3 ``sigma_s`` of each sample (uneven times allowed).

    Examples
    --------
    >>> smooth_speed_mps(np.arange(5.0), np.array([0.0, 0.0, 3.0, 0.0, 0.0]), 1.0).round(3).tolist()
    [0.232, 0.771, 1.208, 0.771, 0.232]
    """
    if sigma_s <= 0 or v_mps.size < 3:
        return v_mps.copy()
    min_dt = max(float(np.min(np.diff(t_s))), 0.05)
    half = int(min(np.ceil(3.0 * sigma_s / min_dt), v_mps.size - 1))
    num = np.zeros_like(v_mps)
    den = np.zeros_like(v_mps)
    n = v_mps.size
    for k in range(-half, half + 1):
        lo, hi = max(0, -k), min(n, n - k)
        w = np.exp(-0.5 * ((t_s[lo + k : hi + k] - t_s[lo:hi]) / sigma_s) ** 2)
        num[lo:hi] += w * v_mps[lo + k : hi + k]
        den[lo:hi] += w
    return num / den


def level_crossing(t_s: np.ndarray, station_m: np.ndarray, level_m: float, start: int = 0) -> tuple[int, float] | None:
    """(index k, instant) of the first sample at or past ``level_m`` (from ``start``), interpolated between samples k-1 and k.

    ``None`` if the stations never reach it; ``k == start`` means the first sample is already past it.

    Examples
    --------
    >>> level_crossing(np.array([0.0, 1.0, 2.0]), np.array([-10.0, 10.0, 30.0]), 0.0)
    (1, 0.5)
    """
    above = np.flatnonzero(station_m[start:] >= level_m)
    if above.size == 0:
        return None
    k = start + int(above[0])
    if k == start:
        return k, float(t_s[k])
    frac = (level_m - station_m[k - 1]) / (station_m[k] - station_m[k - 1])
    return k, float(t_s[k - 1] + frac * (t_s[k] - t_s[k - 1]))


@dataclass(frozen=True, slots=True)
class ZoneCut:
    """A drive cut to the zone ``[0, length]``: samples ``(t, v)`` from the entry instant to the exit instant.

    ``entry_seen`` / ``exit_seen``: the fixes bracket that edge (interpolated); otherwise the entry is
    extrapolated back from the first fix inside, and the exit is the last fix (the drive is incomplete).
    """

    t_s: np.ndarray
    v_mps: np.ndarray
    t_in_s: float
    t_out_s: float
    entry_seen: bool
    exit_seen: bool
    first_station_m: float
    last_station_m: float


def cut_to_zone(t_s: np.ndarray, station_m: np.ndarray, v_mps: np.ndarray, length_m: float) -> ZoneCut | None:
    """The part of a drive inside the zone, interpolated at its edges; ``None`` if it never reaches it.

    Fixes outside ``[0, length_m]`` only serve to interpolate the entry and exit instants and speeds: they
    are never moved onto the zone's ends. Stations are the fixes' (map-matched, extended beyond the ends).

    Examples
    --------
    >>> z = cut_to_zone(np.arange(5.0), np.array([-15.0, 5.0, 25.0, 45.0, 65.0]), np.full(5, 20.0), 50.0)
    >>> z.t_s.tolist(), (z.t_in_s, z.t_out_s, z.entry_seen, z.exit_seen)
    ([0.75, 1.0, 2.0, 3.0, 3.25], (0.75, 3.25, True, True))
    """
    inside = np.flatnonzero(station_m <= length_m)
    entry = level_crossing(t_s, station_m, 0.0)
    if entry is None or inside.size == 0:
        return None
    k0, t_in = entry
    entry_seen = not (k0 == 0 and station_m[0] > 0.0)
    if not entry_seen:
        t_in = entry_instant_s(t_s[0], station_m[0], v_mps[0])
    exit_ = level_crossing(t_s, station_m, length_m, start=k0)
    k1, t_out = (t_s.size, float(t_s[-1])) if exit_ is None else exit_
    v_in = float(np.interp(t_in, t_s, v_mps))
    v_out = float(np.interp(t_out, t_s, v_mps))
    zt = np.concatenate([[t_in], t_s[k0:k1], [t_out]])
    zv = np.concatenate([[v_in], v_mps[k0:k1], [v_out]])
    keep = np.concatenate([[True], np.diff(zt) > 1e-6])  # a fix exactly on a crossing
    zt, zv = zt[keep], zv[keep]
    if zt.size < 2:
        return None
    inner = station_m[k0:k1] if k1 > k0 else station_m[k0 : k0 + 1]
    return ZoneCut(zt, zv, float(t_in), float(t_out), entry_seen, exit_ is not None,
                   max(float(station_m[k0]), 0.0) if entry_seen else float(station_m[0]), float(min(inner.max(), length_m)))  # fmt: skip


RED_TOLERANCE_M = 3.0
"""How far the recorded position at a stop line may be off (1 Hz GPS, map matching). A crossing counts as a
red-light crossing only if the car is still in the red this far past the line (a car waiting just short of
the line cannot be told from one just past it). [m]"""
RED_TOLERANCE_S = 0.5
"""Least time tolerance of that test (timestamps, 1 Hz interpolation). [s]"""
ANCHOR_WINDOW_M = 60.0
"""Fixes within this of a stop line anchor the integrated positions to the matched stations there. [m]"""


FIX_GAP_S = 3.0
"""A stop line crossed between two fixes farther apart than this is not judged from the interpolated drive: the
car may have crossed anywhere in the gap (an outage, a tunnel). It is judged only when the light was red, or not
red, throughout the gap; else the verdict is "unknown". [s]"""


@dataclass(frozen=True, slots=True)
class RedCrossing:
    """A stop line crossed while its light was red: which light (1-based along the route), when (on the
    drive's time axis), how long after the red began, and the speed then. [-], [s], [s], [m/s]"""

    light: int
    position_m: float
    t_s: float
    into_red_s: float
    speed_mps: float


@dataclass(frozen=True, slots=True)
class UnjudgedCrossing:
    """A stop line crossed inside a gap between fixes (``gap_from_s`` to ``gap_to_s``, on the drive's time axis)
    longer than :data:`FIX_GAP_S` while its light changed: whether it was red is unknown. [-], [m], [s], [s]"""

    light: int
    position_m: float
    gap_from_s: float
    gap_to_s: float


@dataclass(frozen=True, slots=True)
class RedLightCheck:
    """The red-light verdicts of one drive: crossings judged red, and crossings that cannot be judged."""

    crossings: list[RedCrossing]
    unknown: list[UnjudgedCrossing]


GAP_SLACK_M = 5.0
"""How far a fix's station may be off the car (GPS noise, correlated over a stop) when the stations alone tell when
the car was clearly before a stop line and clearly past it. [m]"""


def _crossing_window(p_m: float, t_fix: np.ndarray, st_fix: np.ndarray) -> tuple[float, float]:
    """From the stations alone: the last fix clearly before the line (``GAP_SLACK_M`` short of it) and the first fix
    clearly past it (``RED_TOLERANCE_M + GAP_SLACK_M`` beyond): the car crossed in between. [s]"""
    before = np.flatnonzero(st_fix < p_m - GAP_SLACK_M)
    past = np.flatnonzero(st_fix > p_m + RED_TOLERANCE_M + GAP_SLACK_M)
    past = past[past > before[0]] if before.size and past.size else past
    t_hi = float(t_fix[past[0]]) if past.size else float(t_fix[-1])
    before = before[t_fix[before] < t_hi] if before.size else before
    t_lo = float(t_fix[before[-1]]) if before.size else float(t_fix[0])
    return t_lo, t_hi


def _long_gap_within(t_fix: np.ndarray, t_lo: float, t_hi: float, overlapping: bool = False) -> tuple[float, float] | None:
    """The longest gap between fixes longer than :data:`FIX_GAP_S` inside ``[t_lo, t_hi]`` (``overlapping``: that
    overlaps it), or None."""
    dt = np.diff(t_fix)
    if overlapping:
        k = np.flatnonzero((dt > FIX_GAP_S) & (t_fix[:-1] < t_hi) & (t_fix[1:] > t_lo))
    else:
        k = np.flatnonzero((dt > FIX_GAP_S) & (t_fix[:-1] >= t_lo - 1e-9) & (t_fix[1:] <= t_hi + 1e-9))
    if k.size == 0:
        return None
    k = int(k[np.argmax(dt[k])])
    return float(t_fix[k]), float(t_fix[k + 1])


def red_light_crossings(traj: Trajectory, signals, t_station_s=None, station_m=None) -> list[RedCrossing]:
    """The crossings :func:`red_light_check` judges red (those it cannot judge left out)."""
    return red_light_check(traj, signals, t_station_s, station_m).crossings


def red_light_check(traj: Trajectory, signals, t_station_s=None, station_m=None) -> RedLightCheck:
    """
    Stop lines the drive crossed while red, with measurement tolerance, and those it cannot tell.

    Parameters
    ----------
    traj : Trajectory
        The drive over the zone (positions integrated from speeds), on the signals' time axis.
    signals : sequence
        Lights with ``position_m``, ``is_red(t)`` and ``red_intervals(t0, t1)`` (``advisory.signals.FixedTimeSignal``
        or an observed light with the same methods).
    t_station_s, station_m : arrays (n,), optional
        The fixes' times (same axis, increasing) and map-matched stations: near each line, the integrated
        positions are shifted by the median of (station - integrated position) over the fixes within
        ``ANCHOR_WINDOW_M``, so slow drift of the integration does not move the crossing, and GPS noise at a
        standstill (speed 0) cannot fake one. They also show gaps: the stretches of fixes between gaps longer
        than :data:`FIX_GAP_S` are anchored apart (the integration across a gap drifts), and a line crossed inside
        a gap is judged by the light over the whole gap (red throughout: a red crossing; never red: none; else
        unknown), never by the crossing instant the interpolation across the gap makes up.

    Returns
    -------
    RedLightCheck
        ``crossings``: at an instant ``t`` such that the light is red from ``t - tol`` (``tol`` =
        max(``RED_TOLERANCE_S``, ``RED_TOLERANCE_M`` / speed)) until the car is ``RED_TOLERANCE_M`` past the
        line: a crossing right at a red's start or end, or a car stopped at the line, is within what a
        recording can tell apart. ``unknown``: the lines crossed in a gap while the light changed.
    """
    out: list[RedCrossing] = []
    unknown: list[UnjudgedCrossing] = []
    t_fix = np.asarray(t_station_s if t_station_s is not None else (), dtype=float)
    st_fix = np.asarray(station_m if station_m is not None else (), dtype=float)
    for n, light in enumerate(signals, start=1):
        p = float(light.position_m)
        if st_fix.size and not (st_fix > p + RED_TOLERANCE_M + GAP_SLACK_M).any():
            continue  # no fix shows the car clearly past the line (a trip ended at it): nothing to judge
        # the instants, from the integrated positions anchored to the stations near the line
        shift = 0.0
        if st_fix.size:
            near = np.abs(st_fix - p) <= ANCHOR_WINDOW_M
            if near.any():
                shift = float(np.median(st_fix[near] - traj.position_at(t_fix[near])))
        t_c = traj.crossing_time_s(p - shift)
        t_past = traj.crossing_time_s(p + RED_TOLERANCE_M - shift)
        if not (np.isfinite(t_c) and np.isfinite(t_past)):
            continue
        v_c = float(traj.speed_at(t_c))
        tol = max(RED_TOLERANCE_S, RED_TOLERANCE_M / max(v_c, 0.1))
        # a gap between fixes where the car may have crossed (by the stations alone), or where those instants fall
        gap, window = None, (t_c - tol, t_past)
        if t_fix.size >= 2:
            t_lo, t_hi = _crossing_window(p, t_fix, st_fix)
            gap = _long_gap_within(t_fix, t_lo, t_hi) or _long_gap_within(t_fix, t_c - tol, t_past, overlapping=True)
            if gap is not None:
                window = (min(t_lo, gap[0], t_c - tol), max(t_hi, gap[1]))
        if gap is not None:  # judged by the light over the whole window, never by an instant the gap makes up
            reds = [(a, b) for a, b in light.red_intervals(window[0], window[1]) if b > window[0] and a < window[1]]
            if not reds:
                continue
            if not any(a <= window[0] and b >= window[1] for a, b in reds):
                unknown.append(UnjudgedCrossing(n, p, gap[0], gap[1]))
                continue
        elif not (bool(light.is_red(t_c - tol)) and bool(light.is_red(t_c)) and bool(light.is_red(t_past)) and bool(light.is_red(t_past - tol))):
            continue
        start = max((s for s, e in light.red_intervals(t_c - 3600.0, t_c) if s <= t_c < e), default=t_c)
        out.append(RedCrossing(n, p, float(t_c), float(t_c - start), v_c))
    return RedLightCheck(out, unknown)
