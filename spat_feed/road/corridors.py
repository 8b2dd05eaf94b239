"""Corridors: a route polyline with its signalised intersections, read from JSON; the paper's presets.

A corridor file (JSON) holds the route as a polyline of WGS 84 points with their station (distance
along the route from the zone entry, in metres), and each intersection's stop line as a station and a
lat/lon, with its approach heading and signal groups. Stations, not coordinates, are what the advisor
uses; coordinates place the route on a map and let a GPS fix be projected onto it (:meth:`Corridor.project`).

Shipped presets (``spat_feed/presets/*.json``) reproduce the paper's zone: 100 m approach, light 2
``s`` = 200/400/600/800 m after light 1, 100 m exit, laid westbound along the Avenue des
Champs-Élysées in Paris (see ``CHAMPS_ELYSEES`` and docs/SPAT.md). Regenerate them with
``python -m spat_feed.road.corridors``; a test checks the shipped files equal the generated ones.

Schema version 2 (``schema_version``; files without it are version 1 and still load) adds the corridor's
speed limits and grades per segment (``segments``, with ``speed_limit_mps`` as the default), its spoken units
(``units``: metric or imperial) and the signal plans known for it (``plans``, ``default_plan``; plan files
can also be loaded on their own, :mod:`spat_feed.timing.signal_plans`). The whole schema: docs/CORRIDORS.md, or
``ecodrive corridor schema`` (JSON Schema). Errors name the file, the field and the reason
(:class:`spat_feed.files.FileFormatError`).

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
from typing import Literal

from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator
from pyproj import Geod

from advisory.signals import PAPER_APPROACH_M, PAPER_EXIT_M, PAPER_SPACINGS_M
from advisory.physics.params import SPEED_LIMIT_MPS
from spat_feed.files import FileFormatError, read_document, validate
from spat_feed.timing.signal_plans import SignalPlan

WGS84 = Geod(ellps="WGS84")
PRESET_DIR = "presets"
SCHEMA_VERSION = 2
"""Version of the corridor schema this program writes; it reads every version up to it."""
MAX_SPEED_LIMIT_MPS = 70.0
"""Largest speed limit a file may state (252 km/h: a typo guard). [m/s]"""


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


class Segment(BaseModel):
    """A stretch ``[start_m, end_m)`` of the route with its speed limit and grade."""

    model_config = ConfigDict(extra="forbid", frozen=True)
    start_m: float = Field(ge=0)
    end_m: float = Field(gt=0)
    speed_limit_mps: float | None = Field(default=None, gt=0, le=MAX_SPEED_LIMIT_MPS, description="None: the corridor's speed_limit_mps")
    grade_frac: float = Field(default=0.0, ge=-0.3, le=0.3, description="rise over run, + uphill in the direction of travel")
    name: str = ""
    source: str = Field(default="", description="where the limit comes from (an OSM tag, a default)")

    @model_validator(mode="after")
    def _ordered(self) -> Segment:
        if not self.end_m > self.start_m:
            raise ValueError(f"end_m {self.end_m:g} must be after start_m {self.start_m:g}")
        return self


class RoadSource(BaseModel):
    """Where the route lies and where its coordinates come from."""

    model_config = ConfigDict(extra="forbid", frozen=True)
    name: str
    start: LatLon
    end: LatLon
    source: str
    note: str = ""


class Corridor(BaseModel):
    """A route from station 0 (zone entry) to ``length_m`` (zone exit) and its intersections in order.

    Each intersection's first signal group is the one the corridor's through movement follows (how a live
    SPaT source finds the light: intersection id + signal group).
    """

    model_config = ConfigDict(extra="forbid", frozen=True)
    schema_version: int = Field(default=1, ge=1, description="1: the first files (no segments, units, plans); 2: this schema")
    name: str = Field(min_length=1, max_length=100)
    description: str = ""
    road: RoadSource | None = None
    units: Literal["metric", "imperial"] = Field(default="metric", description="default units of spoken advice (km/h or mph)")
    length_m: float = Field(gt=0)
    speed_limit_mps: float | None = Field(default=None, gt=0, le=MAX_SPEED_LIMIT_MPS, description="limit where no segment says; None: the program's default")
    segments: tuple[Segment, ...] = Field(default=(), description="speed limit and grade per stretch, covering [0, length_m] in order")
    polyline: tuple[RoutePoint, ...] = Field(min_length=2)
    intersections: tuple[IntersectionSpec, ...]
    plans: tuple[SignalPlan, ...] = Field(default=(), description="signal plans known for this corridor")
    default_plan: str | None = Field(default=None, description="the plan trips use unless they name one")

    @field_validator("schema_version")
    @classmethod
    def _known_version(cls, value: int) -> int:
        if value > SCHEMA_VERSION:
            raise ValueError(f"corridor schema version {value} is newer than this program's ({SCHEMA_VERSION}); upgrade ecodrive")
        return value

    @model_validator(mode="after")
    def _consistent(self) -> Corridor:
        stations = [p.station_m for p in self.polyline]
        if stations[0] != 0.0 or any(b <= a for a, b in zip(stations, stations[1:])):
            bad = next((i for i, (a, b) in enumerate(zip(stations, stations[1:])) if b <= a), None)
            where = "polyline[0].station_m must be 0" if stations[0] != 0.0 else f"polyline[{bad + 1}].station_m {stations[bad + 1]:g} <= the one before"
            raise ValueError(f"polyline stations must start at 0 and increase: {where}")
        if abs(stations[-1] - self.length_m) > 1e-6:
            raise ValueError(f"last polyline station {stations[-1]} != length_m {self.length_m}")
        lines = [ix.stop_line_m for ix in self.intersections]
        if lines != sorted(lines) or (lines and not lines[-1] < self.length_m):
            raise ValueError("intersections must be ordered by stop line and inside the route")
        ids = [ix.id for ix in self.intersections]
        if len(set(ids)) != len(ids):
            raise ValueError("intersection ids must be unique")
        if self.segments:
            ends = [(seg.start_m, seg.end_m) for seg in self.segments]
            if ends[0][0] != 0.0 or abs(ends[-1][1] - self.length_m) > 1e-6 or any(abs(a[1] - b[0]) > 1e-6 for a, b in zip(ends, ends[1:])):
                raise ValueError("segments must cover [0, length_m] without gaps or overlaps, in order")
        names = [p.name for p in self.plans]
        if len(set(names)) != len(names):
            raise ValueError(f"plan names must be unique: {names}")
        for i, plan in enumerate(self.plans):
            try:
                plan.check(self)
            except ValueError as exc:
                raise ValueError(f"plans[{i}] ({plan.name}): {exc}") from None
        if self.default_plan is not None and self.default_plan not in names:
            raise ValueError(f"default_plan {self.default_plan!r} is not among the plans {names}")
        return self

    # -- speed limits and grades ------------------------------------------------------------------------
    @cached_property
    def _profile(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        if not self.segments:
            return np.array([0.0]), np.array([np.nan]), np.array([0.0])
        return (
            np.array([seg.start_m for seg in self.segments]),
            np.array([np.nan if seg.speed_limit_mps is None else seg.speed_limit_mps for seg in self.segments]),
            np.array([seg.grade_frac for seg in self.segments]),
        )

    def limit_profile(self, default_mps: float = SPEED_LIMIT_MPS) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(start stations, speed limits, grades) of the route's stretches, shape (n,) each; the last
        stretch runs to ``length_m``. A stretch without a limit gets ``speed_limit_mps`` or ``default_mps``."""
        starts, limits, grades = self._profile
        return starts, np.where(np.isnan(limits), self.speed_limit_mps or default_mps, limits), grades

    def speed_limit_mps_over(self, from_m: float, to_m: float, default_mps: float = SPEED_LIMIT_MPS) -> float:
        """Lowest speed limit on ``[from_m, to_m]`` (clipped to the route). [m/s]

        Examples
        --------
        >>> paper_corridor(400.0).speed_limit_mps_over(0.0, 600.0)
        24.5872
        """
        starts, limits, _ = self._profile
        lo = max(int(np.searchsorted(starts, max(from_m, 0.0), side="right")) - 1, 0)
        hi = max(int(np.searchsorted(starts, min(max(to_m, from_m), self.length_m), side="left")), lo + 1)
        fallback = self.speed_limit_mps or default_mps
        return float(min(fallback if math.isnan(x) else x for x in limits[lo:hi].tolist()))

    def zone_speed_limit_mps(self, default_mps: float = SPEED_LIMIT_MPS) -> float:
        """Lowest speed limit over the whole zone: the one the DP and the regular driver use. [m/s]"""
        return self.speed_limit_mps_over(0.0, self.length_m, default_mps)

    def advisory_limit_mps(self, station_m: float, default_mps: float = SPEED_LIMIT_MPS, n_lights: int = 2) -> float:
        """The limit for advice at ``station_m``: the lowest from there to the ``n_lights``-th stop line ahead
        (or the zone end), so an advised speed held to the lights never exceeds a limit on the way. [m/s]"""
        if not self.segments:
            return self.speed_limit_mps or default_mps
        ahead = [ix.stop_line_m for ix in self.intersections if ix.stop_line_m > station_m][:n_lights]
        return self.speed_limit_mps_over(station_m, ahead[-1] if len(ahead) == n_lights else self.length_m, default_mps)

    # -- plans ------------------------------------------------------------------------------------------
    def plan(self, name: str | None = None) -> SignalPlan | None:
        """The plan called ``name`` (``KeyError`` if unknown), or with None the default plan (or the only
        one); None when the corridor has no plans."""
        if name is None:
            if self.default_plan is not None:
                name = self.default_plan
            elif len(self.plans) == 1:
                return self.plans[0]
            else:
                return None
        for p in self.plans:
            if p.name == name:
                return p
        raise KeyError(name)

    def with_plans(self, *plans: SignalPlan, default: str | None = None) -> Corridor:
        """This corridor with ``plans`` added (same names replaced); checked against the corridor."""
        keep = tuple(p for p in self.plans if p.name not in {q.name for q in plans})
        return Corridor.model_validate({**self.model_dump(exclude={"plans"}), "plans": keep + tuple(plans),
                                        "default_plan": default if default is not None else self.default_plan})  # fmt: skip

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


