"""The hindsight bound of a car in traffic: the DP that knows the lights the car met, over the car's own drive.

For one car of a SUMO run, :func:`hindsight_drive` gives the cheapest drive (``advisory.optimizer.dp``, the cost the
paired runs score: energy and battery wear to the zone's end plus the re-acceleration penalty of the common end
state) from the car's own insertion (time, station, speed) to the zone's end, through the lights' red intervals as
that run's SUMO steps ran them (:attr:`~ecodrive.traffic.sim.RunResult.reds`; amber is not red: the loosest reading,
as spat-eval's hindsight), within the car's own time to the end state (its trajectory's duration plus the penalty's
time: the paper's limit, the regular driver's time). No other car is in the DP: a car whose optimum runs into the
car ahead could not have driven it (:func:`runs_into`), and where the run's queues delayed the car the DP has that
delay to spend. Advice cannot beat the bound for a car alone on the road with the same lights and time.

The DP lays stages every ``grid.stage_m`` metres back from the zone's end, and every stop line on a stage. The DP
starts on the first stage at or past the car's first station, or a later station ``from_m`` (the car's own drive up
to there kept: under one stage, or up to where the service begins to advise). A stop line between stages is moved
to the nearest one, ``delta_m`` closer to the entry or farther, and its reds ``delta_m / v_limit`` earlier or later
with it (the time a car at the limit takes over ``delta_m``): exact where the lines lie on the stages (paper_s400 at
10 or 20 m), within ``stage_m / 2`` of a line elsewhere (7th Street's lines lie 172.58 m apart). SUMO reports speeds
to 0.01 m/s (24.59 for a 24.5872 m/s limit): a drive faster than the limit allows is taken as the same drive at the
limit (the DP's fastest).

Behind the car ahead (``ahead``: its drive as it went, unadvised): a line on every stage, closed from the DP's start
until that car's front is :data:`CAR_GAP_M` past it (:func:`behind_lights`), so that the DP's drive keeps a car's
length behind it at every stage (not checked between stages; no time gap: SUMO's driver keeps far more at speed). A
car ahead that is not connected drives the same whatever this car is told: that drive is the one an advised car meets.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from advisory.drivers.closed_loop import hindsight_optimum
from advisory.optimizer.dp import GridSpec
from advisory.signals import Scenario, TimelineSignal
from advisory.trajectory import Trajectory

HINDSIGHT_GRID = GridSpec(stage_m=10.0)
"""The study's stages (10 m, 0.25 s time bins: ~0.1 % above the refined optimum; at 20 m, spat-eval's, the paper
cases' optimum costs up to 5 % more, a bound that much too low)."""
CAR_GAP_M = 7.5
"""A car's length and SUMO's standstill gap (``network.VTYPE``: 5 m + 2.5 m): a front this close behind the car
ahead's front has run into it. [m]"""


def snapped_lights(stop_lines_m, reds_s, start_m: float, start_s: float, stage_m: float, speed_limit_mps: float) -> tuple[TimelineSignal, ...]:
    """The lights ahead of station ``start_m`` on the DP's axis (origin at ``start_m``, ``start_s``), each line moved
    to the nearest stage and its reds by the time a car at the limit takes over the move.

    Examples
    --------
    >>> snapped_lights([104.0], [((50.0, 80.0),)], 0.0, 10.0, 10.0, 20.0)
    (TimelineSignal(position_m=100.0, reds_s=((39.8, 69.8),), ambers_s=()),)
    """
    out = []
    for line, reds in zip(stop_lines_m, reds_s):
        if line <= start_m:
            continue
        at_m = round((line - start_m) / stage_m) * stage_m
        shift_s = (line - start_m - at_m) / speed_limit_mps
        out.append(TimelineSignal(float(at_m), tuple((a - start_s - shift_s, b - start_s - shift_s) for a, b in reds)))
    return tuple(out)


def closed_until(reds_s, until_s: float) -> tuple[tuple[float, float], ...]:
    """``reds_s`` (sorted, disjoint) with the line also closed from 0 until ``until_s``: their union, sorted and disjoint.

    Examples
    --------
    >>> closed_until(((5.0, 8.0), (20.0, 30.0)), 6.0), closed_until(((-3.0, 1.0),), 0.0), closed_until((), 4.0)
    (((0.0, 8.0), (20.0, 30.0)), ((-3.0, 1.0),), ((0.0, 4.0),))
    """
    if not until_s > 0.0:
        return tuple(reds_s)
    lo, hi, apart = 0.0, until_s, []
    for a, b in reds_s:
        if b < lo or a > hi:
            apart.append((a, b))
        else:
            lo, hi = min(lo, a), max(hi, b)
    return tuple(sorted([*apart, (lo, hi)]))


