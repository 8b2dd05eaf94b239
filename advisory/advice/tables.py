"""DP lookup tables for the advisor: the optimal speed at the next stop line, by table lookup, for any
fixed-time plan on a corridor of any number of lights.

A rolling two-light horizon (the paper's method taken two lights at a time): for each light ``a`` the
table covers the **stretch** from the previous stop line (or the zone entry) through ``a`` and the next
light ``b`` to ``exit_m`` past ``b`` (or to the light after ``b``, or the zone end). A backward DP over
(stage, speed, phase) on that stretch gives, for every position before ``a``, speed and phase, the optimal
next speed; following it to ``a``'s stop line gives the speed the optimal driver crosses it with, which is
what the advisor asks the driver to ease off (or speed up) to. When the car passes ``a``, ``b``'s table
(stretch from ``a``) takes over.

**Joint phase.** The lights' state is one number per table: the time modulo the pair's common period
``P = lcm(C_a, C_b)`` (on the ``tau_step_s`` grid), in a frame where ``a`` turns red at 0 and ``b`` at
``delta`` (``b``'s offset from ``a`` modulo ``gcd(C_a, C_b)``: shifting the frame by whole cycles of ``a``
reaches every other offset). Stages past ``a`` need only ``b``'s phase (period ``C_b``), so the DP runs in
two parts and only the approach to ``a`` is stored. Equal cycles give ``P = C``; 60/90 s give 180 s; 90/120 s
give 360 s. A pair whose ``P`` exceeds ``max_phase_cells`` steps (incommensurate cycles) gets no pair table.
Every fixed light also gets a **one-light table** (``a`` alone, then the exit), used when ``b`` is live or
uncertain or its pair table is missing. No table exists only where ``a`` itself has no fixed plan (live,
actuated timing): the advisor then uses its rules.

* Cost per transition: paper Eq. 4 (``advisory.physics.model``) on the stage's grade, plus a value of time
  ``time_value_usd_per_s``. Without a price on time the optimum crawls (air drag falls with speed); the
  default 4.5e-4 $/s is the value at which, with no lights, cruising at the limit is the cheapest steady
  speed for the paper car (d(cost/m)/dv = lambda / v² at 24.6 m/s), so the tables never advise dawdling.
* Terminal cost at the stretch end: the re-acceleration penalty to the limit there
  (``advisory.evaluation.endstate``), priced the same way.
* Speed limits per stretch of road: a transition over a stage may not exceed the lowest limit on it.
* Red: a transition into a stop-line stage at a red instant is forbidden (checked at the exact arrival
  time of the grid state); values are interpolated in the phase, and an infeasible neighbour poisons the value.
* Waiting at standstill (not on a stop line) in steps of the phase grid.
* Stages: each part of a stretch (approach, between the lights, exit) is cut into equal stages of about
  ``stage_m``, so stop lines at any station fall on stage boundaries; speed nodes are the coasting chain of
  ``stage_m`` (``advisory.optimizer.dp.coast_chain_mps``).

``AdviceTables.target_speed_mps(obs)`` recovers the phase from the live SPaT of the next two lights (their
current red windows); if the lights' durations, cycles or relative offset differ from every table, or a
change is uncertain, it returns None and the advisor falls back to its rules (never a confident wrong target).
Saved as ``.npz`` with the grid, the parameters and the code version.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
from numba import njit

from advisory.evaluation.endstate import reacceleration_penalty
from advisory.optimizer._kernels import is_red
from advisory.optimizer.dp import coast_chain_mps
from advisory.physics.model import I_AUX, pack, step_battery_power_w, step_cost_usd
from advisory.physics.params import TIME_VALUE_USD_PER_S, ModelParams
from advisory.signals import FixedTimeSignal, Scenario

TABLES_VERSION = "2"
MATCH_TOL_S = 0.6
"""Live red windows must match a table's durations, cycle and offsets within this. [s]"""
POSITION_TOL_M = 5.0
"""A light seen in the SPaT is the table's light if their stop lines are this close. [m]"""
TAU_STEPS_S = (0.5, 0.25, 0.2, 0.1)
"""Phase steps tried, coarsest first (the grid's own step first): the step must divide every cycle. [s]"""


