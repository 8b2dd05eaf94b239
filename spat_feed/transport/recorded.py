"""Recorded SPaT logs: the flattened Open Traffic Lights CSV format, read into our J2735-aligned schema.

The CSV format (``../shared/data/spat/README.md``) has one row per (snapshot, signal group)::

    generated_utc,intersection,signal_group,phase,min_end_utc,max_end_utc
    2019-05-01T16:04:25.609Z,K648,1,6,2019-05-01T16:04:38.009Z,2019-05-01T16:07:13.009Z

``phase`` is the J2735 MovementPhaseState *number*; ``min_end_utc`` / ``max_end_utc`` are the current
phase's ``minEndTime`` / ``maxEndTime``. Only the current phase is published (no next events, no
``likelyTime``, no ``confidence``). :func:`read_spat_csv` returns one :class:`IntersectionState` per
(snapshot, intersection), in time order, each signal group with one event carrying exactly what the row
says: reading is lossless; what the values *mean* (a ``maxEndTime`` about an hour ahead is unknown, a
missing confidence is not a low one) is decided where plans are made (:func:`spat_feed.timing.messages.plan_from_movement`).

Intersection ids: J2735 ids are integers, the log names controllers (``K648``). By default the id is the
name's digits (``K648`` -> 648); pass ``intersection_ids`` to choose others. The name is kept in ``name``.
"""

from __future__ import annotations

import csv
import gzip
import io
import logging
import re
from collections.abc import Callable, Iterable, Iterator, Mapping
from datetime import datetime
from pathlib import Path

from pydantic import ValidationError

from spat_feed.timing.messages import IntersectionState, MovementState, _short
from spat_feed.timing.plans import J2735_STATE_NUMBERS

CSV_COLUMNS = ("generated_utc", "intersection", "signal_group", "phase", "min_end_utc", "max_end_utc")


class RecordedLogError(ValueError):
    """A log that cannot be read; the message names the file and the line."""


MAX_LINE_CHARS = 256 * 1024
"""A log line longer than this (``spat_feed.transport.store.MAX_SPAT_BYTES``) is skipped unread, never parsed."""


def bounded_lines(fh: io.TextIOBase, source: str, too_large: Callable[[str], None] | None = None, limit: int = MAX_LINE_CHARS) -> Iterator[str]:
    """The lines of ``fh``; one over ``limit`` characters is read in pieces and dropped (``"\\n"`` in its place, so that
    line numbers hold), ``too_large`` called with where it was (default: a WARNING)."""
    line_no = 0
    while line := fh.readline(limit + 1):
        line_no += 1
        if len(line.rstrip("\r\n")) <= limit:
            yield line
            continue
        while not line.endswith("\n") and (line := fh.readline(65536)):
            pass  # the rest of it, piece by piece
        where = f"{source}, line {line_no}: over {limit} characters, skipped"
        (too_large or logging.getLogger("spat_feed.transport.recorded").warning)(where)
        yield "\n"


def default_intersection_id(name: str) -> int:
    """A J2735 intersection id from a controller name: its digits (``"K648"`` -> 648).

    Examples
    --------
    >>> default_intersection_id("K648")
    648
    """
    digits = re.sub(r"\D", "", name)
    if not digits or not 0 <= int(digits) <= 65_535:
        raise ValueError(f"cannot make a J2735 intersection id (0..65535) from {name!r}; pass intersection_ids")
    return int(digits)


def _open_text(path: Path) -> io.TextIOBase:
    if path.suffix == ".gz":
        return gzip.open(path, "rt", encoding="utf-8", newline="")
    return path.open("r", encoding="utf-8", newline="")


def _utc(text: str) -> datetime:
    value = datetime.fromisoformat(text.strip().replace("Z", "+00:00"))
    if value.tzinfo is None:
        raise ValueError(f"time {text!r} has no zone (expected UTC, ending in Z)")
    return value


