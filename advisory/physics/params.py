"""Named parameters and presets of the EV, battery-wear and cost models.

Every number that is not a physical constant lives here, in a frozen dataclass, with its unit in its
name and its source in the docs (README "Parameters" table, docs/MODEL.md). Algorithms take these
objects as arguments; nothing here reads the environment.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

G_MPS2 = 9.80665
"""Standard gravity [m/s²]."""

GAS_CONSTANT_J_PER_MOL_K = 8.3144
"""Ideal gas constant as used by the paper [J/(mol K)]."""

MPH_TO_MPS = 0.44704
SPEED_LIMIT_MPS = 55.0 * MPH_TO_MPS
"""The paper's speed limit, 55 mph = 88.5 km/h [m/s]."""

LB_TO_KG = 0.45359237

EM_MAP_MAX_POINTS = 16
"""Most points of an electric-machine efficiency curve (they travel in the kernels' parameter vector)."""


def _check_frac(name: str, value: float, *, allow_zero: bool = False) -> None:
    low_ok = value >= 0.0 if allow_zero else value > 0.0
    if not (low_ok and value <= 1.0):
        raise ValueError(f"{name} must be in {'[0' if allow_zero else '(0'}, 1], got {value}")


def _check_positive(**values: float) -> None:
    for name, value in values.items():
        if not value > 0.0:
            raise ValueError(f"{name} must be > 0, got {value}")


@dataclass(frozen=True, slots=True)
class VehicleParams:
    """Longitudinal model of one EV (paper Eq. 1) plus the pieces the paper leaves out.

    Units are in the field names. ``rolling_coef`` and ``rolling_speed_coef_s_per_m`` are the
    paper's C_r1 [-] and C_r2 [s/m]: rolling force = (C_r1 + C_r2 v) m g cos(theta).

    Electric machine (motor + inverter): with ``em_eff_power_frac`` / ``em_eff_frac`` empty its efficiency is
    the constant ``motor_eff_frac * inverter_eff_frac`` (the paper); otherwise it is read off that curve at the
    machine's power over ``em_power_max_w`` (both directions, FASTSim's convention). The share of braking routed
    to the motor fades at low speed as ``regen_share_frac / (1 + a exp(-b (v_mph + 1)))`` with
    ``a = regen_fade_a`` (0: no fade) and ``b = regen_fade_b_per_mph``; the motor then returns at most
    ``regen_power_max_w`` to the battery (``inf``: no limit).
    """

    name: str
    mass_kg: float
    rolling_coef: float
    rolling_speed_coef_s_per_m: float
    frontal_area_m2: float
    drag_coef: float
    trans_eff_frac: float
    motor_eff_frac: float
    inverter_eff_frac: float
    pack_energy_kwh: float
    pack_voltage_v: float
    air_density_kg_per_m3: float = 1.225
    regen_share_frac: float = 1.0
    regen_power_max_w: float = 60e3
    aux_power_w: float = 0.0
    em_power_max_w: float = math.inf
    em_eff_power_frac: tuple[float, ...] = ()
    em_eff_frac: tuple[float, ...] = ()
    regen_fade_a: float = 0.0
    regen_fade_b_per_mph: float = 0.0

    def __post_init__(self) -> None:
        _check_positive(
            mass_kg=self.mass_kg,
            frontal_area_m2=self.frontal_area_m2,
            drag_coef=self.drag_coef,
            pack_energy_kwh=self.pack_energy_kwh,
            pack_voltage_v=self.pack_voltage_v,
            air_density_kg_per_m3=self.air_density_kg_per_m3,
        )
        for name in ("trans_eff_frac", "motor_eff_frac", "inverter_eff_frac"):
            _check_frac(name, getattr(self, name))
        _check_frac("regen_share_frac", self.regen_share_frac, allow_zero=True)
        if self.rolling_coef < 0 or self.rolling_speed_coef_s_per_m < 0:
            raise ValueError("rolling coefficients must be >= 0")
        if self.regen_power_max_w < 0 or self.aux_power_w < 0:
            raise ValueError("regen_power_max_w and aux_power_w must be >= 0")
        _check_positive(em_power_max_w=self.em_power_max_w)
        if self.regen_fade_a < 0 or self.regen_fade_b_per_mph < 0:
            raise ValueError("regen_fade_a and regen_fade_b_per_mph must be >= 0")
        xs, ys = self.em_eff_power_frac, self.em_eff_frac
        if len(xs) != len(ys) or len(xs) == 1 or len(xs) > EM_MAP_MAX_POINTS:
            raise ValueError(f"em_eff_power_frac and em_eff_frac need the same length, 0 or 2..{EM_MAP_MAX_POINTS}")
        if any(b <= a for a, b in zip(xs, xs[1:], strict=False)) or (xs and xs[0] < 0):
            raise ValueError("em_eff_power_frac must start at >= 0 and increase")
        for value in ys:
            _check_frac("em_eff_frac", value)

    @property
    def drivetrain_eff_frac(self) -> float:
        """eta_trans * eta_motor * eta_invert, the paper's Eq. 1 denominator [-] (constant-efficiency chain)."""
        return self.trans_eff_frac * self.motor_eff_frac * self.inverter_eff_frac

    @property
    def em_map(self) -> tuple[tuple[float, ...], tuple[float, ...]]:
        """The machine's efficiency curve (power fraction, efficiency); two flat points for a constant chain."""
        if self.em_eff_power_frac:
            return self.em_eff_power_frac, self.em_eff_frac
        flat = self.motor_eff_frac * self.inverter_eff_frac
        return (0.0, 1.0), (flat, flat)

    @property
    def pack_capacity_ah(self) -> float:
        """Pack charge capacity at nominal voltage [Ah]."""
        return self.pack_energy_kwh * 1000.0 / self.pack_voltage_v


