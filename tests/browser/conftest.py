"""Fixtures for the phone app's tests: a real service process and Debian's headless chromium.

Chromium comes from ``scripts/system-deps.sh`` (``make test`` runs it; as root it installs what is
missing with apt-get). Where it cannot be installed the browser tests are skipped and say why.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.browser.cdp import find_chromium
from tests.procs import Proc

CHROMIUM = find_chromium()
needs_chromium = pytest.mark.skipif(
    CHROMIUM is None, reason="chromium is not installed (sh scripts/system-deps.sh installs it as root with apt-get: Debian package 'chromium')"
)

FIGURE_ENV = "ECODRIVE_APP_FIGURE"
"""Set to a PNG path to also write the README's figure (setup, drive, score side by side) from the demo test."""


@pytest.fixture(scope="module")
def app_service(tmp_path_factory) -> Iterator[Proc]:
    """The advisory service with the app, two corridors, speech if espeak-ng is there, and a per-trip rate
    high enough for a demo drive played 20 times faster than recorded."""
    log_dir = tmp_path_factory.mktemp("app_service")
    env = {"ECO_CORRIDORS": "paper_s200,paper_s400", "ECO_DEFAULT_CORRIDOR": "paper_s400", "ECO_RATE_PER_S": "100", "ECO_RATE_BURST": "100",
           "ECO_TABLES_DIR": str(log_dir / "tables")}  # fmt: skip
    proc = Proc(["-m", "server", "--log-level", "warning", "--no-access-log"], log_dir / "service.log", env).start()
    yield proc
    proc.kill()


@pytest.fixture
def shots(tmp_path) -> Path:
    """Where a test saves its screenshots (the test's tmp dir)."""
    path = tmp_path / "screenshots"
    path.mkdir()
    return path


def figure_path() -> Path | None:
    value = os.environ.get(FIGURE_ENV)
    return Path(value) if value else None


FIGURE_DIR_ENV = "ECODRIVE_APP_FIGURE_DIR"
"""Set to a folder to also write docs/APP.md's figures of the countdown and of a lost service (``make app-figure``)."""


def figure_dir() -> Path | None:
    value = os.environ.get(FIGURE_DIR_ENV)
    return Path(value) if value else None
