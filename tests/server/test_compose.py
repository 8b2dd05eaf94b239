"""docker-compose.yml: broker, SPaT player and service wired by URL, all health-checked (no Docker engine needed)."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest
import yaml

REPO = Path(__file__).resolve().parents[2]


def test_compose_wiring():
    spec = yaml.safe_load((REPO / "docker-compose.yml").read_text())
    broker, feed, svc = spec["services"]["mqtt"], spec["services"]["spat-feed"], spec["services"]["advisory"]
    assert "mosquitto" in " ".join(broker["command"]) and "1883" in " ".join(broker["healthcheck"]["test"])
    assert "mosquitto" in (REPO / "Dockerfile").read_text()  # Debian's broker in our image
    cmd = " ".join(feed["command"])
    assert "8765" in cmd and "--mqtt mqtt://mqtt:1883" in cmd and "--log /data/spat/antwerp-2019-05-01.csv.gz" in cmd and "--loop" in cmd
    assert any(v.endswith(":/data/spat:ro") for v in feed["volumes"]) and "/health" in " ".join(feed["healthcheck"]["test"])
    assert "/health" in " ".join(svc["healthcheck"]["test"])
    assert svc["environment"]["ECO_SPAT_MQTT_URL"] == "mqtt://mqtt:1883" and svc["environment"]["ECO_CORRIDOR_DIR"].endswith("spat_feed/presets/live")
    assert (REPO / "spat_feed" / "presets" / "live" / "antwerp_k648.json").exists()
    assert svc["depends_on"]["mqtt"]["condition"] == feed["depends_on"]["mqtt"]["condition"] == "service_healthy"
    assert svc["command"][:2] == ["ecodrive", "serve"] and "0.0.0.0" in svc["command"]
    assert svc["environment"]["ECO_API_KEYS"].startswith("${ECO_API_KEYS:?")  # creation is never open in a deployment


def test_compose_file_validates_with_the_client():
    if shutil.which("docker-compose"):
        cmd = ["docker-compose", "-f", "docker-compose.yml", "config", "-q"]
    elif shutil.which("docker") and subprocess.run(["docker", "compose", "version"], capture_output=True).returncode == 0:
        cmd = ["docker", "compose", "-f", "docker-compose.yml", "config", "-q"]
    else:
        pytest.skip("no docker compose client installed")
    import os

    r = subprocess.run(cmd, cwd=REPO, capture_output=True, text=True, timeout=60, env={**os.environ, "ECO_API_KEYS": "test-key"})
    assert r.returncode == 0, r.stderr
