"""Map matching a whole GPS trace onto a corridor at once, and finding the corridor.

``Corridor.project_many`` does the projection (nearest segment in a local flat frame, then station and
signed cross-track offset with WGS 84 geodesics; first and last segments extended, so a fix before the
zone entry gets a negative station and one past the exit a station beyond ``length_m``, and the entry and
exit crossings can be found).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from spat_feed.road.corridors import Corridor, load_corridor, preset_names

ON_ROUTE_M = 30.0
"""A fix farther than this from the route counts as off route (the service's default ``off_route_m``). [m]"""


@dataclass(frozen=True, slots=True)
class MatchedTrace:
    """Per fix, shape (n,): station along the route [m] and signed cross-track offset (+ right) [m]."""

    corridor: Corridor
    station_m: np.ndarray
    cross_track_m: np.ndarray

    @property
    def on_route(self) -> np.ndarray:
        return np.abs(self.cross_track_m) <= ON_ROUTE_M

    @property
    def median_offset_m(self) -> float:
        inside = self.on_route & (self.station_m >= 0) & (self.station_m <= self.corridor.length_m)
        return float(np.median(np.abs(self.cross_track_m[inside]))) if inside.any() else float("inf")

    def coverage_frac(self) -> float:
        """Share of the zone [0, length] between the lowest and highest on-route station."""
        st = self.station_m[self.on_route]
        if st.size < 2:
            return 0.0
        lo, hi = max(float(st.min()), 0.0), min(float(st.max()), self.corridor.length_m)
        return max(hi - lo, 0.0) / self.corridor.length_m


def match(corridor: Corridor, lat_deg, lon_deg) -> MatchedTrace:
    """Stations and cross-track offsets of fixes ``(lat_deg, lon_deg)`` (arrays (n,)) on ``corridor``."""
    return MatchedTrace(corridor, *corridor.project_many(lat_deg, lon_deg))


@dataclass(frozen=True, slots=True)
class CorridorChoice:
    matched: MatchedTrace
    how: str  # "given" or a sentence on how it was found
    ambiguous: tuple[str, ...] = ()


def find_corridor(lat_deg, lon_deg, names: list[str] | None = None) -> CorridorChoice:
    """The shipped corridor the fixes follow: smallest median cross-track offset over the fixes in its zone.

    Corridors laid on the same road (the paper's ``paper_s200`` ... ``paper_s800`` share their entry and
    axis) fit equally well; among those within 1 m of the best offset, the longest zone the trace covers
    wholly (>= 95 %) wins, else the best-covered one; the others are listed in ``ambiguous``.
    """
    names = names or preset_names()
    fits = []
    for name in names:
        m = match(load_corridor(name), lat_deg, lon_deg)
        if m.on_route.mean() < 0.5 or m.coverage_frac() < 0.5:
            continue
        fits.append((m.median_offset_m, m))
    if not fits:
        raise ValueError(f"the trace follows none of the shipped corridors {names} (give --corridor)")
    best_off = min(f[0] for f in fits)
    close = [m for off, m in fits if off <= best_off + 1.0]
    whole = [m for m in close if m.coverage_frac() >= 0.95]
    pick = max(whole, key=lambda m: m.corridor.length_m) if whole else max(close, key=lambda m: m.coverage_frac())
    others = tuple(m.corridor.name for m in close if m is not pick)
    how = f"found by map matching (median cross-track {pick.median_offset_m:.1f} m)"
    return CorridorChoice(pick, how, others)
