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
  position and the speed from GPX 1.0 ``<speed>`` or a GPX 1.1 extension (OsmAnd ``osmand:speed``,
  GPSLogger ``<speed>``, Garmin TrackPointExtension ``gpxtpx:speed``); ``key: value`` lines in its
  metadata or track description.

Real phone exports differ in their details, and each is detected and reported (``GpsTrace.columns``):

* **delimiter and decimal mark**: ``,``, ``;``, tab or ``|``, sniffed from the header and first rows; a
  ``;``/tab file whose numbers use a decimal comma (European spreadsheets) is read as such;
* **headers**: case, spaces and units in brackets are normalised (``Speed (km/h)`` -> ``speed_kmh``), and
  common names are aliases (``latitude``/``lat``, ``longitude``/``lon``/``lng``, ``bearing``/``course``/
  ``heading``, ``accuracy``/``horizontal_accuracy``, ``timestamp``/``time``/``date_time``);
* **time**: ISO 8601, or a number whose magnitude says its unit: Unix seconds, milliseconds (Android's
  ``Location.getTime()``, JavaScript), microseconds or nanoseconds (``timestamp_ms``-style names force
  the unit); a small number is seconds from any origin.
"""

from __future__ import annotations

import csv
import math
import re
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
    **{name: ("t_s", 1.0) for name in ("t_unix_s", "t_s", "time_s", "time", "timestamp", "date_time", "datetime", "utc_time", "t")},
    **{name: ("t_s", 1.0) for name in ("epoch", "epoch_s", "unix_time", "unix_time_s")},
    **{name: ("t_s", 1e-3) for name in ("timestamp_ms", "time_ms", "t_ms", "t_unix_ms", "epoch_ms")},
    **{name: ("t_s", 1e-6) for name in ("timestamp_us", "time_us", "epoch_us")},
    **{name: ("t_s", 1e-9) for name in ("timestamp_ns", "time_ns", "epoch_ns")},
    **{name: ("lat_deg", 1.0) for name in ("lat_deg", "lat", "latitude", "latitude_deg")},
    **{name: ("lon_deg", 1.0) for name in ("lon_deg", "lon", "lng", "long", "longitude", "longitude_deg")},
    "speed_mps": ("speed_mps", 1.0),
    "speed": ("speed_mps", 1.0),
    "speed_kmh": ("speed_mps", 1 / 3.6),
    "speed_kph": ("speed_mps", 1 / 3.6),
    "speed_mph": ("speed_mps", 0.44704),
    **{name: ("accuracy_m", 1.0) for name in ("accuracy_m", "accuracy", "horizontal_accuracy", "horizontalaccuracy", "hacc", "hdop_m")},
    **{name: ("heading_deg", 1.0) for name in ("heading_deg", "heading", "course", "course_deg", "bearing", "bearing_deg")},
}
"""GPS CSV header (normalised, see :func:`normalise_header`) -> (our column, factor to SI). The first match of
each of ours wins, in header order. Time: ISO 8601 or Unix s / ms / µs / ns by magnitude (``*_ms`` names: ms)."""
LAT_NAMES = {k for k, (ours, _) in GPS_COLUMN_MAP.items() if ours == "lat_deg"}
LON_NAMES = {k for k, (ours, _) in GPS_COLUMN_MAP.items() if ours == "lon_deg"}

EPOCH_UNITS = ((1e17, 1e-9, "Unix nanoseconds"), (1e14, 1e-6, "Unix microseconds"), (1e11, 1e-3, "Unix milliseconds"), (1e8, 1.0, "Unix seconds"))
"""Numeric times by magnitude: at least this -> (factor to seconds, name). 1e8 s is 1973; 1e11 ms is 1973 too,
while 1e11 s would be the year 5138. Smaller numbers are seconds from any origin (a relative clock)."""

_UNIT_SUFFIX = {"km/h": "kmh", "kmh": "kmh", "kph": "kmh", "m/s": "mps", "mps": "mps", "mph": "mph", "deg": "deg", "°": "deg",
                "m": "m", "s": "s", "ms": "ms"}  # fmt: skip


def normalise_header(name: str) -> str:
    """A header as a key of the column maps: lower case, units in brackets as a suffix, spaces as ``_``.

    Examples
    --------
    >>> normalise_header(" Speed (km/h) "), normalise_header("horizontalAccuracy"), normalise_header("Bearing [deg]")
    ('speed_kmh', 'horizontalaccuracy', 'bearing')
    """
    text = name.strip().strip('"').strip().lower()
    unit = ""
    match = re.search(r"[\(\[]\s*([^\)\]]*?)\s*[\)\]]\s*$", text)
    if match:
        unit = _UNIT_SUFFIX.get(match.group(1), "")
        text = text[: match.start()]
    text = re.sub(r"[\s\-./]+", "_", text.strip()).strip("_")
    if unit in ("kmh", "mps", "mph", "ms"):
        return f"{text}_{unit}"
    return text

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
    columns: dict[str, str] = field(default_factory=dict)  # ours -> where it was read from and how (reported)

    @property
    def has_speed(self) -> bool:
        return bool(np.isfinite(self.speed_mps).any())


def read_trace(path: str | Path) -> SpeedTrace | GpsTrace:
    """A GPX file, a GPS CSV (has latitude and longitude columns) or a speed CSV."""
    path = Path(path)
    if path.suffix.lower() == ".gpx":
        return read_gpx(path)
    head = _csv_head(path)
    names = {normalise_header(h) for h in head.header}
    if names & LAT_NAMES and names & LON_NAMES:
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


@dataclass(frozen=True, slots=True)
class CsvHead:
    """What the top of a CSV says: ``# key: value`` lines, the header, its line, the dialect found."""

    meta: dict[str, str]
    header: list[str]
    line: int
    delimiter: str
    decimal_comma: bool

    @property
    def dialect(self) -> str:
        name = {",": "comma", ";": "semicolon", "\t": "tab", "|": "pipe"}[self.delimiter]
        return f"{name}-separated" + (", decimal comma" if self.decimal_comma else "")