@dataclass(frozen=True, slots=True)
class TableGrid:
    """Resolution of the lookup tables. Units in names.

    ``exit_m``: a stretch ends this far past its last light (the paper's 100 m exit), or earlier at the
    next light or the zone end. ``max_phase_cells``: largest joint period, in phase steps, a pair table may
    have (3600 = 30 min at 0.5 s); beyond it the pair gets only one-light tables.
    """

    stage_m: float = 20.0
    tau_step_s: float = 0.5
    time_value_usd_per_s: float = TIME_VALUE_USD_PER_S
    accel_max_mps2: float = 2.0
    brake_max_mps2: float = 4.0
    exit_m: float = 100.0
    max_phase_cells: int = 3600


@dataclass(frozen=True, slots=True)
class LightTiming:
    """One fixed-time light as the tables see it: red for ``red_s`` from ``red_start_s`` every ``cycle_s``. [s]"""

    red_s: float
    cycle_s: float
    red_start_s: float = 0.0

    @classmethod
    def of(cls, signal: FixedTimeSignal) -> LightTiming:
        return cls(float(signal.red_s), float(signal.cycle_s), float(signal.red_start_s) % signal.cycle_s)


@njit(cache=True, nogil=True)
def _periodic_backward(speed, stage_cls, band_lo, step_dt, step_usd, cap, is_stop, red_start, red_s, cycle, period, tau_step,
                       lam, idle_usd, terminal, policy, none_code, wait_code):  # fmt: skip
    """Backward DP over one part of a stretch; returns the value at its first stage (n_v, n_tau) [$].

    Shapes: ``stage_cls``, ``cap`` (K,): transition class and highest allowed speed index of stage k -> k+1;
    ``band_lo`` (n_cls, n_v), ``step_dt``/``step_usd`` (n_cls, n_v, width); ``is_stop``, ``red_start``,
    ``red_s``, ``cycle`` (K + 1,); ``terminal`` (n_v, n_term) periodic in the phase with ``n_term`` dividing
    ``n_tau = period / tau_step``; ``policy`` (K, n_v, n_tau) is written: next-speed index, ``wait_code`` = wait
    at standstill, ``none_code`` = no feasible move.
    Only two value layers are kept. The phase after a transition is ``j + dt / tau_step`` cells, so the
    interpolation weights depend on the transition only; the red check uses the exact arrival time.
    """
    n_stage = policy.shape[0]
    n_v, n_tau = policy.shape[1], policy.shape[2]
    n_term = terminal.shape[1]
    nxt = np.empty((n_v, n_tau))
    cur = np.empty((n_v, n_tau))
    for i in range(n_v):
        for j in range(n_tau):
            nxt[i, j] = terminal[i, j % n_term]
    width = step_dt.shape[2]
    for k in range(n_stage - 1, -1, -1):
        k2 = k + 1
        c = stage_cls[k]
        stop = is_stop[k2]
        for i in range(n_v):
            for j in range(n_tau):
                cur[i, j] = np.inf
                policy[k, i, j] = none_code
            if i > cap[k]:
                continue
            for jj in range(width):  # next speeds ascending: on ties the lowest wins
                dt = step_dt[c, i, jj]
                if dt == np.inf:
                    continue
                i2 = band_lo[c, i] + jj
                if i2 > cap[k]:
                    break
                q = dt / tau_step  # the arrival falls q phase steps later: between cells j + sh and j + sh + 1
                sh = int(q)
                w = q - sh
                sh = sh % n_tau
                base = step_usd[c, i, jj] + lam * dt
                for j in range(n_tau):
                    if stop and is_red(j * tau_step + dt, red_start[k2], red_s[k2], cycle[k2]):
                        continue
                    j0 = j + sh
                    if j0 >= n_tau:
                        j0 -= n_tau
                    j1 = j0 + 1
                    if j1 == n_tau:
                        j1 = 0
                    v0, v1 = nxt[i2, j0], nxt[i2, j1]
                    if v0 == np.inf or v1 == np.inf:
                        continue
                    cost = base + (1.0 - w) * v0 + w * v1
                    if cost < cur[i, j]:
                        cur[i, j] = cost
                        policy[k, i, j] = i2
        if speed[0] == 0.0 and not is_stop[k]:
            wait = idle_usd + lam * tau_step
            for _sweep in range(2):
                for j in range(n_tau - 1, -1, -1):
                    cost = cur[0, (j + 1) % n_tau] + wait
                    if cost < cur[0, j]:
                        cur[0, j] = cost
                        policy[k, 0, j] = wait_code
        nxt, cur = cur, nxt
    return nxt


