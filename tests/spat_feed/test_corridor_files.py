"""Corridor schema v2 and signal-plan files: versions, limits per segment, plans by time of day, errors that
name the file, the field and the reason, folders of files, timing resolution, tables per corridor."""

from __future__ import annotations

import doctest
import json
from datetime import datetime
from zoneinfo import ZoneInfo

import numpy as np
import pytest

from advisory.physics.params import SPEED_LIMIT_MPS, model_params
from spat_feed import files
from spat_feed.timing import signal_plans
from spat_feed.road.corridor_tables import cache_key, corridor_tables, table_timings, variants_of
from spat_feed.road.corridors import (
    SCHEMA_VERSION,
    Corridor,
    FileFormatError,
    load_corridor,
    load_corridor_dir,
    load_plan,
    paper_corridor,
    preset_names,
)
from spat_feed.transport.scenarios import FeedScenario, advisory_scenario_at, make_scenario, resolve_timing, spat_message_at
from spat_feed.timing.signal_plans import SignalPlan, light_plans_at


def test_doctests_of_the_file_modules():
    for module in (files, signal_plans):
        assert doctest.testmod(module).failed == 0


def corridor_doc(**update) -> dict:
    doc = json.loads(paper_corridor(400.0).model_dump_json())
    doc.update(update)
    return doc


def plan_doc(**update) -> dict:
    doc = {
        "kind": "signal_plan",
        "name": "weekday",
        "corridor": "paper_s400",
        "time_zone": "Europe/Paris",
        "default_pattern": "day",
        "schedule": [{"days": ["mon", "tue", "wed", "thu", "fri"], "start": "07:00", "end": "09:30", "pattern": "peak"}],
        "patterns": {
            "day": {"lights": [{"intersection_id": 1, "red_s": 30, "green_s": 26, "amber_s": 4, "offset_s": 30},
                               {"intersection_id": 2, "red_s": 30, "green_s": 26, "amber_s": 4, "offset_s": 50}]},
            "peak": {"lights": [{"intersection_id": 1, "red_s": 40, "green_s": 46, "amber_s": 4, "cycle_s": 90, "offset_s": 0},
                                {"intersection_id": 2, "kind": "live"}]},
        },
    }  # fmt: skip
    doc.update(update)
    return doc


def write(path, doc) -> str:
    path.write_text(json.dumps(doc), encoding="utf-8")
    return str(path)


def test_version_1_files_still_load_and_version_2_adds_limits_units_plans(tmp_path):
    v1 = corridor_doc()
    for key in ("schema_version", "units", "speed_limit_mps", "segments", "plans", "default_plan"):
        v1.pop(key, None)
    old = load_corridor(write(tmp_path / "v1.json", v1))
    assert old.schema_version == 1 and old.units == "metric" and old.segments == () and old.speed_limit_mps is None
    assert old.zone_speed_limit_mps(20.0) == 20.0  # no limit in the file: the caller's default
    new = load_corridor("paper_s400")
    assert new.schema_version == SCHEMA_VERSION == 2 and new.zone_speed_limit_mps(10.0) == SPEED_LIMIT_MPS
    seg = corridor_doc(segments=[{"start_m": 0, "end_m": 250, "speed_limit_mps": 13.9}, {"start_m": 250, "end_m": 600, "grade_frac": 0.03}])
    c = load_corridor(write(tmp_path / "seg.json", seg))
    assert c.speed_limit_mps_over(0, 100) == 13.9 and c.speed_limit_mps_over(300, 500) == SPEED_LIMIT_MPS
    assert c.zone_speed_limit_mps() == 13.9 and c.advisory_limit_mps(260.0) == SPEED_LIMIT_MPS and c.advisory_limit_mps(0.0) == 13.9
    starts, limits, grades = c.limit_profile()
    assert starts.tolist() == [0, 250] and limits.tolist() == [13.9, SPEED_LIMIT_MPS] and grades.tolist() == [0, 0.03]
    toml = tmp_path / "c.toml"
    toml.write_text('name = "tiny"\nlength_m = 100.0\nintersections = []\nunits = "imperial"\n'
                    '[[polyline]]\nlat_deg = 37.8\nlon_deg = -122.3\nstation_m = 0.0\n'
                    '[[polyline]]\nlat_deg = 37.8009\nlon_deg = -122.3\nstation_m = 100.0\n', encoding="utf-8")  # fmt: skip
    assert load_corridor(toml).units == "imperial"


