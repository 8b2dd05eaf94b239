"""Fixtures for the service tests: real ``python -m server`` / ``python -m spat_feed`` processes on loopback.

Every process is started on a free port, waited for on ``/health`` (bounded), and killed at the end.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest

from spat_feed.road.corridors import load_corridor

from tests.procs import REPO, Proc, RedisServer, free_port, redis_server_path  # noqa: F401  (re-exported for the test modules)


SERVICE_ENV = {
    "ECO_CORRIDORS": "paper_s200,paper_s400",
    "ECO_DEFAULT_CORRIDOR": "paper_s200",
    "ECO_RATE_PER_S": "50",
    "ECO_RATE_BURST": "60",
    "ECO_CREATE_RATE_PER_CLIENT_PER_S": "100",  # the tests create many trips from one address
    "ECO_CREATE_BURST_PER_CLIENT": "500",
    "ECO_MAX_TRIPS_PER_CLIENT": "5000",
}


def service_proc(log_dir: Path, **env: str) -> Proc:
    return Proc(["-m", "server", "--log-level", "warning", "--no-access-log"], log_dir / "service.log", {**SERVICE_ENV, **env})


@pytest.fixture(scope="session")
def service(tmp_path_factory) -> Iterator[Proc]:
    """One advisory service for the read-mostly live tests (tables for paper_s200 only, to start fast)."""
    proc = service_proc(tmp_path_factory.mktemp("service"), ECO_CORRIDORS="paper_s200,paper_s400", ECO_TABLES="true",
                        ECO_TABLES_DIR=str(tmp_path_factory.mktemp("tables"))).start()  # fmt: skip
    yield proc
    proc.kill()


@pytest.fixture
def store(tmp_path) -> Iterator[RedisServer]:
    """A ``redis-server`` of this test's own on loopback (skipped where it cannot be installed), killed at the end."""
    if redis_server_path() is None:
        pytest.skip("redis-server is not installed and scripts/system-deps.sh could not install it (needs root and apt-get)")
    server = RedisServer(tmp_path).start()
    yield server
    server.kill()


@pytest.fixture(scope="session")
def s200():
    return load_corridor("paper_s200")


def new_trip(client: httpx.Client, **body) -> tuple[str, dict[str, str], dict]:
    r = client.post("/v1/trips", json=body)
    assert r.status_code == 201, r.text
    data = r.json()
    return data["trip_id"], {"Authorization": f"Bearer {data['token']}"}, data


FIX_ERROR_STATUSES = [422, 422, 422, 401, 403, 404, 413, 422]
"""The statuses of :func:`fix_errors`' requests, in order."""


def fix_errors(url: str, fix: dict, auth: dict, other_auth: dict, max_body_bytes: int) -> list[tuple[str, dict, dict]]:
    """``(path, httpx body arguments, headers)`` of the fix requests every store and route answers with a 4xx, built
    around ``fix`` (a valid body for ``url``, the trip's fix route): out of range, malformed, a lone surrogate, no token,
    another trip's token, an unknown trip, a body over ``max_body_bytes``, a time an hour ahead."""
    return [
        (url, {"json": {**fix, "lat_deg": 91.0}}, auth),  # 422 validation
        (url, {"content": b"{not json"}, auth),  # 422 malformed
        (url, {"content": b'{"t_unix_s": 1, "x": "\\ud800"}'}, auth),  # 422, lone surrogate
        (url, {"json": fix}, {}),  # 401
        (url, {"json": fix}, other_auth),  # 403
        ("/v1/trips/nosuchtrip/fixes", {"json": fix}, auth),  # 404
        (url, {"content": b"x" * (2 * max_body_bytes)}, auth),  # 413
        (url, {"json": {**fix, "t_unix_s": fix["t_unix_s"] + 3600}}, auth),  # 422 time out of range
    ]
