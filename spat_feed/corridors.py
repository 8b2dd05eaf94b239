"""Corridors: a route polyline with its signalised intersections, read from JSON; the paper's presets.

A corridor file (JSON) holds the route as a polyline of WGS 84 points with their station (distance
along the route from the zone entry, in metres), and each intersection's stop line as a station and a
lat/lon, with its approach heading and signal groups. Stations, not coordinates, are what the advisor
uses; coordinates place the route on a map and let a GPS fix be projected onto it (:meth:`Corridor.project`).

Shipped presets (``spat_feed/presets/*.json``) reproduce the paper's zone: 100 m approach, light 2
``s`` = 200/400/600/800 m after light 1, 100 m exit, laid westbound along the Avenue des
Champs-Élysées in Paris (see ``CHAMPS_ELYSEES`` and docs/SPAT.md). Regenerate them with
``python -m spat_feed.corridors``; a test checks the shipped files equal the generated ones.

Geodesy uses pyproj's WGS 84 geodesic (Karney's algorithm), not a spherical approximation.
"""

from __future__ import annotations

import math
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from functools import cached_property
from importlib import resources
from pathlib import Path

import numpy as np
from numba import njit
from pydantic import BaseModel, ConfigDict, Field, model_validator
from pyproj import Geod

from advisory.signals import (
    PAPER_APPROACH_M,
    PAPER_EXIT_M,
    PAPER_SPACINGS_M,
    PAPER_TIMINGS_S,
)

WGS84 = Geod(ellps="WGS84")
PRESET_DIR = "presets"


class LatLon(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)
    lat_deg: float = Field(ge=-90, le=90)
    lon_deg: float = Field(ge=-180, le=180)


class RoutePoint(LatLon):
    station_m: float = Field(ge=0)


class SignalGroupSpec(BaseModel):
    """One signal group (J2735 SignalGroupID) controlling the corridor's movement at an intersection."""

    model_config = ConfigDict(extra="forbid", frozen=True)
    id: int = Field(ge=1, le=255)
    name: str = ""


class IntersectionSpec(BaseModel):
    """A signalised intersection on the route: J2735 id, stop line (station and lat/lon), approach heading."""

    model_config = ConfigDict(extra="forbid", frozen=True)
    id: int = Field(ge=0, le=65_535)
    name: str
    stop_line_m: float = Field(gt=0)
    lat_deg: float = Field(ge=-90, le=90)
    lon_deg: float = Field(ge=-180, le=180)
    approach_heading_deg: float = Field(ge=0, lt=360, description="direction of travel, clockwise from true north")
    signal_groups: tuple[SignalGroupSpec, ...] = Field(min_length=1)


class RoadSource(BaseModel):
    """Where the route lies and where its coordinates come from."""

    model_config = ConfigDict(extra="forbid", frozen=True)
    name: str
    start: LatLon
    end: LatLon
    source: str
    note: str = ""


