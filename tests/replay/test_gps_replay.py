"""`replay` on GPS traces: the shipped field-test traces, GPX, validation, map matching, comparison."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from advisory.physics.params import model_params
from replay.cli import main
from replay.drive import score_drive, smooth_speed_mps
from replay.matching import find_corridor, match
from replay.trace_io import read_trace
from spat_feed.road.corridors import load_corridor

DATA = Path(__file__).resolve().parents[2] / "replay" / "data"
ADVISED, REGULAR, GPX = DATA / "field_test_advised.csv", DATA / "field_test_regular.csv", DATA / "field_test_advised.gpx"


def run_json(capsys, *argv) -> tuple[int, dict]:
    rc = main([*map(str, argv), "--json"])
    return rc, json.loads(capsys.readouterr().out)


def test_entry_point_scores_the_shipped_advised_trace():
    """Through the installed console script, as a user runs it."""
    exe = Path(sys.executable).with_name("replay")
    out = subprocess.run([str(exe), str(ADVISED), "--json"], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    d = json.loads(out.stdout)
    assert d["corridor"]["name"] == "paper_s400" and d["timing"] == "field_test" and d["complete"]
    assert d["distance_m"] == pytest.approx(600, rel=0.02)
    saved = d["comparison"]["savings_frac"]  # positive = less than the regular driver, as the service's
    assert saved["driven"]["energy"] > 0.2 and saved["driven"]["cost"] > 0.2  # the advised drive saves
    assert saved["dp_optimum"]["cost"] >= saved["driven"]["cost"]  # and the optimum saves more


def test_regular_trace_reads_like_the_model_regular_driver(capsys):
    rc, d = run_json(capsys, REGULAR)
    assert rc == 0
    c = d["comparison"]
    assert c["driven"]["energy_kwh"] == pytest.approx(c["regular"]["energy_kwh"], rel=0.08)  # GPS noise and 1 Hz only
    assert c["driven"]["duration_s"] == pytest.approx(c["regular"]["duration_s"], abs=1.5)


def test_field_test_reproduction_against_the_regular_trace(capsys):
    rc, d = run_json(capsys, ADVISED, "--baseline", REGULAR)
    assert rc == 0
    saved = d["baseline"]["savings_frac"]
    assert 0.2 < saved["energy"] < 0.6 and 0.2 < saved["wear"] < 0.6 and 0.2 < saved["cost"] < 0.6  # paper: 29 / 38 / 32 %


def test_gpx_gives_the_same_score_as_the_csv(capsys):
    _, a = run_json(capsys, ADVISED, "--no-compare")
    _, b = run_json(capsys, GPX, "--no-compare")
    assert b["timing"] == "field_test" and b["corridor"]["name"] == "paper_s400"
    assert b["net_kwh"] == pytest.approx(a["net_kwh"], rel=1e-3)


def test_table_output_and_plot(tmp_path, capsys):
    png = tmp_path / "panels.png"
    assert main([str(ADVISED), "--plot", str(png)]) == 0
    out = capsys.readouterr().out
    assert "Comparison through the same lights" in out and "DP optimum vs regular" in out
    assert png.stat().st_size > 10_000


def _rewrite(tmp_path: Path, src: Path, *, keep_meta=True, edit=None) -> Path:
    lines = src.read_text().splitlines()
    meta = [ln for ln in lines if ln.startswith("#")]
    body = [ln for ln in lines if not ln.startswith("#")]
    if edit:
        body = edit(body)
    f = tmp_path / src.name
    f.write_text("\n".join((meta if keep_meta else []) + body) + "\n")
    return f


def test_duplicates_backward_times_and_gaps_are_handled_and_reported(tmp_path, capsys):
    def edit(body):
        hdr, rows = body[0], body[1:]
        rows = rows[:10] + [rows[9], rows[5]] + rows[10:30] + rows[34:]  # duplicate, backward, 5 s gap
        return [hdr, *rows]

    rc, d = run_json(capsys, _rewrite(tmp_path, ADVISED, edit=edit))
    assert rc == 0
    notes = " ".join(d["notes"])
    assert "duplicate timestamp dropped (line(s) 18)" in notes  # 6 meta lines + header + 11th row
    assert "older than the fix before dropped (line(s) 19)" in notes
    assert "gap(s) longer than" in notes


def test_speed_from_positions_when_the_fixes_have_none(tmp_path, capsys):
    def edit(body):
        return [",".join(c for i, c in enumerate(row.split(",")) if i != 3) for row in body]  # drop speed_mps

    rc, d = run_json(capsys, _rewrite(tmp_path, ADVISED, edit=edit))
    assert rc == 0 and d["fixes"]["speed_source"] == "positions" and d["fixes"]["smooth_s"] == 1.0
    _, ref = run_json(capsys, ADVISED)
    assert d["comparison"]["driven"]["energy_kwh"] == pytest.approx(ref["comparison"]["driven"]["energy_kwh"], rel=0.15)


def test_corridor_found_by_map_matching_without_header(tmp_path, capsys):
    f = _rewrite(tmp_path, ADVISED, keep_meta=False)
    rc, d = run_json(capsys, f, "--timing", "field_test", "--entry", "1714557600")
    assert rc == 0
    assert d["corridor"]["how"].startswith("found by map matching")
    assert d["corridor"]["name"] in ("paper_s400", "paper_s600")  # all paper corridors share the road
    rc, d = run_json(capsys, f, "--corridor", "paper_s400")
    assert d["corridor"]["how"] == "given" and d["timing"] is None
    assert d["comparison"]["against"] == "recorded stops" and d["comparison"]["dp_optimum"] is None  # no timing: on its own stops


def test_a_drive_without_timing_is_compared_on_its_own_stops(tmp_path, capsys):
    """Finding: a real GPS drive with no signal timing got no comparison at all. Now the regular driver is held at
    the drive's own standstills; independent answer: the paper's regular driver, recorded (1 Hz, GPS noise), against
    the regular driver held at its own recorded stops is the same driver: it saves nothing."""
    f = _rewrite(tmp_path, REGULAR, keep_meta=False)
    rc, d = run_json(capsys, f, "--corridor", "paper_s400")
    c = d["comparison"]
    assert rc == 0 and d["timing"] is None and c["against"] == "recorded stops"
    # it stood at light 1 (100 m) and light 2 (500 m), 1 m short of each line, until each turned green (15 s, 60 s)
    assert [round(st["position_m"]) for st in c["recorded_stops"]] == [98, 499]
    assert [st["until_s"] for st in c["recorded_stops"]] == [pytest.approx(14.0, abs=1.5), pytest.approx(59.0, abs=1.5)]
    assert abs(c["savings_frac"]["driven"]["energy"]) < 0.03 and abs(c["savings_frac"]["driven"]["cost"]) < 0.03
    assert c["regular"]["duration_s"] == pytest.approx(c["driven"]["duration_s"], abs=2.0)
    assert any("--timing PLAN.json" in n for n in d["notes"])  # says how to give timing
    # the EPA cycles beside its energy per km, same vehicle
    cycles = {x["cycle"]: x for x in d["epa_cycles"]}
    assert set(cycles) == {"udds", "hwfet"}
    for x in cycles.values():
        assert x["ratio"] == pytest.approx(d["end_state_wh_per_km"] / x["wh_per_km"])
    out = capsys.readouterr().out if main([str(f), "--corridor", "paper_s400"]) == 0 else ""
    assert "Comparison on the drive's own stops" in out and "EPA UDDS (city)" in out and "EPA HWFET (highway)" in out


def test_shipped_epa_cycles_are_the_epa_schedules():
    """The cycles `replay` compares with: the EPA's UDDS (1369 s, 7.45 mi = 11.99 km) and HWFET (765 s, 10.26 mi = 16.51 km)."""
    from replay.cycles import load_cycle

    for name, duration_s, km in (("udds", 1369.0, 11.99), ("hwfet", 765.0, 16.51)):
        t, v = load_cycle(name)
        assert t[-1] - t[0] == duration_s and np.all(np.diff(t) == 1.0)
        assert float(np.sum(0.5 * (v[1:] + v[:-1]))) / 1000 == pytest.approx(km, abs=0.01)


