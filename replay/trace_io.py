"""Read recorded drives: speed CSVs, GPS CSVs and GPX files. Column renaming and validation only.

Every error names the file and line. Two kinds of trace:

* **speed trace** (``SpeedTrace``): a time column and a speed column (``COLUMN_MAP``), optionally grade.
  Times must increase strictly (a bad row is an error).
* **GPS trace** (``GpsTrace``): time, latitude and longitude (``GPS_COLUMN_MAP``), optionally speed over
  ground, horizontal accuracy and heading. Recorded fixes are messy, so a duplicate timestamp or a time
  that goes backwards drops that fix, and gaps are kept; each is reported in ``GpsTrace.notes``.
  Comment lines before the header (``# corridor: paper_s400``, ``# timing: field_test``,
  ``# entry_unix_s: 1700000000``) say which corridor and signal timing the drive went through
  (``GpsTrace.meta``). A GPX file (``.gpx``, read with gpxpy) gives the same: track points with time,
  position and ``<speed>`` when present; ``key: value`` lines in its metadata or track description.
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

# Accepted header -> (our column, factor to SI).
COLUMN_MAP: dict[str, tuple[str, float]] = {
    "t_s": ("t_s", 1.0),
    "time_s": ("t_s", 1.0),
    "time": ("t_s", 1.0),
    "t": ("t_s", 1.0),
    "speed_mps": ("speed_mps", 1.0),
    "speed": ("speed_mps", 1.0),
    "speed_kmh": ("speed_mps", 1 / 3.6),
    "speed_mph": ("speed_mps", 0.44704),
    "grade_frac": ("grade_frac", 1.0),
    "grade": ("grade_frac", 1.0),
    "grade_pct": ("grade_frac", 0.01),
}

GPS_COLUMN_MAP: dict[str, tuple[str, float]] = {
    "t_unix_s": ("t_s", 1.0),
    "t_s": ("t_s", 1.0),
    "time_s": ("t_s", 1.0),
    "time": ("t_s", 1.0),
    "timestamp": ("t_s", 1.0),
    "t": ("t_s", 1.0),
    "lat_deg": ("lat_deg", 1.0),
    "lat": ("lat_deg", 1.0),
    "latitude": ("lat_deg", 1.0),
    "lon_deg": ("lon_deg", 1.0),
    "lon": ("lon_deg", 1.0),
    "lng": ("lon_deg", 1.0),
    "long": ("lon_deg", 1.0),
    "longitude": ("lon_deg", 1.0),
    "speed_mps": ("speed_mps", 1.0),
    "speed": ("speed_mps", 1.0),
    "speed_kmh": ("speed_mps", 1 / 3.6),
    "speed_mph": ("speed_mps", 0.44704),
    "accuracy_m": ("accuracy_m", 1.0),
    "accuracy": ("accuracy_m", 1.0),
    "hdop_m": ("accuracy_m", 1.0),
    "heading_deg": ("heading_deg", 1.0),
    "heading": ("heading_deg", 1.0),
    "course": ("heading_deg", 1.0),
}
"""GPS CSV header -> (our column, factor to SI). Time: Unix seconds, any seconds, or ISO 8601."""

META_KEYS = ("corridor", "timing", "entry_unix_s", "vehicle", "note")
"""Keys read from ``# key: value`` comment lines (others are kept too, but not used)."""

GAP_S = 2.5
"""A step longer than this between accepted fixes is reported as a gap (scored by interpolation). [s]"""


class TraceError(ValueError):
    """A trace file that cannot be scored; the message names the file and line."""


@dataclass(frozen=True, slots=True)
class SpeedTrace:
    t_s: np.ndarray
    speed_mps: np.ndarray
    grade_frac: np.ndarray | None
    source: str


@dataclass(frozen=True, slots=True)
class GpsTrace:
    """Accepted fixes in time order, shape (n,). ``speed_mps``: NaN where the fix had none."""

    t_s: np.ndarray
    lat_deg: np.ndarray
    lon_deg: np.ndarray
    speed_mps: np.ndarray
    accuracy_m: np.ndarray
    lines: np.ndarray  # the file line of each accepted fix (GPX: the point's index from 1)
    source: str
    meta: dict[str, str] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)

    @property
    def has_speed(self) -> bool:
        return bool(np.isfinite(self.speed_mps).any())


def read_trace(path: str | Path) -> SpeedTrace | GpsTrace:
    """A GPX file, a GPS CSV (has latitude and longitude columns) or a speed CSV."""
    path = Path(path)
    if path.suffix.lower() == ".gpx":
        return read_gpx(path)
    meta, header, _ = _csv_head(path)
    names = {h.strip().lower() for h in header}
    if names & {"lat", "lat_deg", "latitude"} and names & {"lon", "lon_deg", "lng", "long", "longitude"}:
        return read_gps_csv(path)
    return read_speed_trace(path)


def _open(path: Path):
    try:
        return path.open(newline="", encoding="utf-8")
    except OSError as exc:
        raise TraceError(f"{path}: cannot open: {exc.strerror}") from None