DELIMITERS = (",", ";", "\t", "|")
_DECIMAL_COMMA = re.compile(r"^\s*[-+]?\d+,\d+\s*$")


def _csv_head(path: Path) -> CsvHead:
    """Meta lines, header and dialect: the delimiter giving the same number (> 1) of fields on the header and
    the first data rows; a decimal comma when fields look like ``12,5`` in a file not separated by commas."""
    meta: dict[str, str] = {}
    header_line, lines = 0, []
    with _open(path) as handle:
        for line_no, line in enumerate(handle, start=1):
            stripped = line.strip()
            if not stripped:
                continue
            if stripped.startswith("#") and not header_line:
                kv = parse_meta_line(stripped.lstrip("#"))
                if kv:
                    meta.setdefault(*kv)
                continue
            header_line = header_line or line_no
            lines.append(line)
            if len(lines) >= 12:
                break
    if not lines:
        raise TraceError(f"{path}: empty file")

    def fields(delim: str) -> list[int]:
        return [len(next(csv.reader([ln], delimiter=delim))) for ln in lines if not ln.lstrip().startswith("#")]

    best = max(DELIMITERS, key=lambda d: (len(set(fields(d))) == 1 and fields(d)[0] > 1, min(fields(d))))
    header = next(csv.reader([lines[0]], delimiter=best))
    rows = [next(csv.reader([ln], delimiter=best)) for ln in lines[1:]]
    decimal_comma = best != "," and any(_DECIMAL_COMMA.match(f) for row in rows for f in row)
    return CsvHead(meta, header, header_line, best, decimal_comma)


def _data_rows(path: Path, head: CsvHead):
    """(line number, fields) of the rows after the header, skipping blank and ``#`` lines."""
    with _open(path) as handle:
        for line_no, line in enumerate(handle, start=1):
            if line_no <= head.line:
                continue
            stripped = line.strip()
            if not stripped or stripped.startswith("#"):
                continue
            row = next(csv.reader([line], delimiter=head.delimiter))
            if all(not f.strip() for f in row):
                continue
            if head.decimal_comma:
                row = [f.replace(",", ".") if _DECIMAL_COMMA.match(f) else f for f in row]
            yield line_no, row


def _missing(path: Path, head: CsvHead, missing: list[str], accepted: dict[str, tuple[str, float]]) -> TraceError:
    names = {ours: sorted(k for k, (o, _) in accepted.items() if o == ours) for ours in missing}
    want = "; ".join(f"{ours}: one of {', '.join(v)}" for ours, v in names.items())
    return TraceError(f"{path}:{head.line}: missing column(s) {missing}; header was {head.header} (read as {head.dialect}). "
                      f"Rename the header to an accepted name ({want})")  # fmt: skip


