"""Recorded SPaT logs played back as if live: the recorded clock mapped onto now, real time or faster, looping.

Two log formats:

* the shared recordings' CSV (``../shared/data/spat``, :mod:`spat_feed.transport.recorded`), ``.csv`` or ``.csv.gz``;
* JSON lines of our own messages (``.jsonl`` or ``.jsonl.gz``): one :class:`~spat_feed.timing.messages.SpatMessage`
  or one :class:`~spat_feed.timing.messages.IntersectionState` per line, as :class:`JsonlRecorder` writes them
  (``python -m spat_feed --record``, ``ECO_SPAT_RECORD``).

Time mapping (:func:`map_times`): a recorded instant ``t`` plays at ``start + (t - t0) / speedup``, and every
time in the state (timestamp, minEndTime, maxEndTime, likelyTime, ...) is mapped the same way, so the windows
keep their meaning relative to the state. A ``maxEndTime`` that means "unknown" (about an hour after the
timestamp, :data:`~spat_feed.timing.messages.UNKNOWN_MAX_END_S`) keeps its distance unscaled: still unknown at any
speed. With ``loop`` the log starts again one recorded second after its end, forever.

Pure: :meth:`LogPlayer.due` is handed the instant; :class:`spat_feed.transport.pump.SpatPump` calls it on a timer.
"""

from __future__ import annotations

import gzip
import io
import json
from collections.abc import Callable, Iterator
from datetime import datetime
from pathlib import Path

from pydantic import ValidationError

from spat_feed.timing.messages import UNKNOWN_MAX_END_S, IntersectionState, MovementEvent, SpatMessage, from_unix_s, to_unix_s
from spat_feed.transport.recorded import RecordedLogError, bounded_lines, read_spat_csv

_TIME_FIELDS = ("start_time", "min_end_time", "max_end_time", "likely_time", "next_time")


def _open(path: Path, mode: str = "rt") -> io.TextIOBase:
    if path.suffix == ".gz":
        return gzip.open(path, mode, encoding="utf-8")
    return path.open(mode[0], encoding="utf-8")


def read_jsonl(path: str | Path, too_large: Callable[[str], None] | None = None) -> list[IntersectionState]:
    """Every intersection state of a JSON-lines SPaT log (messages or single states), in time order; a line over
    ``MAX_LINE_CHARS`` is skipped unparsed (``too_large`` told where, default a WARNING).

    Raises :class:`~spat_feed.transport.recorded.RecordedLogError` naming the file and line of a bad record.
    """
    path = Path(path)
    out: list[IntersectionState] = []
    with _open(path) as fh:
        for line_no, line in enumerate(bounded_lines(fh, str(path), too_large), start=1):
            if not line.strip():
                continue
            try:
                data = json.loads(line)
                if isinstance(data, dict) and "intersections" in data:
                    out.extend(SpatMessage.model_validate(data).intersections)
                else:
                    out.append(IntersectionState.model_validate(data))
            except (ValueError, ValidationError) as exc:
                raise RecordedLogError(f"{path}, line {line_no}: not a SPaT message or intersection state: {str(exc).splitlines()[0][:200]}") from None
    out.sort(key=lambda ix: ix.timestamp)
    return out


def read_spat_log(path: str | Path, too_large: Callable[[str], None] | None = None) -> list[IntersectionState]:
    """A recorded log by its suffix: ``.csv[.gz]`` (shared recordings) or ``.jsonl[.gz]`` (ours); lines over
    ``MAX_LINE_CHARS`` skipped unread, ``too_large`` told where."""
    path = Path(path)
    if not path.is_file():
        raise RecordedLogError(f"{path}: no such file")
    name = path.name.lower().removesuffix(".gz")
    if name.endswith(".csv"):
        return read_spat_csv(path, too_large=too_large)
    if name.endswith((".jsonl", ".ndjson", ".json")):
        return read_jsonl(path, too_large)
    raise RecordedLogError(f"{path}: unknown log format (expected .csv, .csv.gz, .jsonl or .jsonl.gz)")