def iter_spat_csv(rows: Iterable[Mapping[str, str]], intersection_ids: Mapping[str, int] | None = None, source: str = "<csv>") -> Iterator[IntersectionState]:
    """Group CSV rows (dicts with :data:`CSV_COLUMNS`) into intersection snapshots, in file order.

    Rows of one snapshot (same ``generated_utc`` and ``intersection``) must be consecutive, as in the
    shared recordings. Raises :class:`RecordedLogError` naming ``source`` and the line on a bad row.
    """
    return _snapshots(([row.get(c) for c in CSV_COLUMNS] for row in rows), intersection_ids, source)


def _snapshots(rows: Iterable[list], intersection_ids: Mapping[str, int] | None, source: str) -> Iterator[IntersectionState]:
    """Rows as lists in :data:`CSV_COLUMNS` order -> snapshots, each validated in one call (a recorded day is
    ~10^5 rows); a bad row is found again row by row so that the error names its line."""
    key = None
    lines: list[tuple[int, list[str]]] = []
    for line_no, row in enumerate(rows, start=2):
        values = [(v or "").strip() for v in row]
        missing = [c for c, v in zip(CSV_COLUMNS, values) if not v] + list(CSV_COLUMNS[len(values) :])
        if missing:
            raise RecordedLogError(f"{source}, line {line_no}: missing {', '.join(missing)}")
        if (values[0], values[1]) != key:
            if key is not None:
                yield _snapshot(lines, intersection_ids, source)
            key, lines = (values[0], values[1]), []
        lines.append((line_no, values))
    if key is not None:
        yield _snapshot(lines, intersection_ids, source)


def _movement(values: list[str]) -> dict:
    number = int(values[3])
    if not 0 <= number < len(J2735_STATE_NUMBERS):
        raise ValueError(f"phase {number} is not a J2735 MovementPhaseState number (0..9)")
    timing = {"min_end_time": values[4], "max_end_time": values[5]}
    return {"signal_group": int(values[2]), "state_time_speed": [{"event_state": J2735_STATE_NUMBERS[number], "timing": timing}]}


def _snapshot(lines: list[tuple[int, list[str]]], ids: Mapping[str, int] | None, source: str) -> IntersectionState:
    first_line, first = lines[0]
    name = first[1]
    try:
        ident = ids[name] if ids is not None and name in ids else default_intersection_id(name)
        _utc(first[0])
        movements = []
        for line_no, values in lines:
            first_line = line_no
            movements.append(_movement(values))
        return IntersectionState.model_validate({"id": ident, "name": name, "timestamp": first[0], "states": movements})
    except ValidationError:  # find the row
        for line_no, values in lines:
            try:
                MovementState.model_validate(_movement(values))
            except ValidationError as exc:
                raise RecordedLogError(f"{source}, line {line_no}: {_short(exc)}") from None
        raise RecordedLogError(f"{source}, line {lines[0][0]}: snapshot of {name!r} at {first[0]} is not valid SPaT") from None
    except ValueError as exc:
        raise RecordedLogError(f"{source}, line {first_line}: {exc}") from exc


def read_spat_csv(path: str | Path, intersection_ids: Mapping[str, int] | None = None, too_large: Callable[[str], None] | None = None) -> list[IntersectionState]:
    """Every snapshot of a recorded SPaT CSV (``.csv`` or ``.csv.gz``), in time order; a line over ``MAX_LINE_CHARS`` is
    skipped unread (``too_large`` told where).

    Raises :class:`RecordedLogError` (naming the file and line) on a malformed file.
    """
    path = Path(path)
    with _open_text(path) as fh:
        reader = csv.reader(bounded_lines(fh, str(path), too_large))
        header = [h.strip() for h in next(reader, [])]
        absent = [c for c in CSV_COLUMNS if c not in header]
        if absent:
            raise RecordedLogError(f"{path}, line 1: missing column(s) {', '.join(absent)}; expected {', '.join(CSV_COLUMNS)}")
        index = [header.index(c) for c in CSV_COLUMNS]
        snapshots = list(_snapshots(([row[i] if i < len(row) else "" for i in index] for row in reader if row), intersection_ids, str(path)))
    snapshots.sort(key=lambda ix: ix.timestamp)  # stable: file order within a timestamp
    return snapshots
