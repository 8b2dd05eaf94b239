"""Eco-driving DP (paper Sec. 2): minimise electricity + battery-wear cost through a signalized zone.

Formulation
-----------
* **Stages** every ``stage_m`` metres from the zone start to its end; every stop line is a stage.
* **State** (speed, time) at each stage. Speed nodes form a *coasting chain* (:func:`coast_chain_mps`): one
  node down over one stage is exactly coasting, at every speed. The optimum coasts a lot, and on a uniform
  grid it can only alternate holding speed and braking, which costs several per cent and converges slowly
  (the convergence table in bench/bench_dp.py shows it); the chain makes coasting exact at any resolution.
* **Transitions** between nodes at constant acceleration, ``a = (v'² - v²) / (2 ds)`` in
  ``[-brake_max, accel_max]``, ``dt = 2 ds / (v + v')``; cost = paper Eq. 4 on the battery power, priced in
  ``step_substeps`` mid-step pieces (``advisory.physics.model.arc_cost_usd``). At standstill (not on a stop
  line) the car may wait in steps of ``dwell_s``.
* **Stops, exactly**: from any label before a light, an arc brakes at a constant rate to a halt ``stop_gap_m``
  short of its line; the car waits there and launches at a constant rate to a node past the line, leaving at
  the exact instant that crosses the line as the red ends. A car standing at a stage launches the same way
  (timed launch). Arc costs do not depend on the grid, so where and when a car stops is not quantized.
* **Time** is carried **exactly** on each label; labels are only *binned* by time (``time_bin_s``) to
  decide which of two paths to keep. A stop line may be crossed only at an exact time outside red, and
  the trip-time limit is checked on exact times: no rounding of time can let a path cheat a red light,
  and paths that run along the speed-limit boundary (the regular driver barely brakes) stay representable.
* **Pruning**: a backward DP on the same moves, with lights and waits left out, bounds what a label still has to
  pay, at several prices of time (a Lagrangian relaxation of the trip-time limit: a label with little time
  left must hurry, which costs). Over the last ``LIGHT_BOUND_STAGES`` stages before each light a second bound
  sees the light: a label that cannot reach the line before the red ends must take at least that long to get
  there, and the least cost of doing so (slowing down, or stopping) is tabulated against that time
  (``_kernels.light_bounds``). A label that cannot finish within a limit on the total cost is dropped. The
  limit is the optimum of the same problem on stages twice as long (or with coarser time bins), which lies a
  little above this one's, or a caller's estimate (the study prices a scenario's optimum for one vehicle for the
  next: ``advisory.evaluation.study.run_cases``); when no path is found within it, looser limits follow, finally
  none. No path within the limit is lost; a time bin then keeps its cheapest label that can still finish, which
  may differ from the cheapest label of all (doomed by the time limit), so the result may differ from the
  unpruned DP's at the level of the binning, and with the limit (on the study grid: 29 of 192 cases, -0.31 %
  to +0.23 %; ``solve_problem(prune=False)``).
  ``refine`` runs one such pass on a finer grid at a known cost: the finer grid's optimum if it is cheaper.
* **End state**: both drivers are compared back at the speed limit (``advisory.evaluation.endstate``): the terminal
  cost is the re-acceleration penalty, and its time part counts against the trip-time limit
  ``(T_regular + penalty time of the regular driver) · (1 + time_buffer_frac)``.

The recursion runs in ``_kernels.forward_pass`` (numba); ``solve_numpy`` is the same recursion in plain
NumPy/Python (unpruned), used by tests and the benchmark.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass, replace
from functools import lru_cache

import numpy as np

from advisory.evaluation.endstate import reacceleration_penalty
from advisory.physics.model import I_AUX, arc_cost_usd, pack, step_cost_usd, step_wheel_power_w
from advisory.optimizer._kernels import (
    LATE_TOL_S,
    RED_TOL_S,
    best_end,
    cost_to_go_bounds,
    count_labels,
    forward_pass,
    light_bounds,
    step_tables,
)
from advisory.physics.params import ModelParams, VehicleParams
from advisory.drivers.regular import time_to_cover_s
from advisory.signals import Scenario
from advisory.trajectory import Trajectory


@dataclass(frozen=True, slots=True)
class GridSpec:
    """DP resolution and limits. Units in names.

    ``stage_m`` sets both the distance step and the speed nodes (a coasting chain, see
    :func:`coast_chain_mps`); ``coast_split`` > 1 adds nodes between chain nodes (finer accelerations,
    coasting stays exact every ``coast_split`` nodes); ``time_bin_s`` is the width of the time bins that
    decide which of two labels to keep (times themselves are exact). Each transition is priced in
    ``step_substeps`` equal time steps (the scoring's aerodynamic and wear terms, not only at mid-stage).

    ``stop_arcs``: stops at a light are exact arcs (brake at a constant rate to a halt ``stop_gap_m`` short
    of the line, wait, launch at a constant rate to a node up to ``launch_max_m`` past the halt), their costs
    integrated in ``arc_steps`` equal time steps, so they do not depend on the grid.
    """

    stage_m: float = 10.0
    coast_split: int = 1
    time_bin_s: float = 0.25
    dwell_s: float = 0.5
    allow_dwell: bool = True
    accel_max_mps2: float = 2.0
    brake_max_mps2: float = 4.0
    time_buffer_frac: float = 0.0
    stop_arcs: bool = True
    stop_gap_m: float = 1.0
    launch_max_m: float = 300.0
    arc_steps: int = 32
    step_substeps: int = 4

    def __post_init__(self) -> None:
        for name in ("stage_m", "time_bin_s", "dwell_s", "accel_max_mps2", "brake_max_mps2", "stop_gap_m", "launch_max_m", "arc_steps"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be > 0")
        if self.coast_split < 1 or self.step_substeps < 1:
            raise ValueError("coast_split and step_substeps must be >= 1")
        if self.time_buffer_frac <= -1:
            raise ValueError("time_buffer_frac must be > -1")

    def refined(self, factor: int = 2) -> GridSpec:
        """Every step divided by ``factor``: stage length, speed spacing (via the stage), time bin, dwell."""
        return replace(
            self,
            stage_m=self.stage_m / factor,
            time_bin_s=self.time_bin_s / factor,
            dwell_s=self.dwell_s / factor,
        )


def _coast_step_mps(v_mps: float, stage_m: float, p: np.ndarray) -> float:
    """Speed after coasting (zero wheel power, flat) one stage from ``v_mps``, in the DP's mid-step model."""
    if step_wheel_power_w(v_mps, 0.0, 2.0 * stage_m / v_mps, 0.0, p) >= 0.0:
        return 0.0  # the car stops within the stage
    lo, hi = 0.0, v_mps
    for _ in range(60):  # wheel power of the step is increasing in v'; bisect for zero
        mid = 0.5 * (lo + hi)
        if step_wheel_power_w(v_mps, mid, 2.0 * stage_m / (v_mps + mid), 0.0, p) < 0.0:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


@lru_cache(maxsize=64)
def coast_chain_mps(speed_limit_mps: float, stage_m: float, vehicle: VehicleParams, coast_split: int = 1) -> np.ndarray:
    """
    Speed nodes: the limit, the speed after coasting one stage from it, after two stages, ..., 0.

    Going one node down over one stage is then exactly coasting (zero wheel power on the flat), the
    cheapest way to slow down, at every speed; other moves are the accelerations between nodes, about one
    coasting deceleration apart (~0.19 m/s² at 88 km/h, 0.065 m/s² at walking pace). ``coast_split``
    inserts nodes evenly in v² between chain nodes. Ascending, shape (n_v,). [m/s]
    """
    p, _, _ = pack(ModelParams(vehicle))
    chain = [speed_limit_mps]
    while chain[-1] > 0.0:
        chain.append(_coast_step_mps(chain[-1], stage_m, p))
    v2 = np.array(chain[::-1]) ** 2
    if coast_split > 1:
        frac = np.arange(coast_split) / coast_split
        v2 = np.concatenate([(v2[:-1, None] + np.diff(v2)[:, None] * frac[None, :]).ravel(), v2[-1:]])
    return np.sqrt(v2)


class InfeasibleError(RuntimeError):
    """No path on the grid meets the constraints (with the reason)."""


TIME_PRICES_USD_PER_S = np.array([0.0, 2e-5, 1e-4, 5e-4, 2.5e-3])
"""Prices of time in the pruning bounds (Lagrangian relaxation of the trip-time limit, ``_kernels.cost_to_go_bounds``):
0 gives the time-free bound; the others let a label that has little time left be bounded by the cost of hurrying.
[$/s] (the accessories alone cost ~1e-5 $/s)"""


@dataclass(frozen=True, slots=True)
class DPProblem:
    """A scenario laid on a grid: everything the kernel needs, plus what is needed to read its result."""

    scenario: Scenario
    grid: GridSpec
    params: ModelParams
    speed_mps: np.ndarray
    band_lo: np.ndarray
    band_hi: np.ndarray
    grade_frac: np.ndarray
    stage_grade: np.ndarray
    step_dt_s: np.ndarray
    step_usd: np.ndarray
    stop_red_start_s: np.ndarray
    stop_red_s: np.ndarray
    stop_cycle_s: np.ndarray
    is_stop: np.ndarray
    t_lo_s: np.ndarray
    t_max_s: float
    t_rem_min_s: np.ndarray
    i_start: int
    n_bins: int
    terminal_cost_usd: np.ndarray
    terminal_time_s: np.ndarray
    light_stage: np.ndarray
    arc_k_lo: np.ndarray
    stop_dt_s: np.ndarray
    stop_usd: np.ndarray
    launch_dt_s: np.ndarray
    launch_usd: np.ndarray
    launch_cross_s: np.ndarray
    rest_dt_s: np.ndarray
    rest_usd: np.ndarray
    lower_bound_usd: np.ndarray
    halt_bound_usd: np.ndarray
    light_bound_usd: np.ndarray
    light_bound_len: np.ndarray
    line_t_min_s: np.ndarray

    def bound_at_usd(self, k: int, i: int, t_s: float) -> float:
        """Least cost still to pay from stage k at speed i at time ``t_s`` (``_kernels.cost_to_go_bounds``)."""
        return float(np.max(self.lower_bound_usd[:, k, i] - TIME_PRICES_USD_PER_S * (self.t_max_s + LATE_TOL_S - t_s)))

    @property
    def n_stages(self) -> int:
        return self.grade_frac.shape[0]

    @property
    def n_lights(self) -> int:
        return self.light_stage.shape[0]


def _tables_key(grid: GridSpec) -> GridSpec:
    """``grid`` less what only the forward pass reads (time bins, dwell, trip-time buffer): the key of the move, bound
    and light-bound tables, so that grids that differ only there (a ladder of time bins) share them."""
    return replace(grid, time_bin_s=1.0, dwell_s=1.0, time_buffer_frac=0.0)


_BOUNDS: dict = {}
"""Pruning bounds by vehicle, grid and geometry (``build_problem``)."""


def build_problem(
    scenario: Scenario, params: ModelParams, grid: GridSpec, t_max_s: float, speed_nodes_mps: np.ndarray | None = None
) -> DPProblem:
    """
    Lay ``scenario`` on ``grid``. ``t_max_s``: latest exact arrival at the end state (zone time + penalty time).

    ``speed_nodes_mps`` replaces the coasting chain (tests use a handful of nodes to compare with brute force).
    """
    ds = grid.stage_m
    n_stage = int(round(scenario.zone_length_m / ds))
    if abs(n_stage * ds - scenario.zone_length_m) > 1e-9:
        raise ValueError(f"stage_m = {ds} does not divide the zone length {scenario.zone_length_m} m")
    v_lim = scenario.speed_limit_mps
    if speed_nodes_mps is None:
        speed_nodes_mps = coast_chain_mps(v_lim, ds, params.vehicle, grid.coast_split)
    speed = np.unique(np.append(speed_nodes_mps, scenario.initial_speed_mps))
    if speed[0] < 0 or speed[-1] > v_lim + 1e-12:
        raise ValueError("speed nodes must lie in [0, speed limit]")
    band_lo, band_hi = _bands(speed, grid)
    red_start, red_s, cycle = np.zeros(n_stage + 1), np.ones(n_stage + 1), np.full(n_stage + 1, 2.0)
    is_stop = np.zeros(n_stage + 1, dtype=np.bool_)
    for light in scenario.signals:
        k = int(round(light.position_m / ds))
        if abs(k * ds - light.position_m) > 1e-9:
            raise ValueError(f"stage_m = {ds} does not divide the stop-line position {light.position_m} m")
        red_start[k], red_s[k], cycle[k], is_stop[k] = light.red_start_s, light.red_s, light.cycle_s, True
    x = np.arange(n_stage + 1) * ds
    t_lo = x / v_lim - 1e-9
    remaining = scenario.zone_length_m - x
    t_rem = time_to_cover_s(remaining[:, None], speed[None, :], grid.accel_max_mps2, v_lim)
    n_bins = _n_bins(scenario, t_max_s, grid)
    if n_bins < 2:
        raise InfeasibleError(f"time limit {t_max_s:.3f} s is below the fastest possible {scenario.zone_length_m / v_lim:.3f} s")
    pen = _terminal_penalty(params, speed.tobytes(), v_lim, grid.accel_max_mps2)
    arcs = _stop_arcs(scenario, params, grid, speed, n_stage) if grid.stop_arcs else _no_arcs(speed.size)
    grade = np.zeros(n_stage)
    grades, stage_grade = np.unique(grade, return_inverse=True)
    moves = [_step_tables(params, _tables_key(grid), tuple(speed), float(g)) for g in grades]
    step_dt, step_usd = np.stack([m[0] for m in moves]), np.stack([m[1] for m in moves])
    # the bounds do not depend on the lights' timings: cases that differ only there share them
    key = (params, _tables_key(grid), speed.tobytes(), v_lim, grade.tobytes(), tuple(arcs["light_stage"]))
    if key not in _BOUNDS:
        if len(_BOUNDS) >= 32:  # ~1 MB each at the study grid
            _BOUNDS.clear()
        _BOUNDS[key] = tuple(map(_a_hair_below, cost_to_go_bounds(
            band_lo, band_hi, stage_grade, step_dt, step_usd, np.asarray(pen.cost_usd, dtype=float), np.asarray(pen.time_s, dtype=float),
            is_stop, arcs["light_stage"], arcs["arc_k_lo"], arcs["stop_dt_s"], arcs["stop_usd"], arcs["launch_dt_s"],
            arcs["launch_usd"], arcs["rest_dt_s"], arcs["rest_usd"], TIME_PRICES_USD_PER_S,
        )))
    lb, halt_lb = _BOUNDS[key]
    light_lb, light_len, line_t_min = _light_bounds(params, grid, speed, band_lo, band_hi, step_dt, step_usd, stage_grade.astype(np.int64),
                                                    is_stop, lb[0], halt_lb[0], arcs, v_lim)
    return DPProblem(
        scenario=scenario,
        grid=grid,
        params=params,
        speed_mps=speed,
        band_lo=band_lo,
        band_hi=band_hi,
        grade_frac=grade,
        stage_grade=stage_grade.astype(np.int64),
        step_dt_s=step_dt,
        step_usd=step_usd,
        stop_red_start_s=red_start,
        stop_red_s=red_s,
        stop_cycle_s=cycle,
        is_stop=is_stop,
        t_lo_s=t_lo,
        t_max_s=float(t_max_s),
        t_rem_min_s=np.ascontiguousarray(t_rem),
        i_start=int(np.flatnonzero(np.isclose(speed, scenario.initial_speed_mps, rtol=0, atol=1e-12))[0]),
        n_bins=n_bins,
        terminal_cost_usd=np.asarray(pen.cost_usd),
        terminal_time_s=np.asarray(pen.time_s),
        **arcs,
        lower_bound_usd=lb,
        halt_bound_usd=halt_lb,
        light_bound_usd=light_lb,
        light_bound_len=light_len,
        line_t_min_s=line_t_min,
    )


LIGHT_BOUND_STAGES = 20
"""Stages before each light over which labels are also bounded by the light's red (``_kernels.light_bounds``)."""
LIGHT_BOUND_BIN_S, LIGHT_BOUND_N = 0.25, 160
"""Resolution and range of the time a label must still take to its line, in those bounds (beyond: clamped). [s]"""

_LIGHT_BOUNDS: dict = {}
"""Light bounds by what they depend on (vehicle, grid, speeds, the bounds at and before the line): a light whose
downstream is the same in several cases (the paper's light 2 at every spacing) shares one table."""


_LIGHT_STACKS: dict = {}
"""``_light_bounds``'s arrays by the geometry of a problem (the study's consecutive cases share them)."""


def _light_bounds(params, grid, speed, band_lo, band_hi, step_dt, step_usd, stage_grade, is_stop, lb0, halt_lb0, arcs, v_lim):
    """The bounds of ``_kernels.light_bounds`` for every light, stacked (n_light, LIGHT_BOUND_STAGES + 1, n_v,
    LIGHT_BOUND_N), the stages each covers, and the least time from each (stage, speed) to the next line (0 where
    no bound applies; a hair short of the fastest drive there, accelerating at the limit to the speed limit)."""
    light_stage, k_lo = arcs["light_stage"], arcs["arc_k_lo"]
    n_l, n_v = light_stage.size, speed.size
    backs = [min(LIGHT_BOUND_STAGES, int(kl - lo)) for kl, lo in zip(light_stage, k_lo, strict=True)]
    keys = [(params, _tables_key(grid), speed.tobytes(), lb0[kl - n : kl + 1].tobytes(), float(halt_lb0[l]), is_stop[kl - n : kl + 1].tobytes(),
             stage_grade[kl - n : kl].tobytes(), n) for l, (kl, n) in enumerate(zip(light_stage, backs, strict=True))]
    stack_key = (tuple(keys), tuple(light_stage), v_lim, stage_grade.size)
    if stack_key in _LIGHT_STACKS:  # the same geometry as a recent case: the same arrays (read only)
        return _LIGHT_STACKS[stack_key]
    out = np.empty((n_l, LIGHT_BOUND_STAGES + 1, n_v, LIGHT_BOUND_N), dtype=np.float32)  # rows past a light's window unused
    t_min = np.zeros((stage_grade.size + 1, n_v))
    for l, (key, n_back) in enumerate(zip(keys, backs, strict=True)):
        kl = int(light_stage[l])
        if key not in _LIGHT_BOUNDS:
            if len(_LIGHT_BOUNDS) >= 48:  # 2-3.5 MB each at the study grid; the paper's study uses ~20
                _LIGHT_BOUNDS.clear()
            _LIGHT_BOUNDS[key] = light_bounds(speed, band_lo, band_hi, step_dt, step_usd, stage_grade, is_stop, grid.allow_dwell, lb0,
                                              float(halt_lb0[l]), arcs["stop_usd"], kl, n_back, LIGHT_BOUND_BIN_S, LIGHT_BOUND_N)
        out[l, : n_back + 1] = _LIGHT_BOUNDS[key]
        d = (kl - np.arange(kl - n_back, kl))[:, None] * grid.stage_m
        t_min[kl - n_back : kl] = time_to_cover_s(d, speed[None, :], grid.accel_max_mps2, v_lim) - 1e-6
    if len(_LIGHT_STACKS) >= 8:  # 7 MB each at the study grid with two lights
        _LIGHT_STACKS.clear()
    _LIGHT_STACKS[stack_key] = out, np.array(backs, dtype=np.int64), t_min
    return _LIGHT_STACKS[stack_key]


@lru_cache(maxsize=32)
def _terminal_penalty(params: ModelParams, speed_bytes: bytes, speed_limit_mps: float, accel_mps2: float):
    """The re-acceleration penalty at every speed node (the terminal cost), shared by the cases that use these nodes."""
    return reacceleration_penalty(np.frombuffer(speed_bytes), params, speed_limit_mps, accel_mps2)


def _a_hair_below(bound: np.ndarray) -> np.ndarray:
    """Bounds lowered by 1e-9 of themselves, against rounding in the sums (inf stays inf: no completion)."""
    finite = np.isfinite(bound)
    out = bound.copy()
    out[finite] -= 1e-9 * np.abs(bound[finite])
    return out


def _divides(scenario: Scenario, stage_m: float) -> bool:
    """Whether stages of ``stage_m`` fit the zone and put every stop line on a stage."""
    return all(abs(x / stage_m - round(x / stage_m)) < 1e-9 for x in (scenario.zone_length_m, *(s.position_m for s in scenario.signals)))


def _n_bins(scenario: Scenario, t_max_s: float, grid: GridSpec) -> int:
    """Time bins from the fastest possible arrival to the time limit (at every stage), with a spare one."""
    return int(np.ceil((t_max_s - scenario.zone_length_m / scenario.speed_limit_mps) / grid.time_bin_s)) + 2


def arc_table(v0_mps, v1_mps, distance_m, params: ModelParams, n_steps: int) -> tuple[np.ndarray, np.ndarray]:
    """
    Duration [s] and cost [$] of constant-acceleration arcs from ``v0`` to ``v1`` over ``distance_m`` (broadcast).

    Priced by ``arc_cost_usd`` in ``n_steps`` equal time steps, so an arc's cost does not depend on the DP grid.
    Arcs with ``v0 + v1 = 0`` get an infinite duration and cost.
    """
    v0, v1, d = np.broadcast_arrays(*(np.asarray(a, dtype=float) for a in (v0_mps, v1_mps, distance_m)))
    moving = v0 + v1 > 0
    total = np.where(moving, 2.0 * d / np.where(moving, v0 + v1, 1.0), np.inf)
    p, rates, pref = pack(params)
    cost = arc_cost_usd(v0, v1, np.where(moving, total, 1.0), 0.0, n_steps, p, rates, pref)
    return total, np.where(moving, cost, np.inf)


def _bands(speed: np.ndarray, grid: GridSpec) -> tuple[np.ndarray, np.ndarray]:
    """Index range of the next speeds reachable over one stage within the acceleration limits, per speed node."""
    v2, ds = speed**2, grid.stage_m
    band_lo = np.searchsorted(v2, v2 - 2 * grid.brake_max_mps2 * ds - 1e-9, side="left").astype(np.int64)
    band_hi = (np.searchsorted(v2, v2 + 2 * grid.accel_max_mps2 * ds + 1e-9, side="right") - 1).astype(np.int64)
    return band_lo, band_hi


@lru_cache(maxsize=32)
def _step_tables(params: ModelParams, grid: GridSpec, speed: tuple[float, ...], grade_frac: float) -> tuple[np.ndarray, np.ndarray]:
    """Duration [s] and cost [$] of every stage move on this grade, (n_v, widest band): computed once and shared
    by the cases of a study that use the same vehicle and grid (the physics does not depend on the lights)."""
    v = np.asarray(speed)
    band_lo, band_hi = _bands(v, grid)
    width = int((band_hi - band_lo).max()) + 1
    step_dt, step_usd = np.full((v.size, width), np.inf), np.full((v.size, width), np.inf)
    p, rates, pref = pack(params)
    step_tables(v, band_lo, band_hi, grid.stage_m, grade_frac, grid.step_substeps, p, rates, pref, step_dt, step_usd)
    return step_dt, step_usd


def _no_arcs(n_v: int) -> dict:
    empty = np.zeros((0, n_v))
    return dict(light_stage=np.zeros(0, dtype=np.int64), arc_k_lo=np.zeros(0, dtype=np.int64), stop_dt_s=empty,
                stop_usd=empty, launch_dt_s=empty, launch_usd=empty, launch_cross_s=empty, rest_dt_s=empty, rest_usd=empty)


_ARCS: dict = {}
"""Arc tables by vehicle, arc geometry and speed nodes (``_arc_tables``), shared by every case and pass that uses them."""


def _arc_tables(params: ModelParams, grid: GridSpec, speed: np.ndarray, n_stop: int) -> tuple[np.ndarray, ...]:
    """Stop arcs by distance (row n: from n + 1 stages before the line to the halt), launches from the halt
    (row m: to m + 1 stages past the line), launches from rest at a stage (row n: over n + 1 stages).

    Computed once per vehicle, arc geometry and speeds; stop rows are added when a longer approach needs them."""
    ds, gap, v = grid.stage_m, grid.stop_gap_m, speed[None, :]
    key = (params, ds, gap, grid.launch_max_m, grid.accel_max_mps2, grid.brake_max_mps2, grid.arc_steps, speed.tobytes())
    tables = _ARCS.get(key)
    if tables is None:
        if len(_ARCS) >= 32:  # ~0.5 MB each at the study grid
            _ARCS.clear()
        n_launch = max(1, int(np.floor((grid.launch_max_m - gap) / ds)))
        out = [np.zeros((0, speed.size)), np.zeros((0, speed.size))]
        for dist in (np.arange(1, n_launch + 1)[:, None] * ds + gap, np.arange(1, n_launch + 1)[:, None] * ds):
            ok = (v > 0) & (v**2 <= 2 * grid.accel_max_mps2 * dist + 1e-9)
            dt, usd = arc_table(0.0, v, dist, params, grid.arc_steps)
            out += [np.where(ok, dt, np.inf), np.where(ok, usd, np.inf)]
        accel = np.where(out[2] < np.inf, v**2, 1.0) / (2 * (np.arange(1, n_launch + 1)[:, None] * ds + gap))
        tables = _ARCS[key] = [*out, np.where(out[2] < np.inf, np.sqrt(2 * gap / accel), np.inf)]
    have = tables[0].shape[0]
    if have < n_stop:
        dist = np.arange(have + 1, n_stop + 1)[:, None] * ds - gap
        ok = (v > 0) & (dist > 0) & (v**2 <= 2 * grid.brake_max_mps2 * dist + 1e-9)
        stop_dt, stop_usd = arc_table(v, 0.0, np.maximum(dist, 1e-9), params, grid.arc_steps)
        tables[0] = np.concatenate([tables[0], np.where(ok, stop_dt, np.inf)])
        tables[1] = np.concatenate([tables[1], np.where(ok, stop_usd, np.inf)])
    return (tables[0][:n_stop], tables[1][:n_stop], *tables[2:])


def _stop_arcs(scenario: Scenario, params: ModelParams, grid: GridSpec, speed: np.ndarray, n_stage: int) -> dict:
    """Tables of the exact stop arcs (see ``_kernels.forward_pass``): halts before each light, launches after it."""
    stages = [int(round(light.position_m / grid.stage_m)) for light in scenario.signals]
    k_lo = [0] + stages[:-1]  # arcs start at or after the previous line: they never cross a light
    n_stop = max(kl - lo for kl, lo in zip(stages, k_lo, strict=True))
    stop_dt, stop_usd, launch_dt, launch_usd, rest_dt, rest_usd, cross = _arc_tables(params, grid, speed, n_stop)
    return dict(light_stage=np.array(stages, dtype=np.int64), arc_k_lo=np.array(k_lo, dtype=np.int64), stop_dt_s=stop_dt,
                stop_usd=stop_usd, launch_dt_s=launch_dt, launch_usd=launch_usd, launch_cross_s=cross,
                rest_dt_s=rest_dt, rest_usd=rest_usd)


@dataclass(frozen=True, slots=True)
class DPSolution:
    """Optimal trajectory through the zone and its DP cost (zone cost + terminal penalty) [$]."""

    problem: DPProblem
    trajectory: Trajectory
    cost_usd: float
    end_time_s: float
    n_labels: int


_WORKSPACE = threading.local()
"""Per thread, the memory of the last pass's (stage, speed, bin) tables, reused by the next pass when large enough:
fresh tables of this size come from the kernel as zero pages, and faulting them in cost ~15 % of a study's time."""

WORKSPACE_MAX_CELLS = 8_000_000
"""Tables above this many cells (3 x 8 bytes each) are not kept for reuse (the study grid's largest: ~6e6)."""


def _empty_tables(prob: DPProblem):
    """The kernel's tables: (stage, speed, bin) ones uninitialised (valid over each row's range in use,
    ``occ_lo..occ_hi``, which the kernel fills; their memory is reused from pass to pass), the halts' ones empty."""
    shape = (prob.n_stages + 1, prob.speed_mps.size, prob.n_bins)
    n = shape[0] * shape[1] * shape[2]
    bufs = getattr(_WORKSPACE, "bufs", None)
    if bufs is None or bufs[0].size < n:
        bufs = (np.empty(n), np.empty(n), np.empty(n, dtype=np.int64))
        _WORKSPACE.bufs = bufs if n <= WORKSPACE_MAX_CELLS else None
    s_shape = (prob.n_lights, prob.n_bins)
    occ_lo = np.full(shape[:2], prob.n_bins, dtype=np.int64)
    occ_hi = np.full(shape[:2], -1, dtype=np.int64)
    return (*(b[:n].reshape(shape) for b in bufs),
            np.full(s_shape, np.inf), np.full(s_shape, np.nan), np.full(s_shape, -1, dtype=np.int64), occ_lo, occ_hi)


def _kernel_args(prob: DPProblem):
    p, rates, pref = pack(prob.params)
    g = prob.grid
    return (
        prob.speed_mps, prob.band_lo, prob.band_hi, g.stage_m, prob.stage_grade, prob.step_dt_s, prob.step_usd, prob.stop_red_start_s,
        prob.stop_red_s, prob.stop_cycle_s, prob.is_stop, prob.t_lo_s, g.time_bin_s, g.dwell_s, g.allow_dwell,
        prob.t_max_s, prob.t_rem_min_s, prob.i_start, p, rates, pref, prob.light_stage, prob.arc_k_lo,
        prob.stop_dt_s, prob.stop_usd, prob.launch_dt_s, prob.launch_usd, prob.launch_cross_s, prob.rest_dt_s, prob.rest_usd,
    )


def _read_solution(prob: DPProblem, cost, time, parent, s_time=None, s_parent=None, occ=None, upper_bound_usd=np.inf) -> DPSolution | None:
    """The optimum from the kernel's tables (``occ``: their rows' ranges in use, None when fully initialised);
    None when it exceeds ``upper_bound_usd`` (the pruned tables then do not hold the unpruned optimum)."""
    if occ is None:
        occ = (np.zeros(cost.shape[:2], dtype=np.int64), np.full(cost.shape[:2], prob.n_bins - 1, dtype=np.int64))
    flat, best = best_end(cost[-1], time[-1], occ[0][-1], occ[1][-1], prob.terminal_cost_usd, prob.terminal_time_s, prob.t_max_s)
    if np.isfinite(upper_bound_usd) and not best <= upper_bound_usd:
        return None
    if not np.isfinite(best):
        raise InfeasibleError(
            f"{prob.scenario.name}: no path reaches the end state by {prob.t_max_s:.3f} s on this grid "
            f"(stage {prob.grid.stage_m} m, {prob.speed_mps.size} speeds, bin {prob.grid.time_bin_s} s)"
        )
    nb, nv, ds = prob.n_bins, prob.speed_mps.size, prob.grid.stage_m
    k, (i, b) = prob.n_stages, divmod(flat, nb)
    knots = []
    while True:
        knots.append((time[k, i, b], k * ds, prob.speed_mps[i]))
        code = int(parent[k, i, b])
        if code == -1:
            break
        if code <= -2 - prob.n_lights * nb:  # a timed launch from a standstill cell: the launch, then the wait
            code = -code - 2 - prob.n_lights * nb
            knots.append((time[k, i, b] - prob.rest_dt_s[k - code // (nv * nb) - 1, i], (code // (nv * nb)) * ds, 0.0))
        elif code <= -2:  # launched from the halt before light l: the halt, its waits, then the stop arc
            l, sb = divmod(-code - 2, nb)
            halt_m = prob.scenario.signals[l].position_m - prob.grid.stop_gap_m
            knots.append((time[k, i, b] - prob.launch_dt_s[k - prob.light_stage[l] - 1, i], halt_m, 0.0))
            while True:
                knots.append((s_time[l, sb], halt_m, 0.0))
                code = int(s_parent[l, sb])
                if code >= 0:
                    break
                sb = -code - 2 - l * nb
        k, rest = divmod(code, nv * nb)
        i, b = divmod(rest, nb)
    knots = knots[::-1]
    keep = [0] + [n for n in range(1, len(knots)) if knots[n][0] > knots[n - 1][0]]  # a launch without a wait
    t, x, v = (np.array([knots[n][c] for n in keep], dtype=float) for c in range(3))
    n_labels = int(np.isfinite(cost).sum()) if occ is None else count_labels(cost, *occ)
    return DPSolution(prob, Trajectory(t, x, v), best, float(t[-1]), n_labels)


PRUNE_MARGINS = (0.1, 0.25, 0.45, 0.7, 1.0, 1.4, 2.0, 3.0)
"""Pruning limits tried in turn when no estimate of the optimum is at hand, as fractions above the bound on the
whole trip; the first whose optimum lies within its limit is the exact optimum, else the next one, then none."""

COARSE_LEVELS = 2
"""Estimates of the optimum come from the same problem with time bins (and dwell) 2, 4, ... 2^COARSE_LEVELS
times wider, solved coarsest first (each estimating the next): a few per cent of the work of the full pass."""


def _pass(prob: DPProblem, limit_usd: float) -> DPSolution | None:
    """One forward pass pruned at ``limit_usd`` (total cost); None when its optimum is not within the limit."""
    cost, time, parent, s_cost, s_time, s_parent, occ_lo, occ_hi = _empty_tables(prob)
    n = TIME_PRICES_USD_PER_S.size if np.isfinite(limit_usd) else 1  # no limit: no bounds to check
    forward_pass(*_kernel_args(prob), cost, time, parent, s_cost, s_time, s_parent, prob.lower_bound_usd[:n],
                 prob.halt_bound_usd[:n], TIME_PRICES_USD_PER_S[:n], min(limit_usd, np.finfo(float).max), occ_lo, occ_hi,
                 prob.light_bound_usd, prob.light_bound_len, prob.line_t_min_s, LIGHT_BOUND_BIN_S)
    return _read_solution(prob, cost, time, parent, s_time, s_parent, (occ_lo, occ_hi), limit_usd)


def _solve_pruned(prob: DPProblem, estimate_usd: float | None) -> DPSolution:
    """The optimum, pruning at ``estimate_usd`` (if given) and a little above it first, then at the limits of
    ``PRUNE_MARGINS``, then not at all: the first pass that finds a path within its limit answers."""
    bound0 = prob.bound_at_usd(0, prob.i_start, 0.0)
    limits = [bound0 + m * abs(bound0) for m in PRUNE_MARGINS] if np.isfinite(bound0) else []
    if estimate_usd is not None:
        near = [estimate_usd * (1 + m) for m in (1e-4, 3e-3, 1e-2, 3e-2)]  # the estimate is rarely below, and then close
        limits = near + [x for x in limits if x > near[-1]]
    for limit in [*limits, np.inf]:
        sol = _pass(prob, limit)
        if sol is not None:
            return sol
    raise AssertionError("unreachable: the unpruned pass always returns")


def _coarser(prob: DPProblem, factor: int) -> DPProblem:
    """The same problem with time bins and dwell ``factor`` times wider (everything else shared)."""
    grid = replace(prob.grid, time_bin_s=prob.grid.time_bin_s * factor, dwell_s=prob.grid.dwell_s * factor)
    return replace(prob, grid=grid, n_bins=_n_bins(prob.scenario, prob.t_max_s, grid))


def solve_problem(prob: DPProblem, prune: bool = True, estimate_usd: float | None = None) -> DPSolution:
    """Run the numba forward pass on a built problem and read off the optimal trajectory.

    With ``prune`` (exact: the result is that of the full pass), labels that cannot finish within a limit on the
    total cost are dropped; the limit is the optimum of the problem with coarser time bins (``COARSE_LEVELS``),
    which is almost always a little above this one's, and falls back to looser limits when it is not.
    ``estimate_usd`` (for example the cost of a feasible path) replaces that estimate: the first limit tried.
    """
    if not prune:
        return _pass(prob, np.inf)
    if estimate_usd is not None:
        return _solve_pruned(prob, estimate_usd)
    estimate = None
    coarse_stage = replace(prob.grid, stage_m=2 * prob.grid.stage_m)
    if _divides(prob.scenario, coarse_stage.stage_m):  # the problem on stages twice as long: a close estimate, cheaply
        try:
            return _solve_pruned(prob, solve_problem(build_problem(prob.scenario, prob.params, coarse_stage, prob.t_max_s)).cost_usd)
        except InfeasibleError:
            pass
    for level in range(COARSE_LEVELS, 0, -1):
        coarse = _coarser(prob, 2**level)
        if coarse.n_bins < 4:
            continue
        try:
            estimate = _solve_pruned(coarse, estimate).cost_usd
        except InfeasibleError:  # too coarse to find a path along the time limit: no estimate from it
            estimate = None
    return _solve_pruned(prob, estimate)


def refine(sol: DPSolution, grid: GridSpec) -> DPSolution:
    """The problem of ``sol`` laid on ``grid`` (a finer one) and solved by one pass pruned at ``sol``'s cost: that
    optimum when it is cheaper than ``sol`` (pruning is exact: no cheaper path on ``grid`` is missed), else ``sol``.

    A pass at a limit the answer is known to lie under costs much less than a solve; the study refines its cases
    this way (``advisory.evaluation.study.solve_case``). ``sol`` is kept when ``grid`` does not fit the scenario."""
    prob = sol.problem
    if not _divides(prob.scenario, grid.stage_m):
        return sol
    try:
        better = _pass(build_problem(prob.scenario, prob.params, grid, prob.t_max_s), sol.cost_usd)
    except InfeasibleError:
        return sol
    return better if better is not None and better.cost_usd < sol.cost_usd else sol


def time_limit_s(regular: Trajectory, params: ModelParams, scenario: Scenario, grid: GridSpec) -> float:
    """The DP's trip-time limit: the regular driver's time to the common end state, with the buffer."""
    pen = reacceleration_penalty(regular.v_mps[-1], params, scenario.speed_limit_mps, grid.accel_max_mps2)
    return (regular.duration_s + float(pen.time_s[0])) * (1.0 + grid.time_buffer_frac)


def solve(
    scenario: Scenario, params: ModelParams, grid: GridSpec | None = None, t_max_s: float | None = None, estimate_usd: float | None = None
) -> DPSolution:
    """
    Optimal eco-driving trajectory through ``scenario``.

    ``t_max_s`` defaults to the regular driver's time to the common end state (paper: the regular
    driver's trip time is the eco-driver's upper limit), times ``1 + grid.time_buffer_frac``.
    ``estimate_usd``: a close estimate of the optimum, if known (see :func:`solve_problem`).
    """
    from advisory.drivers.regular import regular_driver

    grid = grid or GridSpec()
    if t_max_s is None:
        t_max_s = time_limit_s(regular_driver(scenario), params, scenario, grid)
    return solve_problem(build_problem(scenario, params, grid, t_max_s), estimate_usd=estimate_usd)


def solve_numpy(prob: DPProblem) -> DPSolution:
    """The same forward recursion as ``forward_pass`` in plain NumPy/Python (reference and benchmark), without stop arcs
    or pruning: it equals ``solve_problem(prob, prune=False)``."""
    if prob.n_lights and prob.grid.stop_arcs:
        raise ValueError("solve_numpy has no stop arcs: build the problem with GridSpec(stop_arcs=False)")
    shape = (prob.n_stages + 1, prob.speed_mps.size, prob.n_bins)
    cost, time, parent = np.full(shape, np.inf), np.full(shape, np.nan), np.full(shape, -1, dtype=np.int64)
    p, rates, pref = pack(prob.params)
    g = prob.grid
    nb = prob.n_bins
    cost[0, prob.i_start, 0], time[0, prob.i_start, 0], parent[0, prob.i_start, 0] = 0.0, 0.0, -1
    idle = step_cost_usd(p[I_AUX], g.dwell_s, p, rates, pref)
    v = prob.speed_mps
    for k in range(prob.n_stages):
        if g.allow_dwell and v[0] == 0.0 and not prob.is_stop[k]:
            for b in range(nb):
                if np.isfinite(cost[k, 0, b]):
                    t2 = time[k, 0, b] + g.dwell_s
                    b2 = int((t2 - prob.t_lo_s[k]) / g.time_bin_s)
                    if t2 + prob.t_rem_min_s[k, 0] <= prob.t_max_s + LATE_TOL_S and b2 < nb and cost[k, 0, b] + idle < cost[k, 0, b2]:
                        cost[k, 0, b2], time[k, 0, b2], parent[k, 0, b2] = cost[k, 0, b] + idle, t2, (k * v.size) * nb + b
        k2 = k + 1
        for i in range(v.size):
            src = np.flatnonzero(np.isfinite(cost[k, i]))
            if src.size == 0:
                continue
            i2 = np.arange(prob.band_lo[i], prob.band_hi[i] + 1)
            i2 = i2[v[i] + v[i2] > 0]
            dt = 2.0 * g.stage_m / (v[i] + v[i2])
            step = arc_cost_usd(v[i], v[i2], dt, prob.grade_frac[k], g.step_substeps, p, rates, pref)
            for j, target in enumerate(i2):
                t2 = time[k, i, src] + dt[j]
                ok = t2 <= prob.t_max_s + LATE_TOL_S - prob.t_rem_min_s[k2, target]
                if prob.is_stop[k2]:
                    phase = (t2 - prob.stop_red_start_s[k2]) % prob.stop_cycle_s[k2]
                    ok &= ~(phase < prob.stop_red_s[k2] - RED_TOL_S)
                b2 = ((t2 - prob.t_lo_s[k2]) / g.time_bin_s).astype(np.int64)
                ok &= b2 < nb
                c2 = cost[k, i, src] + step[j]
                for s_b, tb, cb, tt in zip(src[ok], b2[ok], c2[ok], t2[ok], strict=True):  # first minimum wins
                    if cb < cost[k2, target, tb]:
                        cost[k2, target, tb], time[k2, target, tb], parent[k2, target, tb] = cb, tt, (k * v.size + i) * nb + s_b
    return _read_solution(prob, cost, time, parent)
