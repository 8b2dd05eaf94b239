"""The paper's study, case by case: regular driver vs DP eco-driver in the same end state.

Pure computation (no files, no clock); ``replay.study`` runs it in parallel and writes the report.

Variants (paper Sec. 4):
* ``lfp54``: paper vehicle, 54 kWh, LFP decay (Table 2, Figs. [15 15] and [-15 15]);
* ``nca54``: same with the decay rate x10 (NCA, Sec. 4.2);
* ``nca75``: 75 kWh / 1726 kg with the decay rate x10 (battery-size study, Sec. 4.3, Table 3).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

from advisory.evaluation.endstate import EndStateScore, score_in_end_state
from advisory.optimizer.dp import GridSpec, solve
from advisory.physics.params import model_params
from advisory.drivers.regular import regular_driver
from advisory.signals import PAPER_EXIT_M, PAPER_SPACINGS_M, PAPER_TIMINGS_S, paper_scenario
from advisory.trajectory import Trajectory

VARIANTS: dict[str, tuple[str, float]] = {
    "lfp54": ("paper_54kwh", 1.0),
    "nca54": ("paper_54kwh", 10.0),
    "nca75": ("paper_75kwh", 10.0),
}

STUDY_GRID = GridSpec(stage_m=10.0, time_bin_s=0.25, dwell_s=0.5)
"""Default resolution of the study (see the convergence table of bench/bench_dp.py)."""


@dataclass(frozen=True, slots=True)
class CaseResult:
    variant: str
    x_s: float
    y_s: float
    spacing_m: float
    regular: EndStateScore
    eco: EndStateScore
    regular_traj: Trajectory
    eco_traj: Trajectory
    dp_cost_usd: float

    @property
    def key(self) -> tuple[str, float, float, float]:
        return (self.variant, self.x_s, self.y_s, self.spacing_m)

    def reduction_pct(self, what: str) -> float:
        """Eco-driving reduction of ``energy``, ``decay`` or ``cost`` against the regular driver. [%]"""
        attr = {"energy": "energy_kwh", "decay": "soh_lost_frac", "cost": "cost_usd"}[what]
        reg, eco = getattr(self.regular, attr), getattr(self.eco, attr)
        return 100.0 * (1.0 - eco / reg)

    def row(self) -> dict:
        out = {"variant": self.variant, "x_s": self.x_s, "y_s": self.y_s, "spacing_m": self.spacing_m}
        for who, s in (("regular", self.regular), ("eco", self.eco)):
            out.update(
                {
                    f"{who}_energy_kwh": s.energy_kwh,
                    f"{who}_soh_lost": s.soh_lost_frac,
                    f"{who}_electricity_usd": s.electricity_usd,
                    f"{who}_wear_usd": s.wear_usd,
                    f"{who}_cost_usd": s.cost_usd,
                    f"{who}_time_s": s.time_s,
                    f"{who}_exit_speed_mps": s.exit_speed_mps,
                }
            )
        for what in ("energy", "decay", "cost"):
            out[f"{what}_reduction_pct"] = self.reduction_pct(what)
        out["dp_cost_usd"] = self.dp_cost_usd
        return out


def study_cases(variants=tuple(VARIANTS)) -> list[tuple[str, float, float, float]]:
    """(variant, x, y, s) for every variant x the paper's 16 timings x 4 spacings."""
    return [(v, x, y, s) for v in variants for x in PAPER_TIMINGS_S for y in PAPER_TIMINGS_S for s in PAPER_SPACINGS_M]


def run_case(
    variant: str,
    x_s: float,
    y_s: float,
    spacing_m: float,
    grid: GridSpec = STUDY_GRID,
    overrides: dict | None = None,
    exit_m: float = PAPER_EXIT_M,
) -> CaseResult:
    """Regular driver and DP optimum for one case, both scored to the common end state.

    ``overrides``: vehicle fields to replace (sensitivity studies), e.g. ``{"regen_power_max_w": 2e5}``.
    """
    vehicle, decay = VARIANTS[variant]
    params = model_params(vehicle, decay)
    if overrides:
        params = replace(params, vehicle=replace(params.vehicle, **overrides))
    scenario = paper_scenario(x_s, y_s, spacing_m, exit_m=exit_m)
    regular = regular_driver(scenario)
    sol = solve(scenario, params, grid)
    v_lim = scenario.speed_limit_mps
    return CaseResult(
        variant=variant,
        x_s=x_s,
        y_s=y_s,
        spacing_m=spacing_m,
        regular=score_in_end_state(regular, params, v_lim, keep_series=True),
        eco=score_in_end_state(sol.trajectory, params, v_lim, keep_series=True),
        regular_traj=regular,
        eco_traj=sol.trajectory,
        dp_cost_usd=sol.cost_usd,
    )