def map_times(state: IntersectionState, shift_s: float, t0_s: float, speedup: float = 1.0) -> IntersectionState:
    """``state`` with every time ``t`` moved to ``t0 + shift + (t - t0) / speedup`` (see the module docstring).

    Examples
    --------
    >>> from spat_feed.transport.recorded import iter_spat_csv
    >>> row = dict(generated_utc="2019-05-01T16:00:00Z", intersection="K648", signal_group="1", phase="3",
    ...            min_end_utc="2019-05-01T16:00:10Z", max_end_utc="2019-05-01T17:00:00Z")
    >>> s = next(iter_spat_csv([row]))
    >>> t0 = to_unix_s(s.timestamp)
    >>> m = map_times(s, 1000.0, t0, speedup=2.0)
    >>> t = m.states[0].state_time_speed[0].timing
    >>> to_unix_s(m.timestamp) - t0, to_unix_s(t.min_end_time) - t0, to_unix_s(t.max_end_time) - t0
    (1000.0, 1005.0, 4600.0)
    """
    stamp_s = to_unix_s(state.timestamp)
    new_stamp_s = t0_s + shift_s + (stamp_s - t0_s) / speedup

    def move(t: datetime, field: str) -> datetime:
        t_s = to_unix_s(t)
        if field == "max_end_time" and t_s - stamp_s >= UNKNOWN_MAX_END_S:
            return from_unix_s(new_stamp_s + (t_s - stamp_s))
        return from_unix_s(t0_s + shift_s + (t_s - t0_s) / speedup)

    def moved(event: MovementEvent) -> MovementEvent:
        if event.timing is None:
            return event
        times = {f: move(t, f) for f in _TIME_FIELDS if (t := getattr(event.timing, f)) is not None}
        return event.model_copy(update={"timing": event.timing.model_copy(update=times)})

    movements = [m.model_copy(update={"state_time_speed": [moved(e) for e in m.state_time_speed]}) for m in state.states]
    return state.model_copy(update={"timestamp": from_unix_s(new_stamp_s), "states": movements})


class LogPlayer:
    """Plays recorded intersection states on the present clock.

    Parameters
    ----------
    states : list of IntersectionState
        The log, in time order (:func:`read_spat_log`).
    start_unix_s : float
        When the log's first state plays.
    speedup : float
        Recorded seconds per played second (1: real time).
    loop : bool
        Start again after the end (one recorded second later), forever.
    """

    def __init__(self, states: list[IntersectionState], start_unix_s: float, speedup: float = 1.0, loop: bool = False) -> None:
        if not states:
            raise ValueError("the log holds no SPaT states")
        if not speedup > 0:
            raise ValueError("speedup must be > 0")
        self.states = states
        self.speedup = float(speedup)
        self.loop = loop
        self.t0_s = to_unix_s(states[0].timestamp)
        self.span_s = to_unix_s(states[-1].timestamp) - self.t0_s + 1.0  # one pass, recorded seconds
        self.start_unix_s = float(start_unix_s)
        self.index = 0
        self.passes = 0

    @property
    def done(self) -> bool:
        return not self.loop and self.index >= len(self.states)

    def _play_at(self, i: int) -> float:
        return self.start_unix_s + (self.passes * self.span_s + to_unix_s(self.states[i].timestamp) - self.t0_s) / self.speedup

    def due(self, now_unix_s: float) -> list[IntersectionState]:
        """The states whose play time has come since the last call, mapped onto the present."""
        out = []
        while True:
            if self.index >= len(self.states):
                if not self.loop:
                    return out
                self.index, self.passes = 0, self.passes + 1
            if self._play_at(self.index) > now_unix_s:
                return out
            shift_s = self.start_unix_s - self.t0_s + self.passes * self.span_s / self.speedup
            out.append(map_times(self.states[self.index], shift_s, self.t0_s, self.speedup))
            self.index += 1

    def __iter__(self) -> Iterator[tuple[float, IntersectionState]]:
        """(play instant, mapped state) for one pass, without waiting (for tests and offline use)."""
        for i, state in enumerate(self.states):
            shift_s = self.start_unix_s - self.t0_s + self.passes * self.span_s / self.speedup
            yield self._play_at(i), map_times(state, shift_s, self.t0_s, self.speedup)


class JsonlRecorder:
    """Appends every state it is handed to a JSON-lines log (``.jsonl`` or ``.jsonl.gz``), one state per line."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._fh = gzip.open(self.path, "at", encoding="utf-8") if self.path.suffix == ".gz" else self.path.open("a", encoding="utf-8")
        self.written = 0

    def __call__(self, state: IntersectionState) -> None:
        self._fh.write(state.model_dump_json(by_alias=True, exclude_none=True) + "\n")
        self.written += 1
        if self.written % 100 == 0:
            self._fh.flush()

    def close(self) -> None:
        self._fh.close()
