"""DP lookup tables for a corridor and its plans, built once and cached on disk.

``corridor_tables(corridor, params)`` gathers the plans a corridor's trips can run under (its plans'
patterns; for a corridor without plans and two lights, the paper's 16 timings and the field test), lays
each as a plan variant of :class:`advisory.advice.tables.AdviceTables`, and builds the tables, or loads
them from ``cache_dir`` when a file with the same key exists. The key hashes the corridor's geometry
(stop lines, zone, speed limits, grades), the variants, the grid, the vehicle parameters and the code
version (the source of the modules the tables depend on), so any change rebuilds them.
"""

from __future__ import annotations

import hashlib
import inspect
import json
import logging
import os
import resource
import time
import tracemalloc
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from functools import lru_cache
from pathlib import Path

from advisory.advice import tables as tables_module
from advisory.advice.tables import TABLES_VERSION, AdviceTables, TableGrid
from advisory.physics.params import SPEED_LIMIT_MPS, ModelParams
from advisory.signals import FixedTimeSignal, Scenario
from spat_feed.road.corridors import Corridor
from spat_feed.timing.plans import to_fixed_time_signal
from spat_feed.timing.paper import PAPER_TIMING_NAMES, TIMING_PRESETS
from spat_feed.timing.signal_plans import SignalPlan, TimingLike

log = logging.getLogger("spat_feed.tables")

PLACEHOLDER_RED_S = 30.0
"""A live light has no plan; the geometry handed to the tables gives it this red and green (unused). [s]"""


def default_cache_dir() -> Path:
    """``$ECO_TABLES_CACHE``, else ``$XDG_CACHE_HOME/ecodrive/tables``, else ``~/.cache/ecodrive/tables``."""
    if os.environ.get("ECO_TABLES_CACHE"):
        return Path(os.environ["ECO_TABLES_CACHE"])
    base = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
    return base / "ecodrive" / "tables"


def table_timings(corridor: Corridor) -> list[TimingLike]:
    """The timings a corridor's trips can run under: its plans; without plans, for two lights, the paper's
    16 timings and the field test (what ``timing="trip"`` and the presets give); else none."""
    if corridor.plans:
        return list(corridor.plans)
    if len(corridor.intersections) == 2:
        return [TIMING_PRESETS[name] for name in (*PAPER_TIMING_NAMES, "field_test")]
    return []


def variants_of(corridor: Corridor, timing: TimingLike) -> list[tuple[FixedTimeSignal | None, ...]]:
    """The lights' plans under ``timing`` as table variants: one per pattern of a plan (None: live light)."""
    out = []
    if isinstance(timing, SignalPlan):
        for pattern in timing.patterns:
            plans = timing.pattern_plans(corridor, pattern, 0.0)
            out.append(tuple(_signal(plans.get((ix.id, ix.signal_groups[0].id)), ix.stop_line_m) for ix in corridor.intersections))
    else:
        plans = timing.fixed_plans(corridor, 0.0)
        out.append(tuple(_signal(plans.get((ix.id, ix.signal_groups[0].id)), ix.stop_line_m) for ix in corridor.intersections))
    return out


def _signal(plan, position_m: float) -> FixedTimeSignal | None:
    return None if plan is None else to_fixed_time_signal(plan, position_m)


def geometry(corridor: Corridor, default_limit_mps: float = SPEED_LIMIT_MPS) -> Scenario:
    """The corridor's lights (placeholder timing), zone and lowest limit as an ``advisory.signals.Scenario``."""
    limit = corridor.zone_speed_limit_mps(default_limit_mps)
    signals = tuple(FixedTimeSignal(ix.stop_line_m, 0.0, PLACEHOLDER_RED_S, PLACEHOLDER_RED_S) for ix in corridor.intersections)
    return Scenario(corridor.name, signals, corridor.length_m, limit, limit)


@lru_cache(maxsize=1)
def code_version() -> str:
    """``TABLES_VERSION`` + a hash of the source of every module the tables' numbers depend on."""
    from advisory.evaluation import endstate
    from advisory.optimizer import _kernels, dp
    from advisory.physics import battery, energy, model, params

    h = hashlib.sha256(TABLES_VERSION.encode())
    for module in (tables_module, endstate, dp, _kernels, battery, energy, model, params):
        h.update(Path(inspect.getfile(module)).read_bytes())
    return f"{TABLES_VERSION}-{h.hexdigest()[:12]}"


