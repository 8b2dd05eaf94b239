from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from advisory.physics.params import model_params

REPO = Path(__file__).resolve().parents[1]
SHARED_DATA = next((p for p in (REPO.parent / "shared" / "data", REPO.parents[1] / "shared" / "data") if p.is_dir()), REPO.parent / "shared" / "data")
"""Real data made by others (``../shared/data``, or ``../../shared/data`` from a worktree: cycles/, spat/, osm/);
tests skip what is absent."""
CYCLES = SHARED_DATA / "cycles"


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
