import csv
import gzip
from collections.abc import Iterator
from dataclasses import dataclass
from datetime import datetime
from functools import lru_cache
from pathlib import Path

import numpy as np
import pytest

from advisory.physics.params import model_params

REPO = Path(__file__).resolve().parents[1]
SHARED_DATA = next((p for p in (REPO.parent / "shared" / "data", REPO.parents[1] / "shared" / "data") if p.is_dir()), REPO.parent / "shared" / "data")
"""Real data made by others (``../shared/data``, or ``../../shared/data`` from a worktree: cycles/, spat/, osm/);
tests skip what is absent."""
CYCLES = SHARED_DATA / "cycles"
SPAT_RECORDINGS = sorted((SHARED_DATA / "spat").glob("*.csv.gz"))
"""The shared SPaT recordings (``shared/data/spat/README.md``): controllers of different kinds; a test that runs on
each reads what it expects of one from :func:`recording_facts`, not from one controller."""
BOUNDED_S = 1800.0
"""A ``max_end_utc`` less than this after its snapshot bounds the phase's end; the recordings write "unknown" as about
an hour ahead (J2735). [s]"""


def pytest_configure(config) -> None:
    """Under pytest-xdist (``make test``: ``-n 2``) the controller compiles numba's kernels into their on-disk cache
    before the workers start, by starting the service in process once (its DP tables, a warm-up advice). On a fresh
    clone that is ~50 s of CPU; left to the workers, both compiled at once inside the services their first tests
    started, and on a loaded 2-core machine every browser test's service ran past the 60 s it is given to answer."""
    if getattr(config.option, "numprocesses", None) and not hasattr(config, "workerinput"):
        from fastapi.testclient import TestClient

        from server.app import create_app
        from server.config import Settings

        with TestClient(create_app(Settings(corridors=("paper_s200", "paper_s400")))) as client:
            client.get("/health")


@pytest.fixture
def start_proc(tmp_path) -> Iterator:
    """``start_proc(Proc) -> Proc`` (a real process on loopback, ``tests.procs``); everything started is killed at the end of the test."""
    procs: list = []

    def start(proc):
        procs.append(proc)
        return proc.start()

    yield start
    for proc in procs:
        proc.kill()


@pytest.fixture(scope="session")
def paper():
    return model_params("paper_54kwh")


@pytest.fixture(scope="session")
def calibrated():
    return model_params("calibrated")


@dataclass(frozen=True)
class RecordingFacts:
    """What a shared SPaT recording holds, read from its raw CSV rows (not through ``spat_feed``). Units in names."""

    rows: int
    first_unix_s: float  # the first and last snapshot's generated_utc
    last_unix_s: float
    groups: frozenset[tuple[str, int]]  # (controller id as written, signal group)

    @property
    def duration_s(self) -> float:
        return self.last_unix_s - self.first_unix_s


def _unix_s(text: str) -> float:
    return datetime.fromisoformat(text.replace("Z", "+00:00")).timestamp()


def _rows(path: Path) -> Iterator[dict[str, str]]:
    with gzip.open(path, "rt", newline="") as fh:
        yield from csv.DictReader(fh)


@lru_cache(maxsize=None)
def recording_facts(path: Path) -> RecordingFacts:
    """The facts of the recording at ``path`` (one pass over its rows)."""
    n, first, last, groups = 0, None, None, set()
    for row in _rows(path):
        n += 1
        first = first or row["generated_utc"]
        last = row["generated_utc"]
        groups.add((row["intersection"], int(row["signal_group"])))
    return RecordingFacts(n, _unix_s(first), _unix_s(last), frozenset(groups))


@lru_cache(maxsize=None)
def publishes_windows(path: Path) -> bool:
    """Whether the controller of the recording at ``path`` bounds when its phases end (some row's ``max_end_utc`` is
    under :data:`BOUNDED_S` ahead, as Antwerp's), or publishes its state only (every end unknown, as the US one)."""
    return any(_unix_s(row["max_end_utc"]) - _unix_s(row["generated_utc"]) < BOUNDED_S for row in _rows(path))


def recorded_spat_slice(folder: Path, n_rows: int = 400, day: str = "2019-05-01") -> Path:
    """The first ``n_rows`` rows of a shared Antwerp recording, as a CSV in ``folder`` (skip if absent)."""
    import gzip

    src = SHARED_DATA / "spat" / f"antwerp-{day}.csv.gz"
    if not src.exists():
        pytest.skip(f"{src} not present")
    with gzip.open(src, "rt") as fh:
        lines = [next(fh) for _ in range(n_rows + 1)]
    path = folder / f"antwerp-{day}-slice.csv"
    path.write_text("".join(lines))
    return path


def load_cycle(name: str) -> tuple[np.ndarray, np.ndarray]:
    path = CYCLES / f"{name}.csv"
    if not path.exists():
        pytest.skip(f"{path} not present (shared/ sits beside the checkout)")
    data = np.loadtxt(path, delimiter=",", skiprows=1)
    return data[:, 0], data[:, 1]