def behind_lights(lights, ahead: Trajectory, start_m: float, start_s: float, zone_m: float, stage_m: float,
                  gap_m: float = CAR_GAP_M) -> tuple[TimelineSignal, ...]:  # fmt: skip
    """``lights`` (on the DP's axis: origin at station ``start_m``, time ``start_s``; each on a stage) and a line on every
    stage before ``zone_m`` (the zone's end, where the DP ends), each closed from 0 until the front of ``ahead`` (on the
    run's axes) is ``gap_m`` past it.

    Examples
    --------
    A car ahead standing 20 m past the start until 5 s, then speeding up to 10 m/s over a second (25 m at 6 s) and on
    at 10 m/s: the stage at 10 m is open (its front is past 17.5 m already), the one at 20 m closed until its front is at
    27.5 m, 6 + 2.5 / 10 = 6.25 s, and the light there is red from 8 s to 9 s as before.

    >>> lead = Trajectory(np.array([0.0, 5.0, 6.0, 30.0]), np.array([20.0, 20.0, 25.0, 265.0]), np.array([0.0, 0.0, 10.0, 10.0]))
    >>> [(light.position_m, light.reds_s) for light in behind_lights((TimelineSignal(20.0, ((8.0, 9.0),)),), lead, 0.0, 0.0, 30.0, 10.0)]
    [(10.0, ()), (20.0, ((0.0, 6.25), (8.0, 9.0)))]
    """
    reds = {light.position_m: light.reds_s for light in lights}
    out = []
    for k in range(1, int(round(zone_m / stage_m))):
        at_m = k * stage_m
        until = ahead.crossing_time_s(start_m + at_m + gap_m) - start_s
        out.append(TimelineSignal(at_m, closed_until(reds.get(at_m, ()), until)))
    return tuple(out)


def _split(drive: Trajectory, stop_lines_m, reds_s, zone_end_m: float, speed_limit_mps: float, stage_m: float, from_m: float):
    """The DP's start on ``drive`` (its first stage at or past ``drive``'s first station and ``from_m``): the knots of
    ``drive`` before it, the start (station, time), the zone from there as a Scenario, and ``drive`` from there on its axes."""
    start_m = zone_end_m - np.floor((zone_end_m - max(drive.x_m[0], from_m)) / stage_m + 1e-9) * stage_m
    start_s = drive.crossing_time_s(start_m)
    v0 = min(float(drive.speed_at(start_s)), speed_limit_mps)
    keep = drive.t_s < start_s - 1e-9
    lights = snapped_lights(stop_lines_m, reds_s, start_m, start_s, stage_m, speed_limit_mps)
    truth = Scenario("hindsight", lights, zone_end_m - start_m, speed_limit_mps, v0)
    after = drive.t_s > start_s + 1e-9
    rest = Trajectory(np.append(0.0, drive.t_s[after] - start_s), np.append(0.0, drive.x_m[after] - start_m), np.append(v0, drive.v_mps[after]))
    slow = truth.zone_length_m / speed_limit_mps / rest.duration_s  # > 1: SUMO's speeds, to 0.01 m/s, above the limit (24.59 for 24.5872)
    if slow > 1.0:  # the same drive at the limit: the DP's fastest
        rest = Trajectory(rest.t_s * slow * (1 + 1e-12), rest.x_m, np.minimum(rest.v_mps / slow, speed_limit_mps))
    return keep, start_m, start_s, truth, rest


def _joined(drive: Trajectory, keep, start_m: float, start_s: float, rest: Trajectory) -> Trajectory:
    """``drive``'s knots ``keep``, then ``rest`` from (``start_s``, ``start_m``) on."""
    return Trajectory(np.append(drive.t_s[keep], rest.t_s + start_s), np.append(drive.x_m[keep], rest.x_m + start_m),
                      np.append(drive.v_mps[keep], rest.v_mps))  # fmt: skip


def hindsight_drive(drive: Trajectory, stop_lines_m, reds_s, zone_end_m: float, speed_limit_mps: float, params,
                    grid: GridSpec = HINDSIGHT_GRID, from_m: float = -np.inf, ahead: Trajectory | None = None) -> Trajectory | None:  # fmt: skip
    """The cheapest drive of the car whose own drive (to the zone's end) is ``drive``, on the run's axes (see the
    module docstring); None where the DP finds none (or its optimum meets a red of the lights as given, which the
    DP's one-cycle reading of them did not repeat: ``hindsight_optimum``).

    ``stop_lines_m``: each light's station; ``reds_s``: each light's red intervals ``[start, end)`` [s]. ``from_m``:
    the car drives its own drive up to this station (where the service begins to advise it), the DP from there.
    ``ahead``: the car in front's drive (on the run's axes, past the zone's end): the DP keeps behind it (module docstring)."""
    keep, start_m, start_s, truth, own = _split(drive, stop_lines_m, reds_s, zone_end_m, speed_limit_mps, grid.stage_m, from_m)
    if ahead is not None:
        truth = replace(truth, signals=behind_lights(truth.signals, ahead, start_m, start_s, truth.zone_length_m, grid.stage_m))
    best = hindsight_optimum(truth, params, grid, own)
    return None if best is None else _joined(drive, keep, start_m, start_s, best)


def runs_into(drive: Trajectory, ahead: Trajectory, gap_m: float = CAR_GAP_M) -> bool:
    """Whether ``drive`` comes within ``gap_m`` of the front of ``ahead`` (the car in front, on the same axes) while
    both are on the road (the overlap of their times).

    Examples
    --------
    >>> lead = Trajectory(np.array([0.0, 10.0]), np.array([20.0, 20.0]), np.array([0.0, 0.0]))
    >>> runs_into(Trajectory(np.array([0.0, 2.0]), np.array([0.0, 20.0]), np.array([10.0, 10.0])), lead)
    True
    >>> runs_into(Trajectory(np.array([0.0, 2.0]), np.array([0.0, 10.0]), np.array([5.0, 5.0])), lead)
    False
    """
    t0, t1 = max(drive.t_s[0], ahead.t_s[0]), min(drive.t_s[-1], ahead.t_s[-1])
    if t1 <= t0:
        return False
    t = np.linspace(t0, t1, int(np.ceil((t1 - t0) / 0.1)) + 1)
    return bool((drive.position_at(t) > ahead.position_at(t) - gap_m + 1e-9).any())