def parse_meta_line(text: str) -> tuple[str, str] | None:
    """``"corridor: paper_s400"`` -> ``("corridor", "paper_s400")``; None if not ``key: value``."""
    key, sep, value = text.partition(":")
    key = key.strip().lower().replace(" ", "_").replace("-", "_")
    if not sep or not key.replace("_", "").isalnum():
        return None
    return key, value.strip()


def _csv_head(path: Path) -> tuple[dict[str, str], list[str], int]:
    """(meta from leading ``#`` lines, header fields, header line number)."""
    meta: dict[str, str] = {}
    with _open(path) as handle:
        for line_no, line in enumerate(handle, start=1):
            stripped = line.strip()
            if not stripped:
                continue
            if stripped.startswith("#"):
                kv = parse_meta_line(stripped.lstrip("#"))
                if kv:
                    meta.setdefault(*kv)
                continue
            return meta, next(csv.reader([line])), line_no
    raise TraceError(f"{path}: empty file")


def _data_rows(path: Path, header_line: int):
    """(line number, fields) of the rows after the header, skipping blank and ``#`` lines."""
    with _open(path) as handle:
        for line_no, line in enumerate(handle, start=1):
            if line_no <= header_line:
                continue
            stripped = line.strip()
            if not stripped or stripped.startswith("#"):
                continue
            row = next(csv.reader([line]))
            if all(not f.strip() for f in row):
                continue
            yield line_no, row


def read_speed_trace(path: str | Path) -> SpeedTrace:
    """Read a CSV with a time column and a speed column (see COLUMN_MAP), optionally grade."""
    path = Path(path)
    _, header, header_line = _csv_head(path)
    cols: dict[str, tuple[int, float]] = {}
    for i, name in enumerate(h.strip().lower() for h in header):
        if name in COLUMN_MAP:
            ours, factor = COLUMN_MAP[name]
            cols.setdefault(ours, (i, factor))
    missing = [c for c in ("t_s", "speed_mps") if c not in cols]
    if missing:
        raise TraceError(f"{path}:{header_line}: missing column(s) {missing}; header was {header}")
    rows: dict[str, list[float]] = {c: [] for c in cols}
    for line_no, row in _data_rows(path, header_line):
        for ours, (i, factor) in cols.items():
            try:
                value = float(row[i]) * factor
            except (IndexError, ValueError):
                field_text = row[i] if i < len(row) else "<missing>"
                raise TraceError(f"{path}:{line_no}: {header[i]!r} is not a number: {field_text!r}") from None
            if not np.isfinite(value):
                raise TraceError(f"{path}:{line_no}: {header[i]!r} is not finite: {row[i]!r}")
            rows[ours].append(value)
        if rows["speed_mps"][-1] < 0:
            raise TraceError(f"{path}:{line_no}: negative speed {rows['speed_mps'][-1]}")
        if len(rows["t_s"]) > 1 and rows["t_s"][-1] <= rows["t_s"][-2]:
            raise TraceError(f"{path}:{line_no}: time {rows['t_s'][-1]} does not increase")
    if len(rows["t_s"]) < 2:
        raise TraceError(f"{path}: needs at least two data rows")
    grade = np.array(rows["grade_frac"]) if "grade_frac" in rows else None
    return SpeedTrace(np.array(rows["t_s"]), np.array(rows["speed_mps"]), grade, str(path))


def parse_time_s(text: str) -> float:
    """Seconds from a number (Unix or any origin) or an ISO 8601 instant (naive = UTC).

    Examples
    --------
    >>> parse_time_s("12.5"), parse_time_s("1970-01-01T00:01:00Z")
    (12.5, 60.0)
    """
    text = text.strip()
    try:
        return float(text)
    except ValueError:
        pass
    stamp = datetime.fromisoformat(text.replace("Z", "+00:00").replace("z", "+00:00"))
    if stamp.tzinfo is None:
        stamp = stamp.replace(tzinfo=timezone.utc)
    return stamp.timestamp()


_LIMITS = {"lat_deg": (-90.0, 90.0), "lon_deg": (-180.0, 180.0), "speed_mps": (0.0, 70.0), "accuracy_m": (0.0, 1e5), "heading_deg": (0.0, 360.0)}


