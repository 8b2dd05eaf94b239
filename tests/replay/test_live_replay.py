"""`replay --server`: the shipped advised trace fed to a real ``python -m server`` on loopback."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from replay.cli import main
from tests.procs import Proc

DATA = Path(__file__).resolve().parents[2] / "replay" / "data"

ENV = {
    "ECO_CORRIDORS": "paper_s400",
    "ECO_DEFAULT_CORRIDOR": "paper_s400",
    "ECO_RATE_PER_S": "50",
    "ECO_RATE_BURST": "60",
    "ECO_SPEECH": "false",
}


@pytest.fixture(scope="module")
def service(tmp_path_factory):
    proc = Proc(["-m", "server", "--log-level", "warning", "--no-access-log"], tmp_path_factory.mktemp("live") / "service.log", ENV).start()
    yield proc
    proc.kill()


def test_replay_feeds_the_service_and_records_its_advice(service, capsys):
    rc = main([str(DATA / "field_test_advised.csv"), "--server", service.base_url, "--speedup", "25", "--no-compare", "--json"])
    assert rc == 0
    live = json.loads(capsys.readouterr().out)["live"]
    assert live["corridor"] == "paper_s400" and live["timing"] == "field_test"
    assert live["fixes_sent"] == 93 and live["fixes_used"] == 93 and not live["ignored"]
    actions = [e["action"] for e in live["timeline"]]
    # the service saw the field test's lights: red at light 1 on entry, then a speed to catch light 2's green
    assert "stop" in actions and ("cruise" in actions or "coast" in actions)
    first_stop = next(e for e in live["timeline"] if e["action"] == "stop")
    assert "Green in 1" in first_stop["message"]  # light 1 turns green 15 s after entry
    assert live["service_score"]["complete"] and live["service_score"]["savings_frac"]["cost"] > 0.1


def test_timeline_is_printed(service, capsys):
    rc = main([str(DATA / "field_test_regular.csv"), "--server", service.base_url, "--speedup", "30", "--no-compare"])
    assert rc == 0
    out = capsys.readouterr().out
    assert "Replaying 88 fixes" in out and "fixes sent" in out and "km/h" in out


def test_unreachable_service_is_a_clear_error(capsys):
    from tests.procs import free_port

    assert main([str(DATA / "field_test_regular.csv"), "--server", f"http://127.0.0.1:{free_port()}", "--no-compare"]) == 2
    assert "--server" in capsys.readouterr().err