@njit(cache=True)
def _follow(policy, stage_cls, step_dt, band_lo, cap, k0, v0, tau0, tau_step, period, speed, none_code, wait_code):
    """Speed index the optimal plan has on reaching the table's stop line (its last stage) from stage
    ``k0`` at the grid speed nearest ``v0`` (at most the stage's limit) and phase ``tau0``; -1 if none."""
    n_tau = policy.shape[2]
    i, tau = int(np.argmin(np.abs(speed - v0))), tau0
    if k0 < policy.shape[0] and i > cap[k0]:
        i = cap[k0]
    for k in range(k0, policy.shape[0]):
        nxt = none_code
        for _ in range(4 * n_tau):  # waits at standstill
            j = int(round((tau % period) / tau_step)) % n_tau
            nxt = policy[k, i, j]
            if nxt != wait_code:
                break
            tau += tau_step
        if nxt == none_code or nxt == wait_code:
            return -1
        c = stage_cls[k]
        tau += step_dt[c, i, int(nxt) - band_lo[c, i]]
        i = int(nxt)
    return i


def _transitions(speed, stage_m, grade_frac, params: ModelParams, grid: TableGrid):
    """Reachable next speeds and their time and cost over one stage of ``stage_m`` at ``grade_frac``."""
    v2 = speed**2
    band_lo = np.searchsorted(v2, v2 - 2 * grid.brake_max_mps2 * stage_m - 1e-9, side="left")
    band_hi = np.searchsorted(v2, v2 + 2 * grid.accel_max_mps2 * stage_m + 1e-9, side="right") - 1
    width = int((band_hi - band_lo).max()) + 1
    p, rates, pref = pack(params)
    step_dt = np.full((speed.size, width), np.inf)
    step_usd = np.zeros((speed.size, width))
    for i in range(speed.size):
        v_next = speed[band_lo[i] : band_hi[i] + 1]
        ok = speed[i] + v_next > 0
        dt = np.where(ok, 2 * stage_m / np.maximum(speed[i] + v_next, 1e-12), np.inf)
        battery = step_battery_power_w(speed[i], v_next, np.where(ok, dt, 1.0), grade_frac, p)
        step_dt[i, : v_next.size] = dt
        step_usd[i, : v_next.size] = np.where(ok, step_cost_usd(battery, np.where(ok, dt, 1.0), p, rates, pref), 0.0)
    return band_lo.astype(np.int64), step_dt, step_usd


def _tau_step(cycles_s: Sequence[float], preferred_s: float) -> float | None:
    """The coarsest phase step (``preferred_s`` first, then :data:`TAU_STEPS_S`) dividing every cycle."""
    for step in (preferred_s, *TAU_STEPS_S):
        if step <= preferred_s + 1e-12 and all(abs(c / step - round(c / step)) < 1e-6 for c in cycles_s):
            return step
    return None


def _red_start_now(light, red_s: float, cycle_s: float) -> float | None:
    """When (seconds from now, mod nothing) the red of ``light`` that is current or next began or begins,
    if its live windows fit a fixed plan of ``red_s`` / ``cycle_s``; else None."""
    if not light.fresh or getattr(light, "scenarios_s", ()):  # stale, or timing only known as scenarios (uncertain)
        return None
    windows = [(s, e) for s, e in light.red_windows_s if e > 0]
    if not windows:
        return None
    start, end = windows[0]
    if start > 0:
        if abs(end - start - red_s) > MATCH_TOL_S:
            return None  # another red duration, or an uncertain window
        r = start
    else:
        if end > red_s + MATCH_TOL_S:
            return None
        r = end - red_s
    if len(windows) > 1 and abs(windows[1][0] - (r + cycle_s)) > MATCH_TOL_S:
        return None  # another cycle
    return r


