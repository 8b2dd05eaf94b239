"""Fixtures for the spat_feed tests: real feed processes on loopback, started and killed by the tests."""

from __future__ import annotations

import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import httpx
import pytest

REPO = Path(__file__).resolve().parents[2]
START_TIMEOUT_S = 30.0  # generous: only there so a broken start cannot hang the suite


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@dataclass
class Feed:
    """A ``python -m spat_feed`` subprocess on 127.0.0.1."""

    port: int
    args: tuple[str, ...]
    log_path: Path
    proc: subprocess.Popen | None = None

    @property
    def base_url(self) -> str:
        return f"http://127.0.0.1:{self.port}"

    def start(self) -> Feed:
        cmd = [sys.executable, "-m", "spat_feed", "--port", str(self.port), *self.args]
        log = self.log_path.open("ab")
        self.proc = subprocess.Popen(cmd, cwd=REPO, stdout=log, stderr=subprocess.STDOUT)
        log.close()
        deadline = time.monotonic() + START_TIMEOUT_S
        while time.monotonic() < deadline:
            if self.proc.poll() is not None:
                raise RuntimeError(f"feed exited with {self.proc.returncode}:\n{self.log_path.read_text()}")
            try:
                if httpx.get(self.base_url + "/health", timeout=1.0).status_code == 200:
                    return self
            except httpx.HTTPError:
                pass
            time.sleep(0.05)
        self.kill()
        raise RuntimeError(f"feed did not answer /health within {START_TIMEOUT_S} s:\n{self.log_path.read_text()}")

    def kill(self) -> None:
        """SIGKILL: the feed dies without closing its sockets politely."""
        if self.proc is not None and self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait(timeout=10)
        self.proc = None


@pytest.fixture
def start_feed(tmp_path) -> Iterator:
    """``start_feed(*cli_args) -> Feed``; every feed started is killed at the end of the test."""
    feeds: list[Feed] = []

    def start(*args: str) -> Feed:
        feed = Feed(free_port(), tuple(args), tmp_path / f"feed{len(feeds)}.log")
        feeds.append(feed)
        return feed.start()

    yield start
    for feed in feeds:
        feed.kill()


@pytest.fixture(scope="module")
def shared_feed(tmp_path_factory) -> Iterator[Feed]:
    """One plain feed for the read-only live tests of a module."""
    feed = Feed(free_port(), (), tmp_path_factory.mktemp("feed") / "feed.log").start()
    yield feed
    feed.kill()
