"""In-process checks of the app factory, settings, the CLI entry and the speech fallback."""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from ecodrive.cli import COMMANDS
from server.app import create_app
from server.config import Settings
from server.main import main


def small_settings(**kw) -> Settings:
    return Settings(corridors=("paper_s200",), default_corridor="paper_s200", tables=False, **kw)


def test_settings_from_environment(monkeypatch):
    monkeypatch.setenv("ECO_CORRIDORS", "paper_s200, paper_s800")
    monkeypatch.setenv("ECO_API_KEYS", "k1,k2")
    monkeypatch.setenv("ECO_SPAT_FEED_URL", "http://feed:8765")
    monkeypatch.setenv("ECO_SPEECH", "false")
    s = Settings()
    assert s.corridors == ("paper_s200", "paper_s800") and s.api_keys == ("k1", "k2")
    assert s.spat_feed_url == "http://feed:8765" and s.speech is False


def test_serve_is_an_ecodrive_command(capsys):
    assert COMMANDS["serve"] == "server.main"
    with pytest.raises(SystemExit) as info:
        main(["--help"])
    assert info.value.code == 0 and "--port" in capsys.readouterr().out


def test_audio_without_speech_engine_is_a_clear_503():
    with TestClient(create_app(small_settings(speech=False))) as client:
        created = client.post("/v1/trips", json={}).json()
        r = client.get(f"/v1/trips/{created['trip_id']}/advice.wav", headers={"Authorization": f"Bearer {created['token']}"})
        assert r.status_code == 503 and r.json()["error"] == "speech_unavailable" and "ECO_SPEECH" in r.json()["message"]


def test_api_keys_guard_trip_creation():
    with TestClient(create_app(small_settings(speech=False, api_keys=("secret",)))) as client:
        assert client.post("/v1/trips", json={}).status_code == 401
        assert client.post("/v1/trips", json={}, headers={"Authorization": "Bearer wrong"}).status_code == 403
        assert client.post("/v1/trips", json={}, headers={"Authorization": "Bearer secret"}).status_code == 201


def test_trip_capacity_and_injected_clock():
    now = [1_800_000_000.0]
    with TestClient(create_app(small_settings(speech=False, max_trips=2), clock=lambda: now[0])) as client:
        a = client.post("/v1/trips", json={"timing": "field_test"}).json()
        assert a["entry_unix_s"] == now[0]
        client.post("/v1/trips", json={})
        r = client.post("/v1/trips", json={})
        assert r.status_code == 503 and r.json()["error"] == "too_many_trips"
        # a fix at the injected clock's time is fine; one an hour ahead of it is not
        from spat_feed.road.corridors import load_corridor

        lat, lon = load_corridor("paper_s200").position(5.0)
        auth = {"Authorization": f"Bearer {a['token']}"}
        ok = client.post(f"/v1/trips/{a['trip_id']}/fixes", json={"t_unix_s": now[0] + 1, "lat_deg": lat, "lon_deg": lon, "speed_mps": 20}, headers=auth)
        assert ok.status_code == 200 and ok.json()["action"] != "none"
        late = client.post(f"/v1/trips/{a['trip_id']}/fixes", json={"t_unix_s": time.time() + 7200 if now[0] < time.time() else now[0] + 3600, "lat_deg": lat, "lon_deg": lon}, headers=auth)
        assert late.status_code == 422


def test_start_up_compiles_the_choice_under_uncertain_timing():
    """Start-up runs the advisor's choice under uncertain timing once (``server.app.warm_up``): the first fix on a
    recorded, MQTT or actuated controller must not wait for numba to compile it (11 s with a cold cache, the event loop
    blocked: a fresh clone's MQTT test timed out on it). In a fresh interpreter, so nothing else ran it before."""
    code = (
        "from fastapi.testclient import TestClient\n"
        "from advisory.advice import screening\n"
        "from server.app import create_app\n"
        "from server.config import Settings\n"
        "before = len(screening._screened.signatures)\n"
        "with TestClient(create_app(Settings(corridors=('paper_s200',), default_corridor='paper_s200', tables=False, speech=False))):\n"
        "    print(before, len(screening._screened.signatures))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=Path(__file__).parents[2])
    assert out.stdout.split()[-2:] == ["0", "1"], out.stdout + out.stderr