def read_gps_csv(path: str | Path) -> GpsTrace:
    """Read a CSV of GPS fixes (see ``GPS_COLUMN_MAP``); comment lines before the header give ``meta``."""
    path = Path(path)
    meta, header, header_line = _csv_head(path)
    cols: dict[str, tuple[int, float]] = {}
    for i, name in enumerate(h.strip().lower() for h in header):
        if name in GPS_COLUMN_MAP:
            ours, factor = GPS_COLUMN_MAP[name]
            cols.setdefault(ours, (i, factor))
    missing = [c for c in ("t_s", "lat_deg", "lon_deg") if c not in cols]
    if missing:
        raise TraceError(f"{path}:{header_line}: missing column(s) {missing}; header was {header}")
    records: list[tuple[int, dict[str, float]]] = []
    for line_no, row in _data_rows(path, header_line):
        rec: dict[str, float] = {}
        for ours, (i, factor) in cols.items():
            text = row[i].strip() if i < len(row) else ""
            if text == "" and ours not in ("t_s", "lat_deg", "lon_deg"):
                rec[ours] = math.nan  # optional column left empty: unknown
                continue
            try:
                value = parse_time_s(text) if ours == "t_s" else float(text) * factor
            except ValueError:
                raise TraceError(f"{path}:{line_no}: {header[i]!r} is not a {'time' if ours == 't_s' else 'number'}: {text or '<missing>'!r}") from None
            if not math.isfinite(value):
                raise TraceError(f"{path}:{line_no}: {header[i]!r} is not finite: {text!r}")
            lo, hi = _LIMITS.get(ours, (-math.inf, math.inf))
            if not lo <= value <= hi:
                raise TraceError(f"{path}:{line_no}: {header[i]!r} = {text} is outside [{lo:g}, {hi:g}]")
            rec[ours] = value
        records.append((line_no, rec))
    return _gps_trace(records, str(path), meta)


def read_gpx(path: str | Path) -> GpsTrace:
    """Read the track points of a GPX file (all tracks and segments, in order) with gpxpy."""
    import gpxpy
    import gpxpy.gpx

    path = Path(path)
    with _open(path) as handle:
        try:
            gpx = gpxpy.parse(handle)
        except gpxpy.gpx.GPXException as exc:
            raise TraceError(f"{path}: not a valid GPX file: {exc}") from None
    meta: dict[str, str] = {}
    for text in [gpx.description, *(trk.description for trk in gpx.tracks), *(trk.comment for trk in gpx.tracks)]:
        for line in (text or "").splitlines():
            kv = parse_meta_line(line.lstrip("#"))
            if kv:
                meta.setdefault(*kv)
    records: list[tuple[int, dict[str, float]]] = []
    n = 0
    for trk in gpx.tracks:
        for seg in trk.segments:
            for pt in seg.points:
                n += 1
                if pt.time is None:
                    raise TraceError(f"{path}: track point {n} has no <time>")
                when = pt.time if pt.time.tzinfo else pt.time.replace(tzinfo=timezone.utc)
                speed = math.nan if pt.speed is None else float(pt.speed)
                if speed < 0 or speed > 70:
                    raise TraceError(f"{path}: track point {n}: speed {speed} outside [0, 70] m/s")
                acc = math.nan if pt.horizontal_dilution is None else float(pt.horizontal_dilution) * 5.0  # HDOP x ~5 m UERE
                records.append((n, {"t_s": when.timestamp(), "lat_deg": pt.latitude, "lon_deg": pt.longitude, "speed_mps": speed, "accuracy_m": acc}))
    return _gps_trace(records, str(path), meta)


def _gps_trace(records: list[tuple[int, dict[str, float]]], source: str, meta: dict[str, str]) -> GpsTrace:
    """Order checks (drop duplicates / backward times, report them and the gaps) and arrays."""
    notes: list[str] = []
    dup_lines: list[int] = []
    back_lines: list[int] = []
    kept: list[tuple[int, dict[str, float]]] = []
    for line_no, rec in records:
        if kept and rec["t_s"] <= kept[-1][1]["t_s"]:
            (dup_lines if rec["t_s"] == kept[-1][1]["t_s"] else back_lines).append(line_no)
            continue
        kept.append((line_no, rec))
    if dup_lines:
        notes.append(f"{len(dup_lines)} fix(es) with a duplicate timestamp dropped (line(s) {_lines(dup_lines)})")
    if back_lines:
        notes.append(f"{len(back_lines)} fix(es) older than the fix before dropped (line(s) {_lines(back_lines)})")
    if len(kept) < 2:
        raise TraceError(f"{source}: needs at least two fixes with increasing times (got {len(kept)})")
    t = np.array([r["t_s"] for _, r in kept])
    lines = np.array([n for n, _ in kept])
    steps = np.diff(t)
    gaps = np.flatnonzero(steps > GAP_S)
    if gaps.size:
        desc = ", ".join(f"{steps[k]:.1f} s before line {lines[k + 1]}" for k in gaps[:5])
        more = f" and {gaps.size - 5} more" if gaps.size > 5 else ""
        notes.append(f"{gaps.size} gap(s) longer than {GAP_S:g} s ({desc}{more}): speed interpolated linearly across them")

    def col(name: str) -> np.ndarray:
        return np.array([r.get(name, math.nan) for _, r in kept])

    return GpsTrace(t, col("lat_deg"), col("lon_deg"), col("speed_mps"), col("accuracy_m"), lines, source, meta, notes)


def _lines(nums: list[int], show: int = 8) -> str:
    head = ", ".join(str(n) for n in nums[:show])
    return head + (f", ... ({len(nums)} in all)" if len(nums) > show else "")
