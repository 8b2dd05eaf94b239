"""Read speed traces from CSV: column renaming and validation only, errors name the line."""

from __future__ import annotations

import csv
from dataclasses import dataclass
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


class TraceError(ValueError):
    """A trace file that cannot be scored; the message names the file and line."""


@dataclass(frozen=True, slots=True)
class SpeedTrace:
    t_s: np.ndarray
    speed_mps: np.ndarray
    grade_frac: np.ndarray | None
    source: str


def read_speed_trace(path: str | Path) -> SpeedTrace:
    """Read a CSV with a time column and a speed column (see COLUMN_MAP), optionally grade."""
    path = Path(path)
    try:
        handle = path.open(newline="", encoding="utf-8")
    except OSError as exc:
        raise TraceError(f"{path}: cannot open: {exc.strerror}") from None
    with handle:
        reader = csv.reader(handle)
        header = next(reader, None)
        if header is None:
            raise TraceError(f"{path}: empty file")
        cols: dict[str, tuple[int, float]] = {}
        for i, name in enumerate(h.strip().lower() for h in header):
            if name in COLUMN_MAP:
                ours, factor = COLUMN_MAP[name]
                cols.setdefault(ours, (i, factor))
        missing = [c for c in ("t_s", "speed_mps") if c not in cols]
        if missing:
            raise TraceError(f"{path}:1: missing column(s) {missing}; header was {header}")
        rows: dict[str, list[float]] = {c: [] for c in cols}
        for line_no, row in enumerate(reader, start=2):
            if not row or all(not f.strip() for f in row):
                continue
            for ours, (i, factor) in cols.items():
                try:
                    value = float(row[i]) * factor
                except (IndexError, ValueError):
                    field = row[i] if i < len(row) else "<missing>"
                    raise TraceError(f"{path}:{line_no}: {header[i]!r} is not a number: {field!r}") from None
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
