"""SPaT messages: a JSON schema aligned with SAE J2735 SPAT, and conversion to J2735 TimeMarks.

The JSON uses J2735's names (``intersections``, ``signalGroup``, ``eventState``, ``startTime``,
``minEndTime``, ``maxEndTime``, ``likelyTime``, ``confidence``, ``nextTime``) and its
MovementPhaseState spellings, but every time is an absolute UTC instant (ISO 8601 with ``Z``), so a
receiver needs no knowledge of the sender's hour. :func:`to_j2735` / :func:`from_j2735` convert to and
from the J2735 form, where times are TimeMarks (tenths of a second in the hour; see
:mod:`spat_feed.timing.timemark`) and the message time is MinuteOfTheYear + DSecond.

One message carries several intersections; :func:`parse_spat_text` validates each intersection on its
own, so one malformed intersection is dropped (and reported) without losing the others.

Python attribute names are snake_case with units where they are numbers; JSON uses the J2735 aliases.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterable
from dataclasses import dataclass
from datetime import datetime, timezone
from typing import Annotated, Any

from pydantic import AfterValidator, AwareDatetime, BaseModel, ConfigDict, Field, PlainSerializer, ValidationError, model_validator
from pydantic.alias_generators import to_camel

from spat_feed.timing.plans import ChangeWindow, MovementPhaseState, Plan, UncertainPlan, next_changes, state_at, state_start_s
from spat_feed.timing.timemark import PAST_WINDOW_START_S, timemark_to_unix, unix_to_timemark

# J2735 DE_TimeIntervalConfidence: index -> probability. A controller's own confidence is read as that of its change
# window [minEnd, maxEnd] (plan_from_movement); the one our republisher adds is that of its likelyTime
# (spat_feed.transport.republish, docs/SPAT.md section 2).
CONFIDENCE_FRAC = (0.21, 0.36, 0.47, 0.56, 0.62, 0.68, 0.73, 0.77, 0.81, 0.85, 0.88, 0.91, 0.94, 0.96, 0.98, 1.00)

UNSTATED_CONFIDENCE_FRAC = 0.9
"""A change window published without ``confidence`` (J2735 makes it optional): the message states no probability,
so none is invented, neither J2735's lowest class (21 %, which silenced every red of a real controller) nor
certainty. ``minEndTime`` stays a hard bound and ``maxEndTime`` a soft one (docs/SPAT.md); 0.9 is the ordinary
reliability of such a window on a real actuated controller (the Antwerp changes ended inside it 88-94 % of the
time), above the advisor's 0.5 gate. A stated low confidence still silences the advisor. [-]"""


def confidence_index(confidence_frac: float) -> int:
    """The J2735 TimeIntervalConfidence index (0..15) for a probability, rounding down (conservative).

    Examples
    --------
    >>> confidence_index(1.0), confidence_index(0.9), confidence_index(0.1)
    (15, 10, 0)
    """
    return max([i for i, p in enumerate(CONFIDENCE_FRAC) if p <= confidence_frac + 1e-9], default=0)


def _to_utc(value: datetime) -> datetime:
    return value.astimezone(timezone.utc)


def _iso_z(value: datetime) -> str:
    return value.astimezone(timezone.utc).isoformat(timespec="milliseconds").replace("+00:00", "Z")


UtcTime = Annotated[AwareDatetime, AfterValidator(_to_utc), PlainSerializer(_iso_z, return_type=str)]
"""A timezone-aware instant, stored in UTC and written as ``YYYY-MM-DDTHH:MM:SS.mmmZ``; naive times are refused."""


def from_unix_s(t_unix_s: float) -> datetime:
    """Unix seconds to an aware UTC datetime (millisecond precision on output)."""
    return datetime.fromtimestamp(t_unix_s, tz=timezone.utc)


def to_unix_s(value: datetime) -> float:
    """An aware datetime to Unix seconds."""
    return value.timestamp()