@pytest.mark.parametrize(
    "doc, field, reason",
    [
        (corridor_doc(schema_version=3), "schema_version", "newer than this program"),
        (corridor_doc(units="furlongs"), "units", "'metric' or 'imperial'"),
        (corridor_doc(segments=[{"start_m": 0, "end_m": 300}]), "(file)", "cover [0, length_m]"),
        (corridor_doc(segments=[{"start_m": 0, "end_m": 600, "speed_limit_mps": 700}]), "segments[0].speed_limit_mps", "less than or equal to 70"),
        (corridor_doc(lenght_m=600), "lenght_m", "unknown field"),
        (corridor_doc(polyline=[{"lat_deg": 48.8, "lon_deg": 2.3, "station_m": 0}]), "polyline", "at least 2"),
    ],
)
def test_corridor_file_errors_name_the_file_the_field_and_the_reason(tmp_path, doc, field, reason):
    path = write(tmp_path / "bad.json", doc)
    with pytest.raises(FileFormatError) as info:
        load_corridor(path)
    assert any(p.startswith(f"{field}:") and reason in p for p in info.value.problems), info.value.problems
    assert str(info.value).startswith(f"{path}: ")


def test_syntax_errors_name_the_line(tmp_path):
    path = tmp_path / "broken.json"
    path.write_text('{\n "name": "x",\n "length_m": 10,,\n}\n', encoding="utf-8")
    with pytest.raises(FileFormatError, match=r"broken.json: line 3 column 17: not valid JSON"):
        load_corridor(path)


@pytest.mark.parametrize(
    "update, message",
    [
        ({"time_zone": "Mars/Olympus"}, "time_zone: unknown time zone"),
        ({"default_pattern": None}, "default_pattern is required"),
        ({"schedule": [{"start": "09:00", "end": "07:00", "pattern": "day"}]}, "schedule[0]: start 09:00 must be before end 07:00"),
        ({"schedule": [{"start": "7h", "end": "09:00", "pattern": "day"}]}, "schedule[0].start: '7h' is not a time of day"),
        ({"schedule": [{"start": "07:00", "end": "09:00", "pattern": "rush"}]}, "no pattern 'rush'"),
        ({"patterns": {"day": {"lights": [{"intersection_id": 1, "red_s": 30, "green_s": 30}]}}}, "a fixed light needs offset_s"),
        ({"patterns": {"day": {"lights": [{"intersection_id": 1, "red_s": 30, "green_s": 30, "cycle_s": 90, "offset_s": 0}]}}}, "cycle_s 90 != red_s + green_s + amber_s = 60"),
        ({"patterns": {"day": {"lights": [{"intersection_id": 1, "kind": "live", "red_s": 3}]}}}, "a live light takes no fixed timing"),
    ],
)
def test_plan_file_errors_name_the_field_and_the_reason(tmp_path, update, message):
    path = write(tmp_path / "plan.json", plan_doc(**update))
    with pytest.raises(FileFormatError) as info:
        load_plan(path)
    assert message in str(info.value) and str(info.value).startswith(str(path))


