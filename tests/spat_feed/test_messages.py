"""SPaT JSON schema, J2735 TimeMark form, and plan <-> message round trips."""

from __future__ import annotations

import json
from datetime import datetime, timezone

import pytest
from pydantic import ValidationError

from spat_feed.timing.messages import (
    CONFIDENCE_FRAC,
    IntersectionState,
    MovementEvent,
    MovementState,
    SpatMessage,
    TimeChangeDetails,
    confidence_index,
    from_j2735,
    from_unix_s,
    movement_events,
    parse_spat_text,
    plan_from_movement,
    to_j2735,
    to_unix_s,
)
from spat_feed.timing.plans import FixedTimePlan, MovementPhaseState, seconds_to_next_green, seconds_to_next_red, state_at
from spat_feed.transport.scenarios import Uncertainty, make_scenario, spat_message_at

T0 = datetime(2024, 5, 1, 12, 0, tzinfo=timezone.utc).timestamp()
J2735_STATE_NAMES = {
    "unavailable", "dark", "stop-Then-Proceed", "stop-And-Remain", "pre-Movement", "permissive-Movement-Allowed",
    "protected-Movement-Allowed", "permissive-clearance", "protected-clearance", "caution-Conflicting-Traffic",
}  # fmt: skip


def message(now_s=T0 + 7.0, timing="15_15", uncertainty=None, entry_s=T0):
    return spat_message_at(make_scenario("paper_s400", timing, entry_s, uncertainty), now_s)


def test_event_state_names_are_j2735s():
    assert {s.value for s in MovementPhaseState} == J2735_STATE_NAMES


def test_json_uses_j2735_names_and_utc_times():
    data = json.loads(message().model_dump_json(by_alias=True, exclude_none=True))
    assert data["timestamp"] == "2024-05-01T12:00:07.000Z"
    event = data["intersections"][0]["states"][0]["stateTimeSpeed"][0]
    assert event["eventState"] == "protected-Movement-Allowed"  # x = 15: green until 15 s after entry
    assert set(event["timing"]) == {"startTime", "minEndTime", "maxEndTime", "likelyTime", "confidence", "nextTime"}
    assert event["timing"]["minEndTime"] == "2024-05-01T12:00:15.000Z"
    assert event["timing"]["confidence"] == 15


def test_json_round_trip():
    msg = message(uncertainty=Uncertainty(2.0, 5.0, 0.8))
    assert SpatMessage.model_validate_json(msg.model_dump_json(by_alias=True)) == msg


@pytest.mark.parametrize(
    "timing",
    [
        {"minEndTime": "2024-05-01T12:00:00"},  # naive: no timezone
        {"minEndTime": "2024-05-01T12:00:10Z", "maxEndTime": "2024-05-01T12:00:05Z"},
        {"minEndTime": "2024-05-01T12:00:10Z", "maxEndTime": "2024-05-01T12:00:20Z", "likelyTime": "2024-05-01T12:00:30Z"},
        {"minEndTime": "2024-05-01T12:00:10Z", "confidence": 16},
        {"maxEndTime": "2024-05-01T12:00:10Z"},  # minEndTime is required
        {"minEndTime": "2024-05-01T12:00:10Z", "colour": "red"},  # unknown field
    ],
)
def test_bad_timing_is_rejected(timing):
    with pytest.raises(ValidationError):
        TimeChangeDetails.model_validate(timing)


def test_other_time_zones_are_converted_to_utc():
    details = TimeChangeDetails.model_validate({"minEndTime": "2024-05-01T14:00:10+02:00"})
    assert details.min_end_time.tzinfo == timezone.utc and details.min_end_time.hour == 12
    assert details.model_dump(mode="json", by_alias=True)["minEndTime"] == "2024-05-01T12:00:10.000Z"


def test_confidence_table():
    assert len(CONFIDENCE_FRAC) == 16 and CONFIDENCE_FRAC[-1] == 1.0
    assert all(confidence_index(p) == i for i, p in enumerate(CONFIDENCE_FRAC))
    assert confidence_index(0.0) == 0 and confidence_index(0.9) == 10


def test_parse_keeps_good_intersections_and_reports_bad_ones():
    data = json.loads(message().model_dump_json(by_alias=True))
    data["intersections"][0]["states"][0]["stateTimeSpeed"][0]["eventState"] = "purple"
    parsed = parse_spat_text(json.dumps(data))
    assert [ix.id for ix in parsed.intersections] == [2]
    assert len(parsed.errors) == 1 and "id=1" in parsed.errors[0] and "eventState" in parsed.errors[0]


