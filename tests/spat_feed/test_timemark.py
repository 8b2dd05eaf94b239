"""J2735 TimeMark: encoding, decoding, the hour rollover, the special values."""

from __future__ import annotations

from datetime import datetime, timezone

import pytest
from hypothesis import given
from hypothesis import strategies as st

from spat_feed.timing.timemark import (
    FUTURE_WINDOW_START_S,
    PAST_WINDOW_START_S,
    TIMEMARK_BEYOND_HOUR,
    TIMEMARK_UNKNOWN,
    timemark_to_unix,
    unix_to_timemark,
)


def utc(*args) -> float:
    return datetime(*args, tzinfo=timezone.utc).timestamp()


def test_tenths_since_the_top_of_the_hour():
    assert unix_to_timemark(utc(2024, 5, 1, 12, 0, 0)) == 0
    assert unix_to_timemark(utc(2024, 5, 1, 12, 34, 56, 700_000)) == (34 * 60 + 56) * 10 + 7
    assert unix_to_timemark(utc(2024, 5, 1, 12, 59, 59, 900_000)) == 35_999


def test_encoding_rounds_to_the_nearest_tenth_and_wraps_at_the_hour():
    assert unix_to_timemark(utc(2024, 5, 1, 12, 0, 0, 40_000)) == 0
    assert unix_to_timemark(utc(2024, 5, 1, 12, 0, 0, 60_000)) == 1
    assert unix_to_timemark(utc(2024, 5, 1, 12, 59, 59, 960_000)) == 0  # rounds into the next hour


def test_special_values():
    ref = utc(2024, 5, 1, 12, 0)
    assert unix_to_timemark(None) == TIMEMARK_UNKNOWN
    assert unix_to_timemark(float("inf")) == TIMEMARK_BEYOND_HOUR
    assert unix_to_timemark(ref + 3600.1, ref_unix_s=ref) == TIMEMARK_BEYOND_HOUR
    assert unix_to_timemark(ref + 3600.0, ref_unix_s=ref) == 0  # exactly an hour ahead is still in range
    assert timemark_to_unix(TIMEMARK_BEYOND_HOUR, ref) is None
    assert timemark_to_unix(TIMEMARK_UNKNOWN, ref) is None
    for bad in (-1, 36_002, 1.5, "10"):
        with pytest.raises(ValueError):
            timemark_to_unix(bad, ref)


def test_leap_second_values_fold_onto_the_last_second():
    ref = utc(2016, 12, 31, 23, 59, 59)  # the last leap second so far was inserted right after this
    assert timemark_to_unix(35_995, ref, PAST_WINDOW_START_S) == pytest.approx(ref + 0.5, abs=1e-3)


def test_rollover_change_time_in_the_next_hour():
    ref = utc(2024, 5, 1, 12, 59, 58)
    change = utc(2024, 5, 1, 13, 0, 5)  # 7 s ahead, in the next hour
    tm = unix_to_timemark(change, ref)
    assert tm == 50
    assert timemark_to_unix(tm, ref) == pytest.approx(change, abs=1e-3)


def test_rollover_start_time_in_the_previous_hour():
    ref = utc(2024, 5, 1, 13, 0, 2)
    start = utc(2024, 5, 1, 12, 50, 0)
    tm = unix_to_timemark(start)
    assert tm == 30_000
    assert timemark_to_unix(tm, ref, PAST_WINDOW_START_S) == pytest.approx(start, abs=1e-3)
    assert timemark_to_unix(unix_to_timemark(ref - 22.0), ref, PAST_WINDOW_START_S) == pytest.approx(ref - 22.0, abs=0.051)
    # read as a change time, a mark 10 min back is 50 min ahead: the window choice matters
    assert timemark_to_unix(tm, ref, FUTURE_WINDOW_START_S) == pytest.approx(start + 3600, abs=1e-3)


def test_rollover_at_midnight_and_new_year():
    ref = utc(2024, 12, 31, 23, 59, 59, 500_000)
    change = utc(2025, 1, 1, 0, 0, 1)
    assert timemark_to_unix(unix_to_timemark(change), ref) == pytest.approx(change, abs=1e-3)


@given(ref=st.floats(1e9, 2e9), ahead_s=st.floats(-299.9, 3299.9))
def test_change_times_round_trip(ref, ahead_s):
    t = ref + ahead_s
    back = timemark_to_unix(unix_to_timemark(t, ref), ref)
    assert back == pytest.approx(t, abs=0.05 + 1e-6)  # half a tenth, plus float64 resolution at 2e9 s (2.4e-7 s)


@given(ref=st.floats(1e9, 2e9), behind_s=st.floats(-299.9, 3299.9))
def test_start_times_round_trip(ref, behind_s):
    t = ref - behind_s
    back = timemark_to_unix(unix_to_timemark(t), ref, PAST_WINDOW_START_S)
    assert back == pytest.approx(t, abs=0.05 + 1e-6)  # half a tenth, plus float64 resolution at 2e9 s (2.4e-7 s)