def test_a_plan_that_does_not_fit_its_corridor_names_the_pattern_and_the_light(tmp_path):
    missing = plan_doc(schedule=[], default_pattern=None, patterns={"day": {"lights": [{"intersection_id": 1, "red_s": 30, "green_s": 30, "offset_s": 0}]}})
    with pytest.raises(FileFormatError, match=r"plan.json: patterns.day.lights: no timing for intersection\(s\) \[2\]"):
        load_corridor("paper_s400", plans=(write(tmp_path / "plan.json", missing),))
    wrong_group = plan_doc()
    wrong_group["patterns"]["day"]["lights"][0]["signal_group"] = 7
    with pytest.raises(FileFormatError, match=r"lights\[0\].signal_group: 7 is not a signal group of intersection 1"):
        load_corridor("paper_s400", plans=(write(tmp_path / "plan.json", wrong_group),))
    other = plan_doc(corridor="elsewhere")
    with pytest.raises(FileFormatError, match="is for corridor 'elsewhere'"):
        load_corridor("paper_s400", plans=(write(tmp_path / "plan.json", other),))


def test_patterns_by_local_time_of_day_and_their_plans_on_the_unix_axis(tmp_path):
    plan = load_plan(write(tmp_path / "plan.json", plan_doc()))
    paris = ZoneInfo("Europe/Paris")
    monday_8 = datetime(2024, 7, 1, 8, 0, tzinfo=paris).timestamp()  # CEST, UTC+2
    saturday_8 = datetime(2024, 7, 6, 8, 0, tzinfo=paris).timestamp()
    midnight = datetime(2024, 7, 1, 0, 0, tzinfo=paris).timestamp()
    assert plan.pattern_at(monday_8) == ("peak", midnight)
    assert plan.pattern_at(saturday_8)[0] == "day"
    assert plan.next_switch_unix_s(monday_8) == datetime(2024, 7, 1, 9, 30, tzinfo=paris).timestamp()
    corridor = load_corridor("paper_s400", plans=(str(tmp_path / "plan.json"),))
    # day pattern: green starts 30 s after midnight, red 30 s: red begins at local midnight, every 60 s
    plans = light_plans_at(corridor, t_unix_s=saturday_8)
    p1 = plans[(1, 2)]
    assert (p1.red_s, p1.green_s, p1.amber_s) == (30.0, 26.0, 4.0) and (p1.offset_s - datetime(2024, 7, 6, tzinfo=paris).timestamp()) % 60.0 == 0.0
    assert light_plans_at(corridor, t_unix_s=monday_8)[(2, 2)] is None  # live in the peak
    # a trip entering on Monday 08:00 gets the peak pattern; the live light has no simulated state
    sc = make_scenario(corridor, None, monday_8)
    assert sc.timing.name == "weekday" and set(sc.fixed_plans()) == {(1, 2)}
    msg = spat_message_at(sc, monday_8 + 5.0)
    assert [ix.id for ix in msg.intersections] == [1]
    with pytest.raises(ValueError, match="live"):
        advisory_scenario_at(sc, monday_8)
    # paper corridors without plans: the paper's 15_15 on the given axis
    assert light_plans_at(load_corridor("paper_s200"), entry_unix_s=100.0)[(1, 2)].offset_s == 115.0


def test_zone_entry_plans_reproduce_the_paper_timings(tmp_path):
    doc = plan_doc(reference="zone_entry", schedule=[], default_pattern=None, time_zone="UTC",
                   patterns={"p": {"lights": [{"intersection_id": 1, "red_s": 30, "green_s": 30, "offset_s": 15.0},
                                              {"intersection_id": 2, "red_s": 30, "green_s": 30, "offset_s": 45.0}]}})  # fmt: skip
    plan = load_plan(write(tmp_path / "p.json", doc))
    corridor = load_corridor("paper_s400")
    mine = advisory_scenario_at(FeedScenario(corridor, plan, 1000.0), 1000.0)
    paper = make_scenario(corridor, "-15_15", 1000.0).advisory_scenario()
    assert [(s.red_start_s % 60, s.red_s, s.green_s) for s in mine.signals] == [(s.red_start_s % 60, s.red_s, s.green_s) for s in paper.signals]