def cache_key(corridor: Corridor, variants, params: ModelParams, grid: TableGrid, default_limit_mps: float = SPEED_LIMIT_MPS) -> str:
    """Hash of what the tables depend on: geometry, limits, grades, variants, grid, parameters, code."""
    starts, limits, grades = corridor.limit_profile(default_limit_mps)
    doc = {
        "code": code_version(),
        "stop_lines_m": [ix.stop_line_m for ix in corridor.intersections],
        "length_m": corridor.length_m,
        "profile": [starts.tolist(), limits.tolist(), grades.tolist()],
        "variants": [[None if s is None else [s.red_start_s, s.red_s, s.green_s] for s in v] for v in variants],
        "grid": asdict(grid),
        "params": repr(params),
    }
    return hashlib.sha256(json.dumps(doc, sort_keys=True).encode()).hexdigest()[:16]


@dataclass(frozen=True, slots=True)
class BuildReport:
    """How a corridor's tables were obtained: built (with time and peak memory) or loaded from the cache."""

    corridor: str
    n_lights: int
    n_tables: int
    nbytes: int
    seconds: float
    loaded: bool
    path: Path | None
    peak_traced_bytes: int | None = None
    max_rss_bytes: int | None = None
    rss_before_bytes: int | None = None

    def line(self) -> str:
        how = f"loaded from {self.path}" if self.loaded else f"built in {self.seconds:.1f} s"
        peak = f", peak {self.peak_traced_bytes / 1e6:.1f} MB traced" if self.peak_traced_bytes is not None else ""
        rss = (f", process max RSS {self.max_rss_bytes / 1e6:.0f} MB ({self.rss_before_bytes / 1e6:.0f} MB before the build)"
               if self.max_rss_bytes is not None and self.rss_before_bytes is not None else "")  # fmt: skip
        saved = f"; saved to {self.path}" if self.path is not None and not self.loaded else ""
        return f"{self.corridor}: {self.n_tables} tables for {self.n_lights} lights, {self.nbytes / 1e6:.1f} MB, {how}{peak}{rss}{saved}"


def corridor_tables(
    corridor: Corridor,
    params: ModelParams,
    grid: TableGrid | None = None,
    *,
    timings: Sequence[TimingLike] | None = None,
    cache_dir: str | Path | None = None,
    default_limit_mps: float = SPEED_LIMIT_MPS,
    workers: int | None = None,
    measure: bool = False,
) -> tuple[AdviceTables | None, BuildReport | None]:
    """Tables for ``corridor`` under ``timings`` (default :func:`table_timings`), from ``cache_dir`` if there.

    Returns ``(None, None)`` when no light has a fixed plan (no table can exist: the rules advise).
    ``measure``: trace the build's peak memory (slower).
    """
    grid = grid or TableGrid()
    timings = table_timings(corridor) if timings is None else list(timings)
    variants = [v for t in timings for v in variants_of(corridor, t)]
    variants = list(dict.fromkeys(variants))
    if not variants or all(s is None for v in variants for s in v):
        return None, None
    key = cache_key(corridor, variants, params, grid, default_limit_mps)
    path = None if cache_dir is None else Path(cache_dir) / f"{corridor.name}-{key}.npz"
    if path is not None and path.exists():
        t0 = time.perf_counter()
        try:
            tables = AdviceTables.load(path, params)
        except (ValueError, OSError, KeyError) as exc:
            log.warning("tables %s unreadable (%s): rebuilding", path, exc)
        else:
            return tables, BuildReport(corridor.name, len(corridor.intersections), tables.n_tables, tables.nbytes, time.perf_counter() - t0, True, path)
    rss0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024 if measure else None
    if measure:
        tracemalloc.start()
    t0 = time.perf_counter()
    tables = AdviceTables.build(geometry(corridor, default_limit_mps), params, grid, variants=variants,
                                profile=corridor.limit_profile(default_limit_mps), workers=workers)  # fmt: skip
    seconds = time.perf_counter() - t0
    peak = None
    if measure:
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
    if path is not None:
        path.parent.mkdir(parents=True, exist_ok=True)
        tables.save(path)
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024 if measure else None
    report = BuildReport(corridor.name, len(corridor.intersections), tables.n_tables, tables.nbytes, seconds, False, path, peak, rss, rss0)
    return tables, report
