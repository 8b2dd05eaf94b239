"""DP lookup tables for the advisor: the optimal speed at the next stop line, by table lookup.

For a corridor of fixed-time lights with a common cycle C, the state of the lights is one number: the
time in the cycle, tau. A backward DP over (stage, speed, tau) with tau periodic gives, for every
position, speed and phase, the optimal next speed; following it to the next stop line gives the speed
the optimal driver crosses it with, which is what the advisor asks the driver to ease off (or speed up) to.

* Cost per transition: paper Eq. 4 (``advisory.physics.model``) plus a value of time ``time_value_usd_per_s``.
  Without a price on time the optimum crawls (air drag falls with speed); the default 4.5e-4 $/s is the
  value at which, with no lights, cruising at the limit is the cheapest steady speed for the paper car
  (d(cost/m)/dv = lambda / v² at 24.6 m/s), so the tables never advise dawdling for its own sake.
* Terminal cost at the zone end: the re-acceleration penalty (``advisory.evaluation.endstate``), priced the same way.
* Red: a transition into a stop-line stage at a red instant is forbidden (checked at the exact arrival
  time of the grid state); values are interpolated in tau, and an infeasible neighbour poisons the value.
* Waiting at standstill (not on a stop line) in steps of the tau grid.

One table per relative offset of the lights (light k's red start minus light 1's, modulo C). The paper's
16 timings use four: 0, 15, 30, 45 s. ``AdviceTables.target_speed_mps(obs)`` recovers tau from the live
SPaT; if the lights' durations or relative offset differ from every table, or a change is uncertain, it
returns None and the advisor falls back to its rules (never a confident wrong target).
Saved as ``.npz`` with the grid, the parameters and the code version.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
from numba import njit

from advisory.evaluation.endstate import reacceleration_penalty
from advisory.physics.model import I_AUX, battery_power_for_wheel_w, pack, step_cost_usd, step_wheel_power_w
from advisory.optimizer._kernels import is_red
from advisory.optimizer.dp import coast_chain_mps
from advisory.physics.params import ModelParams
from advisory.signals import Scenario

TABLES_VERSION = "1"
MATCH_TOL_S = 0.6


@dataclass(frozen=True, slots=True)
class TableGrid:
    """Resolution of the lookup tables. Units in names."""

    stage_m: float = 20.0
    tau_step_s: float = 0.5
    time_value_usd_per_s: float = 4.5e-4
    accel_max_mps2: float = 2.0
    brake_max_mps2: float = 4.0


@njit(cache=True)
def _periodic_backward(speed, band_lo, step_dt, step_usd, is_stop, red_start, red_s, cycle, tau_step, lam, idle_usd, terminal, value, policy):
    """value (K+1, n_v, n_tau) [$], policy (K, n_v, n_tau): next-speed index, -2 = wait, -1 = none."""
    n_stage = value.shape[0] - 1
    n_v, n_tau = value.shape[1], value.shape[2]
    for i in range(n_v):
        for j in range(n_tau):
            value[n_stage, i, j] = terminal[i]
    for k in range(n_stage - 1, -1, -1):
        k2 = k + 1
        for i in range(n_v):
            for j in range(n_tau):
                tau = j * tau_step
                best, arg = np.inf, -1
                for jj in range(step_dt.shape[1]):
                    dt = step_dt[i, jj]
                    if dt == np.inf:
                        continue
                    i2 = band_lo[i] + jj
                    t2 = tau + dt
                    if is_stop[k2] and is_red(t2, red_start[k2], red_s[k2], cycle):
                        continue
                    x = (t2 % cycle) / tau_step
                    j0 = int(x)
                    w = x - j0
                    j0 = j0 % n_tau
                    j1 = (j0 + 1) % n_tau
                    v0, v1 = value[k2, i2, j0], value[k2, i2, j1]
                    if v0 == np.inf or v1 == np.inf:
                        continue
                    c = step_usd[i, jj] + lam * dt + (1.0 - w) * v0 + w * v1
                    if c < best:
                        best, arg = c, i2
                value[k, i, j] = best
                policy[k, i, j] = arg
        if speed[0] == 0.0 and not is_stop[k]:
            wait = idle_usd + lam * tau_step
            for _sweep in range(2):
                for j in range(n_tau - 1, -1, -1):
                    c = value[k, 0, (j + 1) % n_tau] + wait
                    if c < value[k, 0, j]:
                        value[k, 0, j] = c
                        policy[k, 0, j] = -2


@njit(cache=True)
def _follow(policy, speed, step_dt, band_lo, k0, v0, tau0, k_stop, tau_step, cycle):
    """Speed index the optimal plan has on reaching stage ``k_stop`` from stage ``k0`` at the grid speed
    nearest ``v0`` and phase ``tau0``; -1 if none."""
    n_tau = policy.shape[2]
    i, tau = int(np.argmin(np.abs(speed - v0))), tau0
    for k in range(k0, k_stop):
        nxt = -1
        for _ in range(4 * n_tau):  # waits at standstill
            j = int(round((tau % cycle) / tau_step)) % n_tau
            nxt = policy[k, i, j]
            if nxt != -2:
                break
            tau += tau_step
        if nxt < 0:
            return -1
        tau += step_dt[i, nxt - band_lo[i]]
        i = nxt
    return i


def _transitions(speed, stage_m, params: ModelParams, grid: TableGrid):
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
        battery = battery_power_for_wheel_w(step_wheel_power_w(speed[i], v_next, np.where(ok, dt, 1.0), 0.0, p), p)
        step_dt[i, : v_next.size] = dt
        step_usd[i, : v_next.size] = np.where(ok, step_cost_usd(battery, np.where(ok, dt, 1.0), p, rates, pref), 0.0)
    return band_lo.astype(np.int64), step_dt, step_usd


@dataclass
class AdviceTables:
    """Lookup tables of one corridor geometry: light positions, durations, one table per relative offset."""

    light_positions_m: np.ndarray
    red_s: float
    green_s: float
    zone_length_m: float
    speed_limit_mps: float
    grid: TableGrid
    params: ModelParams
    speed_mps: np.ndarray = field(repr=False)
    band_lo: np.ndarray = field(repr=False)
    step_dt: np.ndarray = field(repr=False)
    offsets_s: dict[tuple[float, ...], tuple[np.ndarray, np.ndarray]] = field(repr=False, default_factory=dict)

    @property
    def cycle_s(self) -> float:
        return self.red_s + self.green_s

    @property
    def nbytes(self) -> int:
        return sum(v.nbytes + p.nbytes for v, p in self.offsets_s.values())

    @classmethod
    def build(cls, geometry: Scenario, params: ModelParams, grid: TableGrid = TableGrid(), offsets_s=None) -> AdviceTables:
        """
        Tables for the lights of ``geometry`` (positions and durations; their timing only sets the default
        offset). ``offsets_s``: relative offsets to tabulate, each a tuple (one entry per light after the
        first, light k's red start minus light 1's, modulo the cycle); default: the geometry's own.
        """
        lights = geometry.signals
        if not lights or len({(s.red_s, s.green_s) for s in lights}) != 1:
            raise ValueError("tables need at least one light, all with the same red and green durations")
        red_s, green_s = lights[0].red_s, lights[0].green_s
        cycle = red_s + green_s
        if offsets_s is None:
            offsets_s = [tuple((s.red_start_s - lights[0].red_start_s) % cycle for s in lights[1:])]
        ds = grid.stage_m
        n_stage = int(round(geometry.zone_length_m / ds))
        stops = [int(round(s.position_m / ds)) for s in lights]
        if abs(n_stage * ds - geometry.zone_length_m) > 1e-9 or any(abs(k * ds - s.position_m) > 1e-9 for k, s in zip(stops, lights, strict=True)):
            raise ValueError(f"stage_m = {ds} must divide the zone length and every stop-line position")
        n_tau = int(round(cycle / grid.tau_step_s))
        if abs(n_tau * grid.tau_step_s - cycle) > 1e-9:
            raise ValueError("tau_step_s must divide the cycle")
        v_lim = geometry.speed_limit_mps
        speed = coast_chain_mps(v_lim, ds, params.vehicle)
        band_lo, step_dt, step_usd = _transitions(speed, ds, params, grid)
        p, rates, pref = pack(params)
        idle = step_cost_usd(p[I_AUX], grid.tau_step_s, p, rates, pref)
        pen = reacceleration_penalty(speed, params, v_lim, grid.accel_max_mps2)
        terminal = np.asarray(pen.cost_usd) + grid.time_value_usd_per_s * np.asarray(pen.time_s)
        is_stop = np.zeros(n_stage + 1, dtype=np.bool_)
        is_stop[stops] = True
        tables = cls(np.array([s.position_m for s in lights]), red_s, green_s, geometry.zone_length_m, v_lim, grid, params, speed, band_lo, step_dt)
        for offs in offsets_s:
            red_start = np.zeros(n_stage + 1)
            red_s_arr = np.full(n_stage + 1, red_s)
            for k, off in zip(stops, (0.0, *offs), strict=True):
                red_start[k] = off
            value = np.empty((n_stage + 1, speed.size, n_tau))
            policy = np.empty((n_stage, speed.size, n_tau), dtype=np.int16)
            _periodic_backward(speed, band_lo, step_dt, step_usd, is_stop, red_start, red_s_arr, cycle, grid.tau_step_s,
                               grid.time_value_usd_per_s, idle, terminal, value, policy)
            tables.offsets_s[tuple(round(o, 6) for o in offs)] = (value.astype(np.float32), policy)
        return tables

    # -- lookup ----------------------------------------------------------------------------------------
    def _phase(self, obs) -> tuple[float, tuple[float, ...] | None] | None:
        """(tau now in the table's frame, offsets seen) from the lights ahead, or None if they do not fit."""
        if obs.position_m is None:
            return None
        cycle = self.cycle_s
        seen: dict[int, float] = {}  # table light index -> its red start in 'now' time, modulo cycle
        for light in obs.lights:
            if not light.fresh:
                return None
            at = obs.position_m + light.distance_m
            idx = [k for k, x in enumerate(self.light_positions_m.tolist()) if abs(x - at) < 5.0]
            if len(idx) != 1:
                return None
            windows = [(s, e) for s, e in light.red_windows_s if e > 0]
            if not windows:
                return None
            start, end = windows[0]
            if start > 0 and abs(end - start - self.red_s) > MATCH_TOL_S:
                return None  # another red duration, or an uncertain window
            if start <= 0 and end > self.red_s + MATCH_TOL_S:
                return None
            seen[idx[0]] = (end - self.red_s) % cycle
        if not seen:
            return None
        first = min(seen)
        tau = (-seen[first]) % cycle  # table frame: light 'first' (or light 1) turns red at its offset
        rel = {k: (seen[k] - seen[first]) % cycle for k in seen}
        return tau, first, rel

    def target_speed_mps(self, obs) -> float | None:
        """Speed the DP optimum has at the next stop line, for this observation; None if the tables don't fit."""
        found = self._phase(obs)
        if found is None:
            return None
        tau_first, first, rel = found
        cycle = self.cycle_s
        for offs, (_value, policy) in self.offsets_s.items():
            full = (0.0, *offs)
            if any(abs(((full[k] - full[first]) - rel[k] + cycle / 2) % cycle - cycle / 2) > MATCH_TOL_S for k in rel):
                continue
            tau = (tau_first + full[first]) % cycle
            ds = self.grid.stage_m
            k0 = math.ceil(obs.position_m / ds - 1e-9)
            next_light = [x for x in self.light_positions_m.tolist() if x >= obs.position_m - 1e-9]
            if not next_light or k0 >= policy.shape[0]:
                return None
            k_stop = round(next_light[0] / ds)
            # time to reach stage k0 from the current position at the current speed
            tau0 = tau + (k0 * ds - obs.position_m) / max(obs.speed_mps, 0.5)
            i = _follow(policy, self.speed_mps, self.step_dt, self.band_lo, k0, float(obs.speed_mps), tau0, k_stop, self.grid.tau_step_s, cycle)
            return None if i < 0 else float(self.speed_mps[i])
        return None

    # -- files -----------------------------------------------------------------------------------------
    def save(self, path: str | Path) -> Path:
        path = Path(path)
        meta = {
            "version": TABLES_VERSION,
            "light_positions_m": self.light_positions_m.tolist(),
            "red_s": self.red_s,
            "green_s": self.green_s,
            "zone_length_m": self.zone_length_m,
            "speed_limit_mps": self.speed_limit_mps,
            "grid": asdict(self.grid),
            "params": repr(self.params),
            "offsets": [list(k) for k in self.offsets_s],
        }
        arrays = {"speed_mps": self.speed_mps, "band_lo": self.band_lo, "step_dt": self.step_dt}
        for n, (value, policy) in enumerate(self.offsets_s.values()):
            arrays[f"value_{n}"], arrays[f"policy_{n}"] = value, policy
        np.savez_compressed(path, meta=json.dumps(meta), **arrays)
        return path

    @classmethod
    def load(cls, path: str | Path, params: ModelParams) -> AdviceTables:
        """Load tables saved by :meth:`save`; refuses files of another code version or other parameters."""
        with np.load(path) as data:
            meta = json.loads(str(data["meta"]))
            if meta["version"] != TABLES_VERSION or meta["params"] != repr(params):
                raise ValueError(f"{path}: tables of another version or other parameters; rebuild them")
            tables = cls(np.array(meta["light_positions_m"]), meta["red_s"], meta["green_s"], meta["zone_length_m"],
                         meta["speed_limit_mps"], TableGrid(**meta["grid"]), params, data["speed_mps"], data["band_lo"], data["step_dt"])
            for n, offs in enumerate(meta["offsets"]):
                tables.offsets_s[tuple(offs)] = (data[f"value_{n}"], data[f"policy_{n}"])
        return tables


def paper_offsets_s() -> list[tuple[float]]:
    """Relative offsets of light 2 used by the paper's 16 timings: (y - x) mod 60 in {0, 15, 30, 45}."""
    return [(0.0,), (15.0,), (30.0,), (45.0,)]