def test_resolve_timing_names_presets_plans_and_files(tmp_path):
    corridor = load_corridor("paper_s400")
    assert resolve_timing(corridor, "15_15").name == "15_15"
    assert resolve_timing(corridor, None, 61.0).name == "-30_-15"  # trip: one of the 16 by entry minute
    path = write(tmp_path / "plan.json", plan_doc())
    assert resolve_timing(corridor, path).name == "weekday"
    with pytest.raises(KeyError, match="unknown timing"):
        resolve_timing(corridor, path, allow_files=False)  # never a path from a request
    with pytest.raises(KeyError, match="unknown timing 'nope'"):
        resolve_timing(corridor, "nope")
    oakland = load_corridor("oakland_7th_westbound")
    assert resolve_timing(oakland, None).name == "plausible" and resolve_timing(oakland, "plausible").name == "plausible"
    with pytest.raises(ValueError, match="has 2 lights"):
        make_scenario(paper_corridor(400.0).model_copy(update={"intersections": paper_corridor(400.0).intersections[:1]}), "15_15")


def test_a_folder_of_corridor_and_plan_files(tmp_path):
    write(tmp_path / "mine.json", corridor_doc(name="mine"))
    write(tmp_path / "mine-plan.json", plan_doc(corridor="mine"))
    (tmp_path / "notes.txt").write_text("ignored", encoding="utf-8")
    loaded = load_corridor_dir(tmp_path)
    assert list(loaded) == ["mine"] and loaded["mine"].plan().name == "weekday"
    write(tmp_path / "stray.json", plan_doc(corridor="nowhere", name="stray"))
    with pytest.raises(FileFormatError, match=r"stray.json: corridor: 'nowhere' names no corridor"):
        load_corridor_dir(tmp_path)
    (tmp_path / "stray.json").unlink()
    write(tmp_path / "twin.json", corridor_doc(name="mine"))
    with pytest.raises(FileFormatError, match="also defined in"):
        load_corridor_dir(tmp_path)


def test_shipped_presets_and_plans():
    assert {"paper_s200", "paper_s400", "paper_s600", "paper_s800", "oakland_7th_westbound"} <= set(preset_names())
    oakland = load_corridor("oakland_7th_westbound")
    assert oakland.units == "imperial" and len(oakland.intersections) == 2 and oakland.plan().name == "plausible"
    assert "NOT MEASURED" in oakland.plan().source
    assert Corridor.model_json_schema()["properties"]["schema_version"]["default"] == 1
    assert "patterns" in SignalPlan.model_json_schema()["properties"]


def test_table_variants_cache_and_build_for_a_plan_with_several_patterns(tmp_path):
    oakland = load_corridor("oakland_7th_westbound")
    variants = variants_of(oakland, oakland.plan())
    assert len(variants) == 3 and {round(v[0].cycle_s) for v in variants} == {70, 90, 100}
    assert len(table_timings(load_corridor("paper_s400"))) == 17 and table_timings(load_corridor("paper_s400").model_copy(update={"intersections": ()})) == []
    params = model_params()
    tables, report = corridor_tables(oakland, params, cache_dir=tmp_path, workers=1)
    assert not report.loaded and report.path.exists() and tables.n_tables == 9
    again, report2 = corridor_tables(oakland, params, cache_dir=tmp_path, workers=1)
    assert report2.loaded and report2.path == report.path and again.n_tables == 9
    # another plan (or grid, or vehicle) is another key
    slower = [tuple(None if s is None else type(s)(s.position_m, s.red_start_s + 1.0, s.red_s, s.green_s) for s in v) for v in variants]
    assert cache_key(oakland, slower, params, tables.grid) != cache_key(oakland, variants, params, tables.grid)
    assert cache_key(oakland, variants, model_params("calibrated"), tables.grid) != cache_key(oakland, variants, params, tables.grid)
    assert np.isclose(tables.speed_limit_mps, 13.4112)