class _Model(BaseModel):
    model_config = ConfigDict(alias_generator=to_camel, populate_by_name=True, extra="forbid", frozen=True)


class TimeChangeDetails(_Model):
    """J2735 DF_TimeChangeDetails with absolute UTC times. ``min_end_time`` is required, as in J2735."""

    start_time: UtcTime | None = None
    min_end_time: UtcTime
    max_end_time: UtcTime | None = None
    likely_time: UtcTime | None = None
    confidence: int | None = Field(default=None, ge=0, le=15)
    next_time: UtcTime | None = None

    @model_validator(mode="after")
    def _ordered(self) -> TimeChangeDetails:
        if self.max_end_time is not None and self.max_end_time < self.min_end_time:
            raise ValueError("maxEndTime is before minEndTime")
        if self.likely_time is not None and not (
            self.min_end_time <= self.likely_time and (self.max_end_time is None or self.likely_time <= self.max_end_time)
        ):
            raise ValueError("likelyTime is outside [minEndTime, maxEndTime]")
        return self


PREDICTED_REGION_ID = 128
"""``regionId`` of the regional extension by which our republisher marks the ``likelyTime`` / ``confidence`` it
predicted (:func:`predicted_fields`; J2735 assigns 1-3 to its add-on groups A-C, none to 128). [-]"""


class RegionalExtension(_Model):
    """J2735 DF_RegionalExtension: what a region (or a local system) adds to a frame, kept as received."""

    region_id: int = Field(ge=0, le=255)
    reg_ext_value: dict[str, Any]


class MovementEvent(_Model):
    """J2735 DF_MovementEvent: a state and when it ends (and J2735's ``regional`` extensions, if any)."""

    event_state: MovementPhaseState
    timing: TimeChangeDetails | None = None
    regional: list[RegionalExtension] | None = Field(default=None, max_length=4)


def predicted_fields(event: MovementEvent) -> frozenset[str]:
    """The timing fields (J2735 names: ``likelyTime``, ``confidence``) of ``event`` that a republisher of ours
    predicted, not the controller (its :data:`PREDICTED_REGION_ID` extension's ``predicted``); empty for a
    controller's own event.

    Examples
    --------
    >>> ext = RegionalExtension(region_id=PREDICTED_REGION_ID, reg_ext_value={"predicted": ["likelyTime", "confidence"]})
    >>> sorted(predicted_fields(MovementEvent(event_state="stop-And-Remain", regional=[ext])))
    ['confidence', 'likelyTime']
    """
    if not event.regional:
        return frozenset()
    marked = (ext.reg_ext_value.get("predicted") for ext in event.regional if ext.region_id == PREDICTED_REGION_ID)
    return frozenset(f for fields in marked if isinstance(fields, list) for f in fields if isinstance(f, str))


class ConnectionManeuverAssist(_Model):
    """J2735 DF_ConnectionManeuverAssist: what the intersection's detectors see on one lane connection of the MAP
    (``connectionID``): the queue standing back from the stop line (``queueLength``, DE_ZoneLength, whole metres,
    0-10,000), the room left for more cars (``availableStorageLength``), whether a car must stop at the line before it
    may go (``waitOnStop``) and a pedestrian or cyclist detected in the crossing (``pedBicycleDetect``)."""

    connection_id: int = Field(ge=0, le=255, alias="connectionID")
    queue_length: int | None = Field(default=None, ge=0, le=10_000)
    available_storage_length: int | None = Field(default=None, ge=0, le=10_000)
    wait_on_stop: bool | None = None
    ped_bicycle_detect: bool | None = None
    regional: list[RegionalExtension] | None = Field(default=None, max_length=4)


ManeuverAssistList = Annotated[list[ConnectionManeuverAssist], Field(min_length=1, max_length=16)]
"""J2735 DF_ManeuverAssistList (1-16 connections)."""


