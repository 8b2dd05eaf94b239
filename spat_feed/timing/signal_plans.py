"""Signal-plan files: each light's fixed-time timing (or ``live``), by time of day, for one corridor.

A plan file (JSON or TOML, schema :class:`SignalPlan`, documented in docs/CORRIDORS.md) is what an
operator's signal-timing sheet says about the lights of a corridor:

* **Patterns** (``patterns``): a named set of timings, one per light (intersection id + signal group):
  ``fixed`` with ``red_s``, ``green_s``, ``amber_s`` (cycle = red + green + amber, order red -> green ->
  amber) and ``offset_s``, or ``live`` (the timing comes from the light's SPaT source only: actuated or
  unknown; no lookup tables, the advisor uses its rules there).
* **Offset** ``offset_s``: seconds from the cycle reference to the start of the light's **green** (the
  coordinated phase's green, the usual timing-sheet convention, FHWA Signal Timing Manual, 2nd ed., ch. 6).
  Red then begins at ``reference + offset_s - red_s`` (mod cycle).
* **Reference** (``reference``): ``local_midnight`` (default; controllers synchronise their cycles to a
  master clock: each local day's 00:00 in ``time_zone``, an IANA name such as ``America/Los_Angeles``) or
  ``zone_entry`` (offsets relative to the instant a trip enters the zone, as the paper's timings are; no
  schedule then).
* **Schedule** (``schedule``): periods ``{days, start, end, pattern}`` in local time; the first period
  that covers an instant names its pattern; outside every period ``default_pattern`` runs (optional when
  there is one pattern).

A plan applies to a trip as the pattern in force when the trip enters the zone (a trip lasts minutes; a
controller changes pattern over several cycles anyway). :func:`light_plans_at` gives every light's plan on
the Unix axis at any instant, for a per-intersection simulator.
"""

from __future__ import annotations

import math
import re
from datetime import datetime, timedelta
from typing import TYPE_CHECKING, Literal
from zoneinfo import ZoneInfo, ZoneInfoNotFoundError

from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator

from spat_feed.timing.paper import TIMING_PRESETS, Timing
from spat_feed.timing.plans import FixedTimePlan

if TYPE_CHECKING:  # pragma: no cover
    from spat_feed.road.corridors import Corridor

PLAN_SCHEMA_VERSION = 1
DAYS = ("mon", "tue", "wed", "thu", "fri", "sat", "sun")
Day = Literal["mon", "tue", "wed", "thu", "fri", "sat", "sun"]
_CLOCK = re.compile(r"^([01]\d|2[0-4]):([0-5]\d)(?::([0-5]\d))?$")


def clock_s(text: str) -> float:
    """Seconds after local midnight of a wall-clock ``"HH:MM"`` or ``"HH:MM:SS"`` (``"24:00"`` allowed).

    Examples
    --------
    >>> clock_s("07:30"), clock_s("24:00")
    (27000.0, 86400.0)
    """
    m = _CLOCK.match(text)
    if not m:
        raise ValueError(f"{text!r} is not a time of day HH:MM or HH:MM:SS")
    s = int(m.group(1)) * 3600 + int(m.group(2)) * 60 + int(m.group(3) or 0)
    if s > 86400:
        raise ValueError(f"{text!r} is past 24:00")
    return float(s)


class LightTiming(BaseModel):
    """One light's timing in a pattern: fixed-time, or ``live`` (from its SPaT source). [s]"""

    model_config = ConfigDict(extra="forbid", frozen=True)
    intersection_id: int = Field(ge=0, le=65_535, description="J2735 intersection id, as in the corridor file")
    signal_group: int | None = Field(default=None, ge=1, le=255, description="default: the intersection's first signal group")
    kind: Literal["fixed", "live"] = "fixed"
    red_s: float | None = Field(default=None, gt=0)
    green_s: float | None = Field(default=None, gt=0)
    amber_s: float = Field(default=0.0, ge=0)
    cycle_s: float | None = Field(default=None, gt=0, description="optional check: must equal red + green + amber")
    offset_s: float | None = Field(default=None, description="green start after the cycle reference")

    @model_validator(mode="after")
    def _complete(self) -> LightTiming:
        if self.kind == "live":
            given = [n for n in ("red_s", "green_s", "cycle_s", "offset_s") if getattr(self, n) is not None]
            if given:
                raise ValueError(f"a live light takes no fixed timing (remove {', '.join(given)})")
            return self
        missing = [n for n in ("red_s", "green_s", "offset_s") if getattr(self, n) is None]
        if missing:
            raise ValueError(f"a fixed light needs {', '.join(missing)}")
        if not math.isfinite(self.offset_s):
            raise ValueError("offset_s must be finite")
        if self.cycle_s is not None and abs(self.cycle_s - self.cycle_sum_s) > 1e-6:
            raise ValueError(f"cycle_s {self.cycle_s:g} != red_s + green_s + amber_s = {self.cycle_sum_s:g}")
        return self

    @property
    def cycle_sum_s(self) -> float:
        return (self.red_s or 0.0) + (self.green_s or 0.0) + self.amber_s

    def plan(self, reference_unix_s: float) -> FixedTimePlan | None:
        """The light's :class:`FixedTimePlan` on the Unix axis for a cycle reference; None if live."""
        if self.kind == "live":
            return None
        red_start = (self.offset_s - self.red_s) % self.cycle_sum_s
        return FixedTimePlan(self.red_s, self.green_s, self.amber_s, reference_unix_s + red_start)


