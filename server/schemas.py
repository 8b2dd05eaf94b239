"""Request and response bodies of the API (pydantic). Units in field names; every float must be finite.

Numbers are strict: a JSON number, never a string or ``true``. Output floats are rounded; each field's
description gives its unit and precision (e.g. ``[m/s, 0.01]``). Times are Unix seconds (``*_unix_s``).
"""

from __future__ import annotations

from enum import Enum
from typing import Literal

from pydantic import AliasChoices, BaseModel, ConfigDict, Field, model_validator

from advisory.advice.views import ACTIONS, REASONS

SERVER_REASONS = ("poor_gps", "no_speed", "no_fix", "clock_skew", "queue", "traffic_behind")
"""Reasons the service decides itself (``server.advising.SERVER_PHRASES``): pauses, ``queue`` (queue-aware advice:
"follow the car in front", no speed, or the glide that meets the queue's tail, a speed: ``server.queue.QueueBoard``)
and ``traffic_behind`` (a speed raised so that the cars behind are not cut off by a red: "Keep up with the traffic.
Hold 40 kilometers per hour.", :func:`advisory.advice.behind.paced_for_behind`)."""
Action = Enum("Action", {a: a for a in ACTIONS}, type=str)
Action.__doc__ = "What the driver is advised to do; `none`: no speed advice (`reason` says why)."
Reason = Enum("Reason", {r: r for r in (*REASONS, *SERVER_REASONS)}, type=str)
Reason.__doc__ = "Why this advice (or why none)."
MS_TIMESTAMP_MIN = 1e11
"""A Unix time at or above this is milliseconds (1973 in ms; the year 5138 in seconds)."""


class _In(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False, strict=True)


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
        description="signal timing of a scenario simulated for this trip alone: one of the corridor's plans (GET /v1/corridors), a paper preset "
        "(e.g. '15_15', 'field_test') or 'trip' (one of the paper's 16 picked from the entry time); default: none, the lights as they run "
        "for everyone (the service's shared SPaT: simulated, a feed, MQTT or a recorded log)",
        max_length=50,
    )
    vehicle: str | None = Field(default=None, description="vehicle preset (paper_54kwh, paper_75kwh, calibrated)", max_length=50)
    entry_unix_s: float | None = Field(
        default=None,
        description="zone-entry instant a trip's own timing is relative to, and the start of its score [Unix s]; default: the creation instant. At most 300 s from server time.",
    )
    units: Literal["metric", "imperial"] | None = Field(
        default=None, description="speeds in the spoken messages: km/h (metric) or mph (imperial); default: the corridor's (metric if it has none)"
    )
    device_id: str | None = Field(
        default=None, min_length=8, max_length=64, pattern=r"^[A-Za-z0-9._:-]+$",
        description="the phone's own id, the same for every trip it starts (the app keeps a random one): its open trips are limited "
        "within the API key's quota (ECO_MAX_TRIPS_PER_DEVICE), so one phone cannot take its fleet's share; default: none, the key's quota alone",
    )


class TripLinks(_Out):
    trip: str
    fixes: str
    advice: str
    stream: str
    audio: str
    spat: str
    end: str


class TripOut(_Out):
    """A trip: its settings and where it stands."""

    trip_id: str
    corridor: str
    timing: str
    vehicle: str
    units: Literal["metric", "imperial"]
    entry_unix_s: float = Field(description="the car is taken to enter the zone (station 0) at this instant: the trip's creation unless given [Unix s, 0.001]")
    created_unix_s: float = Field(description="[Unix s, 0.001]")
    idle_ttl_s: float = Field(description="the trip is closed after this long without a request or stream message [s]")
    n_fixes: int = Field(description="fixes accepted so far")
    links: TripLinks


class TripCreated(TripOut):
    token: str = Field(description="bearer token for this trip only: 'Authorization: Bearer <token>' (WebSocket handshake: also ?token=)")
    token_type: Literal["bearer"] = "bearer"