class MovementState(_Model):
    """J2735 DF_MovementState: one signal group's current and coming events (``state-time-speed``), and what the
    detectors see on the lane connections it serves (``maneuverAssistList``: :meth:`queue_length_m`)."""

    signal_group: int = Field(ge=0, le=255)
    movement_name: str | None = Field(default=None, max_length=63)
    state_time_speed: list[MovementEvent] = Field(min_length=1, max_length=16)
    maneuver_assist_list: ManeuverAssistList | None = None

    def queue_length_m(self) -> float | None:
        """The longest ``queueLength`` published for the lane connections this movement serves (a car does not know
        which lane it will queue in: the longest queue is the one that may hold it up), or None when none says. [m]"""
        lengths = [c.queue_length for c in self.maneuver_assist_list or () if c.queue_length is not None]
        return float(max(lengths)) if lengths else None


class IntersectionState(_Model):
    """J2735 DF_IntersectionState: one intersection's signal groups at ``timestamp``."""

    id: int = Field(ge=0, le=65_535)
    name: str | None = Field(default=None, max_length=63)
    revision: int = Field(default=0, ge=0, le=127)
    timestamp: UtcTime
    states: list[MovementState] = Field(min_length=1, max_length=255)
    maneuver_assist_list: ManeuverAssistList | None = None  # per lane connection of the MAP (kept; a queue for a movement is read from its own list)

    def movement(self, signal_group: int) -> MovementState | None:
        """The state of ``signal_group``, or ``None`` if this intersection does not report it."""
        return next((m for m in self.states if m.signal_group == signal_group), None)


class SpatMessage(_Model):
    """A SPaT message: its send time and the intersections it reports (J2735 MessageFrame SPAT, as JSON)."""

    timestamp: UtcTime
    name: str | None = Field(default=None, max_length=63)
    intersections: list[IntersectionState] = Field(max_length=32)


# --------------------------------------------------------------------------------------------------
# From plans to messages and back


def movement_events(plan: Plan, now_unix_s: float, n_events: int = 3) -> list[MovementEvent]:
    """The current state and the next ``n_events - 1`` ones of a plan on the Unix axis, as J2735 events.

    The current event's ``startTime`` is when its state began; each event's end is its change window,
    with ``minEndTime`` clipped to ``now_unix_s`` (a controller never says a change is possible in the
    past). An uncertain plan may yield fewer events near its horizon.
    """
    current = state_at(plan, now_unix_s)
    start_s = state_start_s(plan, now_unix_s)
    events: list[MovementEvent] = []
    states = [current]
    changes = next_changes(plan, now_unix_s, n_events)
    for i, change in enumerate(changes):
        state = states[-1]
        min_s = max(change.min_s, now_unix_s)
        likely_s = max(change.likely_s, min_s)
        timing = TimeChangeDetails(
            start_time=from_unix_s(start_s) if math.isfinite(start_s) else None,
            min_end_time=from_unix_s(min_s),
            max_end_time=from_unix_s(max(change.max_s, likely_s)) if math.isfinite(change.max_s) else None,
            likely_time=from_unix_s(likely_s),
            confidence=confidence_index(change.confidence_frac),
            next_time=from_unix_s(changes[i + 1].likely_s) if i + 1 < len(changes) else None,
        )
        events.append(MovementEvent(event_state=state, timing=timing))
        states.append(change.state)
        start_s = change.likely_s
    if not events:  # an uncertain plan past its last change: the state holds, end unknown
        events.append(MovementEvent(event_state=current))
    return events


UNKNOWN_MAX_END_S = 3540.0
"""A ``maxEndTime`` this far (59 min) or more after the message's timestamp means "unknown": controllers
write "an hour from now" (J2735 TimeMark 36000, "more than an hour") when they cannot bound the change. [s]"""