class Corridor(BaseModel):
    """A route from station 0 (zone entry) to ``length_m`` (zone exit) and its intersections in order."""

    model_config = ConfigDict(extra="forbid", frozen=True)
    name: str
    description: str = ""
    road: RoadSource | None = None
    length_m: float = Field(gt=0)
    polyline: tuple[RoutePoint, ...] = Field(min_length=2)
    intersections: tuple[IntersectionSpec, ...]

    @model_validator(mode="after")
    def _consistent(self) -> Corridor:
        stations = [p.station_m for p in self.polyline]
        if stations[0] != 0.0 or any(b <= a for a, b in zip(stations, stations[1:])):
            raise ValueError("polyline stations must start at 0 and increase")
        if abs(stations[-1] - self.length_m) > 1e-6:
            raise ValueError(f"last polyline station {stations[-1]} != length_m {self.length_m}")
        lines = [ix.stop_line_m for ix in self.intersections]
        if lines != sorted(lines) or (lines and not lines[-1] < self.length_m):
            raise ValueError("intersections must be ordered by stop line and inside the route")
        ids = [ix.id for ix in self.intersections]
        if len(set(ids)) != len(ids):
            raise ValueError("intersection ids must be unique")
        return self

    def intersection(self, intersection_id: int) -> IntersectionSpec:
        """The intersection with this J2735 id (``KeyError`` if absent)."""
        for ix in self.intersections:
            if ix.id == intersection_id:
                return ix
        raise KeyError(intersection_id)

    @cached_property
    def _arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        pts = self.polyline
        return (
            np.array([p.station_m for p in pts]),
            np.array([p.lat_deg for p in pts]),
            np.array([p.lon_deg for p in pts]),
        )

    def position(self, station_m: float) -> tuple[float, float]:
        """(lat_deg, lon_deg) of the point ``station_m`` along the route (geodesic between vertices)."""
        st, lat, lon = self._arrays
        i = int(np.clip(np.searchsorted(st, station_m, side="right") - 1, 0, len(st) - 2))
        az12, _, _ = WGS84.inv(lon[i], lat[i], lon[i + 1], lat[i + 1])
        lon_deg, lat_deg, _ = WGS84.fwd(lon[i], lat[i], az12, station_m - st[i])
        return float(lat_deg), float(lon_deg)

    @cached_property
    def _segments(self) -> _Segments:
        st, lat, lon = self._arrays
        kx = EARTH_M_PER_DEG * np.cos(np.radians(lat[:-1]))
        sx, sy = (lon[1:] - lon[:-1]) * kx, (lat[1:] - lat[:-1]) * EARTH_M_PER_DEG
        seg_az, _, _ = WGS84.inv(lon[:-1], lat[:-1], lon[1:], lat[1:])
        packed = np.ascontiguousarray(np.column_stack([lon[:-1], lat[:-1], kx, sx, sy, np.maximum(sx * sx + sy * sy, 1e-9)]))
        return _Segments(st, lat, lon, packed, np.asarray(seg_az, dtype=float))

    def project(self, lat_deg: float, lon_deg: float) -> tuple[float, float]:
        """Project a fix onto the route: (station_m, signed offset_m, + to the right of travel).

        The nearest segment is chosen in a local flat frame (equirectangular about each segment's start,
        exact to millimetres on segments of a few hundred metres); on it, the WGS 84 geodesic from the
        segment's start to the fix gives along = d cos Δaz and across = d sin Δaz. The first and last
        segments are extended, so a fix before the zone entry gets a negative station and one past the exit
        a station beyond ``length_m``. Past an inner vertex (the fix beyond a bend), the offset is the
        distance to that vertex, with the sign of the cross track. :meth:`project_many` is the same for arrays.
        """
        g = self._segments
        j = _nearest_segment(float(lon_deg), float(lat_deg), g.packed)
        az, _, dist = WGS84.inv(g.lon[j], g.lat[j], lon_deg, lat_deg)
        d_rad = math.radians(az - g.seg_az[j])
        along, across = dist * math.cos(d_rad), dist * math.sin(d_rad)
        lo = 0.0 if j > 0 else -math.inf
        hi = g.st[j + 1] - g.st[j] if j < g.packed.shape[0] - 1 else math.inf
        clipped = min(max(along, lo), hi)
        offset = math.copysign(math.hypot(along - clipped, across), across) if clipped != along else across
        return float(g.st[j] + clipped), float(offset)

    def project_many(self, lat_deg, lon_deg) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`project` for arrays of fixes (n,): stations and signed offsets, shape (n,). [m]"""
        lat, lon = np.asarray(lat_deg, dtype=float).ravel(), np.asarray(lon_deg, dtype=float).ravel()
        g = self._segments
        j = _nearest_segments(lon, lat, g.packed)
        az, _, dist = WGS84.inv(g.lon[j], g.lat[j], lon, lat)
        d_rad = np.radians(np.asarray(az) - g.seg_az[j])
        along, across = np.asarray(dist) * np.cos(d_rad), np.asarray(dist) * np.sin(d_rad)
        lo = np.where(j == 0, -np.inf, 0.0)
        hi = np.where(j == g.packed.shape[0] - 1, np.inf, g.st[j + 1] - g.st[j])
        clipped = np.clip(along, lo, hi)
        offset = np.where(clipped != along, np.copysign(np.hypot(along - clipped, across), across), across)
        return g.st[j] + clipped, offset


EARTH_M_PER_DEG = 6_371_008.8 * np.pi / 180.0
"""Metres per degree of latitude on the mean sphere: only for choosing the nearest segment. [m/deg]"""


@dataclass(frozen=True, slots=True)
class _Segments:
    """A corridor's polyline for projection: vertices (n+1,); per segment (n, 6) its start (lon, lat), the
    flat frame's metres per degree of longitude kx, its vector (sx, sy) and squared length there; and its
    geodesic azimuth (n,)."""

    st: np.ndarray
    lat: np.ndarray
    lon: np.ndarray
    packed: np.ndarray
    seg_az: np.ndarray


@njit(cache=True)
def _nearest_segment(lon, lat, seg):
    """Index of the polyline segment nearest the fix, in each segment's flat frame (ends extended).
    ``seg``: per segment (start lon, start lat, kx, sx, sy, len2), shape (n, 6)."""
    n_seg = seg.shape[0]
    best, best_d2 = 0, np.inf
    for j in range(n_seg):
        px = (lon - seg[j, 0]) * seg[j, 2]
        py = (lat - seg[j, 1]) * EARTH_M_PER_DEG
        sx, sy = seg[j, 3], seg[j, 4]
        u = (px * sx + py * sy) / seg[j, 5]
        if j > 0:
            u = max(u, 0.0)
        if j < n_seg - 1:
            u = min(u, 1.0)
        d2 = (px - u * sx) ** 2 + (py - u * sy) ** 2
        if d2 < best_d2:
            best, best_d2 = j, d2
    return best


@njit(cache=True)
def _nearest_segments(lon, lat, seg):
    """:func:`_nearest_segment` for arrays of fixes. (n,)"""
    out = np.empty(lon.size, dtype=np.int64)
    for i in range(lon.size):
        out[i] = _nearest_segment(lon[i], lat[i], seg)
    return out


# --------------------------------------------------------------------------------------------------
# Loading


def corridor_from_json(text: str) -> Corridor:
    """Validate a corridor JSON text."""
    return Corridor.model_validate_json(text)


def preset_names() -> list[str]:
    """Names of the shipped corridor presets."""
    folder = resources.files("spat_feed") / PRESET_DIR
    return sorted(p.name.removesuffix(".json") for p in folder.iterdir() if p.name.endswith(".json"))


def load_corridor(name_or_path: str | Path) -> Corridor:
    """A shipped preset by name (``"paper_s400"``), or a corridor JSON file by path."""
    path = Path(name_or_path)
    if path.suffix == ".json" or path.exists():
        return corridor_from_json(path.read_text(encoding="utf-8"))
    resource = resources.files("spat_feed") / PRESET_DIR / f"{name_or_path}.json"
    if not resource.is_file():
        raise KeyError(f"no corridor preset {name_or_path!r}; presets: {preset_names()}")
    return corridor_from_json(resource.read_text(encoding="utf-8"))


# --------------------------------------------------------------------------------------------------
# The paper's corridor on a real road


@dataclass(frozen=True, slots=True)
class StraightRoad:
    """A straight stretch of real road, given by two well-known points on its axis."""

    name: str
    a: tuple[float, float]  # (lat_deg, lon_deg)
    b: tuple[float, float]
    source: str
    note: str
    start_offset_m: float  # zone entry this far from ``a`` towards ``b``


CHAMPS_ELYSEES = StraightRoad(
    name="Avenue des Champs-Élysées, Paris, westbound (Concorde towards Étoile)",
    a=(48.865556, 2.321111),  # Luxor Obelisk, Place de la Concorde: 48°51'56"N 2°19'16"E
    b=(48.873778, 2.295028),  # Arc de Triomphe, Place Charles-de-Gaulle: 48°52'25.6"N 2°17'42.1"E
    source=(
        "Both ends of Paris's historic axis, which the avenue follows in a straight line for about 1.9 km: the "
        "Luxor Obelisk (48°51'56\"N 2°19'16\"E) and the Arc de Triomphe (48°52'25.6\"N 2°17'42.1\"E), as given "
        "on their Wikipedia pages; the avenue is OpenStreetMap's 'Avenue des Champs-Élysées' between them."
    ),
    note=(
        "Coordinates are approximate (about ±10 m): the route is the geodesic from the obelisk to the arch, "
        "which runs along the avenue's axis, not a surveyed lane centre line. The zone starts 300 m west of "
        "the obelisk, past Place de la Concorde. Stop lines are placed by the paper's distances, not at the "
        "avenue's real signals; the route crosses the Rond-Point des Champs-Élysées (a roundabout)."
    ),
    start_offset_m=300.0,
)

POLYLINE_STEP_M = 50.0


def straight_corridor(
    name: str,
    road: StraightRoad,
    stop_lines_m: Sequence[float],
    length_m: float,
    *,
    description: str = "",
    first_id: int = 1,
    signal_group: int = 2,
) -> Corridor:
    """A corridor along ``road`` from its zone start, with a light at each of ``stop_lines_m``.

    Vertices every 50 m (and at each stop line) lie on the WGS 84 geodesic from ``road.a`` to
    ``road.b``. Intersection ids are ``first_id, first_id + 1, ...``; each has one signal group,
    ``signal_group`` (NEMA phase 2, main-street through, by convention).
    """
    (lat_a, lon_a), (lat_b, lon_b) = road.a, road.b
    az_deg, _, total_m = WGS84.inv(lon_a, lat_a, lon_b, lat_b)
    if road.start_offset_m + length_m > total_m:
        raise ValueError(f"route of {length_m} m does not fit on {road.name} ({total_m:.0f} m)")

    def point(station_m: float) -> tuple[float, float, float]:
        lon, lat, back_az = WGS84.fwd(lon_a, lat_a, az_deg, road.start_offset_m + station_m)
        return round(lat, 7), round(lon, 7), (back_az + 180.0) % 360.0

    stations = sorted(set(np.arange(0.0, length_m, POLYLINE_STEP_M).tolist()) | set(map(float, stop_lines_m)) | {float(length_m)})
    polyline = [RoutePoint(station_m=s, lat_deg=point(s)[0], lon_deg=point(s)[1]) for s in stations]
    intersections = []
    for i, stop_m in enumerate(stop_lines_m):
        lat, lon, heading = point(stop_m)
        intersections.append(
            IntersectionSpec(
                id=first_id + i,
                name=f"light {i + 1}",
                stop_line_m=float(stop_m),
                lat_deg=lat,
                lon_deg=lon,
                approach_heading_deg=round(heading, 2),
                signal_groups=(SignalGroupSpec(id=signal_group, name="westbound through"),),
            )
        )
    lat_s, lon_s, _ = point(0.0)
    lat_e, lon_e, _ = point(length_m)
    return Corridor(
        name=name,
        description=description,
        road=RoadSource(
            name=road.name,
            start=LatLon(lat_deg=lat_s, lon_deg=lon_s),
            end=LatLon(lat_deg=lat_e, lon_deg=lon_e),
            source=road.source,
            note=road.note,
        ),
        length_m=float(length_m),
        polyline=tuple(polyline),
        intersections=tuple(intersections),
    )


def paper_corridor(spacing_m: float, road: StraightRoad = CHAMPS_ELYSEES) -> Corridor:
    """The paper's zone with light 2 ``spacing_m`` after light 1, laid on ``road``.

    Light 1 (id 1) at 100 m, light 2 (id 2) at 100 + s m, zone end at 200 + s m.
    """
    return straight_corridor(
        f"paper_s{spacing_m:g}",
        road,
        [PAPER_APPROACH_M, PAPER_APPROACH_M + spacing_m],
        PAPER_APPROACH_M + spacing_m + PAPER_EXIT_M,
        description=(
            f"Paper Sec. 2: 100 m approach, light 2 s = {spacing_m:g} m after light 1, 100 m exit "
            "(Wang, Advani & Prasad)."
        ),
    )


PAPER_CORRIDOR_NAMES = tuple(f"paper_s{s:g}" for s in PAPER_SPACINGS_M)


# --------------------------------------------------------------------------------------------------
# Timings: when each light turns red, relative to the car's zone entry


@dataclass(frozen=True, slots=True)
class Timing:
    """Fixed-time plans for a corridor's lights, relative to the instant a car enters the zone.

    ``red_starts_s[i]``: seconds after entry at which light ``i`` turns red (the paper's x, y). [s]
    """

    name: str
    red_starts_s: tuple[float, ...]
    red_s: float = 30.0
    green_s: float = 30.0
    amber_s: float = 0.0
    description: str = ""


def _paper_timing(x_s: float, y_s: float) -> Timing:
    return Timing(f"{x_s:g}_{y_s:g}", (x_s, y_s), description=f"paper [{x_s:g} {y_s:g}]")


TIMING_PRESETS: dict[str, Timing] = {t.name: t for t in (_paper_timing(x, y) for x in PAPER_TIMINGS_S for y in PAPER_TIMINGS_S)}
"""The paper's 16 timings ``"x_y"`` (e.g. ``"-15_15"``), plus ``"field_test"``."""

TIMING_PRESETS["field_test"] = Timing(
    "field_test",
    (-15.0, 30.0),
    description="paper Sec. 4.4 field test: light 1 turns green 15 s and light 2 turns red 30 s after entry",
)

PAPER_TIMING_NAMES = tuple(f"{x:g}_{y:g}" for x in PAPER_TIMINGS_S for y in PAPER_TIMINGS_S)


def timing_for_trip(entry_unix_s: float, period_s: float = 60.0) -> Timing:
    """One of the paper's 16 timings picked from a trip's entry time: ``floor(entry / period) mod 16``.

    Lets a fleet of test trips cover all 16 cases without configuring each one.

    Examples
    --------
    >>> timing_for_trip(0.0).name, timing_for_trip(61.0).name
    ('-30_-30', '-30_-15')
    """
    return TIMING_PRESETS[PAPER_TIMING_NAMES[int(math.floor(entry_unix_s / period_s)) % len(PAPER_TIMING_NAMES)]]


def write_presets(folder: Path) -> list[Path]:
    """Write the paper corridors as JSON into ``folder``; returns the paths."""
    folder.mkdir(parents=True, exist_ok=True)
    out = []
    for s in PAPER_SPACINGS_M:
        corridor = paper_corridor(s)
        path = folder / f"{corridor.name}.json"
        path.write_text(corridor.model_dump_json(indent=1) + "\n", encoding="utf-8")
        out.append(path)
    return out


if __name__ == "__main__":
    for written in write_presets(Path(__file__).with_name(PRESET_DIR)):
        sys.stdout.write(f"wrote {written}\n")