class Pattern(BaseModel):
    """A timing pattern: every light's timing while it runs."""

    model_config = ConfigDict(extra="forbid", frozen=True)
    description: str = ""
    lights: tuple[LightTiming, ...] = Field(min_length=1)

    @field_validator("lights")
    @classmethod
    def _unique(cls, lights: tuple[LightTiming, ...]) -> tuple[LightTiming, ...]:
        ids = [light.intersection_id for light in lights]
        dup = sorted({i for i in ids if ids.count(i) > 1})
        if dup:
            raise ValueError(f"intersection(s) {dup} given more than once")
        return lights


class Period(BaseModel):
    """When a pattern runs: local wall-clock ``[start, end)`` on ``days``."""

    model_config = ConfigDict(extra="forbid", frozen=True)
    days: tuple[Day, ...] = Field(default=DAYS, min_length=1)
    start: str
    end: str
    pattern: str

    @field_validator("start", "end")
    @classmethod
    def _clock(cls, value: str) -> str:
        clock_s(value)
        return value

    @model_validator(mode="after")
    def _ordered(self) -> Period:
        if not clock_s(self.start) < clock_s(self.end):
            raise ValueError(f"start {self.start} must be before end {self.end} (split a period that runs past midnight)")
        return self


class SignalPlan(BaseModel):
    """A plan file: the timing of a corridor's lights by time of day (see the module docstring)."""

    model_config = ConfigDict(extra="forbid", frozen=True)
    schema_version: int = Field(default=PLAN_SCHEMA_VERSION, ge=1)
    kind: Literal["signal_plan"] = "signal_plan"
    name: str = Field(min_length=1, max_length=100)
    corridor: str | None = Field(default=None, description="the corridor this plan is for (checked when both are loaded)")
    description: str = ""
    source: str = Field(default="", description="where the timing comes from: a timing sheet, or 'plausible, not measured'")
    reference: Literal["local_midnight", "zone_entry"] = "local_midnight"
    time_zone: str = "UTC"
    patterns: dict[str, Pattern] = Field(min_length=1)
    schedule: tuple[Period, ...] = ()
    default_pattern: str | None = None

    @field_validator("schema_version")
    @classmethod
    def _known_version(cls, value: int) -> int:
        if value > PLAN_SCHEMA_VERSION:
            raise ValueError(f"plan schema version {value} is newer than this program's ({PLAN_SCHEMA_VERSION}); upgrade ecodrive")
        return value

    @field_validator("time_zone")
    @classmethod
    def _zone(cls, value: str) -> str:
        try:
            ZoneInfo(value)
        except (ZoneInfoNotFoundError, ValueError):
            raise ValueError(f"unknown time zone {value!r} (an IANA name such as 'Europe/Paris' or 'America/Los_Angeles')") from None
        return value

    @model_validator(mode="after")
    def _consistent(self) -> SignalPlan:
        if self.default_pattern is None and len(self.patterns) > 1:
            raise ValueError(f"default_pattern is required with several patterns (one of {sorted(self.patterns)})")
        for where, name in [("default_pattern", self.default_pattern)] + [(f"schedule[{i}].pattern", p.pattern) for i, p in enumerate(self.schedule)]:
            if name is not None and name not in self.patterns:
                raise ValueError(f"{where}: no pattern {name!r} (patterns: {sorted(self.patterns)})")
        if self.reference == "zone_entry" and self.schedule:
            raise ValueError("a plan relative to the zone entry has no time-of-day schedule")
        return self

    # -- which pattern runs when ----------------------------------------------------------------------
    @property
    def fallback_pattern(self) -> str:
        return self.default_pattern or next(iter(self.patterns))

    def pattern_at(self, t_unix_s: float) -> tuple[str, float]:
        """(pattern name, cycle reference on the Unix axis) in force at ``t_unix_s``.

        The reference is that local day's midnight (``local_midnight``) or 0 (``zone_entry``: callers add
        the entry instant).
        """
        if self.reference == "zone_entry":
            return self.fallback_pattern, 0.0
        zone = ZoneInfo(self.time_zone)
        local = datetime.fromtimestamp(t_unix_s, zone)
        midnight = datetime(local.year, local.month, local.day, tzinfo=zone)
        wall_s = local.hour * 3600 + local.minute * 60 + local.second + local.microsecond / 1e6
        day = DAYS[local.weekday()]
        for period in self.schedule:
            if day in period.days and clock_s(period.start) <= wall_s < clock_s(period.end):
                return period.pattern, midnight.timestamp()
        return self.fallback_pattern, midnight.timestamp()

    def next_switch_unix_s(self, t_unix_s: float) -> float:
        """The next instant after ``t_unix_s`` at which the pattern or its reference may change (a period
        boundary or local midnight); ``inf`` for a ``zone_entry`` plan."""
        if self.reference == "zone_entry":
            return math.inf
        zone = ZoneInfo(self.time_zone)
        local = datetime.fromtimestamp(t_unix_s, zone)
        midnight = datetime(local.year, local.month, local.day, tzinfo=zone)
        marks = sorted({clock_s(p.start) for p in self.schedule} | {clock_s(p.end) for p in self.schedule} | {86400.0})
        for mark in marks:
            at = (midnight + timedelta(seconds=mark)).timestamp() if mark < 86400 else datetime.combine(
                (midnight + timedelta(days=1)).date(), datetime.min.time(), zone).timestamp()  # fmt: skip
            if at > t_unix_s:
                return at
        return math.inf  # pragma: no cover - 24:00 is always a mark

    # -- checks and plans -----------------------------------------------------------------------------
    def check(self, corridor: Corridor) -> None:
        """Raise ``ValueError`` naming the pattern and light unless every pattern times exactly the
        corridor's intersections, with signal groups the corridor knows."""
        if self.corridor is not None and self.corridor != corridor.name:
            raise ValueError(f"plan {self.name!r} is for corridor {self.corridor!r}, not {corridor.name!r}")
        known = {ix.id: {sg.id for sg in ix.signal_groups} for ix in corridor.intersections}
        for pname, pattern in self.patterns.items():
            given = {light.intersection_id for light in pattern.lights}
            if missing := sorted(set(known) - given):
                raise ValueError(f"patterns.{pname}.lights: no timing for intersection(s) {missing} of corridor {corridor.name!r}")
            for i, light in enumerate(pattern.lights):
                if light.intersection_id not in known:
                    raise ValueError(f"patterns.{pname}.lights[{i}].intersection_id: {light.intersection_id} is not on corridor {corridor.name!r} (ids {sorted(known)})")
                if light.signal_group is not None and light.signal_group not in known[light.intersection_id]:
                    raise ValueError(f"patterns.{pname}.lights[{i}].signal_group: {light.signal_group} is not a signal group of intersection {light.intersection_id}")

    def pattern_plans(self, corridor: Corridor, pattern: str, reference_unix_s: float) -> dict[tuple[int, int], FixedTimePlan | None]:
        """(intersection id, signal group) -> plan on the Unix axis (None: live) for one pattern."""
        by_id = {light.intersection_id: light for light in self.patterns[pattern].lights}
        out: dict[tuple[int, int], FixedTimePlan | None] = {}
        for ix in corridor.intersections:
            light = by_id[ix.id]
            plan = light.plan(reference_unix_s)
            for sg in ix.signal_groups:  # the plan's signal group and, with the same timing, the others the corridor lists
                out[(ix.id, sg.id)] = plan
        return out

    def fixed_plans(self, corridor: Corridor, entry_unix_s: float) -> dict[tuple[int, int], FixedTimePlan]:
        """The fixed plans on the Unix axis for a trip entering at ``entry_unix_s`` (live lights left out)."""
        pattern, reference = self.pattern_at(entry_unix_s)
        if self.reference == "zone_entry":
            reference = entry_unix_s
        return {k: p for k, p in self.pattern_plans(corridor, pattern, reference).items() if p is not None}

    def is_live(self, intersection_id: int, pattern: str | None = None) -> bool:
        lights = self.patterns[pattern or self.fallback_pattern].lights
        return any(light.intersection_id == intersection_id and light.kind == "live" for light in lights)