def plan_from_movement(movement: MovementState, timestamp_unix_s: float | None = None) -> UncertainPlan:
    """An :class:`~spat_feed.timing.plans.UncertainPlan` on the Unix axis from a received movement state.

    ``timestamp_unix_s`` is the intersection's timestamp: a ``maxEndTime`` :data:`UNKNOWN_MAX_END_S` or
    more after it is read as absent (unbounded), as J2735's 36000 is.

    Event ``i``'s state holds until its ``timing`` window, then event ``i + 1``'s; after the last
    event (or an event without timing) nothing is known (``UNAVAILABLE``). A missing ``likelyTime`` is
    taken as the middle of the window (``minEndTime`` if the window is open-ended); a missing
    ``maxEndTime`` is unbounded on the last event and the next event's ``minEndTime`` otherwise;
    a missing confidence is not a low one: :data:`UNSTATED_CONFIDENCE_FRAC`. Windows that overlap a later one are cut to fit:
    the earlier change's latest end comes down to the later one's earliest, never the later ``minEndTime`` up (a green
    that may end at 5-25 s into a 3 s amber publishes the red at 8-28 s: raising the red's earliest to 25 s would
    plan a crossing into a red that may begin at 8 s; cutting the green's latest end only makes the plan warier).
    A ``likelyTime`` or ``confidence`` that a republisher of ours predicted (:func:`predicted_fields`) is read as
    absent: the plan is the controller's own, the window's confidence only ever one the controller stated.
    """
    states = []
    changes: list[ChangeWindow] = []
    events = movement.state_time_speed
    for i, ev in enumerate(events):
        states.append(ev.event_state)
        if ev.timing is None:
            break
        min_s = to_unix_s(ev.timing.min_end_time)
        if changes:  # windows may not overlap: the earlier change's latest end is cut, never this one's earliest
            prev = changes[-1]
            min_s = max(min_s, prev.min_end_s)
            if prev.max_end_s > min_s:
                cut_s = min_s
                changes[-1] = ChangeWindow(prev.min_end_s, min(prev.likely_s, cut_s), cut_s, prev.confidence_frac)
        max_end_s = None if ev.timing.max_end_time is None else to_unix_s(ev.timing.max_end_time)
        if max_end_s is not None and timestamp_unix_s is not None and max_end_s - timestamp_unix_s >= UNKNOWN_MAX_END_S:
            max_end_s = None
        if max_end_s is not None:
            max_s = max(max_end_s, min_s)
        elif i + 1 < len(events) and events[i + 1].timing is not None:
            max_s = max(to_unix_s(events[i + 1].timing.min_end_time), min_s)
        else:
            max_s = math.inf
        predicted = predicted_fields(ev) if ev.regional else ()
        likely_time = None if "likelyTime" in predicted else ev.timing.likely_time
        confidence = None if "confidence" in predicted else ev.timing.confidence
        if likely_time is not None:
            likely_s = min(max(to_unix_s(likely_time), min_s), max_s)
        else:
            likely_s = min_s if math.isinf(max_s) else 0.5 * (min_s + max_s)
        conf = CONFIDENCE_FRAC[confidence] if confidence is not None else UNSTATED_CONFIDENCE_FRAC
        changes.append(ChangeWindow(min_s, likely_s, max_s, conf))
    states.append(MovementPhaseState.UNAVAILABLE)
    if len(states) > len(changes) + 1:  # stopped at an event without timing: its state holds for good
        states = states[: len(changes) + 1]
    return UncertainPlan(tuple(states), tuple(changes))


# --------------------------------------------------------------------------------------------------
# Parsing with per-intersection rejection


@dataclass(frozen=True, slots=True)
class ParsedSpat:
    """A received message split into its valid intersections and the reasons for the rejected ones."""

    timestamp_unix_s: float | None
    intersections: tuple[IntersectionState, ...]
    errors: tuple[str, ...]