def test_every_timing_an_error_lists_is_accepted(tmp_path, capsys):
    """Finding: `--timing plausible` was listed as a choice (a plan of another corridor) and then refused."""
    f = _rewrite(tmp_path, ADVISED, keep_meta=False)
    assert main([str(f), "--timing", "nope", "--no-compare"]) == 2
    err = capsys.readouterr().err
    listed = json.loads(err[err.index("choose from ") + len("choose from ") : err.index("]") + 1].replace("'", '"'))
    assert "plausible" not in listed and "'trip'" in err  # the trace follows a paper corridor: no Oakland plan
    for name in [*listed, "trip"]:
        assert main([str(f), f"--timing={name}", "--no-compare"]) in (0, 1), name
    capsys.readouterr()


def test_off_corridor_error_says_how_far_and_how_to_make_one(tmp_path, capsys):
    """Finding: off every corridor, the error did not say how far the trace was, nor how to make a corridor."""
    f = _rewrite(tmp_path, ADVISED, keep_meta=False, edit=lambda body: [body[0]] + [_shift_lat(row, 0.01) for row in body[1:]])  # ~1.1 km north
    assert main([str(f)]) == 2
    err = capsys.readouterr().err
    for name in ("paper_s200", "paper_s400", "paper_s600", "paper_s800", "oakland_7th_westbound"):
        assert f"{name}: nearest fix" in err
    assert "paper_s400: nearest fix 1.0 km" in err and "ecodrive corridor from-osm" in err and "--corridor" in err
    assert main([str(f), "--corridor", "paper_s400"]) == 2
    err = capsys.readouterr().err
    assert "paper_s400: nearest fix 1.0 km" in err and "ecodrive corridor from-osm" in err


