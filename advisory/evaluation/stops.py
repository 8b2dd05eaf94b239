"""The regular driver on a drive's own recorded stops: a comparison that needs no signal timing.

Without the lights' timing, the paper's regular driver cannot be driven through the lights the recorded drive
met. What the recording does say is where the car stood still and until when. :func:`recorded_stops` finds those
standstills; :func:`stops_scenario` turns each into a light that is red from long before the entry until the
instant the car moved off, placed ``stop_gap_m`` past where it stood (the regular driver halts that far short of a
red stop line). The regular driver then stops where the drive stopped and leaves when it left: what remains
between the two is how each drove between the stops (accelerations, cruising, braking), which is what advice
changes; the stops themselves, which advice could have avoided, are taken as given.
"""

from __future__ import annotations

from dataclasses import dataclass

from advisory.drivers.regular import DriverParams
from advisory.signals import Scenario, TimelineSignal
from advisory.trajectory import Trajectory

MERGE_M = 10.0
"""Standstills closer than this along the route are one stop (a queue creeping up to its line). [m]"""
RED_SINCE_S = -3600.0
"""The stand-in lights are red from this long before the entry. [s]"""


@dataclass(frozen=True, slots=True)
class Stop:
    """Where a drive stood still (station from the zone entry) and from when until when (time 0 = the entry). [m], [s], [s]"""

    position_m: float
    from_s: float
    until_s: float

    @property
    def duration_s(self) -> float:
        return self.until_s - self.from_s


def recorded_stops(traj: Trajectory, merge_m: float = MERGE_M) -> list[Stop]:
    """
    The standstills of a drive: runs of knots at speed 0, those within ``merge_m`` of each other merged (at the last
    one's position, from the first's start to the last's end).

    Parameters
    ----------
    traj : Trajectory
        The drive (time 0 = the zone entry, positions from station 0; standstill speeds exactly 0).

    Examples
    --------
    >>> import numpy as np
    >>> from advisory.evaluation.track import trajectory_from_samples
    >>> traj = trajectory_from_samples(np.arange(8.0), np.array([5, 0, 0, 0, 5, 5, 0, 5.0]))
    >>> [(s.position_m, s.from_s, s.until_s) for s in recorded_stops(traj)]
    [(2.5, 1.0, 3.0), (12.5, 6.0, 6.0)]
    """
    stops: list[Stop] = []
    still = traj.v_mps <= 0.0
    k, n = 0, still.size
    while k < n:
        if not still[k]:
            k += 1
            continue
        j = k
        while j + 1 < n and still[j + 1]:
            j += 1
        stop = Stop(float(traj.x_m[j]), float(traj.t_s[k]), float(traj.t_s[j]))
        if stops and stop.position_m - stops[-1].position_m < merge_m:
            stop = Stop(stop.position_m, stops[-1].from_s, stop.until_s)
            stops.pop()
        stops.append(stop)
        k = j + 1
    return stops


def stops_scenario(stops: list[Stop], zone_length_m: float, speed_limit_mps: float, entry_speed_mps: float,
                   driver: DriverParams | None = None) -> tuple[Scenario, list[Stop]]:  # fmt: skip
    """The zone with a stand-in light at each stop the regular driver can make: red until the drive left, placed
    ``stop_gap_m`` past the stop. A stop nearer the entry than the regular driver needs to halt from
    ``entry_speed_mps`` at its hardest braking, or within ``stop_gap_m`` of the zone's end, gets no light; those are
    returned as left out."""
    driver = driver or DriverParams()
    first_m = entry_speed_mps**2 / (2.0 * driver.brake_max_mps2)
    signals, left_out = [], []
    for stop in stops:
        p = stop.position_m + driver.stop_gap_m
        if stop.position_m < first_m or p >= zone_length_m or (signals and p <= signals[-1].position_m):
            left_out.append(stop)
            continue
        signals.append(TimelineSignal(p, ((RED_SINCE_S, max(stop.until_s, RED_SINCE_S + 1.0)),)))
    scenario = Scenario("recorded stops", tuple(signals), float(zone_length_m), float(speed_limit_mps), float(min(max(entry_speed_mps, 0.0), speed_limit_mps)))
    return scenario, left_out