@pytest.mark.parametrize("text", ["", "{not json", "[]", '{"intersections": 5}', '{"timestamp": "yesterday", "intersections": []}', b"\xff\xfe"])
def test_parse_never_raises_on_garbage(text):
    parsed = parse_spat_text(text)
    assert parsed.intersections == () and len(parsed.errors) == 1


# ------------------------------------------------------------------------------ J2735 TimeMark form


@pytest.mark.parametrize("offset_s", [-2.0, -0.05, 0.0, 0.04, 3.0])
def test_j2735_round_trip_across_the_hour(offset_s):
    """Messages generated around 13:00:00 (changes on both sides of the hour) survive TimeMark encoding."""
    top_s = T0 + 3600.0
    msg = message(now_s=top_s + offset_s, timing="-15_15", uncertainty=Uncertainty(2.0, 5.0, 0.8), entry_s=top_s - 20.0)
    j = to_j2735(msg)
    assert all(0 <= v < 36_000 for v in _timemarks(j))
    back = from_j2735(json.loads(json.dumps(j)), ref_unix_s=top_s + offset_s + 0.3)  # receiver a bit later
    assert len(back.intersections) == len(msg.intersections)
    for a, b in zip(msg.intersections, back.intersections):
        assert abs(to_unix_s(a.timestamp) - to_unix_s(b.timestamp)) <= 0.0005
        for ea, eb in zip(a.states[0].state_time_speed, b.states[0].state_time_speed):
            assert ea.event_state == eb.event_state and ea.timing.confidence == eb.timing.confidence
            for name in ("start_time", "min_end_time", "max_end_time", "likely_time", "next_time"):
                ta, tb = getattr(ea.timing, name), getattr(eb.timing, name)
                assert (ta is None) == (tb is None), name
                if ta is not None:
                    assert abs(to_unix_s(ta) - to_unix_s(tb)) <= 0.0501, (name, ta, tb)


def _timemarks(j):
    for ix in j["intersections"]:
        for st in ix["states"]:
            for ev in st["state-time-speed"]:
                yield from (v for k, v in ev.get("timing", {}).items() if k != "confidence")


def test_j2735_beyond_the_hour_and_unknown():
    ix = IntersectionState.model_validate(
        {
            "id": 7,
            "timestamp": "2024-05-01T12:00:00Z",
            "states": [{"signalGroup": 2, "stateTimeSpeed": [{"eventState": "stop-And-Remain", "timing": {"minEndTime": "2024-05-01T12:30:00Z", "maxEndTime": "2024-05-01T14:00:00Z"}}]}],
        }
    )
    msg = SpatMessage(timestamp=ix.timestamp, intersections=[ix])
    j = to_j2735(msg)
    timing = j["intersections"][0]["states"][0]["state-time-speed"][0]["timing"]
    assert timing == {"minEndTime": 18_000, "maxEndTime": 36_000}
    back = from_j2735(j, to_unix_s(ix.timestamp)).intersections[0].states[0].state_time_speed[0].timing
    assert back.max_end_time is None  # "more than an hour" bounds nothing we can use
    timing["minEndTime"] = 36_001  # unknown: may change at any moment
    back = from_j2735(j, to_unix_s(ix.timestamp)).intersections[0].states[0].state_time_speed[0].timing
    assert back.min_end_time == ix.timestamp


# ------------------------------------------------------------------------------- plans <-> messages


@pytest.mark.parametrize("now_s", [T0 + 0.0, T0 + 14.9, T0 + 15.0, T0 + 44.0, T0 + 1234.5])
def test_fixed_plan_survives_the_message(now_s):
    plan = FixedTimePlan(30, 30, offset_s=T0 + 15.0)
    received = plan_from_movement(
        IntersectionState.model_validate(
            {"id": 1, "timestamp": now_s, "states": [{"signalGroup": 2, "stateTimeSpeed": [e.model_dump() for e in movement_events(plan, now_s, 4)]}]}
        ).states[0]
    )
    for dt_s in (0.0, 0.1, 10.0, 29.9, 45.0, 89.0):
        t = now_s + dt_s
        assert state_at(received, t) == state_at(plan, t)
        for fn in (seconds_to_next_green, seconds_to_next_red):
            got, want = fn(received, t), fn(plan, t)
            if got is not None:  # the message covers 4 events; beyond them it says "unknown"
                assert got.likely_s == pytest.approx(want.likely_s, abs=1e-3)
                assert got.min_s == pytest.approx(got.max_s, abs=1e-3)


