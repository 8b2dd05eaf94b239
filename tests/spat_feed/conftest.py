"""Fixtures for the spat_feed tests: real feed processes on loopback, started and killed by the tests."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from tests.procs import REPO, Proc, free_port  # noqa: F401  (re-exported for the test modules)


@pytest.fixture(scope="package")
def recorded_snapshots() -> Iterator[Callable[[Path], tuple]]:
    """``recorded_snapshots(path)``: every snapshot of a shared recording, as ``read_spat_csv`` returns them, parsed once
    for this package's tests (~3 s and ~160 MB a day; let go when the package's tests end). A tuple of frozen models:
    nothing a test does to it reaches another test."""
    from spat_feed.transport.recorded import read_spat_csv

    parsed: dict[Path, tuple] = {}

    def read(path: Path) -> tuple:
        if path not in parsed:
            parsed[path] = tuple(read_spat_csv(path))
        return parsed[path]

    yield read
    parsed.clear()



@pytest.fixture
def start_feed(tmp_path) -> Iterator:
    """``start_feed(*cli_args) -> Proc``; every feed started is killed at the end of the test."""
    feeds: list[Proc] = []

    def start(*args: str) -> Proc:
        feed = Proc(["-m", "spat_feed", *args], tmp_path / f"feed{len(feeds)}.log")
        feeds.append(feed)
        return feed.start()

    yield start
    for feed in feeds:
        feed.kill()


@pytest.fixture(scope="module")
def shared_feed(tmp_path_factory) -> Iterator[Proc]:
    """One plain feed for the read-only live tests of a module."""
    feed = Proc(["-m", "spat_feed"], tmp_path_factory.mktemp("feed") / "feed.log").start()
    yield feed
    feed.kill()