TimingLike = Timing | SignalPlan
"""A corridor's timing for a trip: one of the paper's (relative to the zone entry) or a plan file."""


def light_plans_at(corridor: Corridor, plan: SignalPlan | None = None, t_unix_s: float = 0.0, entry_unix_s: float = 0.0) -> dict[tuple[int, int], FixedTimePlan | None]:
    """Every light's plan on the Unix axis at ``t_unix_s``: (intersection id, signal group) -> plan, None = live.

    ``plan`` None: the corridor's default plan (``Corridor.default_plan``), else, for a corridor without
    plans, the paper's ``15_15`` timing (red 30 s, green 30 s, every light turns red at 15 s past each
    minute of ``entry_unix_s``'s axis). What a per-intersection simulator runs; re-ask at
    :meth:`SignalPlan.next_switch_unix_s`.
    """
    plan = plan or corridor.plan()
    if plan is None:
        timing = TIMING_PRESETS["15_15"]
        start = timing.red_starts_s[0]
        return {(ix.id, sg.id): FixedTimePlan(timing.red_s, timing.green_s, timing.amber_s, entry_unix_s + start)
                for ix in corridor.intersections for sg in ix.signal_groups}  # fmt: skip
    pattern, reference = plan.pattern_at(t_unix_s)
    return plan.pattern_plans(corridor, pattern, entry_unix_s if plan.reference == "zone_entry" else reference)