def _shift_lat(row: str, dlat_deg: float) -> str:
    cells = row.split(",")
    cells[1] = f"{float(cells[1]) + dlat_deg:.7f}"
    return ",".join(cells)


def test_trimmed_trace_is_incomplete_exit_1(tmp_path, capsys):
    f = _rewrite(tmp_path, ADVISED, edit=lambda body: body[:45])
    rc, d = run_json(capsys, f)
    assert rc == 1 and not d["complete"]
    stop_m = d["comparison"]["compared_m"]
    assert 0 < stop_m < 600 and any(f"compared over those {stop_m:.1f} m" in n for n in d["notes"])  # over the distance it drove
    assert d["comparison"]["regular"]["distance_m"] == pytest.approx(stop_m, abs=5.0) and d["comparison"]["dp_optimum"] is None


@pytest.mark.parametrize(
    "content,needle",
    [
        ("time,lat,lon\n0,48.86,2.32\n1,48.86,abc\n", ":3: 'lon' is not a number: 'abc'"),
        ("time,lat,lon\n0,48.86,2.32\nyesterday,48.86,2.32\n", ":3: 'time' is not a time"),
        ("# corridor: paper_s400\ntime,lat,lon,speed_mps\n0,48.86,2.32,1\n1,48.86,2.32,-3\n", ":4: 'speed_mps' = -3 is outside"),
        ("time,lat,lon\n0,95,2.32\n", ":2: 'lat' = 95 is outside"),
        ("time,lat,lon\n0,48.86,2.32\n0,48.86,2.32\n", "at least two fixes"),
        ("time,lat,lon\n0,0.0,0.0\n1,0.0,0.0001\n", "follows none of the corridors"),
        ("# corridor: paper_s400\n# timing: nope\ntime,lat,lon\n0,48.8658,2.3176\n10,48.8665,2.3146\n", "unknown timing 'nope'"),
    ],
)
def test_malformed_gps_files_name_the_line(tmp_path, capsys, content, needle):
    f = tmp_path / "bad.csv"
    f.write_text(content)
    assert main([str(f)]) == 2
    assert needle in capsys.readouterr().err