def corridor_from_json(text: str, source: str = "<corridor JSON>") -> Corridor:
    """Validate a corridor JSON text (errors: :class:`FileFormatError` naming ``source`` and the field)."""
    from spat_feed.files import parse_text

    return validate(Corridor, parse_text(text, source), source)


def preset_names() -> list[str]:
    """Names of the shipped corridor presets."""
    folder = resources.files("spat_feed") / PRESET_DIR
    return sorted(p.name.removesuffix(".json") for p in folder.iterdir() if p.name.endswith(".json"))


def is_plan_document(data: dict) -> bool:
    """A parsed file is a plan file (``"kind": "signal_plan"``) rather than a corridor."""
    return data.get("kind") == "signal_plan"


def load_plan(path: str | Path) -> SignalPlan:
    """A signal-plan file (JSON or TOML) by path; errors name the file and the field."""
    data = read_document(path)
    return validate(SignalPlan, data, str(path))


def load_corridor(name_or_path: str | Path, plans: tuple[str | Path, ...] = ()) -> Corridor:
    """A shipped preset by name (``"paper_s400"``), or a corridor file (JSON or TOML) by path.

    A preset comes with the shipped plan files naming it (``presets/plans/``). ``plans``: plan files to
    attach (each checked against the corridor; errors name the file). Unknown names raise ``KeyError``;
    bad files :class:`FileFormatError` (a ``ValueError``).
    """
    path = Path(name_or_path)
    if path.suffix.lower() in (".json", ".toml") or path.exists():
        data, source = read_document(path), str(path)
        preset_plans: list[tuple[str, SignalPlan]] = []
    else:
        resource = resources.files("spat_feed") / PRESET_DIR / f"{name_or_path}.json"
        if not resource.is_file():
            raise KeyError(f"no corridor preset {name_or_path!r}; presets: {preset_names()}")
        from spat_feed.files import parse_text

        source = f"preset {name_or_path}"
        data = parse_text(resource.read_text(encoding="utf-8"), source)
        preset_plans = [(src, p) for src, p in _preset_plans() if p.corridor == name_or_path]
    if is_plan_document(data):
        raise FileFormatError(source, ["(file): this is a signal-plan file (kind: signal_plan), not a corridor; give it as the timing"])
    corridor = validate(Corridor, data, source)
    return attach_plans(corridor, preset_plans + [(str(p), load_plan(p)) for p in plans])