class GpsFixIn(_In):
    """One GPS fix. Only time and position are required; speed over ground is used when present.

    W3C Geolocation names are accepted too: `latitude`, `longitude`, `speed`, `heading`, `accuracy`,
    `altitude`, `altitudeAccuracy` (so a flattened `GeolocationCoordinates` is a fix as it is), and `timestamp`
    in milliseconds instead of `t_unix_s` (give one of the two).
    """

    model_config = ConfigDict(
        json_schema_extra={"examples": [{"t_unix_s": 1714557600.0, "lat_deg": 48.86675, "lon_deg": 2.31728, "speed_mps": 13.9, "heading_deg": 295.5, "accuracy_m": 4.0}]}
    )

    t_unix_s: float | None = Field(default=None, description="fix time [Unix s] (the advisory is computed at this instant); or `timestamp` [ms]")
    timestamp: float | None = Field(default=None, description="fix time [Unix ms], as a W3C GeolocationPosition or JavaScript's Date.now() gives it")
    lat_deg: float = Field(ge=-90, le=90, validation_alias=AliasChoices("lat_deg", "latitude"), description="WGS 84 [deg] (alias `latitude`)")
    lon_deg: float = Field(ge=-180, le=180, validation_alias=AliasChoices("lon_deg", "longitude"), description="WGS 84 [deg] (alias `longitude`)")
    speed_mps: float | None = Field(default=None, ge=0, le=70, validation_alias=AliasChoices("speed_mps", "speed"),
                                    description="speed over ground [m/s] (alias `speed`); null: derived from positions")  # fmt: skip
    heading_deg: float | None = Field(default=None, ge=0, le=360, validation_alias=AliasChoices("heading_deg", "heading"),
                                      description="course over ground, clockwise from true north [deg] (alias `heading`)")  # fmt: skip
    accuracy_m: float | None = Field(default=None, ge=0, le=100_000, validation_alias=AliasChoices("accuracy_m", "accuracy"),
                                     description="horizontal accuracy [m] (alias `accuracy`)")  # fmt: skip
    altitude_m: float | None = Field(default=None, ge=-1000, le=10_000, validation_alias=AliasChoices("altitude_m", "altitude"),
                                     description="height above the WGS 84 ellipsoid [m] (alias `altitude`); accepted, not used (grades come from the corridor)")  # fmt: skip
    altitude_accuracy_m: float | None = Field(default=None, ge=0, le=100_000, validation_alias=AliasChoices("altitude_accuracy_m", "altitudeAccuracy"),
                                              description="vertical accuracy [m] (alias `altitudeAccuracy`); accepted, not used")  # fmt: skip

    @model_validator(mode="after")
    def _one_time(self) -> GpsFixIn:
        if (self.t_unix_s is None) == (self.timestamp is None):
            raise ValueError("give the fix time as t_unix_s (Unix seconds) or timestamp (Unix milliseconds), exactly one of them")
        if self.t_unix_s is not None and self.t_unix_s >= MS_TIMESTAMP_MIN:
            raise ValueError(f"t_unix_s = {self.t_unix_s:.0f} looks like milliseconds (JavaScript's Date.now()): divide by 1000, or send it as timestamp")
        if self.timestamp is not None and self.timestamp < MS_TIMESTAMP_MIN:
            raise ValueError(f"timestamp = {self.timestamp:g} looks like seconds: timestamp is in milliseconds (W3C Geolocation); send seconds as t_unix_s")
        return self

    @property
    def time_unix_s(self) -> float:
        return self.t_unix_s if self.t_unix_s is not None else self.timestamp / 1000.0


