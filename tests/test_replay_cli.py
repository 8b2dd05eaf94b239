import json

import pytest

from replay.cli import main
from tests.conftest import CYCLES


def test_scores_a_shipped_cycle(capsys):
    if not (CYCLES / "udds.csv").exists():
        pytest.skip("shared cycles not present")
    assert main([str(CYCLES / "udds.csv"), "--json", "--vehicle", "calibrated"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["distance_m"] == pytest.approx(11990, abs=10)
    assert out["total_usd"] == pytest.approx(out["electricity_usd"] + out["wear_usd"])


def test_table_output_and_units(tmp_path, capsys):
    f = tmp_path / "drive.csv"
    f.write_text("time,speed_kmh\n0,0\n10,36\n20,36\n30,0\n")
    assert main([str(f)]) == 0
    out = capsys.readouterr().out
    assert "0.200 km" in out  # 50 + 100 + 50 m and "Wh/km" in out


@pytest.mark.parametrize(
    "content,needle",
    [
        ("t_s,speed_mps\n0,1\n1,abc\n", ":3: 'speed_mps' is not a number"),
        ("t_s,speed_mps\n0,1\n0,2\n", ":3: time 0.0 does not increase"),
        ("t_s,speed_mps\n0,1\n1,-2\n", ":3: negative speed"),
        ("t_s,velocity\n0,1\n", ":1: missing column"),
        ("t_s,speed_mps\n0,1\n", "at least two"),
        ("", "empty file"),
    ],
)
def test_bad_files_get_an_error_naming_the_line(tmp_path, capsys, content, needle):
    f = tmp_path / "bad.csv"
    f.write_text(content)
    assert main([str(f)]) == 2
    assert needle in capsys.readouterr().err


def test_missing_file(capsys, tmp_path):
    assert main([str(tmp_path / "nope.csv")]) == 2
    assert "cannot open" in capsys.readouterr().err
