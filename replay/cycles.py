"""The EPA's certification cycles, scored by the same model as a drive: a yardstick for its energy per km.

``replay/data/cycles/`` ships the EPA Urban Dynamometer Driving Schedule (UDDS, city) and the Highway Fuel
Economy Test (HWFET) as 1 Hz ``t_s,speed_mps`` (where they come from: ``replay/data/README.md``). A drive's
Wh/km beside the same vehicle's on these two says whether it was driven like city or highway traffic, or
worse, with no signal timing needed.
"""

from __future__ import annotations

from functools import lru_cache
from importlib.resources import files
from pathlib import Path

import numpy as np

from advisory.evaluation.scoring import score_trace
from advisory.physics.params import model_params

CYCLE_DIR = Path(str(files("replay") / "data" / "cycles"))
EPA_CYCLES = {"udds": "EPA UDDS (city)", "hwfet": "EPA HWFET (highway)"}
"""File stem -> name, in the order they are reported."""


def load_cycle(name: str) -> tuple[np.ndarray, np.ndarray]:
    """A shipped cycle's times and speeds. [s], [m/s]"""
    data = np.loadtxt(CYCLE_DIR / f"{name}.csv", delimiter=",", skiprows=1)
    return data[:, 0], data[:, 1]


@lru_cache(maxsize=16)
def cycle_wh_per_km(name: str, vehicle: str, decay_multiplier: float = 1.0) -> float:
    """Net battery energy per km of ``vehicle`` on the cycle ``name`` (regen counted, flat road). [Wh/km]"""
    t, v = load_cycle(name)
    return float(score_trace(t, v, model_params(vehicle, decay_multiplier)).wh_per_km)


def against_cycles(wh_per_km: float, vehicle: str, decay_multiplier: float = 1.0) -> list[dict]:
    """Each EPA cycle's Wh/km for the same vehicle and the drive's ratio to it (``ratio`` > 1: the drive used more)."""
    out = []
    for name, title in EPA_CYCLES.items():
        ref = cycle_wh_per_km(name, vehicle, decay_multiplier)
        out.append({"cycle": name, "name": title, "wh_per_km": ref, "ratio": float(wh_per_km / ref) if ref > 0 else None})
    return out
