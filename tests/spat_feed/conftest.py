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
def shared_recordings_parsed_once(monkeypatch, recorded_snapshots) -> None:
    """``spat_feed.transport.recorded.read_spat_csv`` of a whole shared recording answers from
    :func:`recorded_snapshots` (a list of its own each call), for code that reads the file itself (predict-eval, the
    switch fit); any other call reads as it does."""
    import spat_feed.transport.recorded as recorded

    from tests.conftest import SPAT_RECORDINGS

    real = recorded.read_spat_csv

    def read(path, *args, **kwargs):
        if Path(path) in SPAT_RECORDINGS and not args and not kwargs:
            return list(recorded_snapshots(Path(path)))
        return real(path, *args, **kwargs)

    monkeypatch.setattr(recorded, "read_spat_csv", read)


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