@dataclass(frozen=True, slots=True)
class DegradationParams:
    """Graphite/LiFePO4 cycle-life model of Wang et al. (2011), paper Eq. 2-3.

    ``m_c_rates`` / ``m_prefactor`` are the measured pre-exponential factors M(c); between them M is
    interpolated linearly in C-rate. The whole model (M and Ea) is evaluated at C-rates clamped to
    [c_rate_min, c_rate_max], the range the fit was measured on (see ``advisory.physics.battery``).
    ``decay_multiplier`` scales the SOH decay rate (the paper's 10x for NCA).
    """

    m_c_rates: tuple[float, ...] = (0.5, 2.0, 6.0, 10.0)
    m_prefactor: tuple[float, ...] = (31630.0, 21681.0, 12934.0, 15512.0)
    activation_j_per_mol: float = 31700.0
    activation_slope_j_per_mol_c: float = 370.3
    power_law_z: float = 0.55
    capacity_loss_eol_pct: float = 20.0
    temperature_k: float = 298.15
    cell_capacity_ah: float = 2.2
    c_rate_min: float = 0.5
    c_rate_max: float = 10.0
    decay_multiplier: float = 1.0

    def __post_init__(self) -> None:
        if len(self.m_c_rates) != len(self.m_prefactor) or len(self.m_c_rates) < 2:
            raise ValueError("m_c_rates and m_prefactor need the same length >= 2")
        if any(b <= a for a, b in zip(self.m_c_rates, self.m_c_rates[1:], strict=False)):
            raise ValueError("m_c_rates must increase")
        _check_positive(
            power_law_z=self.power_law_z,
            capacity_loss_eol_pct=self.capacity_loss_eol_pct,
            temperature_k=self.temperature_k,
            cell_capacity_ah=self.cell_capacity_ah,
            c_rate_min=self.c_rate_min,
            decay_multiplier=self.decay_multiplier,
        )
        if self.c_rate_max <= self.c_rate_min:
            raise ValueError("c_rate_max must exceed c_rate_min")


@dataclass(frozen=True, slots=True)
class CostParams:
    """Prices of paper Eq. 4."""

    electricity_usd_per_kwh: float = 0.12
    battery_usd_per_kwh: float = 125.0


