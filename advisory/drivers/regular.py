"""The paper's regular driver (Sec. 2), simulated exactly as piecewise-constant acceleration.

The rule
--------
* Drive at the speed limit; after a stop or a slow-down, accelerate at ``accel_mps2`` (2 m/s²) back to it.
* Decide about each light once, at the **decision point** ``D`` before its stop line:
  ``D = max(look_ahead_m, v_lim² / (2 brake_max) + stop_gap_m)``. The paper's 75 m look-ahead is 0.6 m
  short of what a car at 88.5 km/h needs to stop at 4 m/s² (75.57 m), so the look-ahead grows just enough
  that the required deceleration never exceeds ``brake_max_mps2``: 76.57 m for the paper's values.
* At the decision point, brake if the light is **red now**, or will be **red when the car arrives** under
  its current plan (cruise, or accelerate to the limit); otherwise go. Braking is at the constant rate that
  halts the car ``stop_gap_m`` short of the stop line (so it never stands *on* the line during red).
* While braking or waiting, the car accelerates again the instant the light turns green.

No amber, and a light turning red when the car is too close to stop
-------------------------------------------------------------------
The paper's lights jump from green to red. Because the decision is taken where a stop is still possible
at <= 4 m/s², and the arrival time under the committed plan is known exactly (fixed timing), a car that
decided to go reaches the line while the light is still green: a green at the decision instant and at the
arrival instant cannot hide a red in between, as a red lasts longer than the approach (76.57 m take at most
8.7 s from standstill at 2 m/s²; reds last 30 s). A red onset the car could not stop for is therefore
never met; the invariant tests check it on all 64 paper scenarios and on random timings.

Lights whose future nobody knows
--------------------------------
For a :class:`~advisory.signals.TimelineSignal` (an actuated or a recorded light: the truth is known to the
evaluation, not to a driver) the driver decides on what it sees (:meth:`_Sim.handle_seen`): red at the
decision point, stop and go at green; otherwise go, and at an amber's onset stop if the car would not clear
the line before the red and can stop at ``brake_max_mps2``, else go on (crossing in amber is legal).
``DriverParams(amber="stop")`` is a more careful person: it stops for any amber it can stop for at
``brake_max_mps2``, whether or not it would clear the line before the red.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from advisory.signals import Scenario, Signal, TimelineSignal
from advisory.trajectory import Trajectory

_EPS = 1e-9


@dataclass(frozen=True, slots=True)
class DriverParams:
    """Regular-driver limits (paper Sec. 2). Units in names."""

    accel_mps2: float = 2.0
    brake_max_mps2: float = 4.0
    look_ahead_m: float = 75.0
    stop_gap_m: float = 1.0
    amber: str = "clear"  # "clear": stop for an amber only if the line is not cleared before the red; "stop": for any amber it can stop for

    def __post_init__(self) -> None:
        if self.amber not in ("clear", "stop"):
            raise ValueError(f"amber must be 'clear' or 'stop', not {self.amber!r}")

    def decision_distance_m(self, speed_limit_mps: float) -> float:
        """Distance before a stop line at which the driver decides. [m]"""
        return max(self.look_ahead_m, speed_limit_mps**2 / (2.0 * self.brake_max_mps2) + self.stop_gap_m)


def time_to_cover_s(distance_m, v_mps, accel_mps2, v_max_mps):
    """
    Shortest time to drive ``distance_m`` from ``v_mps``, accelerating at ``accel_mps2`` up to ``v_max_mps``.

    Elementwise over numpy arrays; returns a float for scalar inputs. [s]

    >>> float(time_to_cover_s(100.0, 20.0, 2.0, 20.0))
    5.0
    >>> round(float(time_to_cover_s(25.0, 0.0, 2.0, 20.0)), 6)  # all accelerating: sqrt(2 * 25 / 2)
    5.0
    """
    d = np.maximum(np.asarray(distance_m, dtype=float), 0.0)
    v = np.minimum(np.asarray(v_mps, dtype=float), v_max_mps)
    d_acc = (v_max_mps**2 - v * v) / (2.0 * accel_mps2)
    t_partial = (np.sqrt(v * v + 2.0 * accel_mps2 * np.minimum(d, d_acc)) - v) / accel_mps2
    t = np.where(d <= d_acc, t_partial, (v_max_mps - v) / accel_mps2 + (d - d_acc) / v_max_mps)
    return t if t.ndim else float(t)


def distance_in_s(dt_s: float, v_mps: float, accel_mps2: float, v_max_mps: float) -> float:
    """Distance covered in ``dt_s`` from ``v_mps``, accelerating at ``accel_mps2`` up to ``v_max_mps``. [m]

    >>> distance_in_s(10.0, 0.0, 2.0, 10.0)  # 5 s to reach 10 m/s (25 m), then 5 s at 10 m/s
    75.0
    """
    t_acc = max(v_max_mps - v_mps, 0.0) / accel_mps2
    if dt_s <= t_acc:
        return v_mps * dt_s + 0.5 * accel_mps2 * dt_s * dt_s
    return v_mps * t_acc + 0.5 * accel_mps2 * t_acc * t_acc + v_max_mps * (dt_s - t_acc)


class _Sim:
    def __init__(self, scenario: Scenario, driver: DriverParams):
        self.sc, self.dr = scenario, driver
        self.v_max = scenario.speed_limit_mps
        self.t, self.x, self.v = 0.0, 0.0, scenario.initial_speed_mps
        self.knots = [(0.0, 0.0, self.v)]

    def advance(self, dt: float, a: float) -> None:
        if dt <= 0.0:
            return
        self.x += self.v * dt + 0.5 * a * dt * dt
        self.v = max(self.v + a * dt, 0.0)
        self.t += dt
        self.knots.append((self.t, self.x, self.v))

    def go_until(self, x_target: float) -> None:
        """Accelerate to / cruise at the limit until position ``x_target``, with exact knots."""
        a = self.dr.accel_mps2
        if self.v < self.v_max - _EPS:
            d_acc = (self.v_max**2 - self.v**2) / (2.0 * a)
            d = min(d_acc, x_target - self.x)
            if d > 0:
                self.advance(time_to_cover_s(d, self.v, a, self.v_max), a)
            if self.v > self.v_max - 1e-6 and self.x < x_target - _EPS:
                self.v = self.v_max
                self.knots[-1] = (self.t, self.x, self.v)
        if self.x < x_target - _EPS:
            self.advance((x_target - self.x) / self.v_max, 0.0)

    def handle(self, light: Signal) -> None:
        if getattr(light, "ambers_s", None) is not None:
            return self.handle_seen(light)
        arrival = self.t + time_to_cover_s(light.position_m - self.x, self.v, self.dr.accel_mps2, self.v_max)
        red_now = bool(light.is_red(self.t))
        if not red_now and not bool(light.is_red(arrival)):
            return  # go: it reaches the line on green
        self.stop_until(light, light.next_green_start_s(self.t if red_now else light.next_red_start_s(arrival)))

    def handle_seen(self, light: TimelineSignal) -> None:
        """A light whose future the driver cannot know (actuated, recorded): it sees the colour. Red at the
        decision point: stop, go at green. Otherwise go, unless an amber shows before the car is over the line
        and, at its onset, the car would not clear the line before the red (any amber for ``amber="stop"``) and
        can stop at ``brake_max_mps2``."""
        if bool(light.is_red(self.t)):
            return self.stop_until(light, light.next_green_start_s(self.t))
        a = self.dr.accel_mps2
        arrival = self.t + time_to_cover_s(light.position_m - self.x, self.v, a, self.v_max)
        onset = next((max(s, self.t) for s, e in light.ambers_s if e > self.t and s < arrival), None)
        if onset is None:
            return  # green to the line (a red with no amber before it is a red entry, which the checks count)
        x_on = self.x + distance_in_s(onset - self.t, self.v, a, self.v_max)
        v_on = min(self.v + a * (onset - self.t), self.v_max)
        red_at = light.next_red_start_s(onset)
        room = light.position_m - self.dr.stop_gap_m - x_on
        clears = self.dr.amber == "clear" and onset + time_to_cover_s(light.position_m - x_on, v_on, a, self.v_max) <= red_at
        if clears or v_on**2 > 2.0 * self.dr.brake_max_mps2 * max(room, 0.0):
            return  # clears the line in the amber (a careful driver does not count on it), or cannot stop for it: go
        self.go_until(x_on)
        self.stop_until(light, light.next_green_start_s(red_at))

    def stop_until(self, light: Signal, green_at: float) -> None:
        """Brake at the constant rate that halts the car ``stop_gap_m`` short of the line; go at ``green_at``."""
        stop_x = light.position_m - self.dr.stop_gap_m
        decel = self.v**2 / (2.0 * (stop_x - self.x)) if self.v > 0 else 0.0
        t_stop = self.v / decel if decel > 0 else 0.0
        if green_at < self.t + t_stop:
            self.advance(green_at - self.t, -decel)  # green while still rolling: accelerate again
        else:
            self.advance(t_stop, -decel)
            self.v = 0.0
            self.knots[-1] = (self.t, self.x, 0.0)
            self.advance(green_at - self.t, 0.0)  # wait at the stop position

    def run(self) -> Trajectory:
        decision_m = self.dr.decision_distance_m(self.v_max)
        for light in self.sc.signals:
            self.go_until(max(light.position_m - decision_m, self.x))
            self.handle(light)
        self.go_until(self.sc.zone_length_m)
        t, x, v = (np.array(c) for c in zip(*self.knots, strict=True))
        return Trajectory(t, x, v)


def regular_driver(scenario: Scenario, driver: DriverParams | None = None) -> Trajectory:
    """The regular driver's exact trajectory through ``scenario`` from entry to the zone end."""
    return _Sim(scenario, driver or DriverParams()).run()
