"""Map matching a whole GPS trace onto a corridor at once (vectorised), and finding the corridor.

For each fix, the nearest route segment is chosen in a local flat frame (equirectangular about the
segment, exact to millimetres on 50 m segments), then the station and signed cross-track offset on that
segment are computed with WGS 84 geodesics (pyproj), as ``Corridor.project`` does fix by fix. Unlike
``Corridor.project``, the first and last segments are extended: a fix before the zone entry gets a
negative station and one past the exit a station beyond ``length_m``, so the entry and exit crossings
can be found.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from spat_feed.corridors import WGS84, Corridor, load_corridor, preset_names

EARTH_M_PER_DEG = 6_371_008.8 * np.pi / 180.0
CHUNK = 512
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
    lat = np.asarray(lat_deg, dtype=float)
    lon = np.asarray(lon_deg, dtype=float)
    pts = corridor.polyline
    st = np.array([p.station_m for p in pts])
    vlat = np.array([p.lat_deg for p in pts])
    vlon = np.array([p.lon_deg for p in pts])
    n_seg = st.size - 1
    best = np.empty(lat.size, dtype=np.int64)
    # segment choice in each segment's local flat frame
    kx = EARTH_M_PER_DEG * np.cos(np.radians(vlat[:-1]))  # (n_seg,)
    ky = EARTH_M_PER_DEG
    sx = (vlon[1:] - vlon[:-1]) * kx
    sy = (vlat[1:] - vlat[:-1]) * ky
    seg_len2 = np.maximum(sx * sx + sy * sy, 1e-9)
    for a in range(0, lat.size, CHUNK):
        px = (lon[a : a + CHUNK, None] - vlon[None, :-1]) * kx[None, :]
        py = (lat[a : a + CHUNK, None] - vlat[None, :-1]) * ky
        u = (px * sx + py * sy) / seg_len2
        u_lo = np.where(np.arange(n_seg) == 0, -np.inf, 0.0)
        u_hi = np.where(np.arange(n_seg) == n_seg - 1, np.inf, 1.0)
        u = np.clip(u, u_lo, u_hi)
        d2 = (px - u * sx) ** 2 + (py - u * sy) ** 2
        best[a : a + CHUNK] = np.argmin(d2, axis=1)
    # exact along / across on the chosen segment (geodesics)
    seg_az, _, _ = WGS84.inv(vlon[best], vlat[best], vlon[best + 1], vlat[best + 1])
    az, _, dist = WGS84.inv(vlon[best], vlat[best], lon, lat)
    d_rad = np.radians(np.asarray(az) - np.asarray(seg_az))
    along = np.asarray(dist) * np.cos(d_rad)
    cross = np.asarray(dist) * np.sin(d_rad)
    seg_len = st[best + 1] - st[best]
    lo = np.where(best == 0, -np.inf, 0.0)
    hi = np.where(best == n_seg - 1, np.inf, seg_len)
    along_c = np.clip(along, lo, hi)
    # beyond a vertex (clipped): the offset is the distance to that vertex, sign of the cross track
    off = np.hypot(along - along_c, cross) * np.where(cross < 0, -1.0, 1.0)
    return MatchedTrace(corridor, st[best] + along_c, off)


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