def test_malformed_gpx(tmp_path, capsys):
    f = tmp_path / "bad.gpx"
    f.write_text("<gpx><trk><trkseg><trkpt lat='48.86' lon='2.32'></trkpt>")
    assert main([str(f)]) == 2
    assert "bad.gpx" in capsys.readouterr().err


def test_matching_agrees_with_corridor_project():
    cor = load_corridor("paper_s400")
    stations = np.array([3.0, 99.0, 250.0, 555.0])
    lat, lon = zip(*(cor.position(s) for s in stations), strict=True)
    m = match(cor, lat, lon)
    np.testing.assert_allclose(m.station_m, stations, atol=0.01)
    np.testing.assert_allclose(m.cross_track_m, 0.0, atol=0.01)
    before = match(cor, *zip(cor.position(-50.0), strict=True))  # extended before the entry
    assert before.station_m[0] == pytest.approx(-50.0, abs=0.05)
    choice = find_corridor(lat, lon)
    assert choice.matched.median_offset_m < 0.1


def test_smoothing_keeps_constants_and_score_drive_is_reusable():
    t = np.arange(0.0, 10.0)
    assert np.allclose(smooth_speed_mps(t, np.full(10, 7.0), 2.0), 7.0)
    trace = read_trace(ADVISED)
    r = score_drive(trace, model_params("paper_54kwh"), compare=False)
    assert r.regular is None and r.scenario is not None and len(r.scenario.signals) == 2


def _spat_log(path: Path, corridor: str, timing: str, entry_unix_s: float, span_s: tuple[float, float]) -> Path:
    """A recorded SPaT log (JSON lines, as the service's recorder writes them) of a simulated timing, a snapshot a second."""
    from spat_feed.transport.player import JsonlRecorder
    from spat_feed.transport.scenarios import make_scenario, spat_message_at

    fs = make_scenario(corridor, timing, entry_unix_s)
    rec = JsonlRecorder(path)
    for k in np.arange(span_s[0], span_s[1], 1.0):
        for ix in spat_message_at(fs, entry_unix_s + k + 0.25).intersections:
            rec(ix)
    rec.close()
    return path


def test_a_recorded_spat_log_gives_the_timing_by_time(tmp_path, capsys):
    """`--timing LOG.jsonl`: the lights as they ran when the fixes were taken. Independent answer: a log of the
    field-test timing gives the field-test comparison (the plan itself), to the printed digit."""
    log = _spat_log(tmp_path / "spat.jsonl", "paper_s400", "field_test", 1714557600.0, (-60.0, 150.0))
    f = _rewrite(tmp_path, ADVISED, edit=None)
    f.write_text("".join(ln + "\n" for ln in f.read_text().splitlines() if not ln.startswith(("# timing", "# entry"))))
    rc, by_log = run_json(capsys, f, "--timing", str(log))
    rc_plan, by_plan = run_json(capsys, ADVISED)
    assert rc == rc_plan == 0 and by_log["comparison"]["against"] == "lights" and by_log["red_light_crossings"] == []
    for key in ("energy", "wear", "cost"):
        assert by_log["comparison"]["savings_frac"]["driven"][key] == pytest.approx(by_plan["comparison"]["savings_frac"]["driven"][key], abs=0.005)
    assert by_log["comparison"]["regular"]["energy_kwh"] == pytest.approx(by_plan["comparison"]["regular"]["energy_kwh"], rel=0.01)
    # a log that does not cover the drive, or lacks a light of the corridor: an error that says so
    short = _spat_log(tmp_path / "short.jsonl", "paper_s400", "field_test", 1714557600.0, (-60.0, 20.0))
    assert main([str(f), "--timing", str(short)]) == 2 and "the log must cover the drive" in capsys.readouterr().err
    other = _spat_log(tmp_path / "oakland.jsonl", "oakland_7th_westbound", "plausible", 1714557600.0, (-60.0, 150.0))
    assert main([str(f), "--timing", str(other)]) == 2 and "no SPaT of intersection 1" in capsys.readouterr().err
