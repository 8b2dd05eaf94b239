"""Deployment settings of the advisory service, read from the environment (prefix ``ECO_``) or ``.env``.

Only ``server/`` reads the environment. Algorithm settings (advisor hysteresis, table grid) stay in
``advisory`` dataclasses; what is here is deployment: which corridors, where SPaT comes from, limits, keys.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator
from pydantic_settings import BaseSettings, NoDecode, SettingsConfigDict

from advisory.physics.params import SPEED_LIMIT_MPS
from spat_feed.road.corridors import preset_names


class KeyQuota(BaseModel):
    """One API key's own limits (``ECO_API_KEY_QUOTAS``); a field left out takes the ``ECO_KEY_*`` default."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    max_trips: int | None = Field(default=None, ge=0, description="open trips; 0 = no limit but the service's")
    create_rate_per_s: float | None = Field(default=None, gt=0, description="trip creation: token bucket rate [1/s]")
    create_burst: float | None = Field(default=None, ge=1, description="trip creation: token bucket capacity")
    max_trips_per_device: int | None = Field(default=None, ge=0, description="open trips per device; 0 = no limit")


class Settings(BaseSettings):
    """Every field can be set as ``ECO_<NAME>`` (e.g. ``ECO_SPAT_FEED_URL=http://feed:8765``)."""

    model_config = SettingsConfigDict(env_prefix="ECO_", env_file=".env", extra="ignore", frozen=True)

    # corridors and vehicles
    corridors: Annotated[tuple[str, ...], NoDecode] = Field(
        default_factory=lambda: tuple(preset_names()), description="corridor presets served (comma-separated in the environment); default: all shipped"
    )
    corridor_dir: Path | None = Field(default=None, description="a folder of corridor and plan files (JSON/TOML) to serve besides the presets")
    corridor_file: Path | None = Field(default=None, description="an extra corridor JSON file to serve")
    default_corridor: str = "paper_s400"
    default_vehicle: str = "paper_54kwh"
    speed_limit_mps: float = Field(default=SPEED_LIMIT_MPS, gt=0, le=70, description="limit on corridors whose files state none [m/s]")

    # SPaT (docs/SPAT.md "Sources"): one shared store per process, filled by any of these at once
    spat_simulate: bool | None = Field(default=None, description="simulate lights with fixed-time plans in process; default: on unless spat_feed_url is set")
    spat_feed_url: str | None = Field(default=None, description="remote SPaT feed (http://host:port): one WebSocket to its /spat/intersections/stream")
    spat_mqtt_url: str | None = Field(default=None, description="MQTT broker with live SPaT: mqtt://[user:pw@]host[:port][/prefix], topic <prefix>/<intersection id>")
    spat_log: Path | None = Field(default=None, description="a recorded SPaT log (.csv[.gz] as in shared/data/spat, or .jsonl[.gz]) played in process")
    spat_log_speedup: float = Field(default=1.0, gt=0, le=1000, description="recorded seconds per second of play")
    spat_log_loop: bool = Field(default=False, description="play the log again after its end")
    spat_record: Path | None = Field(default=None, description="append every SPaT state received to this .jsonl[.gz] log")
    spat_rate_hz: float = Field(default=10.0, gt=0, le=100, description="log player ticks per second")
    spat_stale_after_s: float = Field(default=2.0, gt=0, description="SPaT older than this (controller timestamp) is stale: no speed advice [s]")
    spat_clock_tolerance_s: float = Field(default=1.0, gt=0, description="a controller clock off ours by more than this: rejected (ahead) or flagged clock_skew [s]")
    spat_early_s: float = Field(default=0.0, ge=0, description="trips with their own timing: simulated actuated windows, earliest change before the plan [s]")
    spat_late_s: float = Field(default=0.0, ge=0)
    spat_confidence_frac: float = Field(default=1.0, ge=0, le=1)

    # queue-aware advice (server.queue; advisory.advice.queue, behind, queue_words; docs/TRAFFIC.md)
    queue_aware: bool = Field(default=False, description="aim advice at the moment the queue ahead has cleared (every trip's fix a probe of its corridor); a car standing in a queue is told to follow the car in front")
    queue_arrivals_vph: float | None = Field(default=None, ge=0, description="flow arriving at each light, per lane (detector counts), to count the cars that are not connected; None: connected cars alone [veh/h]")
    queue_connected_share: float = Field(default=1.0, ge=0, le=1, description="share of the arriving cars that are connected (with queue_arrivals_vph)")
    queue_sync_s: float = Field(default=0.25, gt=0, le=1.0, description="with the Redis store: each worker publishes its trips' probes and loads every other "
                                "worker's this often, in the background (server.storage.queue_store) [s]")

    # lookup tables (advisory.advice.tables), built or loaded at start-up
    tables: bool = Field(default=True, description="build/load the DP lookup tables at start-up")
    tables_dir: Path | None = Field(default=None, description="cache folder for the tables (.npz); None = build in memory")

    # speech
    speech: bool = True
    audio_cache_size: int = Field(default=256, ge=0)

    # auth: keys allowed to create trips ("X-API-Key: <key>" or "Authorization: Bearer <key>"); empty = open creation (development)
    api_keys: Annotated[tuple[str, ...], NoDecode] = ()
    anonymous_trips: bool | None = Field(default=None, description="trips created without an API key: allowed (counted per address, shed first when the service is full), "
                                         "refused (401), or None: allowed only when no ECO_API_KEYS are set")  # fmt: skip
    api_key_quotas: dict[str, KeyQuota] = Field(default_factory=dict, description="a key's own quota, by the key or its id (key-<8 hex of its SHA-256>), "
                                                "JSON: {\"<key>\": {\"max_trips\": 5000, \"create_rate_per_s\": 10, \"create_burst\": 200, \"max_trips_per_device\": 2}}; "
                                                "a field left out takes the ECO_KEY_* default")  # fmt: skip
    key_max_trips: int = Field(default=5_000, ge=0, description="open trips per API key unless ECO_API_KEY_QUOTAS says otherwise; 0 = no limit but ECO_MAX_TRIPS")
    key_create_rate_per_s: float = Field(default=10.0, gt=0, description="trip creation per API key: token bucket rate [1/s]")
    key_create_burst: float = Field(default=200.0, ge=1, description="trip creation per API key: token bucket capacity (phones of one app starting together)")
    max_trips_per_device: int = Field(default=2, ge=0, description="open trips per device (the device_id a trip is created with) within its key or address; 0 = no limit")
    metrics_access: Literal["public", "api_key", "off"] = Field(default="api_key", description="/metrics: open, an API key needed (when keys are set), or not served")
    docs_access: Literal["public", "api_key", "off"] = Field(default="public", description="/docs, /redoc, /openapi.json: same choices")
    cors_origins: Annotated[tuple[str, ...], NoDecode] = Field(default=(), description="browser origins allowed to call the API (CORS); '*' = any; empty = CORS off")

    # trip store (server.storage.store): where open trips live
    store_url: str | None = Field(default=None, description="Redis holding the open trips, shared by every worker (redis://host:6379/0), run with --appendonly yes "
                                     "(without it a restart of Redis loses every open trip); None = in this process (one worker; a restart loses them)")
    store_prefix: str = Field(default="eco", min_length=1, description="prefix of the store's Redis keys (several services on one Redis)")
    store_timeout_s: float = Field(default=2.0, gt=0, description="a Redis call failing for this long answers 503 + Retry-After [s]")
    store_write_window_s: float = Field(default=0.0, ge=0, le=0.05, description="a worker's Redis commands wait up to this long to be written together "
                                        "(fewer system calls per fix under load, each answer that much later; 0: at once when none is in flight, else at the end of the event loop's turn) [s]")

    # limits
    max_trips: int = Field(default=20_000, ge=1)
    trip_idle_ttl_s: float = Field(default=1800.0, gt=0)
    max_body_bytes: int = Field(default=16_384, ge=256)
    ws_max_message_bytes: int = Field(default=16_384, ge=256)
    ws_max_frame_bytes: int = Field(default=262_144, ge=256, description="WebSocket messages above this are not read: closed 1009 (uvicorn's ws_max_size); "
                                    "above ws_max_message_bytes only: a 413 error message, the stream goes on")  # fmt: skip
    rate_per_s: float = Field(default=5.0, gt=0, description="per-trip token bucket: refill rate [1/s]")
    rate_burst: float = Field(default=20.0, ge=1, description="per-trip token bucket: capacity")
    create_rate_per_s: float = Field(default=500.0, gt=0, description="trip creation, whole service [1/s]")
    create_burst: float = Field(default=2_500.0, ge=1)
    max_fix_past_s: float = Field(default=300.0, gt=0, description="reject fixes older than this vs server time [s]")
    max_fix_future_s: float = Field(
        default=2.0, gt=0, description="reject fixes this far ahead of server time: an accepted fix from the future would make the honest ones look late [s]"
    )
    max_entry_future_s: float = Field(default=300.0, gt=0, description="a trip's entry_unix_s may lie this far ahead [s]")
    max_trips_per_client: int = Field(default=200, ge=0, description="open trips per client address, of trips created without an API key; 0 = no limit")
    create_rate_per_client_per_s: float = Field(default=1.0, gt=0, description="trip creation per client address without an API key: token bucket rate [1/s]")
    create_burst_per_client: float = Field(default=20.0, ge=1)

    # connections (enforced by server.web.protocol in the uvicorn process)
    read_timeout_s: float = Field(default=10.0, gt=0, description="a request's headers and body must arrive within this, else 408 and close [s]")
    keep_alive_s: float = Field(default=5.0, gt=0, description="idle keep-alive connections are closed after this [s]")
    max_connections: int = Field(default=0, ge=0, description="open connections in all; 0 = the process's file limit less a reserve")
    max_connections_per_client: int = Field(default=256, ge=0, description="open connections per client address; 0 = no limit (behind a proxy)")
    ws_max_per_trip: int = Field(default=2, ge=1, description="open WebSocket streams per trip; a newer one replaces the oldest (closed 4409)")
    ws_lease_s: float = Field(default=15.0, ge=1, description="with Redis, a stream's lease, renewed by its worker every third of it: a dead worker's streams stop counting within this [s]")
    ws_max_per_client: int = Field(default=256, ge=0, description="open WebSocket streams per client address; 0 = no limit")

    # GPS
    off_route_m: float = Field(default=30.0, gt=0, description="farther than this from the route: advice paused [m]")
    approach_m: float | None = Field(default=None, ge=0, description="fixes this far before the zone entry, on the line of the route's first stretch, are on the route (advice for the first light starts there); None: as far as a car at the entry's limit needs to hear and stop comfortably for the first light (advising.approach_m) [m]")
    max_accuracy_m: float = Field(default=50.0, gt=0, description="fixes less accurate than this are not used [m]")
    dropout_s: float = Field(default=5.0, gt=0, description="longer gaps reset the position-derived speed [s]")
    max_speed_mps: float = Field(default=50.0, gt=0, description="a fix implying a faster jump along the route is ignored as a GPS glitch [m/s]")
    max_trace_fixes: int = Field(default=7_200, ge=10, description="fixes kept per trip for its score")

    # overload (server.admission.overload, per worker): beyond either, 503 overloaded + Retry-After instead of a queue
    max_in_flight: int = Field(default=256, ge=1, description="requests served at once per worker (awaiting Redis or a trip's turn)")
    max_loop_lag_s: float = Field(default=0.25, gt=0, description="shed while the worker's event loop runs this late at two probes in a row [s]")

    @property
    def spat_simulated(self) -> bool:
        """Whether lights with fixed plans are simulated in process (``spat_simulate``, default: no remote feed)."""
        return self.spat_simulate if self.spat_simulate is not None else not self.spat_feed_url

    @field_validator("spat_mqtt_url")
    @classmethod
    def _mqtt_url(cls, value: str | None) -> str | None:
        if value:
            from spat_feed.transport.mqtt import parse_mqtt_url

            parse_mqtt_url(value)
        return value or None

    @field_validator("corridors", "api_keys", "cors_origins", mode="before")
    @classmethod
    def _split_commas(cls, value: object) -> object:
        if isinstance(value, str):
            return tuple(part.strip() for part in value.split(",") if part.strip())
        return value

    @model_validator(mode="after")
    def _quotas_name_keys(self) -> Settings:
        from server.admission.quotas import key_id

        known = {*self.api_keys, *(key_id(k) for k in self.api_keys)}
        if unknown := sorted(set(self.api_key_quotas) - known):
            raise ValueError(f"ECO_API_KEY_QUOTAS names {len(unknown)} key(s) not in ECO_API_KEYS (give the key or its id, key-<8 hex of its SHA-256>)")
        if self.anonymous_trips is False and not self.api_keys:
            raise ValueError("ECO_ANONYMOUS_TRIPS=false without ECO_API_KEYS: nobody could create a trip")
        return self

    @field_validator("corridors")
    @classmethod
    def _some_corridor(cls, value: tuple[str, ...]) -> tuple[str, ...]:
        if not value:
            raise ValueError("at least one corridor")
        return value
