"""Fixtures for the spat_feed tests: real feed processes on loopback, started and killed by the tests."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from tests.procs import REPO, Proc, free_port  # noqa: F401  (re-exported for the test modules)



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
