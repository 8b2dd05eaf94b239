"""Fixed-time traffic lights and the paper's scenarios (two lights, [x, y] timing, spacing s).

Pure schedule functions; times are seconds since the car entered the control zone. A light is red on
half-open intervals ``[start, start + red_s)``: a car may cross a stop line at the very instant the light
turns green (the paper's eco-driver does exactly that), never while it is red.
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np

from advisory.physics.params import SPEED_LIMIT_MPS


@dataclass(frozen=True, slots=True)
class FixedTimeSignal:
    """A two-phase light (no amber, as in the paper) at ``position_m`` along the route.

    ``red_start_s`` is one instant at which a red phase begins (the paper's x or y); the plan repeats
    every ``red_s + green_s`` seconds in both directions of time.
    """

    position_m: float
    red_start_s: float
    red_s: float = 30.0
    green_s: float = 30.0

    def __post_init__(self) -> None:
        if not (self.red_s > 0 and self.green_s > 0):
            raise ValueError("red_s and green_s must be > 0")

    @property
    def cycle_s(self) -> float:
        return self.red_s + self.green_s

    def phase_s(self, t_s):
        """Seconds since the last red began, in [0, cycle). [s]"""
        return np.mod(np.asarray(t_s, dtype=float) - self.red_start_s, self.cycle_s)

    def _cycle_index(self, t_s):
        """The ``k`` whose cycle ``[red_start + k cycle, red_start + (k + 1) cycle)`` holds ``t_s``, as computed.

        Every instant this class reports is one of ``red_start + k cycle`` (a red begins) or
        ``(red_start + k cycle) + red_s`` (a green begins), and every answer compares ``t_s`` with those same
        floating-point numbers: a light asked at the instant it reported for a green is green there, to the bit.
        """
        t = np.asarray(t_s, dtype=float)
        k = np.floor((t - self.red_start_s) / self.cycle_s)
        k = np.where(self.red_start_s + k * self.cycle_s > t, k - 1, k)
        return np.where(self.red_start_s + (k + 1) * self.cycle_s <= t, k + 1, k)

    def is_red(self, t_s):
        """True where the light is red at ``t_s`` (scalar or array)."""
        k = self._cycle_index(t_s)
        red = np.asarray(t_s, dtype=float) < (self.red_start_s + k * self.cycle_s) + self.red_s
        return red if red.ndim else bool(red)

    def next_green_start_s(self, t_s: float) -> float:
        """``t_s`` itself if green now, else the instant the current red ends. [s]"""
        k = float(self._cycle_index(t_s))
        green_s = (self.red_start_s + k * self.cycle_s) + self.red_s
        return float(green_s) if t_s < green_s else t_s

    def next_red_start_s(self, t_s: float) -> float:
        """``t_s`` itself if red now, else the instant the current green ends. [s]"""
        k = float(self._cycle_index(t_s))
        return t_s if t_s < (self.red_start_s + k * self.cycle_s) + self.red_s else float(self.red_start_s + (k + 1) * self.cycle_s)

    def red_intervals(self, t0_s: float, t1_s: float) -> list[tuple[float, float]]:
        """Red intervals ``[start, end)`` that overlap ``[t0_s, t1_s]``. [s]"""
        k = int(np.floor((t0_s - self.red_start_s) / self.cycle_s)) - 1
        out = []
        while (start := self.red_start_s + k * self.cycle_s) <= t1_s:
            if start + self.red_s > t0_s:
                out.append((float(start), float(start + self.red_s)))
            k += 1
        return out


@runtime_checkable
class Signal(Protocol):
    """A light's real timing, the truth at every instant: :class:`FixedTimeSignal`, :class:`TimelineSignal`.

    Drivers and scoring take any of these; what a driver may *know* of it is the simulator's business (a
    human sees only the present colour; the advisor only the published SPaT).
    """

    position_m: float

    def is_red(self, t_s): ...

    def next_green_start_s(self, t_s: float) -> float: ...

    def next_red_start_s(self, t_s: float) -> float: ...

    def red_intervals(self, t0_s: float, t1_s: float) -> list[tuple[float, float]]: ...


@dataclass(frozen=True, slots=True)
class TimelineSignal:
    """A light whose reds are listed: ``reds_s`` are ``[start, end)`` intervals, sorted and disjoint; green
    between them (amber counts as green, as in the paper). An end may be ``inf`` (red for good).

    The truth of an actuated light, or a recorded one; also a driver's belief built from a display.

    Examples
    --------
    >>> light = TimelineSignal(300.0, ((10.0, 40.0), (70.0, 95.0)))
    >>> light.is_red(10.0), light.is_red(40.0), light.next_green_start_s(20.0), light.next_red_start_s(50.0)
    (True, False, 40.0, 70.0)
    """

    position_m: float
    reds_s: tuple[tuple[float, float], ...] = ()
    ambers_s: tuple[tuple[float, float], ...] = ()  # clearance before a red: green for the rules, a warning to the eye

    def is_amber(self, t_s: float) -> bool:
        """True while the light shows amber (a car that can stop should)."""
        return any(a <= t_s < b for a, b in self.ambers_s)

    def __post_init__(self) -> None:
        for (a, b), (c, _) in zip(self.reds_s, self.reds_s[1:]):
            if not a < b <= c:
                raise ValueError(f"reds must be sorted, disjoint and non-empty: {(a, b)} then {(c, _)}")
        if self.reds_s and not self.reds_s[-1][0] < self.reds_s[-1][1]:
            raise ValueError("a red must end after it begins")

    def _index(self, t_s: float) -> int:
        """Index of the last red that began at or before ``t_s`` (-1: none)."""
        return bisect.bisect_right(self.reds_s, (t_s, math.inf)) - 1

    def is_red(self, t_s):
        if not isinstance(t_s, float | int):
            t = np.asarray(t_s, dtype=float)
            if t.ndim:
                return np.array([self.is_red(float(x)) for x in t.ravel()], dtype=bool).reshape(t.shape)
            t_s = float(t)
        i = self._index(t_s)
        return bool(i >= 0 and t_s < self.reds_s[i][1])

    def next_green_start_s(self, t_s: float) -> float:
        """``t_s`` itself if green now, else the instant the current red ends (``inf``: never). [s]"""
        i = self._index(t_s)
        return float(self.reds_s[i][1]) if i >= 0 and t_s < self.reds_s[i][1] else t_s

    def next_red_start_s(self, t_s: float) -> float:
        """``t_s`` itself if red now, else the instant the next red begins (``inf``: none known). [s]"""
        i = self._index(t_s)
        if i >= 0 and t_s < self.reds_s[i][1]:
            return t_s
        return float(self.reds_s[i + 1][0]) if i + 1 < len(self.reds_s) else math.inf

    def red_intervals(self, t0_s: float, t1_s: float) -> list[tuple[float, float]]:
        """Red intervals ``[start, end)`` that overlap ``[t0_s, t1_s]``. [s]"""
        return [(a, b) for a, b in self.reds_s if b > t0_s and a <= t1_s]

    def shifted(self, dt_s: float) -> TimelineSignal:
        """The same light on an axis whose origin is ``dt_s`` later."""
        return TimelineSignal(self.position_m, tuple((a - dt_s, b - dt_s) for a, b in self.reds_s), tuple((a - dt_s, b - dt_s) for a, b in self.ambers_s))


@dataclass(frozen=True, slots=True)
class Scenario:
    """A control zone: lights along a straight route from 0 to ``zone_length_m``, entered at t = 0."""

    name: str
    signals: tuple[Signal, ...]
    zone_length_m: float
    speed_limit_mps: float = SPEED_LIMIT_MPS
    initial_speed_mps: float = SPEED_LIMIT_MPS

    def __post_init__(self) -> None:
        positions = [s.position_m for s in self.signals]
        if positions != sorted(positions) or (positions and not 0 < positions[0] and positions[-1] < self.zone_length_m):
            raise ValueError("signals must be ordered and strictly inside the zone")
        if not 0 <= self.initial_speed_mps <= self.speed_limit_mps:
            raise ValueError("initial speed must be within [0, speed limit]")


PAPER_TIMINGS_S = (-30.0, -15.0, 0.0, 15.0)
PAPER_SPACINGS_M = (200.0, 400.0, 600.0, 800.0)
PAPER_APPROACH_M = 100.0
PAPER_EXIT_M = 100.0


def paper_scenario(
    x_s: float,
    y_s: float,
    spacing_m: float,
    *,
    approach_m: float = PAPER_APPROACH_M,
    exit_m: float = PAPER_EXIT_M,
    red_s: float = 30.0,
    green_s: float = 30.0,
) -> Scenario:
    """The paper's zone: light 1 at ``approach_m``, light 2 ``spacing_m`` later, then ``exit_m`` to the end.

    ``x_s`` / ``y_s``: seconds after entry at which light 1 / light 2 turn red (negative: before entry).
    """
    light1 = FixedTimeSignal(approach_m, x_s, red_s, green_s)
    light2 = FixedTimeSignal(approach_m + spacing_m, y_s, red_s, green_s)
    return Scenario(
        name=f"[{x_s:g} {y_s:g}] s={spacing_m:g}m",
        signals=(light1, light2),
        zone_length_m=approach_m + spacing_m + exit_m,
    )


def paper_scenarios(**kwargs) -> list[Scenario]:
    """The 64 cases of paper Table 2: 16 timings [x, y] x 4 spacings s (row-major, as the table reads)."""
    return [
        paper_scenario(x, y, s, **kwargs) for x in PAPER_TIMINGS_S for y in PAPER_TIMINGS_S for s in PAPER_SPACINGS_M
    ]
