"""spat_feed.transport.recorded (the shared recordings' CSV format), the J2735 phase table, and the 'an hour ahead' rule."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from spat_feed.timing.messages import plan_from_movement, to_unix_s
from spat_feed.timing.plans import GO_STATES, J2735_STATE_NUMBERS, STOP_STATES, UNKNOWN_STATES, MovementPhaseState, PhaseClass, phase_class
from spat_feed.transport.recorded import RecordedLogError, read_spat_csv

from tests.conftest import SPAT_RECORDINGS as RECORDINGS
from tests.conftest import recording_facts

HEADER = "generated_utc,intersection,signal_group,phase,min_end_utc,max_end_utc\n"


@pytest.mark.parametrize(
    ("number", "meaning"),
    [(0, "unknown"), (1, "unknown"), (2, "red"), (3, "red"), (4, "red"), (5, "green"), (6, "green"), (7, "amber"), (8, "amber"), (9, "amber")],
)
def test_every_j2735_phase_state_has_its_meaning(number, meaning):
    # SAE J2735 DE_MovementPhaseState: the number, its spelling, what a car may do
    assert phase_class(J2735_STATE_NUMBERS[number]) is PhaseClass(meaning)


def test_phase_sets_follow_the_table():
    assert GO_STATES == {MovementPhaseState.PERMISSIVE_MOVEMENT_ALLOWED, MovementPhaseState.PROTECTED_MOVEMENT_ALLOWED}
    assert MovementPhaseState.PRE_MOVEMENT in STOP_STATES  # red + amber: still no entry
    assert UNKNOWN_STATES == {MovementPhaseState.UNAVAILABLE, MovementPhaseState.DARK}


def _write(tmp_path: Path, body: str, name: str = "log.csv") -> Path:
    path = tmp_path / name
    path.write_text(HEADER + body)
    return path


def test_rows_become_one_snapshot_per_instant(tmp_path):
    path = _write(
        tmp_path,
        "2019-05-01T16:04:25.609Z,K648,1,6,2019-05-01T16:04:38.009Z,2019-05-01T16:07:13.009Z\n"
        "2019-05-01T16:04:25.609Z,K648,3,3,2019-05-01T16:05:04.009Z,2019-05-01T17:04:25.609Z\n"
        "2019-05-01T16:04:26.609Z,K648,1,0,2019-05-01T16:04:38.009Z,2019-05-01T16:07:13.009Z\n",
    )
    snaps = read_spat_csv(path)
    assert [len(s.states) for s in snaps] == [2, 1]
    first = snaps[0]
    assert (first.id, first.name) == (648, "K648")
    assert to_unix_s(first.timestamp) == pytest.approx(1556726665.609, abs=1e-3)
    green = first.movement(1).state_time_speed[0]
    assert green.event_state is MovementPhaseState.PROTECTED_MOVEMENT_ALLOWED
    assert to_unix_s(green.timing.min_end_time) - to_unix_s(first.timestamp) == pytest.approx(12.4)
    assert snaps[1].movement(1).state_time_speed[0].event_state is MovementPhaseState.UNAVAILABLE
    assert read_spat_csv(path, {"K648": 7})[0].id == 7


def test_a_max_end_an_hour_ahead_is_unknown_not_a_bound(tmp_path):
    snap = read_spat_csv(
        _write(
            tmp_path,
            "2019-05-01T16:04:25.609Z,K648,3,3,2019-05-01T16:05:04.009Z,2019-05-01T17:04:25.609Z\n"
            "2019-05-01T16:04:25.609Z,K648,5,3,2019-05-01T16:04:46.009Z,2019-05-01T16:07:21.009Z\n",
        )
    )[0]
    t0 = to_unix_s(snap.timestamp)
    unknown = plan_from_movement(snap.movement(3), t0)
    assert math.isinf(unknown.changes[0].max_end_s) and unknown.changes[0].min_end_s == pytest.approx(t0 + 38.4, abs=1e-3)
    bounded = plan_from_movement(snap.movement(5), t0)
    assert bounded.changes[0].max_end_s == pytest.approx(t0 + 175.4, abs=1e-3)
    assert plan_from_movement(snap.movement(3)).changes[0].max_end_s == pytest.approx(t0 + 3600.0, abs=1e-3)  # no timestamp: as written


@pytest.mark.parametrize(
    ("body", "says"),
    [
        ("2019-05-01T16:04:25.609Z,K648,1,12,2019-05-01T16:04:38.009Z,2019-05-01T16:07:13.009Z\n", "line 2: phase 12"),
        ("2019-05-01T16:04:25.609Z,K648,1,6,,2019-05-01T16:07:13.009Z\n", "line 2: missing min_end_utc"),
        ("2019-05-01T16:04:25.609Z,K648,1,6,2019-05-01T16:08:38.009Z,2019-05-01T16:07:13.009Z\n", "line 2: "),
        ("2019-05-01T16:04:25.609,K648,1,6,2019-05-01T16:04:38.009Z,2019-05-01T16:07:13.009Z\n", "no zone"),
    ],
)
def test_bad_rows_name_the_line(tmp_path, body, says):
    good = "2019-05-01T16:04:24.609Z,K648,1,6,2019-05-01T16:04:38.009Z,2019-05-01T16:07:13.009Z\n"
    with pytest.raises(RecordedLogError, match=says.replace("line 2", "line 3")):
        read_spat_csv(_write(tmp_path, good + body))


def test_missing_columns_are_named(tmp_path):
    path = tmp_path / "x.csv"
    path.write_text("time,phase\n1,2\n")
    with pytest.raises(RecordedLogError, match="missing column.*generated_utc"):
        read_spat_csv(path)


@pytest.mark.skipif(not RECORDINGS, reason="shared recordings not present")
@pytest.mark.parametrize("path", RECORDINGS, ids=lambda p: p.name)
def test_the_shared_recordings_read_whole(path, recorded_snapshots):
    """Every row, from the first snapshot to the last, with the signal groups the file names (whatever its controller:
    its facts come from its raw rows, :func:`~tests.conftest.recording_facts`). ``read_spat_csv``'s snapshots, parsed
    once for the package (``recorded_snapshots``)."""
    facts = recording_facts(path)
    snaps = recorded_snapshots(path)
    assert sum(len(s.states) for s in snaps) == facts.rows  # lossless: one movement per row
    stamps = [to_unix_s(s.timestamp) for s in snaps]
    assert stamps == sorted(stamps)
    assert stamps[0] == pytest.approx(facts.first_unix_s, abs=1e-3) and stamps[-1] == pytest.approx(facts.last_unix_s, abs=1e-3)
    assert len({s.id for s in snaps}) == len({ix for ix, _ in facts.groups})
    assert {m.signal_group for s in snaps for m in s.states} == {g for _, g in facts.groups}
    # the README's facts, read through our semantics: minEnd never in the past, windows well formed
    for s in snaps[::500]:
        for m in s.states:
            timing = m.state_time_speed[0].timing
            assert timing.min_end_time >= s.timestamp and timing.max_end_time >= timing.min_end_time
