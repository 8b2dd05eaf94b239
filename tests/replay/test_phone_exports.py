"""`replay` reads real phone exports (issue 15, "replay"): each style of the same drive scores like our own CSV.

The fixtures in ``tests/replay/data/phone/`` are ``replay/data/field_test_advised.csv`` written the way each
app documents its export (``tests/replay/make_phone_exports.py``).
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from replay.cli import main
from replay.trace_io import read_trace

PHONE = Path(__file__).resolve().parent / "data" / "phone"
OURS = Path(__file__).resolve().parents[2] / "replay" / "data" / "field_test_advised.csv"
ARGS = ["--corridor", "paper_s400", "--timing", "field_test", "--entry", "1714557600", "--json"]

STYLES = [  # file, how its time is read, where its speed comes from
    ("android_location_ms.csv", "Unix milliseconds", "'speed' [m/s]"),
    ("gpslogger.csv", "ISO 8601", "'speed' [m/s]"),
    ("sensor_logger_ns.csv", "Unix nanoseconds", "'speed' [m/s]"),
    ("epoch_us.csv", "Unix microseconds", "'Speed (km/h)' x 0.277778 -> m/s"),
    ("excel_de.csv", "ISO 8601", "'Speed (km/h)' x 0.277778 -> m/s"),
    ("osmand.gpx", "ISO 8601", "GPX extension <osmand:speed> [m/s]"),
    ("gpslogger.gpx", "ISO 8601", "GPX extension <speed> [m/s]"),
    ("garmin.gpx", "ISO 8601", "GPX extension <gpxtpx:speed> [m/s]"),
]


def run_json(capsys, *argv) -> tuple[int, dict]:
    rc = main([*map(str, argv)])
    return rc, json.loads(capsys.readouterr().out)


@pytest.fixture(scope="module")
def ours():
    rc = main([str(OURS), *ARGS])
    assert rc == 0
    return None


@pytest.mark.parametrize("name,time_read,speed_read", STYLES, ids=[s[0] for s in STYLES])
def test_each_phone_export_scores_like_our_csv(capsys, name, time_read, speed_read):
    """Findings: epoch ms read as seconds (600 km, 60,007 s, exit 0); GPX 1.1 extension speeds ignored; a
    semicolon / decimal-comma CSV failed with 'missing column(s)'. Same drive, same numbers (3 %)."""
    _, ref = run_json(capsys, OURS, *ARGS)
    rc, got = run_json(capsys, PHONE / name, *ARGS)
    assert rc == 0 and got["complete"]
    cols = got["fixes"]["columns"]
    assert time_read in cols["t_s"] and cols["speed_mps"].endswith(speed_read) and got["fixes"]["speed_source"] == "gps"
    for key in ("distance_m", "duration_s", "net_kwh"):
        assert got[key] == pytest.approx(ref[key], rel=0.03), key
    for key in ("distance_m", "duration_s", "energy_kwh"):
        assert got["comparison"]["driven"][key] == pytest.approx(ref["comparison"]["driven"][key], rel=0.03), key


def test_the_dialect_is_reported(capsys):
    assert read_trace(PHONE / "excel_de.csv").columns["file"] == "semicolon-separated, decimal comma"
    assert read_trace(PHONE / "gpslogger.csv").columns["file"] == "comma-separated"
    assert main([str(PHONE / "excel_de.csv"), "--corridor", "paper_s400", "--no-compare"]) == 0
    assert "read       semicolon-separated, decimal comma: time from 'Time' (ISO 8601)" in capsys.readouterr().out


@pytest.mark.parametrize(
    "content,needle",
    [
        ("when;where\n1;2\n", ":1: missing column(s) ['t_s', 'speed_mps']; header was ['when', 'where'] (read as semicolon-separated). Rename the header"),
        ("timestamp,latitude,longitude\n1714557592789,48.86,2.32\n1714557593,48.86,2.32\n", ":3: 'timestamp' = 1714557593 is not in Unix milliseconds like the first row"),
        ("time,lat,lon,speed\n0,48.86,2.32,1\n1,48.86,2.32,95\n", "is it in km/h? name the column speed_kmh"),
        ('time,lat,lon\n0,"48,86",2.32\n', "decimal comma need a ';' or tab separator"),
    ],
    ids=["names what to rename", "mixed time units", "km/h in m/s column", "decimal comma with comma separator"],
)
def test_errors_name_the_line_and_what_to_change(tmp_path, capsys, content, needle):
    f = tmp_path / "bad.csv"
    f.write_text(content)
    assert main([str(f)]) == 2
    err = capsys.readouterr().err
    assert needle in err, err


def test_missing_columns_say_which_names_are_accepted(tmp_path, capsys):
    f = tmp_path / "bad.csv"
    f.write_text("time;breite;laenge\n0;48,86;2,32\n")
    assert main([str(f)]) == 2
    err = capsys.readouterr().err
    assert "read as semicolon-separated, decimal comma" in err and "Rename the header" in err and "velocity" not in err


def test_a_red_light_crossing_is_flagged_and_not_a_saving(tmp_path, capsys):
    """Finding: a trace crossing a stop line during red was scored as a saving with `notes: []`."""
    from spat_feed.road.corridors import load_corridor

    cor = load_corridor("paper_s400")
    v = 50 / 3.6  # field_test: light 1 (100 m) is red until 15 s after entry; at 50 km/h it is reached at 7.2 s
    rows = ["# corridor: paper_s400", "# timing: field_test", "# entry_unix_s: 1714557600", "t_unix_s,lat,lon,speed_mps"]
    for k in range(-3, 48):
        lat, lon = cor.position(v * k)
        rows.append(f"{1714557600 + k},{lat:.7f},{lon:.7f},{v:.2f}")
    f = tmp_path / "red.csv"
    f.write_text("\n".join(rows) + "\n")
    rc, d = run_json(capsys, f, "--json", "--baseline", OURS)
    assert rc == 0 and d["comparison"]["savings_frac"]["driven"] is None and d["baseline"]["savings_frac"] is None
    first = d["red_light_crossings"][0]
    assert first["light"] == 1 and first["into_red_s"] == pytest.approx(15 + 100 / v, abs=0.5)
    assert any("not reported as a saving" in n for n in d["notes"])
    # the shipped regular and advised drives run no red light
    for trace in (OURS, OURS.with_name("field_test_regular.csv")):
        _, d = run_json(capsys, trace, "--json")
        assert d["red_light_crossings"] == [] and d["comparison"]["savings_frac"]["driven"] is not None