@dataclass
class LightTable:
    """The approach to one light (index ``light``): policy over (stage, speed, phase) from ``x0_m`` to its line.

    ``timing``: the light's plan and, for a pair table, the next light's, in the table's frame (the light
    turns red at 0; the next at ``timing[1].red_start_s``). ``period_s``: the joint period.
    """

    light: int
    timing: tuple[LightTiming, ...]
    period_s: float
    tau_step_s: float
    x0_m: float
    stage_m: float
    stage_cls: np.ndarray = field(repr=False)
    cap: np.ndarray = field(repr=False)
    policy: np.ndarray = field(repr=False)
    value0: np.ndarray | None = field(default=None, repr=False)  # value at x0 (n_v, n_tau), kept on request [$]

    @property
    def is_pair(self) -> bool:
        return len(self.timing) == 2

    @property
    def codes(self) -> tuple[int, int]:
        """(no feasible move, wait at standstill) as stored in ``policy``."""
        return _codes(self.policy.dtype)

    @property
    def nbytes(self) -> int:
        return self.policy.nbytes + self.stage_cls.nbytes + self.cap.nbytes + (0 if self.value0 is None else self.value0.nbytes)

    def phase_now(self, lights) -> float | None:
        """The phase (s into the joint period) at the observation's instant, or None if the live windows do
        not fit this table. ``lights``: the LightViews of this light and, for a pair table, the next."""
        a = self.timing[0]
        r_a = _red_start_now(lights[0], a.red_s, a.cycle_s)
        if r_a is None:
            return None
        x_a = (-r_a) % a.cycle_s  # frame: a turns red at 0
        if not self.is_pair:
            return x_a
        if len(lights) < 2:
            return None
        b = self.timing[1]
        r_b = _red_start_now(lights[1], b.red_s, b.cycle_s)
        if r_b is None:
            return None
        x_b = (b.red_start_s - r_b) % b.cycle_s  # frame: b turns red at its red_start_s
        best, tau = math.inf, None
        for m in range(int(round(self.period_s / a.cycle_s))):
            x = x_a + m * a.cycle_s
            d = (x - x_b) % b.cycle_s
            d = min(d, b.cycle_s - d)
            if d < best:
                best, tau = d, x
        return tau if best <= MATCH_TOL_S else None


