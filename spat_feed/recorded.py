"""Recorded SPaT logs: the flattened Open Traffic Lights CSV format, read into our J2735-aligned schema.

The CSV format (``../shared/data/spat/README.md``) has one row per (snapshot, signal group)::

    generated_utc,intersection,signal_group,phase,min_end_utc,max_end_utc
    2019-05-01T16:04:25.609Z,K648,1,6,2019-05-01T16:04:38.009Z,2019-05-01T16:07:13.009Z

``phase`` is the J2735 MovementPhaseState *number*; ``min_end_utc`` / ``max_end_utc`` are the current
phase's ``minEndTime`` / ``maxEndTime``. Only the current phase is published (no next events, no
``likelyTime``, no ``confidence``). :func:`read_spat_csv` returns one :class:`IntersectionState` per
(snapshot, intersection), in time order, each signal group with one event carrying exactly what the row
says: reading is lossless; what the values *mean* (a ``maxEndTime`` about an hour ahead is unknown, a
missing confidence is not a low one) is decided where plans are made (:func:`spat_feed.messages.plan_from_movement`).

Intersection ids: J2735 ids are integers, the log names controllers (``K648``). By default the id is the
name's digits (``K648`` -> 648); pass ``intersection_ids`` to choose others. The name is kept in ``name``.
"""

from __future__ import annotations

import csv
import gzip
import io
import re
from collections.abc import Iterable, Iterator, Mapping
from datetime import datetime
from pathlib import Path

from spat_feed.messages import IntersectionState, MovementEvent, MovementState, TimeChangeDetails
from spat_feed.plans import J2735_STATE_NUMBERS

CSV_COLUMNS = ("generated_utc", "intersection", "signal_group", "phase", "min_end_utc", "max_end_utc")


class RecordedLogError(ValueError):
    """A log that cannot be read; the message names the file and the line."""


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
    key = None
    movements: list[MovementState] = []
    stamp: datetime | None = None
    name = ""
    for line_no, row in enumerate(rows, start=2):
        try:
            missing = [c for c in CSV_COLUMNS if not (row.get(c) or "").strip()]
            if missing:
                raise ValueError(f"missing {', '.join(missing)}")
            number = int(row["phase"])
            if not 0 <= number < len(J2735_STATE_NUMBERS):
                raise ValueError(f"phase {number} is not a J2735 MovementPhaseState number (0..9)")
            row_key = (row["generated_utc"].strip(), row["intersection"].strip())
            if row_key != key:
                if key is not None:
                    yield _snapshot(name, stamp, movements, intersection_ids)
                key, movements, stamp, name = row_key, [], _utc(row_key[0]), row_key[1]
            timing = TimeChangeDetails(min_end_time=_utc(row["min_end_utc"]), max_end_time=_utc(row["max_end_utc"]))
            event = MovementEvent(event_state=J2735_STATE_NUMBERS[number], timing=timing)
            movements.append(MovementState(signal_group=int(row["signal_group"]), state_time_speed=[event]))
        except ValueError as exc:  # pydantic's ValidationError is a ValueError
            raise RecordedLogError(f"{source}, line {line_no}: {exc}") from exc
    if key is not None:
        yield _snapshot(name, stamp, movements, intersection_ids)


def _snapshot(name: str, stamp: datetime | None, movements: list[MovementState], ids: Mapping[str, int] | None) -> IntersectionState:
    ident = ids[name] if ids is not None and name in ids else default_intersection_id(name)
    return IntersectionState(id=ident, name=name, timestamp=stamp, states=movements)


def read_spat_csv(path: str | Path, intersection_ids: Mapping[str, int] | None = None) -> list[IntersectionState]:
    """Every snapshot of a recorded SPaT CSV (``.csv`` or ``.csv.gz``), in time order.

    Raises :class:`RecordedLogError` (naming the file and line) on a malformed file.
    """
    path = Path(path)
    with _open_text(path) as fh:
        reader = csv.DictReader(fh)
        absent = [c for c in CSV_COLUMNS if c not in (reader.fieldnames or ())]
        if absent:
            raise RecordedLogError(f"{path}, line 1: missing column(s) {', '.join(absent)}; expected {', '.join(CSV_COLUMNS)}")
        snapshots = list(iter_spat_csv(reader, intersection_ids, str(path)))
    snapshots.sort(key=lambda ix: ix.timestamp)  # stable: file order within a timestamp
    return snapshots