class AdviceOut(_Out):
    """The advisory for the trip's latest fix, with what the service made of the fix."""

    trip_id: str
    seq: int = Field(description="fixes accepted so far")
    t_unix_s: float | None = Field(description="time of the fix the advice was computed for [Unix s, 0.001]")
    fix_status: Literal["ok", "duplicate", "out_of_order", "implausible", "none"] = Field(
        description="what happened to the fix just sent: used; or ignored as a duplicate, as older than the last one, or as an implausible jump (a GPS glitch, `fix_note` says why): then the latest advice is returned"
    )
    fix_note: str | None = Field(default=None, description="why the fix was ignored, when it was")
    on_route: bool
    station_m: float | None = Field(default=None, description="distance along the corridor from the zone entry [m, 0.01]")
    cross_track_m: float | None = Field(default=None, description="signed distance from the route, + to the right of travel [m, 0.01]")
    offset_m: float | None = Field(default=None, description="distance from the fix to the route [m, 0.01]")
    speed_mps: float | None = Field(default=None, description="speed used [m/s, 0.01]")
    speed_source: Literal["gps", "positions", "none"] = "none"
    next_intersection_id: int | None = None
    distance_to_line_m: float | None = Field(default=None, description="to the next stop line [m, 0.01]")
    spat_fresh: bool | None = None
    action: Action
    reason: Reason
    target_speed_mps: float | None = Field(default=None, description="advised speed [m/s, 0.01, rounded down: never above the limit]")
    light_red: bool | None = Field(default=None, description="the light named by `light_intersection_id` is red now (amber counts as not red)")
    seconds_to_change_s: float | None = Field(
        default=None, description="until that light's next change, the one `counts_down_to` names: to green when it is red now, else to red (after any amber); never a later change [s, 0.1]; null: unknown"
    )
    light_intersection_id: int | None = Field(
        default=None, description="the light that `light_red`, `seconds_to_change_s` and `counts_down_to` are about: the next light (`next_intersection_id`), or the one after it when the advice is for that one (the message then says 'Second light: ...')"
    )
    light_distance_m: float | None = Field(default=None, description="to that light's stop line [m, 0.01]")
    counts_down_to: Literal["red", "green"] | None = Field(default=None, description="what `seconds_to_change_s` counts down to: 'green' when `light_red`, else 'red'; null when there is no countdown")
    message: str = Field(description="what the driver hears, in the trip's units")
    speak: bool = Field(default=False, description="say the message now (it changed meaningfully)")
    source: Literal["rules", "dp_table", "service"] = Field(default="rules", description="rules, the DP lookup tables, or the service itself (pauses)")


class DriverScoreOut(_Out):
    """One driver over the zone, in the common end state (zone plus re-acceleration to the speed limit)."""

    distance_m: float = Field(description="distance driven in the zone [m, 0.1]")
    duration_s: float = Field(description="time from zone entry to exit [s, 0.01]")
    exit_speed_mps: float = Field(description="speed at the zone exit [m/s, 0.01]")
    energy_kwh: float = Field(description="net battery energy in the zone plus re-acceleration to the limit [kWh, 1e-6]")
    soh_lost_frac: float = Field(description="battery state of health lost [fraction of life, 4 significant digits]")
    electricity_usd: float = Field(description="[USD, 1e-6]")
    wear_usd: float = Field(description="battery wear [USD, 1e-6]")
    cost_usd: float = Field(description="electricity + wear [USD, 1e-6]")


class RedLightCrossingOut(_Out):
    """A stop line crossed while its light was red (beyond what GPS noise can explain)."""

    light: int = Field(description="1 = the first light along the corridor")
    intersection_id: int
    t_unix_s: float = Field(description="when the car crossed the stop line [Unix s, 0.001]")
    into_red_s: float = Field(description="how long the light had been red then [s, 0.1]")
    speed_mps: float = Field(description="[m/s, 0.01]")


class RedLightUnknownOut(_Out):
    """A stop line passed inside a gap between fixes (an outage, a tunnel) while its light changed: red or not is unknown."""

    light: int = Field(description="1 = the first light along the corridor")
    intersection_id: int
    gap_from_unix_s: float = Field(description="the last fix before the gap [Unix s, 0.001]")
    gap_to_unix_s: float = Field(description="the first fix after it [Unix s, 0.001]")


