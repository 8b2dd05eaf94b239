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


def load_cycle(name: str) -> tuple[np.ndarray, np.ndarray]:
    path = CYCLES / f"{name}.csv"
    if not path.exists():
        pytest.skip(f"{path} not present (shared/ sits beside the checkout)")
    data = np.loadtxt(path, delimiter=",", skiprows=1)
    return data[:, 0], data[:, 1]
