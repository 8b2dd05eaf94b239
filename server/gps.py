"""GPS fixes onto a corridor: map matching, plausibility, and the speed when the fix has none.

:class:`RouteMatcher` projects a fix onto the corridor polyline with pyproj's WGS 84 geodesics
(``Corridor.project`` / ``Corridor.position``): station along the route, signed cross-track offset, and
the geodesic distance from the fix to the route (which also catches fixes before the zone start or past
its end). :class:`Track` is one trip's fix history: it orders fixes, drops duplicates and late arrivals,
and estimates the speed from positions (least squares over the last seconds) when the fix carries none.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

from advisory.frozen import quick_init
from spat_feed.road.corridors import WGS84, Corridor

SPEED_WINDOW_S = 4.0
"""Positions of the last this many seconds give the speed when the fix has none. [s]"""
JUMP_SLACK_M = 25.0
"""A step along the route longer than ``max_speed_mps * dt`` plus this (two fixes' position errors) is a jump. [m]"""
REANCHOR_FIXES = 5
"""This many consecutive jumped fixes that agree with each other re-anchor the track: the track was the outlier
(a bad first fix, a tunnel exit). Fewer are a glitch and stay rejected. [-]"""


@quick_init
@dataclass(frozen=True, slots=True)
class Fix:
    """One GPS fix as received. Angles in degrees, clockwise from true north for the heading."""

    t_unix_s: float
    lat_deg: float
    lon_deg: float
    speed_mps: float | None = None
    heading_deg: float | None = None
    accuracy_m: float | None = None


@quick_init
@dataclass(frozen=True, slots=True)
class Match:
    """A fix placed on the route. ``station_m`` within [0, length]; ``route_m`` the same along the route extended
    beyond its ends (negative before the entry); ``offset_m``: geodesic distance from the fix to the route. [m]"""

    station_m: float
    cross_track_m: float
    offset_m: float
    route_m: float


class RouteMatcher:
    """Projects fixes onto one corridor."""

    def __init__(self, corridor: Corridor) -> None:
        self.corridor = corridor

    def match(self, lat_deg: float, lon_deg: float) -> Match:
        route_m, cross_m = self.corridor.project(lat_deg, lon_deg)
        station_m, offset_m = route_m, abs(cross_m)
        if station_m < 0.0 or station_m > self.corridor.length_m:  # beyond an end: distance to that end
            end = self.corridor.polyline[0 if station_m < 0.0 else -1]
            _, _, offset_m = WGS84.inv(end.lon_deg, end.lat_deg, lon_deg, lat_deg)
            station_m = min(max(station_m, 0.0), self.corridor.length_m)
        return Match(float(station_m), float(cross_m), float(offset_m), float(route_m))


@quick_init
@dataclass(frozen=True, slots=True)
class TrackPoint:
    """An accepted fix on the route: time [s], station [m], speed used [m/s] (None: not known yet)."""

    t_unix_s: float
    station_m: float
    speed_mps: float | None
    speed_source: str  # "gps", "positions" or "none"


class Track:
    """One trip's recent fixes: ordering, duplicates, speed from positions. Bounded memory."""

    __slots__ = ("last_t_unix_s", "_recent", "dropout_s", "max_speed_mps", "_jumped", "reanchors")

    def __init__(self, dropout_s: float = 5.0, keep: int = 8, max_speed_mps: float = 50.0) -> None:
        self.last_t_unix_s: float | None = None
        self._recent: deque[tuple[float, float]] = deque(maxlen=keep)  # (t, station) of on-route fixes
        self.dropout_s = dropout_s
        self.max_speed_mps = max_speed_mps
        self._jumped: list[tuple[float, float]] = []  # consecutive rejected (t, station), bounded by REANCHOR_FIXES
        self.reanchors = 0

    def state(self) -> list:
        """Everything this track remembers, as plain data (for a shared trip store); :meth:`restore` reads it back."""
        return [self.last_t_unix_s, [list(p) for p in self._recent], [list(p) for p in self._jumped], self.reanchors]

    def restore(self, state: list) -> None:
        last_t, recent, jumped, self.reanchors = state
        self.last_t_unix_s = last_t
        self._recent.clear()
        self._recent.extend((t, s) for t, s in recent)
        self._jumped = [(t, s) for t, s in jumped]

    def implausible(self, t_unix_s: float, station_m: float) -> str | None:
        """Why an on-route fix at ``station_m`` cannot follow the track (a teleport), or None if it can.

        Call after :meth:`order` said "ok". A rejected fix changes nothing but the jump memory: after
        ``REANCHOR_FIXES`` consecutive ones that agree with each other, the next is accepted (re-anchor).
        """
        if not self._recent:
            return None
        t0, s0 = self._recent[-1]
        dt = t_unix_s - t0
        if abs(station_m - s0) <= self.max_speed_mps * dt + JUMP_SLACK_M:
            self._jumped.clear()
            return None
        if self._jumped:
            tj, sj = self._jumped[-1]
            if abs(station_m - sj) > self.max_speed_mps * (t_unix_s - tj) + JUMP_SLACK_M:
                self._jumped.clear()
        if len(self._jumped) >= REANCHOR_FIXES:
            self._jumped.clear()
            self._recent.clear()
            self.reanchors += 1
            return None
        self._jumped.append((t_unix_s, station_m))
        return (f"a jump of {station_m - s0:+.0f} m along the route in {dt:.1f} s ({abs(station_m - s0) / max(dt, 1e-3):.0f} m/s, "
                f"limit {self.max_speed_mps:g} m/s): ignored as a GPS glitch")  # fmt: skip

    def order(self, t_unix_s: float) -> str:
        """``"ok"`` for a fix newer than every fix so far, ``"duplicate"`` (same time) or ``"out_of_order"``."""
        last = self.last_t_unix_s
        if last is None or t_unix_s > last:
            return "ok"
        return "duplicate" if t_unix_s == last else "out_of_order"

    def add(self, t_unix_s: float, station_m: float | None, fix_speed_mps: float | None) -> TrackPoint | None:
        """Record a fix (call :meth:`order` first; only ``"ok"`` fixes belong here).

        ``station_m`` None: the fix is off the route (kept for ordering only; it breaks the position chain).
        """
        if self.last_t_unix_s is not None and t_unix_s - self.last_t_unix_s > self.dropout_s:
            self._recent.clear()  # after a dropout, old positions say nothing about the speed now
        self.last_t_unix_s = t_unix_s
        if station_m is None:
            self._recent.clear()
            return None
        self._recent.append((t_unix_s, station_m))
        if fix_speed_mps is not None:
            return TrackPoint(t_unix_s, station_m, fix_speed_mps, "gps")
        speed = self.speed_from_positions_mps()
        return TrackPoint(t_unix_s, station_m, speed, "positions" if speed is not None else "none")

    def speed_from_positions_mps(self) -> float | None:
        """Least-squares slope of station over time in the last ``SPEED_WINDOW_S``, >= 0; None if < 2 fixes. [m/s]"""
        if not self._recent:
            return None
        t_last = self._recent[-1][0]
        pts = [(t, s) for t, s in self._recent if t_last - t <= SPEED_WINDOW_S + 1e-9]
        if len(pts) < 2 or pts[-1][0] - pts[0][0] < 0.5:
            return None
        n = len(pts)
        t_mean = sum(t for t, _ in pts) / n
        s_mean = sum(s for _, s in pts) / n
        var = sum((t - t_mean) ** 2 for t, _ in pts)
        cov = sum((t - t_mean) * (s - s_mean) for t, s in pts)
        slope = cov / var
        return max(slope, 0.0) if math.isfinite(slope) else None
