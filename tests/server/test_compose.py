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
    # no anonymous client (issue 30): the shipped config from spat_feed.transport.broker, a volume of credentials
    assert "spat_feed.transport.broker /app/mqtt-auth" in broker["command"][-1] and "mosquitto -c /app/mqtt-auth/mosquitto.conf" in broker["command"][-1]
    assert "allow_anonymous" not in " ".join(broker["command"]) and "mqtt-auth:/app/mqtt-auth" in broker["volumes"]
    assert "mosquitto" in (REPO / "Dockerfile").read_text()  # Debian's broker in our image
    cmd = " ".join(feed["command"])
    assert "8765" in cmd and "SPAT_MQTT_URL=$$(cat /app/mqtt-auth/spat-feed.url)" in cmd and "--log /data/spat/antwerp-2019-05-01.csv.gz" in cmd and "--loop" in cmd
    assert "--controller spat-feed=648," in broker["command"][-1] and "--reader service" in broker["command"][-1]
    assert any(v.endswith(":/data/spat:ro") for v in feed["volumes"]) and "/health" in " ".join(feed["healthcheck"]["test"])
    assert "/health" in " ".join(svc["healthcheck"]["test"])
    assert "ECO_SPAT_MQTT_URL=$$(cat /app/mqtt-auth/service.url)" in svc["command"][-1] and svc["environment"]["ECO_CORRIDOR_DIR"].endswith("spat_feed/presets/live")
    assert "mqtt-auth:/app/mqtt-auth:ro" in svc["volumes"] and "mqtt-auth:/app/mqtt-auth:ro" in feed["volumes"]
    assert (REPO / "spat_feed" / "presets" / "live" / "antwerp_k648.json").exists()
    assert svc["depends_on"]["mqtt"]["condition"] == feed["depends_on"]["mqtt"]["condition"] == "service_healthy"
    assert "exec ecodrive serve --host 0.0.0.0" in svc["command"][-1]
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