def parse_spat_text(text: str | bytes) -> ParsedSpat:
    """Parse a SPaT JSON text; keep each intersection that validates, report the others.

    A text that is not JSON, or whose envelope (``timestamp``, ``intersections``) is wrong, yields no
    intersections and one error. Never raises on bad input.
    """
    try:
        raw = json.loads(text)
    except (ValueError, UnicodeDecodeError) as exc:
        return ParsedSpat(None, (), (f"not JSON: {exc}",))
    if not isinstance(raw, dict) or not isinstance(raw.get("intersections"), list):
        return ParsedSpat(None, (), ("not a SPaT message: no 'intersections' list",))
    try:
        envelope = SpatMessage.model_validate({k: v for k, v in raw.items() if k != "intersections"} | {"intersections": []})
    except ValidationError as exc:
        return ParsedSpat(None, (), (f"bad envelope: {_short(exc)}",))
    good, errors = [], []
    for i, item in enumerate(raw["intersections"]):
        try:
            good.append(IntersectionState.model_validate(item))
        except ValidationError as exc:
            ident = item.get("id") if isinstance(item, dict) else None
            errors.append(f"intersection #{i} (id={ident!r}) rejected: {_short(exc)}")
    return ParsedSpat(to_unix_s(envelope.timestamp), tuple(good), tuple(errors))


def _short(exc: ValidationError) -> str:
    return "; ".join(f"{'.'.join(map(str, e['loc']))}: {e['msg']}" for e in exc.errors(include_url=False)[:3])


# --------------------------------------------------------------------------------------------------
# J2735 TimeMark form


def _minute_of_year_and_ms(t_unix_s: float) -> tuple[int, int]:
    """J2735 MinuteOfTheYear (0..527040) and DSecond (milliseconds in the minute, 0..59999)."""
    dt = from_unix_s(t_unix_s)
    year_start = datetime(dt.year, 1, 1, tzinfo=timezone.utc).timestamp()
    minutes, rem_s = divmod(t_unix_s - year_start, 60.0)
    return int(minutes), min(int(round(rem_s * 1000.0)), 59_999)


def _from_minute_of_year(moy: int, dsecond_ms: int, ref_unix_s: float) -> float:
    """Unix time of (MinuteOfTheYear, DSecond) in the year of ``ref_unix_s`` (or the one before/after, nearest)."""
    year = from_unix_s(ref_unix_s).year
    candidates = [datetime(y, 1, 1, tzinfo=timezone.utc).timestamp() + moy * 60.0 + dsecond_ms / 1000.0 for y in (year - 1, year, year + 1)]
    return min(candidates, key=lambda t: abs(t - ref_unix_s))


_TIME_FIELDS = ("start_time", "min_end_time", "max_end_time", "likely_time", "next_time")


def to_j2735(message: SpatMessage) -> dict:
    """The message in J2735 form: times as TimeMarks, message time as ``moy`` + ``timeStamp``.

    Field names follow the J2735 ASN.1 (``state-time-speed``, ``id: {id: n}``). A time more than an
    hour after the intersection's timestamp becomes 36000 (beyond the hour); an absent optional time
    is left out. ``minEndTime`` is always present.
    """
    moy, _ = _minute_of_year_and_ms(to_unix_s(message.timestamp))
    out: dict[str, Any] = {"timeStamp": moy, "intersections": []}
    if message.name is not None:
        out["name"] = message.name
    for ix in message.intersections:
        ref_s = to_unix_s(ix.timestamp)
        ix_moy, ix_ms = _minute_of_year_and_ms(ref_s)
        states = []
        for mv in ix.states:
            events = []
            for ev in mv.state_time_speed:
                event: dict[str, Any] = {"eventState": ev.event_state.value}
                if ev.timing is not None:
                    timing: dict[str, Any] = {}
                    for name in _TIME_FIELDS:
                        value = getattr(ev.timing, name)
                        if value is not None:
                            timing[to_camel(name)] = unix_to_timemark(to_unix_s(value), ref_s)
                    if ev.timing.confidence is not None:
                        timing["confidence"] = ev.timing.confidence
                    event["timing"] = timing
                if ev.regional:
                    event["regional"] = [x.model_dump(by_alias=True) for x in ev.regional]
                events.append(event)
            state: dict[str, Any] = {"signalGroup": mv.signal_group, "state-time-speed": events}
            if mv.movement_name is not None:
                state["movementName"] = mv.movement_name
            if mv.maneuver_assist_list:
                state["maneuverAssistList"] = _assists(mv.maneuver_assist_list)
            states.append(state)
        item: dict[str, Any] = {"id": {"id": ix.id}, "revision": ix.revision, "status": "0000", "moy": ix_moy, "timeStamp": ix_ms, "states": states}
        if ix.name is not None:
            item["name"] = ix.name
        if ix.maneuver_assist_list:
            item["maneuverAssistList"] = _assists(ix.maneuver_assist_list)
        out["intersections"].append(item)
    return out