def read_speed_trace(path: str | Path) -> SpeedTrace:
    """Read a CSV with a time column and a speed column (see COLUMN_MAP), optionally grade."""
    path = Path(path)
    head = _csv_head(path)
    header = head.header
    cols: dict[str, tuple[int, float]] = {}
    for i, name in enumerate(normalise_header(h) for h in header):
        if name in COLUMN_MAP:
            ours, factor = COLUMN_MAP[name]
            cols.setdefault(ours, (i, factor))
    missing = [c for c in ("t_s", "speed_mps") if c not in cols]
    if missing:
        raise _missing(path, head, missing, COLUMN_MAP)
    rows: dict[str, list[float]] = {c: [] for c in cols}
    for line_no, row in _data_rows(path, head):
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


def time_unit(values: list[str], header: str) -> tuple[float | None, str]:
    """(factor to seconds, description) of a time column from its first values; factor None: ISO 8601.

    Examples
    --------
    >>> time_unit(["1714557592789"], "timestamp"), time_unit(["2024-05-01T09:59:52Z"], "time")[1]
    ((0.001, 'Unix milliseconds'), 'ISO 8601')
    """
    name = normalise_header(header)
    try:
        first = float(values[0])
    except ValueError:
        return None, "ISO 8601"
    except IndexError:
        return 1.0, "seconds"
    by_name = GPS_COLUMN_MAP.get(name, ("", 1.0))[1]
    if by_name != 1.0:
        return by_name, next(what for _, f, what in EPOCH_UNITS if f == by_name) + " (by its name)"
    for threshold, factor, what in EPOCH_UNITS:
        if abs(first) >= threshold:
            return factor, what
    return 1.0, "seconds from any origin (not Unix time)"


def read_gps_csv(path: str | Path) -> GpsTrace:
    """Read a CSV of GPS fixes (see ``GPS_COLUMN_MAP``); comment lines before the header give ``meta``."""
    path = Path(path)
    head = _csv_head(path)
    header, header_line = head.header, head.line
    cols: dict[str, tuple[int, float]] = {}
    for i, name in enumerate(normalise_header(h) for h in header):
        if name in GPS_COLUMN_MAP:
            ours, factor = GPS_COLUMN_MAP[name]
            cols.setdefault(ours, (i, factor))
    missing = [c for c in ("t_s", "lat_deg", "lon_deg") if c not in cols]
    if missing:
        raise _missing(path, head, missing, GPS_COLUMN_MAP)
    rows = list(_data_rows(path, head))
    ti = cols["t_s"][0]
    t_factor, t_what = time_unit([r[ti].strip() for _, r in rows[:1] if ti < len(r)], header[ti])
    magnitude = next((th for th, _, what in EPOCH_UNITS if t_what == what), None)
    units = {"speed_mps": "m/s", "accuracy_m": "m", "heading_deg": "deg", "lat_deg": "deg", "lon_deg": "deg"}
    columns = {ours: f"{header[i].strip()!r} ({t_what})" if ours == "t_s" else
               f"{header[i].strip()!r}" + (f" x {factor:.6g} -> {units[ours]}" if factor != 1.0 else f" [{units[ours]}]")
               for ours, (i, factor) in cols.items()}  # fmt: skip
    columns["file"] = head.dialect
    records: list[tuple[int, dict[str, float]]] = []
    for line_no, row in rows:
        rec: dict[str, float] = {}
        for ours, (i, factor) in cols.items():
            text = row[i].strip() if i < len(row) else ""
            if text == "" and ours not in ("t_s", "lat_deg", "lon_deg"):
                rec[ours] = math.nan  # optional column left empty: unknown
                continue
            try:
                if ours == "t_s":
                    value = parse_time_s(text) if t_factor is None else float(text) * t_factor
                else:
                    value = float(text) * factor
            except ValueError:
                hint = " (numbers with a decimal comma need a ';' or tab separator)" if "," in text and head.delimiter == "," else ""
                raise TraceError(f"{path}:{line_no}: {header[i]!r} is not a {'time' if ours == 't_s' else 'number'}: {text or '<missing>'!r}{hint}") from None
            if not math.isfinite(value):
                raise TraceError(f"{path}:{line_no}: {header[i]!r} is not finite: {text!r}")
            if ours == "t_s" and magnitude is not None and not magnitude <= abs(float(text)) < magnitude * 1000:
                raise TraceError(f"{path}:{line_no}: {header[i]!r} = {text} is not in {t_what} like the first row: use one unit for the whole column")
            lo, hi = _LIMITS.get(ours, (-math.inf, math.inf))
            if not lo <= value <= hi:
                raise TraceError(f"{path}:{line_no}: {header[i]!r} = {text} is outside [{lo:g}, {hi:g}]" + (
                    " (is it in km/h? name the column speed_kmh)" if ours == "speed_mps" and factor == 1.0 and value > hi else ""))  # fmt: skip
            rec[ours] = value
        records.append((line_no, rec))
    return _gps_trace(records, str(path), head.meta, columns)


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
    speed_from: set[str] = set()
    n = 0
    for trk in gpx.tracks:
        for seg in trk.segments:
            for pt in seg.points:
                n += 1
                if pt.time is None:
                    raise TraceError(f"{path}: track point {n} has no <time>")
                when = pt.time if pt.time.tzinfo else pt.time.replace(tzinfo=timezone.utc)
                speed, where = (math.nan, "") if pt.speed is None else (float(pt.speed), "GPX 1.0 <speed>")
                heading = math.nan if pt.course is None else float(pt.course)
                if where == "":
                    speed, where, ext_heading = _extension_speed(pt.extensions)
                    heading = heading if math.isfinite(heading) else ext_heading
                if where:
                    speed_from.add(where)
                if speed < 0 or speed > 70:
                    raise TraceError(f"{path}: track point {n}: speed {speed} outside [0, 70] m/s ({where})")
                acc = math.nan if pt.horizontal_dilution is None else float(pt.horizontal_dilution) * 5.0  # HDOP x ~5 m UERE
                records.append((n, {"t_s": when.timestamp(), "lat_deg": pt.latitude, "lon_deg": pt.longitude, "speed_mps": speed, "accuracy_m": acc}))
    columns = {"t_s": "<time> (ISO 8601)", "lat_deg": "lat attribute [deg]", "lon_deg": "lon attribute [deg]", "file": f"GPX {gpx.version or '?'}"}
    if speed_from:
        columns["speed_mps"] = " and ".join(sorted(speed_from)) + " [m/s]"
    return _gps_trace(records, str(path), meta, columns)


