"""Map matching a whole GPS trace onto a corridor at once, and finding the corridor.

``Corridor.project_many`` does the projection (nearest segment in a local flat frame, then station and
signed cross-track offset with WGS 84 geodesics; first and last segments extended, so a fix before the
zone entry gets a negative station and one past the exit a station beyond ``length_m``, and the entry and
exit crossings can be found).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from spat_feed.road.corridors import WGS84, Corridor, load_corridor, preset_names

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


def distance_to_route_m(matched: MatchedTrace, lat_deg, lon_deg) -> np.ndarray:
    """Per fix, the geodesic distance to the corridor's route, the zone ``[0, length]`` only (a fix beyond an end:
    its distance to that end). Shape (n,). [m]"""
    c = matched.corridor
    out = np.abs(matched.cross_track_m).astype(float)
    lat, lon = np.asarray(lat_deg, dtype=float).ravel(), np.asarray(lon_deg, dtype=float).ravel()
    for beyond, end in ((matched.station_m < 0.0, c.polyline[0]), (matched.station_m > c.length_m, c.polyline[-1])):
        if beyond.any():
            _, _, d = WGS84.inv(np.full(beyond.sum(), end.lon_deg), np.full(beyond.sum(), end.lat_deg), lon[beyond], lat[beyond])
            out[beyond] = np.asarray(d)
    return out


def how_far(lat_deg, lon_deg, names: list[str]) -> str:
    """How far the fixes are from each corridor in ``names``: nearest and median fix, in words."""
    parts = []
    for name in names:
        m = match(load_corridor(name), lat_deg, lon_deg)
        d = distance_to_route_m(m, lat_deg, lon_deg)
        parts.append(f"{name}: nearest fix {_dist_text(float(d.min()))}, median {_dist_text(float(np.median(d)))}, {int((d <= ON_ROUTE_M).sum())} of {d.size} within {ON_ROUTE_M:g} m")
    return "; ".join(parts)


def _dist_text(d_m: float) -> str:
    return f"{d_m / 1000:.1f} km" if d_m >= 999.5 else f"{d_m:.0f} m"


MAKE_CORRIDOR = (
    "make a corridor of the road you drove from OpenStreetMap (ecodrive corridor from-osm MAP.osm --street 'NAME' -o road.json; "
    "docs/CORRIDORS.md) and give it with --corridor road.json"
)


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
        raise ValueError(f"the trace follows none of the corridors (at least half its fixes within {ON_ROUTE_M:g} m of one, covering half its zone): "
                         f"{how_far(lat_deg, lon_deg, names)}. To score it, {MAKE_CORRIDOR}")  # fmt: skip
    best_off = min(f[0] for f in fits)
    close = [m for off, m in fits if off <= best_off + 1.0]
    whole = [m for m in close if m.coverage_frac() >= 0.95]
    pick = max(whole, key=lambda m: m.corridor.length_m) if whole else max(close, key=lambda m: m.coverage_frac())
    others = tuple(m.corridor.name for m in close if m is not pick)
    how = f"found by map matching (median cross-track {pick.median_offset_m:.1f} m)"
    return CorridorChoice(pick, how, others)
