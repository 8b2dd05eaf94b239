"""docker-compose.yml: two services wired by URL, both health-checked (no Docker engine needed)."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest
import yaml

REPO = Path(__file__).resolve().parents[2]


def test_compose_wiring():
    spec = yaml.safe_load((REPO / "docker-compose.yml").read_text())
    feed, svc = spec["services"]["spat-feed"], spec["services"]["advisory"]
    assert "8765" in " ".join(feed["command"]) and "/health" in " ".join(feed["healthcheck"]["test"])
    assert "/health" in " ".join(svc["healthcheck"]["test"])
    assert svc["environment"]["ECO_SPAT_FEED_URL"] == "http://spat-feed:8765"
    assert svc["depends_on"]["spat-feed"]["condition"] == "service_healthy"
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