SPEED_TAGS = ("speed",)
HEADING_TAGS = ("course", "heading", "bearing")


def _extension_speed(extensions) -> tuple[float, str, float]:
    """(speed [m/s], where it was found, heading [deg]) from a GPX 1.1 track point's ``<extensions>``.

    By local name, whatever the namespace: OsmAnd's ``<osmand:speed>`` (and ``osmand:heading``), GPSLogger's
    ``<speed>``, and Garmin's ``<gpxtpx:TrackPointExtension>`` (v2) with ``<gpxtpx:speed>`` and
    ``<gpxtpx:course>``: all three formats document the speed in metres per second.
    """
    speed, where, heading = math.nan, "", math.nan
    for element in extensions or ():
        for child in [element, *list(element)]:
            tag = str(child.tag)
            ns, local = (tag[1:].split("}", 1) if tag.startswith("{") else ("", tag))
            local = local.split(":")[-1].lower()
            text = (child.text or "").strip()
            if not text:
                continue
            prefix = "osmand" if "osmand" in ns else "gpxtpx" if "TrackPointExtension" in ns else ""
            try:
                value = float(text)
            except ValueError:
                continue
            if local in SPEED_TAGS and not where:
                speed, where = value, f"GPX extension <{prefix + ':' if prefix else ''}speed>"
            elif local in HEADING_TAGS and math.isnan(heading):
                heading = value
    return speed, where, heading


def _gps_trace(records: list[tuple[int, dict[str, float]]], source: str, meta: dict[str, str], columns: dict[str, str] | None = None) -> GpsTrace:
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

    return GpsTrace(t, col("lat_deg"), col("lon_deg"), col("speed_mps"), col("accuracy_m"), lines, source, meta, notes, dict(columns or {}))


def _lines(nums: list[int], show: int = 8) -> str:
    head = ", ".join(str(n) for n in nums[:show])
    return head + (f", ... ({len(nums)} in all)" if len(nums) > show else "")