def _preset_plans() -> list[tuple[str, SignalPlan]]:
    """The shipped plan files (``presets/plans/*.json``) as (source, plan)."""
    from spat_feed.files import parse_text

    folder = resources.files("spat_feed") / PRESET_DIR / "plans"
    if not folder.is_dir():
        return []
    out = []
    for entry in sorted(folder.iterdir(), key=lambda e: e.name):
        if entry.name.endswith(".json"):
            source = f"preset plan {entry.name}"
            out.append((source, validate(SignalPlan, parse_text(entry.read_text(encoding="utf-8"), source), source)))
    return out


def attach_plans(corridor: Corridor, plans: list[tuple[str, SignalPlan]]) -> Corridor:
    """``corridor`` with ``plans`` (source, plan) attached; a plan that does not fit names its file."""
    for source, plan in plans:
        try:
            plan.check(corridor)
        except ValueError as exc:
            raise FileFormatError(source, [str(exc)]) from None
    return corridor.with_plans(*(p for _, p in plans)) if plans else corridor


def load_corridor_dir(folder: str | Path) -> dict[str, Corridor]:
    """Every corridor in ``folder`` (``*.json``, ``*.toml``), with the plan files there attached to the
    corridor they name (``"corridor": NAME``). Errors name the file; two corridors of one name are refused."""
    folder = Path(folder)
    if not folder.is_dir():
        raise FileFormatError(str(folder), ["not a folder"])
    corridors: dict[str, tuple[str, Corridor]] = {}
    plans: list[tuple[str, SignalPlan]] = []
    for path in sorted(p for p in folder.iterdir() if p.suffix.lower() in (".json", ".toml") and p.is_file()):
        data = read_document(path)
        if is_plan_document(data):
            plans.append((str(path), validate(SignalPlan, data, str(path))))
            continue
        corridor = validate(Corridor, data, str(path))
        if corridor.name in corridors:
            raise FileFormatError(str(path), [f"name: corridor {corridor.name!r} is also defined in {corridors[corridor.name][0]}"])
        corridors[corridor.name] = (str(path), corridor)
    out = {name: c for name, (_, c) in corridors.items()}
    for source, plan in plans:
        if plan.corridor is None or plan.corridor not in out:
            raise FileFormatError(source, [f"corridor: {plan.corridor!r} names no corridor in {folder} ({sorted(out)})"])
        out[plan.corridor] = attach_plans(out[plan.corridor], [(source, plan)])
    return out


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
    speed_limit_mps: float | None = SPEED_LIMIT_MPS,
) -> Corridor:
    """A corridor along ``road`` from its zone start, with a light at each of ``stop_lines_m``.

    Vertices every 50 m (and at each stop line) lie on the WGS 84 geodesic from ``road.a`` to
    ``road.b``. Intersection ids are ``first_id, first_id + 1, ...``; each has one signal group,
    ``signal_group`` (NEMA phase 2, main-street through, by convention). ``speed_limit_mps``: the whole
    route's limit (the paper's 55 mph by default).
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
        schema_version=SCHEMA_VERSION,
        name=name,
        description=description,
        units="metric",
        speed_limit_mps=speed_limit_mps,
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
            f"The paper's test track (Wang, Advani & Prasad, Sec. 2): 100 m approach, light 2 s = {spacing_m:g} m after light 1, "
            "100 m exit, the paper's 55 mph (88.5 km/h) limit. Drawn on the Champs-Élysées only to have coordinates: "
            "its lights and limit are the paper's, not the avenue's (50 km/h)."
        ),
    )


PAPER_CORRIDOR_NAMES = tuple(f"paper_s{s:g}" for s in PAPER_SPACINGS_M)


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
    for written in write_presets(Path(__file__).resolve().parents[1] / PRESET_DIR):
        sys.stdout.write(f"wrote {written}\n")
