"""Request and response bodies of the API (pydantic). Units in field names; every float must be finite."""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field


class _In(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)


class _Out(BaseModel):
    model_config = ConfigDict(frozen=True)


class ErrorOut(_Out):
    """Every 4xx/5xx body: a short machine-readable code, a sentence, and details when there are some."""

    error: str = Field(examples=["validation_error"])
    message: str
    detail: list[dict] | dict | None = None


class TripCreate(_In):
    corridor: str | None = Field(default=None, description="corridor name (GET /v1/corridors); default: the service's", max_length=200)
    timing: str | None = Field(
        default=None,
        description="signal timing: one of the corridor's plans (GET /v1/corridors), or a paper preset (e.g. '15_15', 'field_test'); "
        "default: the corridor's own plan, else one of the paper's 16 picked from the entry time",
        max_length=50,
    )
    vehicle: str | None = Field(default=None, description="vehicle preset (paper_54kwh, paper_75kwh, calibrated)", max_length=50)
    entry_unix_s: float | None = Field(
        default=None,
        description="zone-entry instant the simulated timing is relative to; default: the creation instant. Within the fix time limits of server time.",
    )


class TripLinks(_Out):
    fixes: str
    advice: str
    stream: str
    audio: str
    spat: str
    end: str


class TripCreated(_Out):
    trip_id: str
    token: str = Field(description="bearer token for this trip only: 'Authorization: Bearer <token>' (WebSocket: also ?token=)")
    token_type: Literal["bearer"] = "bearer"
    corridor: str
    timing: str
    vehicle: str
    entry_unix_s: float = Field(description="the car is taken to enter the zone (station 0) at this instant: the trip's creation unless given")
    created_unix_s: float
    idle_ttl_s: float
    links: TripLinks


class GpsFixIn(_In):
    """One GPS fix. Only time and position are required; speed over ground is used when present."""

    t_unix_s: float = Field(description="fix time, Unix seconds (the advisory is computed at this instant)")
    lat_deg: float = Field(ge=-90, le=90)
    lon_deg: float = Field(ge=-180, le=180)
    speed_mps: float | None = Field(default=None, ge=0, le=70, description="speed over ground; None: derived from positions")
    heading_deg: float | None = Field(default=None, ge=0, le=360, description="course over ground, clockwise from true north")
    accuracy_m: float | None = Field(default=None, ge=0, le=100_000, description="horizontal accuracy (1 sigma)")


class AdviceOut(_Out):
    """The advisory for the trip's latest fix, with what the service made of the fix."""

    trip_id: str
    seq: int = Field(description="fixes accepted so far")
    t_unix_s: float | None = Field(description="time of the fix the advice was computed for")
    fix_status: Literal["ok", "duplicate", "out_of_order", "none"] = Field(
        description="what happened to the fix just sent: used, or ignored as a duplicate / older than the last one (the latest advice is returned)"
    )
    on_route: bool
    station_m: float | None = None
    cross_track_m: float | None = None
    offset_m: float | None = Field(default=None, description="distance from the fix to the route")
    speed_mps: float | None = None
    speed_source: Literal["gps", "positions", "none"] = "none"
    next_intersection_id: int | None = None
    distance_to_line_m: float | None = None
    spat_fresh: bool | None = None
    action: str = Field(description="cruise, ease_off, accelerate, stop, resume or none (no speed advice)")
    reason: str
    target_speed_mps: float | None = None
    light_red: bool | None = None
    seconds_to_change_s: float | None = None
    message: str = Field(description="what the driver hears")
    speak: bool = False
    source: str = "rules"


class DriverScoreOut(_Out):
    distance_m: float
    duration_s: float
    exit_speed_mps: float
    energy_kwh: float = Field(description="net battery energy in the zone plus re-acceleration to the limit")
    soh_lost_frac: float
    electricity_usd: float
    wear_usd: float
    cost_usd: float


class TripScoreOut(_Out):
    trip_id: str
    complete: bool = Field(description="the fixes cover the zone from entry to exit (else the comparison is indicative)")
    n_fixes: int
    coverage_frac: float
    vehicle: str
    driven: DriverScoreOut | None
    regular: DriverScoreOut
    savings_frac: dict[str, float] | None = Field(default=None, description="1 - driven / regular for energy, wear and cost")
    note: str = ""


class CorridorSummary(_Out):
    name: str
    description: str
    length_m: float
    intersection_ids: list[int]
    units: Literal["metric", "imperial"] = Field(default="metric", description="the corridor's default units for spoken speeds")
    plans: list[str] = Field(default_factory=list, description="signal plans known for the corridor (trip 'timing')")
    default_plan: str | None = None


class HealthOut(_Out):
    status: Literal["ok"]
    now_unix_s: float
    trips: int
    spat: str
    tables: list[str]
    speech: bool