def _assists(assists: list[ConnectionManeuverAssist]) -> list[dict]:
    return [c.model_dump(by_alias=True, exclude_none=True) for c in assists]


def from_j2735(data: dict, ref_unix_s: float) -> SpatMessage:
    """Rebuild a :class:`SpatMessage` from :func:`to_j2735` output, resolving TimeMarks near each timestamp.

    ``ref_unix_s`` (the receiver's clock) fixes the year of MinuteOfTheYear; the intersection's own
    ``moy`` + ``timeStamp`` then fix the hour of every TimeMark (see :func:`timemark_to_unix`), so the
    hour rollover is handled. ``minEndTime`` = 36000 ("at least an hour") decodes as timestamp + 1 h;
    36001 (unknown) as the timestamp itself (the change may come at any moment). Other unknown times
    are left out. Raises ``ValueError`` (or ``pydantic.ValidationError``) on malformed input.
    """
    intersections = []
    latest_s = None
    for item in data["intersections"]:
        ref_s = _from_minute_of_year(item["moy"], item.get("timeStamp", 0), ref_unix_s)
        latest_s = ref_s if latest_s is None else max(latest_s, ref_s)
        states = []
        for st in item["states"]:
            events = []
            for ev in st["state-time-speed"]:
                timing = None
                if "timing" in ev:
                    raw = ev["timing"]
                    fields: dict[str, Any] = {}
                    for name in _TIME_FIELDS:
                        key = to_camel(name)
                        if key not in raw:
                            continue
                        window = PAST_WINDOW_START_S if name == "start_time" else -300.0
                        t_s = timemark_to_unix(raw[key], ref_s, window)
                        if t_s is None and name == "min_end_time":
                            t_s = ref_s + 3600.0 if raw[key] == 36_000 else ref_s
                        if t_s is not None:
                            fields[name] = from_unix_s(t_s)
                    if "confidence" in raw:
                        fields["confidence"] = raw["confidence"]
                    timing = TimeChangeDetails(**fields)
                events.append(MovementEvent(event_state=MovementPhaseState(ev["eventState"]), timing=timing, regional=ev.get("regional")))
            states.append(MovementState(signal_group=st["signalGroup"], movement_name=st.get("movementName"), state_time_speed=events,
                                        maneuver_assist_list=st.get("maneuverAssistList")))  # fmt: skip
        intersections.append(
            IntersectionState(
                id=item["id"]["id"], name=item.get("name"), revision=item.get("revision", 0), timestamp=from_unix_s(ref_s), states=states,
                maneuver_assist_list=item.get("maneuverAssistList"),
            )
        )
    if "timeStamp" in data:
        msg_s = _from_minute_of_year(data["timeStamp"], 0, ref_unix_s)
        if latest_s is not None and 0 <= latest_s - msg_s < 60.0:
            msg_s = latest_s  # MinuteOfTheYear alone drops the seconds; the intersection time is finer
    else:
        msg_s = latest_s if latest_s is not None else ref_unix_s
    return SpatMessage(timestamp=from_unix_s(msg_s), name=data.get("name"), intersections=intersections)


def intersections_by_id(items: Iterable[IntersectionState]) -> dict[int, IntersectionState]:
    """Index intersections by J2735 id (later ones win)."""
    return {ix.id: ix for ix in items}