def test_uncertain_windows_survive_the_message():
    msg = message(now_s=T0 + 12.0, uncertainty=Uncertainty(early_s=2.0, late_s=5.0, confidence_frac=0.8))
    plan = plan_from_movement(msg.intersections[0].states[0])
    # light 1 (x = 15): green, change to red likely at 15 s, window [13, 20], confidence index 7 (77 %)
    to_red = seconds_to_next_red(plan, T0 + 12.0)
    assert (to_red.min_s, to_red.likely_s, to_red.max_s) == pytest.approx((1.0, 3.0, 8.0), abs=1e-3)
    assert to_red.confidence_frac == CONFIDENCE_FRAC[7]
    # inside the window the receiver sees "red or green" and the earliest next green is now
    assert seconds_to_next_green(plan, T0 + 16.0).min_s == 0.0


def test_min_end_time_is_clipped_to_now():
    """Inside a window, a controller says the change may come now, never in the past."""
    msg = message(now_s=T0 + 14.0, uncertainty=Uncertainty(early_s=2.0, late_s=5.0, confidence_frac=0.8))
    timing = msg.intersections[0].states[0].state_time_speed[0].timing
    assert to_unix_s(timing.min_end_time) == pytest.approx(T0 + 14.0, abs=1e-3)
    assert to_unix_s(timing.likely_time) == pytest.approx(T0 + 15.0, abs=1e-3)


def test_event_without_timing_holds():
    ix = IntersectionState.model_validate({"id": 1, "timestamp": T0, "states": [{"signalGroup": 1, "stateTimeSpeed": [{"eventState": "dark"}]}]})
    plan = plan_from_movement(ix.states[0])
    assert state_at(plan, T0 + 1e6) == MovementPhaseState.DARK and seconds_to_next_green(plan, T0) is None


def test_overlapping_windows_cut_the_earlier_end_never_raise_the_later_start():
    """A green+amber feed: the green may end 5-25 s from now into a 3 s amber, so the red may begin 8-28 s from now.
    Windows of a plan may not overlap; the red's earliest start stays 8 s (a plan on 25 s would cross a red that
    began at 8 s), the green's latest end comes down to it (warier, never unsafe)."""
    def event(state, lo_s, hi_s):
        timing = TimeChangeDetails(min_end_time=from_unix_s(T0 + lo_s), max_end_time=from_unix_s(T0 + hi_s), likely_time=from_unix_s(T0 + lo_s + 2.0))
        return MovementEvent(event_state=state, timing=timing)

    G, A, R = MovementPhaseState.PROTECTED_MOVEMENT_ALLOWED, MovementPhaseState.PROTECTED_CLEARANCE, MovementPhaseState.STOP_AND_REMAIN
    plan = plan_from_movement(MovementState(signal_group=1, state_time_speed=[event(G, 5.0, 25.0), event(A, 8.0, 28.0), MovementEvent(event_state=R)]), T0)
    to_amber, to_red = plan.changes
    assert (to_red.min_end_s - T0, to_red.max_end_s - T0) == pytest.approx((8.0, 28.0))
    assert (to_amber.min_end_s - T0, to_amber.max_end_s - T0) == pytest.approx((5.0, 8.0))
    assert to_amber.likely_s - T0 == pytest.approx(7.0)
    assert seconds_to_next_red(plan, T0).min_s == pytest.approx(8.0)


def test_maneuver_assist_list_is_read_and_kept():
    """J2735 MovementState.maneuverAssistList (DF_ConnectionManeuverAssist per lane connection): a message that carries
    it is accepted (it was refused as an unknown field), the longest queue of a movement's connections is its queue,
    it survives the J2735 form both ways, and a queueLength outside DE_ZoneLength (0-10,000 m) rejects the
    intersection with a message naming the field."""
    movement = {"signalGroup": 2, "stateTimeSpeed": [{"eventState": "stop-And-Remain", "timing": {"minEndTime": T0 + 10.0}}],
                "maneuverAssistList": [{"connectionID": 1, "queueLength": 18, "waitOnStop": False}, {"connectionID": 2, "queueLength": 42},
                                       {"connectionID": 3, "pedBicycleDetect": True}]}  # fmt: skip
    ix = IntersectionState.model_validate({"id": 7, "timestamp": T0, "states": [movement, {**movement, "signalGroup": 3, "maneuverAssistList": None}]})
    assert ix.movement(2).queue_length_m() == 42.0 and ix.movement(3).queue_length_m() is None
    back = from_j2735(to_j2735(SpatMessage(timestamp=T0, intersections=[ix])), T0)
    assert back.intersections[0].movement(2).maneuver_assist_list == ix.movement(2).maneuver_assist_list
    assert back.intersections[0].movement(2).queue_length_m() == 42.0
    text = json.dumps({"timestamp": T0, "intersections": [{"id": 7, "timestamp": T0, "states": [{**movement, "maneuverAssistList": [{"connectionID": 1, "queueLength": 10_001}]}]}]})
    parsed = parse_spat_text(text)
    assert parsed.intersections == () and "queueLength" in parsed.errors[0]