@dataclass
class AdviceTables:
    """Lookup tables of one corridor: per light, its pair and one-light tables for every plan variant."""

    light_positions_m: np.ndarray
    zone_length_m: float
    speed_limit_mps: float
    grid: TableGrid
    params: ModelParams
    speed_mps: np.ndarray = field(repr=False)
    band_lo: np.ndarray = field(repr=False)  # (n_cls, n_v)
    step_dt: np.ndarray = field(repr=False)  # (n_cls, n_v, width)
    tables: list[list[LightTable]] = field(repr=False, default_factory=list)  # per light, pair tables first
    build_s: float = 0.0

    @property
    def nbytes(self) -> int:
        """Bytes held by the tables (policies, transitions). [B]"""
        return sum(t.nbytes for ts in self.tables for t in ts) + self.band_lo.nbytes + self.step_dt.nbytes + self.speed_mps.nbytes

    @property
    def n_tables(self) -> int:
        return sum(len(ts) for ts in self.tables)

    # -- build ------------------------------------------------------------------------------------------
    @classmethod
    def build(
        cls,
        geometry: Scenario,
        params: ModelParams,
        grid: TableGrid = TableGrid(),
        offsets_s=None,
        *,
        variants: Sequence[Sequence[FixedTimeSignal | None]] | None = None,
        profile: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
        workers: int | None = None,
        keep_values: bool = False,
    ) -> AdviceTables:
        """Tables for the lights of ``geometry`` (their positions; the zone length and speed limit).

        The plans tabulated: ``variants`` (each a sequence with one entry per light: a
        :class:`FixedTimeSignal`, or None for a light without a fixed plan), else, with ``offsets_s`` (each a
        tuple, one entry per light after the first: its red start minus light 1's), the geometry's lights
        shifted to those offsets, else the geometry's own timing. Pairs and lights that repeat across
        variants are built once. ``profile``: (start stations, speed limits, grades) of the road's stretches
        (``Corridor.limit_profile``); default: the geometry's limit, flat. ``workers``: threads (default:
        the CPU count). ``keep_values``: keep each table's value at its first stage (tests).
        """
        import time

        t0 = time.perf_counter()
        lights = geometry.signals
        pos = np.array([s.position_m for s in lights], dtype=float)
        if not lights:
            raise ValueError("tables need at least one light")
        if np.any(np.diff(pos) <= 0):
            raise ValueError("tables need lights at distinct, increasing stations")
        if variants is None:
            if offsets_s is None:
                variants = [tuple(lights)]
            else:
                l0 = lights[0]
                variants = [
                    tuple(FixedTimeSignal(s.position_m, l0.red_start_s + off, s.red_s, s.green_s) for s, off in zip(lights, (0.0, *offs), strict=True))
                    for offs in offsets_s
                ]
        for v in variants:
            if len(v) != len(lights):
                raise ValueError(f"a plan variant has {len(v)} lights, the geometry {len(lights)}")
        if profile is None:
            profile = (np.array([0.0]), np.array([geometry.speed_limit_mps]), np.array([0.0]))
        starts, limits, grades = (np.asarray(a, dtype=float) for a in profile)
        v_top = float(limits.max())
        speed = coast_chain_mps(v_top, grid.stage_m, params.vehicle)
        builder = _Builder(speed, pos, geometry.zone_length_m, starts, limits, grades, params, grid)
        jobs: dict[tuple, tuple[int, tuple[LightTiming, ...]]] = {}
        for variant in variants:
            timings = [None if s is None else LightTiming.of(s) for s in variant]
            for a, ta in enumerate(timings):
                if ta is None:
                    continue
                one = (LightTiming(ta.red_s, ta.cycle_s, 0.0),)
                jobs.setdefault(_key(a, one), (a, one))
                tb = timings[a + 1] if a + 1 < len(timings) else None
                if tb is not None:
                    pair = builder.pair_timing(ta, tb)
                    if pair is not None:
                        jobs.setdefault(_key(a, pair), (a, pair))
        workers = workers or os.cpu_count() or 1
        ordered = sorted(jobs.values(), key=lambda job: -builder.cost_estimate(*job))  # longest first
        if workers > 1 and len(ordered) > 1:
            with ThreadPoolExecutor(workers) as pool:
                built = list(pool.map(lambda job: builder.table(*job, keep_values=keep_values), ordered))
        else:
            built = [builder.table(*job, keep_values=keep_values) for job in ordered]
        per_light: list[list[LightTable]] = [[] for _ in lights]
        for table in built:
            if table is not None:
                per_light[table.light].append(table)
        for ts in per_light:
            ts.sort(key=lambda t: (not t.is_pair, t.timing[0].cycle_s))
        band_lo, step_dt = builder.class_arrays()
        return cls(pos, float(geometry.zone_length_m), v_top, grid, params, speed, band_lo, step_dt, per_light, time.perf_counter() - t0)

    # -- lookup ----------------------------------------------------------------------------------------
    def light_index(self, station_m: float) -> int | None:
        """Index of the table light whose stop line is within :data:`POSITION_TOL_M` of ``station_m``."""
        pos = self.light_positions_m
        k = int(np.searchsorted(pos, station_m))
        for j in (k - 1, k):
            if 0 <= j < pos.size and abs(pos[j] - station_m) < POSITION_TOL_M:
                return j
        return None

    def target_speed_mps(self, obs) -> float | None:
        """Speed the DP optimum has at the next stop line, for this observation; None if no table fits."""
        if obs.position_m is None or not obs.lights:
            return None
        first = obs.lights[0]
        a = self.light_index(obs.position_m + first.distance_m)
        if a is None or not self.tables[a]:
            return None
        seen = [first]
        if len(obs.lights) > 1 and a + 1 < self.light_positions_m.size:
            b = self.light_index(obs.position_m + obs.lights[1].distance_m)
            if b == a + 1:
                seen.append(obs.lights[1])
        for table in self.tables[a]:
            tau = table.phase_now(seen)
            if tau is None:
                continue
            k0 = min(max(math.ceil((obs.position_m - table.x0_m) / table.stage_m - 1e-9), 0), table.policy.shape[0])  # at the line: the speed now
            # time to reach stage k0 from the current position at the current speed
            tau0 = tau + (table.x0_m + k0 * table.stage_m - obs.position_m) / max(obs.speed_mps, 0.5)
            i = _follow(table.policy, table.stage_cls, self.step_dt, self.band_lo, table.cap, k0, float(obs.speed_mps), tau0,
                        table.tau_step_s, table.period_s, self.speed_mps, *table.codes)  # fmt: skip
            return None if i < 0 else float(self.speed_mps[i])
        return None

    # -- files -----------------------------------------------------------------------------------------
    def save(self, path: str | Path) -> Path:
        path = Path(path)
        meta = {
            "version": TABLES_VERSION,
            "light_positions_m": self.light_positions_m.tolist(),
            "zone_length_m": self.zone_length_m,
            "speed_limit_mps": self.speed_limit_mps,
            "grid": asdict(self.grid),
            "params": repr(self.params),
            "build_s": self.build_s,
            "tables": [
                {"light": t.light, "timing": [asdict(x) for x in t.timing], "period_s": t.period_s, "tau_step_s": t.tau_step_s,
                 "x0_m": t.x0_m, "stage_m": t.stage_m}  # fmt: skip
                for ts in self.tables for t in ts
            ],
        }
        arrays = {"speed_mps": self.speed_mps, "band_lo": self.band_lo, "step_dt": self.step_dt}
        for n, t in enumerate(t for ts in self.tables for t in ts):
            arrays[f"policy_{n}"], arrays[f"stage_cls_{n}"], arrays[f"cap_{n}"] = t.policy, t.stage_cls, t.cap
        tmp = path.with_name(path.name + ".tmp.npz")
        np.savez_compressed(tmp, meta=json.dumps(meta), **arrays)
        os.replace(tmp, path)  # never a half-written file under the real name
        return path

    @classmethod
    def load(cls, path: str | Path, params: ModelParams) -> AdviceTables:
        """Load tables saved by :meth:`save`; refuses files of another code version or other parameters."""
        with np.load(path) as data:
            meta = json.loads(str(data["meta"]))
            if meta.get("version") != TABLES_VERSION or meta["params"] != repr(params):
                raise ValueError(f"{path}: tables of another version or other parameters; rebuild them")
            pos = np.array(meta["light_positions_m"])
            per_light: list[list[LightTable]] = [[] for _ in pos]
            for n, t in enumerate(meta["tables"]):
                per_light[t["light"]].append(LightTable(
                    t["light"], tuple(LightTiming(**x) for x in t["timing"]), t["period_s"], t["tau_step_s"], t["x0_m"], t["stage_m"],
                    data[f"stage_cls_{n}"], data[f"cap_{n}"], data[f"policy_{n}"]))  # fmt: skip
            return cls(pos, meta["zone_length_m"], meta["speed_limit_mps"], TableGrid(**meta["grid"]), params, data["speed_mps"],
                       data["band_lo"], data["step_dt"], per_light, meta.get("build_s", 0.0))  # fmt: skip