TIME_VALUE_USD_PER_S = 4.5e-4
"""The price on time where advice trades time for energy (the lookup tables, the choice under uncertainty): with no
lights, cruising at the paper car's limit is then the cheapest steady speed (d(cost/m)/dv = lambda / v² at 24.6
m/s). Without one the optimum crawls (air drag falls with speed). [$/s]"""


@dataclass(frozen=True, slots=True)
class ModelParams:
    """Everything the scoring and the optimizer need: vehicle, battery wear and prices."""

    vehicle: VehicleParams
    degradation: DegradationParams = field(default_factory=DegradationParams)
    cost: CostParams = field(default_factory=CostParams)

    def with_decay_multiplier(self, multiplier: float) -> ModelParams:
        return replace(self, degradation=replace(self.degradation, decay_multiplier=multiplier))


PAPER_54KWH = VehicleParams(
    name="paper_54kwh",
    mass_kg=1611.0,
    rolling_coef=0.0065,
    rolling_speed_coef_s_per_m=4.92e-5,
    frontal_area_m2=2.22,
    drag_coef=0.23,
    trans_eff_frac=0.8536,
    motor_eff_frac=0.90,
    inverter_eff_frac=0.95,
    pack_energy_kwh=54.0,
    pack_voltage_v=350.0,
    regen_power_max_w=math.inf,
)
"""Paper Table 1 (Tesla Model 3 standard range), literally: Eq. 1 states no regen power limit, so there is none
(all braking through the motor, the chain efficiency multiplied on the way back). Motor efficiency and pack
voltage are our choices (the paper omits them)."""

PAPER_75KWH = replace(PAPER_54KWH, name="paper_75kwh", mass_kg=1726.0, pack_energy_kwh=75.0)
"""Paper Sec. 4.3: the long-range Model 3, 75 kWh and 1726 kg, same pack voltage."""

FASTSIM_MODEL3_EM_POWER_FRAC = (0.0, 0.02, 0.04, 0.06, 0.08, 0.1, 0.2, 0.4, 0.6, 0.8, 1.0)
FASTSIM_MODEL3_EM_EFF_FRAC = (0.84, 0.86, 0.88, 0.90, 0.91, 0.92, 0.94, 0.95, 0.95, 0.94, 0.93)
"""FASTSim 3.1, vehicle "2022 Tesla Model 3 RWD": electric machine (motor + power electronics) efficiency
against output power over its 239 kW peak (``em.eff_interp_achieved``), docs/MODEL.md."""

CALIBRATED = replace(
    PAPER_54KWH,
    name="calibrated",
    mass_kg=4250.0 * LB_TO_KG,
    trans_eff_frac=0.98,
    em_power_max_w=239e3,
    em_eff_power_frac=FASTSIM_MODEL3_EM_POWER_FRAC,
    em_eff_frac=FASTSIM_MODEL3_EM_EFF_FRAC,
    regen_share_frac=0.98,
    regen_fade_a=500.0,
    regen_fade_b_per_mph=0.99,
    regen_power_max_w=60e3,
    aux_power_w=250.0,
)
"""A Model 3 RWD on the EPA dynamometer from public sources (docs/MODEL.md): EPA's equivalent test weight
(4250 lb), the paper's road load, FASTSim's 2022 Model 3 RWD drivetrain (0.98 gear, the efficiency curve
above, 250 W accessories) and FASTSim's low-speed regen fade, with a 60 kW regen limit at the battery."""

VEHICLE_PRESETS: dict[str, VehicleParams] = {
    v.name: v for v in (PAPER_54KWH, PAPER_75KWH, CALIBRATED)
}
DEFAULT_VEHICLE = PAPER_54KWH.name


def model_params(vehicle: str | VehicleParams = DEFAULT_VEHICLE, decay_multiplier: float = 1.0) -> ModelParams:
    """A ModelParams for a preset name (or a VehicleParams) with the paper's LFP model and prices."""
    if isinstance(vehicle, str):
        try:
            vehicle = VEHICLE_PRESETS[vehicle]
        except KeyError:
            raise ValueError(f"unknown vehicle preset {vehicle!r}; choose from {sorted(VEHICLE_PRESETS)}") from None
    return ModelParams(vehicle).with_decay_multiplier(decay_multiplier)