class TripScoreOut(_Out):
    """The trip's drive against the paper's regular driver entering when and as fast as the car did, through
    the same signal timing; both sampled and smoothed alike (docs/SERVICE.md, Score)."""

    trip_id: str
    complete: bool = Field(description="the fixes cover the zone from entry to exit (else the comparison is indicative)")
    n_fixes: int = Field(description="on-route fixes inside the zone")
    coverage_frac: float = Field(description="share of the zone covered by the fixes [0.0001]")
    compared_m: float | None = Field(default=None, description="the distance both drivers are scored over: the zone's length, or where the fixes of a trip ended early stop [m, 0.1]; null when there is no drive")
    vehicle: str
    entry_unix_s: float = Field(description="when the car entered the zone (interpolated between fixes) [Unix s, 0.001]")
    entry_speed_mps: float = Field(description="the car's speed then, the regular driver's entry speed [m/s, 0.01]")
    driven: DriverScoreOut | None
    regular: DriverScoreOut
    savings_frac: dict[str, float] | None = Field(
        default=None, description="1 - driven / regular for energy, wear and cost over `compared_m`, positive = less than the regular driver (the sign `replay` uses too) [0.0001]; null when there is no drive to compare or it crossed a red light"
    )
    red_light_crossings: list[RedLightCrossingOut] = Field(default_factory=list)
    red_light_unknown: list[RedLightUnknownOut] = Field(
        default_factory=list, description="lights passed inside a gap of more than 3 s between fixes while they changed: not judged (the drive is still compared)"
    )
    note: str = ""


class CorridorSummary(_Out):
    name: str
    description: str
    length_m: float
    intersection_ids: list[int]
    units: Literal["metric", "imperial"] = Field(default="metric", description="the corridor's default units for spoken speeds")
    plans: list[str] = Field(default_factory=list, description="signal plans known for the corridor (trip 'timing')")
    default_plan: str | None = None


class SpatIntersectionOut(_Out):
    id: int = Field(description="J2735 intersection id")
    status: Literal["ok", "stale", "clock_skew", "no_spat"] = Field(description="ok: fresh; stale: older than spat_stale_after_s; clock_skew: the controller's clock is off ours; no_spat: never heard")
    age_s: float | None = Field(description="age of the latest state (controller timestamp) [s]")
    clock_offset_s: float | None = Field(None, description="arrival - controller timestamp, its floor (clock_skew beyond the tolerance) [s]")
    rejected: dict[str, int] = Field(default_factory=dict, description="messages rejected, by reason (implausible, too_large, clock_ahead, ...)")
    implausible_s_ago: float | None = Field(None, description="set for a minute after a message that contradicted its controller (a red ended before its minEndTime): forged? [s]")


class SpatSourceOut(_Out):
    model_config = ConfigDict(extra="allow")
    kind: Literal["simulator", "feed", "mqtt", "log"]
    connected: bool = Field(description="connected (feed, MQTT) or still playing (log)")


class SpatHealthOut(_Out):
    source: str = Field(description="where the SPaT comes from, in words")
    sources: list[SpatSourceOut]
    intersections: list[SpatIntersectionOut] = Field(description="intersections whose SPaT comes from a source (simulated lights are always fresh)")


class HealthOut(_Out):
    status: Literal["ok", "degraded"] = Field(description="degraded: a SPaT source is down, an intersection's SPaT is not fresh, or the queue board counts "
                                                      "this worker's trips only (queue_board; the service still answers)")
    now_unix_s: float
    trips: int
    spat: str = Field(description="where the SPaT comes from, in words (spat_health has the details)")
    spat_health: SpatHealthOut
    tables: list[str]
    speech: bool
    queue_board: Literal["local", "shared", "own_trips_only"] | None = Field(
        default=None, description="queue-aware advice's probes (ECO_QUEUE_AWARE; None: off): local (one process, every trip), shared (every worker's, "
                                  "through Redis), own_trips_only (Redis unreachable for the board: this worker's trips only)")  # fmt: skip