def _codes(dtype) -> tuple[int, int]:
    """Policy codes (no move, wait) for a policy dtype: 255/254 in one byte, -1/-2 in two."""
    return (255, 254) if np.dtype(dtype) == np.uint8 else (-1, -2)


def _key(light: int, timing: tuple[LightTiming, ...]) -> tuple:
    return (light, *((round(t.red_s, 6), round(t.cycle_s, 6), round(t.red_start_s, 6)) for t in timing))


class _Builder:
    """Lays the stretches of one corridor on stages and runs the DP for each table (thread-safe: the
    transition classes are computed under a lock)."""

    def __init__(self, speed, pos, zone_m, starts, limits, grades, params: ModelParams, grid: TableGrid) -> None:
        import threading

        self.speed, self.pos, self.zone_m = speed, pos, float(zone_m)
        self.starts, self.limits, self.grades = starts, limits, grades
        self.params, self.grid = params, grid
        self.dtype = np.dtype(np.uint8) if speed.size <= 254 else np.dtype(np.int16)  # one byte per cell when the speeds fit
        self._classes: dict[tuple[float, float], int] = {}
        self._arrays: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
        self._lock = threading.Lock()
        p, rates, pref = pack(params)
        self.idle_usd = float(step_cost_usd(p[I_AUX], 1.0, p, rates, pref))  # per second, scaled by the step below

    def pair_timing(self, a: LightTiming, b: LightTiming) -> tuple[LightTiming, LightTiming] | None:
        """The pair's timing in the frame where ``a`` turns red at 0 (``b``'s offset reduced modulo gcd),
        or None if the joint period is longer than ``max_phase_cells`` phase steps."""
        step = _tau_step((a.cycle_s, b.cycle_s), self.grid.tau_step_s)
        if step is None:
            return None
        na, nb = round(a.cycle_s / step), round(b.cycle_s / step)
        if math.lcm(na, nb) > self.grid.max_phase_cells:
            return None
        g = math.gcd(na, nb) * step
        delta = (b.red_start_s - a.red_start_s) % g
        if g - delta < 1e-6:
            delta = 0.0
        return LightTiming(a.red_s, a.cycle_s, 0.0), LightTiming(b.red_s, b.cycle_s, round(delta, 6))

    def _limit_grade(self, x0: float, x1: float) -> tuple[float, float]:
        """Lowest limit and mean grade on ``[x0, x1]``."""
        lo = max(int(np.searchsorted(self.starts, x0, side="right")) - 1, 0)
        hi = max(int(np.searchsorted(self.starts, x1, side="left")), lo + 1)
        edges = np.clip(np.append(self.starts[lo:hi], x1), x0, x1)
        weights = np.diff(edges)
        grade = float(np.dot(weights, self.grades[lo:hi]) / (x1 - x0)) if x1 > x0 else float(self.grades[lo])
        return float(self.limits[lo:hi].min()), grade

    def _cls(self, stage_m: float, grade: float) -> int:
        key = (round(stage_m, 6), round(grade, 6))
        with self._lock:
            if key not in self._classes:
                self._arrays.append(_transitions(self.speed, stage_m, grade, self.params, self.grid))
                self._classes[key] = len(self._arrays) - 1
            return self._classes[key]

    def class_arrays(self) -> tuple[np.ndarray, np.ndarray]:
        """(band_lo (n_cls, n_v), step_dt (n_cls, n_v, width)) of every class made so far."""
        width = max(a[1].shape[1] for a in self._arrays)
        band = np.stack([a[0] for a in self._arrays])
        dt = np.full((len(self._arrays), self.speed.size, width), np.inf)
        for n, a in enumerate(self._arrays):
            dt[n, :, : a[1].shape[1]] = a[1]
        return band, dt

    def _stages(self, marks: Sequence[float]) -> tuple[np.ndarray, np.ndarray]:
        """Stations of the stages over consecutive ``marks`` (each part cut into equal stages of about
        ``stage_m``), and the index of each mark among them."""
        xs, at = [marks[0]], [0]
        for x0, x1 in zip(marks, marks[1:]):
            n = max(1, int(round((x1 - x0) / self.grid.stage_m)))
            xs.extend(x0 + (x1 - x0) * np.arange(1, n + 1) / n)
            at.append(len(xs) - 1)
        xs[-1] = marks[-1]
        return np.array(xs), np.array(at)

    def _part(self, xs: np.ndarray):
        """Per stage of stations ``xs`` (K+1,): transition class and highest speed index allowed (K,)."""
        cls, cap = np.empty(xs.size - 1, dtype=np.int64), np.empty(xs.size - 1, dtype=np.int64)
        for k in range(xs.size - 1):
            limit, grade = self._limit_grade(xs[k], xs[k + 1])
            cls[k] = self._cls(xs[k + 1] - xs[k], grade)
            cap[k] = int(np.searchsorted(self.speed, limit + 1e-9, side="right")) - 1
        return cls, cap

    def _end_m(self, last: int) -> float:
        """Where a stretch whose last light is ``last`` ends: ``exit_m`` past it, or the next light, or the zone end."""
        end = min(self.pos[last] + self.grid.exit_m, self.zone_m)
        if last + 1 < self.pos.size:
            end = min(end, self.pos[last + 1])
        return float(end)

    def cost_estimate(self, a: int, timing: tuple[LightTiming, ...]) -> float:
        x0 = self.pos[a - 1] if a > 0 else 0.0
        period = timing[0].cycle_s if len(timing) == 1 else math.lcm(round(timing[0].cycle_s * 10), round(timing[1].cycle_s * 10)) / 10
        return (self.pos[a] - x0) * period

    def table(self, a: int, timing: tuple[LightTiming, ...], keep_values: bool = False) -> LightTable | None:
        grid = self.grid
        cycles = [t.cycle_s for t in timing]
        step = _tau_step(cycles, grid.tau_step_s)
        if step is None:
            return None
        cells = [round(c / step) for c in cycles]
        n_tau = math.lcm(*cells)
        if n_tau > max(grid.max_phase_cells, cells[0]):
            return None
        period = n_tau * step
        x0 = float(self.pos[a - 1]) if a > 0 else 0.0
        pair = len(timing) == 2
        last = a + 1 if pair else a
        end = self._end_m(last)
        lam = grid.time_value_usd_per_s
        idle = self.idle_usd * step
        # back part: a's line -> (b's line ->) the stretch end, phase of b only (or none)
        marks = [float(self.pos[a])] + ([float(self.pos[a + 1])] if pair else [])
        if end > marks[-1] + 1e-9:
            marks.append(end)
        limit_end, _ = self._limit_grade(end, end)
        pen = reacceleration_penalty(np.minimum(self.speed, limit_end), self.params, limit_end, grid.accel_max_mps2)
        terminal = (np.asarray(pen.cost_usd) + lam * np.asarray(pen.time_s))[:, None]
        if len(marks) > 1:
            xs, at = self._stages(marks)
            s_cls, s_cap = self._part(xs)
            n_back = cells[1] if pair else 1
            p_back = n_back * step
            is_stop = np.zeros(xs.size, dtype=np.bool_)
            red_start, red_len, cyc = np.zeros(xs.size), np.ones(xs.size), np.full(xs.size, 2.0)
            if pair:
                b = timing[1]
                k_b = at[1]
                is_stop[k_b], red_start[k_b], red_len[k_b], cyc[k_b] = True, b.red_start_s, b.red_s, b.cycle_s
            band, dt, usd = self._stack()
            policy = np.empty((xs.size - 1, self.speed.size, n_back), dtype=self.dtype)
            terminal = _periodic_backward(self.speed, s_cls, band, dt, usd, s_cap, is_stop, red_start, red_len, cyc, p_back, step,
                                          lam, idle, terminal, policy, *_codes(self.dtype))  # fmt: skip
        # front part: x0 -> a's line, joint phase; stored
        xs, _ = self._stages([x0, float(self.pos[a])])
        s_cls, s_cap = self._part(xs)
        is_stop = np.zeros(xs.size, dtype=np.bool_)
        red_start, red_len, cyc = np.zeros(xs.size), np.ones(xs.size), np.full(xs.size, 2.0)
        is_stop[-1], red_start[-1], red_len[-1], cyc[-1] = True, 0.0, timing[0].red_s, timing[0].cycle_s
        band, dt, usd = self._stack()
        policy = np.empty((xs.size - 1, self.speed.size, n_tau), dtype=self.dtype)
        value0 = _periodic_backward(self.speed, s_cls, band, dt, usd, s_cap, is_stop, red_start, red_len, cyc, period, step,
                                    lam, idle, np.ascontiguousarray(terminal), policy, *_codes(self.dtype))  # fmt: skip
        return LightTable(a, timing, period, step, x0, float(xs[1] - xs[0]), s_cls, s_cap, policy,
                          value0.astype(np.float32) if keep_values else None)  # fmt: skip

    def _stack(self):
        """Transition arrays of all classes so far, stacked (n_cls, n_v, width)."""
        with self._lock:
            arrays = list(self._arrays)
        width = max(a[1].shape[1] for a in arrays)
        band = np.stack([a[0] for a in arrays])
        dt = np.full((len(arrays), self.speed.size, width), np.inf)
        usd = np.zeros((len(arrays), self.speed.size, width))
        for n, a in enumerate(arrays):
            dt[n, :, : a[1].shape[1]], usd[n, :, : a[2].shape[1]] = a[1], a[2]
        return band, dt, usd


def paper_offsets_s() -> list[tuple[float]]:
    """Relative offsets of light 2 used by the paper's 16 timings: (y - x) mod 60 in {0, 15, 30, 45}."""
    return [(0.0,), (15.0,), (30.0,), (45.0,)]
