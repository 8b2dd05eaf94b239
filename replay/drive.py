"""Score a recorded GPS drive: map matching, the zone trajectory, and the comparison drivers.

``score_drive(trace, params, ...)`` is what ``replay`` runs on a GPS trace:

1. **Corridor**: given (``--corridor`` or the trace's ``# corridor:`` line), else found among the shipped
   ones by map matching (``replay.matching.find_corridor``).
2. **Stations** of every fix (``replay.matching.match``); fixes more than 30 m off the route are dropped.
3. **Speeds**: the fixes' speed over ground; where a fix has none, the slope of the stations over time.
4. **The zone and the comparison** (``advisory.evaluation.compare``, the same code as the service's trip
   score): the speeds smoothed (``smooth_s``, default ``SMOOTH_S`` = 1 s, as the service), standstill
   below 0.2 m/s; the zone from the instant the fixes cross station 0 to the instant they cross
   ``length_m`` (interpolated between fixes; a trace that starts inside the zone is extrapolated back),
   or to where they stop (a partial drive is compared over the distance it drove), as a trajectory whose
   positions are integrated from the speeds; the regular driver measured alike (sampled at the fixes'
   instants, smoothed, cut at the same distance). The DP optimum is its exact trajectory over the whole
   zone (none for a partial drive).
5. **The lights**: the timing (``--timing`` / ``# timing:``: a paper preset, a plan of the corridor, or a
   plan file; default: the corridor's own plan if it has one) anchored at ``entry_unix_s`` (``--entry`` /
   ``# entry_unix_s:``, default: the measured zone entry; a plan by time of day runs on the trace's own
   clock), seen from the measured entry (``spat_feed.transport.scenarios.advisory_scenario_at``), through all N lights.
6. **Scores** (``advisory.evaluation.endstate.score_in_end_state``: zone + re-acceleration to the limit) of the drive,
   the paper's regular driver entering at the same instant and as fast, and the DP optimum
   (``advisory.optimizer.dp.solve``, 20 m stages), and the savings against the regular driver
   (``savings_frac``: ``1 - drive / regular``, positive = less, as the service's). The DP needs
   every stop line on a stage boundary: where a corridor's are not (a real road), it solves with 10 m
   stages and the stop lines moved to the nearest boundary (at most 5 m; said in the notes,
   :func:`dp_scenario`). The speed limit is the corridor's lowest over the zone where its file states one.
7. **No timing**: the regular driver on the drive's own stops (``advisory.evaluation.stops``: held where the
   drive stood still until it moved off), no DP optimum, and a note on how to give the timing.
8. **EPA cycles**: the drive's end-state energy per km of the zone beside the same vehicle's on the EPA UDDS and
   HWFET cycles (``replay.cycles``), with or without timing.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from advisory.evaluation.compare import SMOOTH_S, Comparison, DriverResult, ZoneDrive, compare_drive, drive_in_zone, savings_frac  # noqa: F401  (DriverResult, savings_frac: re-exported)
from advisory.evaluation.endstate import score_in_end_state
from advisory.physics.params import SPEED_LIMIT_MPS, ModelParams
from advisory.evaluation.scoring import DriveScore
from advisory.evaluation.stops import Stop, recorded_stops, stops_scenario
from advisory.signals import Scenario
from advisory.evaluation.track import STANDSTILL_MPS, RedCrossing, UnjudgedCrossing, smooth_speed_mps  # noqa: F401  (re-exported, used by tests)
from replay.matching import MAKE_CORRIDOR, ON_ROUTE_M, CorridorChoice, MatchedTrace, find_corridor, how_far, match
from replay.trace_io import GpsTrace, TraceError
from spat_feed.road.corridors import load_corridor
from spat_feed.transport.scenarios import FeedScenario, advisory_scenario_at, make_scenario, resolve_timing

DP_STAGE_M = 20.0
DP_FINE_STAGE_M = 10.0
"""DP stage where the stop lines are not on the 20 m grid; they move at most half of it. [m]"""


def dp_scenario(scenario: Scenario, stage_m: float = DP_STAGE_M) -> tuple[Scenario, float, float]:
    """The scenario the DP can solve, its stage and the largest stop-line move. [-, m, m]

    Unchanged with ``stage_m`` when every stop line and the zone end lie on its grid; else on the
    :data:`DP_FINE_STAGE_M` grid, each stop line (and the zone end) moved to the nearest boundary, kept in
    order and inside the zone. The timing is not moved.
    """
    from dataclasses import replace

    def on_grid(x: float, ds: float) -> bool:
        return abs(x / ds - round(x / ds)) < 1e-9

    if all(on_grid(s.position_m, stage_m) for s in scenario.signals) and on_grid(scenario.zone_length_m, stage_m):
        return scenario, stage_m, 0.0
    ds = DP_FINE_STAGE_M
    moved, out, last = 0.0, [], 0.0
    for s in scenario.signals:
        x = max(round(s.position_m / ds) * ds, last + ds)
        moved = max(moved, abs(x - s.position_m))
        out.append(replace(s, position_m=x))
        last = x
    zone = max(round(scenario.zone_length_m / ds) * ds, last + ds)
    moved = max(moved, abs(zone - scenario.zone_length_m))
    return replace(scenario, signals=tuple(out), zone_length_m=zone), ds, moved


SPAT_LOG_SUFFIXES = (".csv", ".csv.gz", ".jsonl", ".jsonl.gz", ".ndjson", ".ndjson.gz")
"""``--timing`` ending so is a recorded SPaT log (``spat_feed.transport.player.read_spat_log``), matched by time."""


def is_spat_log(timing: str | None) -> bool:
    return timing is not None and timing.lower().endswith(SPAT_LOG_SUFFIXES)


@dataclass(frozen=True)
class SpatLogLights:
    """The corridor's lights as a recorded SPaT log shows them, on the Unix clock: per stop line, the truth of
    its intersection's first signal group (a phase switches midway between snapshots, ``ecodrive.spat_eval``)."""

    path: str
    positions_m: tuple[float, ...]
    truths: tuple  # TimelineSignal per light, times in Unix s
    first_unix_s: float
    last_unix_s: float

    @classmethod
    def read(cls, path: str, corridor) -> SpatLogLights:
        from ecodrive.spat_eval import group_logs
        from spat_feed.transport.player import RecordedLogError, read_spat_log
        from spat_feed.timing.messages import to_unix_s

        try:
            snapshots = read_spat_log(path)
        except (RecordedLogError, OSError) as exc:
            raise TraceError(f"--timing {path}: {exc}") from None
        if not snapshots:
            raise TraceError(f"--timing {path}: the log holds no SPaT")
        groups = {g.key: g for g in group_logs(snapshots)}
        truths = []
        for ix in corridor.intersections:
            key = (ix.id, ix.signal_groups[0].id)
            if key not in groups:
                raise TraceError(f"--timing {path}: no SPaT of intersection {ix.id} signal group {key[1]} ({ix.name}) of corridor {corridor.name}; "
                                 f"the log has (intersection, signal group) {sorted(groups)}")  # fmt: skip
            truths.append(groups[key].truth)
        stamps = [to_unix_s(x.timestamp) for x in snapshots]
        return cls(path, tuple(ix.stop_line_m for ix in corridor.intersections), tuple(truths), min(stamps), max(stamps))

    def scenario_at(self, entry_unix_s: float, zone_length_m: float, speed_limit_mps: float) -> Scenario:
        """The lights on an axis whose 0 is ``entry_unix_s``."""
        signals = tuple(replace(t.shifted(entry_unix_s), position_m=p) for t, p in zip(self.truths, self.positions_m, strict=True))
        return Scenario(f"SPaT log {self.path}", signals, zone_length_m, speed_limit_mps, speed_limit_mps)


NO_TIMING_NOTE = (
    "no signal timing: compared with the regular driver on the drive's own stops (it stops where the drive stood still "
    "and leaves when it left), not through the lights; for that, give the timing the lights ran: --timing PLAN.json/.toml "
    "(a plan file, docs/CORRIDORS.md), --timing SPAT_LOG.csv.gz/.jsonl (a recorded SPaT log of the corridor's "
    "intersections, matched to the fixes by time), a plan of the corridor or a paper preset by name, or '# timing:' in the trace"
)


def _compare_on_recorded_stops(result: DriveResult, params: ModelParams, speed_limit_mps: float) -> None:
    """No timing: the regular driver held at the drive's own standstills (``advisory.evaluation.stops``)."""
    drive = result.drive
    stops = recorded_stops(drive.driven.trajectory)
    scenario, left_out = stops_scenario(stops, drive.length_m, speed_limit_mps, float(drive.zone.v_mps[0]))
    comparison = compare_drive(drive, lambda _entry_s: scenario, params, speed_limit_mps, keep_series=True)
    # stand-in lights, not real ones: the drive cannot cross them "on red"
    result.comparison = replace(comparison, red_crossings=[], red_unknown=[])
    result.scenario = result.comparison.lights
    result.against = "recorded stops"
    result.stops = [st for st in stops if st not in left_out]
    for st in left_out:
        result.notes.append(f"the standstill at {st.position_m:.0f} m ({st.from_s:.1f}-{st.until_s:.1f} s after the entry) is too near the entry "
                            "or the exit for the regular driver to make it: left out")  # fmt: skip
    result.notes.append("DP optimum: not computed without signal timing")


def _compare_on_log(result: DriveResult, log: SpatLogLights, params: ModelParams, speed_limit_mps: float, compare: bool) -> None:
    """A recorded SPaT log: the lights as they ran when the fixes were taken (by time), the red-light check and the
    regular driver through them; no DP optimum (a log is no plan to optimise over)."""
    drive, notes = result.drive, result.notes
    t0, t1 = drive.entry_s, drive.zone.t_out_s
    if t0 < 1e8:
        raise TraceError(f"--timing {log.path}: a SPaT log is matched by time, and the trace's times are not Unix times (give ISO 8601 or epoch times)")
    if t0 < log.first_unix_s or t1 > log.last_unix_s:
        raise TraceError(f"--timing {log.path}: the log covers {log.first_unix_s:.1f}-{log.last_unix_s:.1f} (Unix s), the drive's zone "
                         f"{t0:.1f}-{t1:.1f}: by time, the log must cover the drive")  # fmt: skip
    result.entry_unix_s = None
    scenario = log.scenario_at(t0, drive.length_m, speed_limit_mps)
    scenario = replace(scenario, initial_speed_mps=float(min(max(drive.zone.v_mps[0], 0.0), speed_limit_mps)))
    result.scenario = scenario
    check = drive.red_check(scenario.signals)
    result.red_crossings, result.red_unknown = check.crossings, check.unknown
    for c in result.red_crossings:
        notes.append(f"crossed light {c.light} ({c.position_m:.0f} m) at {t0 + c.t_s:.1f} (Unix s), {c.into_red_s:.1f} s into red, at {c.speed_mps * 3.6:.0f} km/h: "
                     "this drive is not reported as a saving")  # fmt: skip
    if compare:
        result.comparison = compare_drive(drive, lambda entry_s: log.scenario_at(entry_s, drive.length_m, speed_limit_mps), params, speed_limit_mps,
                                          keep_series=True)  # fmt: skip
        result.scenario = result.comparison.lights
        notes.append("DP optimum: not computed on a recorded SPaT log")


def speed_from_stations_mps(t_s: np.ndarray, station_m: np.ndarray) -> np.ndarray:
    """Central-difference slope of station over time, >= 0 (one-sided at the ends). [m/s]"""
    return np.maximum(np.gradient(station_m, t_s), 0.0)


@dataclass
class DriveResult:
    """What ``replay`` reports on a GPS trace."""

    trace: GpsTrace
    corridor: CorridorChoice
    matched: MatchedTrace
    speed_source: str
    smooth_s: float
    zone_entry_unix_s: float
    entry_unix_s: float | None  # the timing's anchor
    timing: str | None
    drive: ZoneDrive
    scenario: Scenario | None = None
    comparison: Comparison | None = None
    dp: DriverResult | None = None
    notes: list[str] = field(default_factory=list)
    red_crossings: list[RedCrossing] = field(default_factory=list)
    against: str = "lights"
    """What the regular driver drove through: "lights" (the timing), or "recorded stops" (no timing: the drive's own
    standstills, ``advisory.evaluation.stops``)."""
    stops: list[Stop] = field(default_factory=list)
    """With ``against == "recorded stops"``: the standstills the regular driver was held at."""
    vehicle: str | None = None
    decay_multiplier: float = 1.0
    red_unknown: list[UnjudgedCrossing] = field(default_factory=list)

    @property
    def complete(self) -> bool:
        return self.drive.complete

    @property
    def driven(self) -> DriverResult:
        return self.drive.driven

    @property
    def regular(self) -> DriverResult | None:
        return None if self.comparison is None else self.comparison.regular

    @property
    def zone(self) -> DriveScore:
        return self.driven.score.zone

    def savings(self) -> dict[str, dict[str, float] | None]:
        """``savings_frac`` (positive = less) of the drive and of the DP optimum against the regular driver,
        over the compared distance; the drive's is None when it crossed a red light."""
        if self.comparison is None:
            return {}
        out = {"driven": self.comparison.savings()}
        if self.dp is not None:
            out["dp_optimum"] = savings_frac(self.dp.score, self.regular.score)
        return out

    @property
    def end_state_wh_per_km(self) -> float:
        """The drive's energy in the common end state (zone + re-acceleration to the limit) per km of the zone: a
        drive that leaves slower than it came is charged the kinetic energy it used up, as the cycles, which
        start and end at rest, are. [Wh/km]"""
        km = self.zone.distance_m / 1000.0
        return float(self.driven.score.energy_kwh * 1000.0 / km) if km > 0 else float("nan")

    def epa_cycles(self) -> list[dict]:
        """:attr:`end_state_wh_per_km` against the same vehicle's Wh/km on the EPA cycles (``replay.cycles``); []
        without a vehicle name."""
        if self.vehicle is None:
            return []
        from replay.cycles import against_cycles

        return against_cycles(self.end_state_wh_per_km, self.vehicle, self.decay_multiplier)

    def as_dict(self) -> dict:
        m = self.matched
        on = m.on_route
        return {
            "trace": self.trace.source,
            "kind": "gps",
            "complete": self.complete,
            "corridor": {
                "name": m.corridor.name,
                "how": self.corridor.how,
                "also_fits": list(self.corridor.ambiguous),
                "length_m": m.corridor.length_m,
            },
            "timing": self.timing,
            "entry_unix_s": self.entry_unix_s,
            "zone_entry_unix_s": self.zone_entry_unix_s,
            "fixes": {
                "n": int(self.trace.t_s.size),
                "on_route": int(on.sum()),
                "median_cross_track_m": float(np.median(np.abs(m.cross_track_m[on]))) if on.any() else None,
                "speed_source": self.speed_source,
                "smooth_s": self.smooth_s,
                "columns": self.trace.columns,
            },
            **self.zone.as_dict(),
            "end_state_wh_per_km": self.end_state_wh_per_km,
            "epa_cycles": self.epa_cycles(),
            "comparison": {
                "against": self.against,
                "recorded_stops": [{"position_m": st.position_m, "from_s": st.from_s, "until_s": st.until_s} for st in self.stops],
                "compared_m": self.drive.distance_m,
                "driven": self.driven.as_dict(),
                "regular": self.regular.as_dict() if self.regular else None,
                "dp_optimum": self.dp.as_dict() if self.dp else None,
                "savings_frac": self.savings(),
            },
            "red_light_crossings": [{"light": c.light, "position_m": c.position_m, "t_unix_s": self.zone_entry_unix_s + c.t_s,
                                     "into_red_s": c.into_red_s, "speed_mps": c.speed_mps} for c in self.red_crossings],
            "red_light_unknown": [{"light": u.light, "position_m": u.position_m, "gap_from_unix_s": self.zone_entry_unix_s + u.gap_from_s,
                                   "gap_to_unix_s": self.zone_entry_unix_s + u.gap_to_s} for u in self.red_unknown],
            "notes": self.trace.notes + self.notes,
        }


def score_drive(
    trace: GpsTrace,
    params: ModelParams,
    *,
    corridor: str | None = None,
    timing: str | None = None,
    entry_unix_s: float | None = None,
    smooth_s: float | None = None,
    compare: bool = True,
    speed_limit_mps: float = SPEED_LIMIT_MPS,
    vehicle: str | None = None,
    decay_multiplier: float = 1.0,
) -> DriveResult:
    """Score a GPS trace over its corridor's zone and compare it (see the module docstring). ``vehicle``: the
    preset's name ``params`` come from, for the EPA cycles' Wh/km beside the drive's (none without it)."""
    notes: list[str] = []
    corridor = corridor or trace.meta.get("corridor")
    timing = timing or trace.meta.get("timing")
    if entry_unix_s is None and trace.meta.get("entry_unix_s"):
        try:
            entry_unix_s = float(trace.meta["entry_unix_s"])
        except ValueError:
            raise TraceError(f"{trace.source}: '# entry_unix_s: {trace.meta['entry_unix_s']}' is not a number") from None
    if corridor:
        try:
            cor = load_corridor(corridor)
        except (KeyError, OSError, ValueError) as exc:
            raise TraceError(f"corridor {corridor!r}: {exc}") from None
        choice = CorridorChoice(match(cor, trace.lat_deg, trace.lon_deg), "given")
    else:
        choice = find_corridor(trace.lat_deg, trace.lon_deg)
        if choice.ambiguous:
            notes.append(f"corridor {choice.matched.corridor.name} {choice.how}; {', '.join(choice.ambiguous)} fit as well: give --corridor")
    m = choice.matched
    log = SpatLogLights.read(timing, m.corridor) if is_spat_log(timing) else None
    if timing is not None and log is None:  # checked at once, against the corridor the trace follows: the choices an error lists are the ones accepted
        try:
            resolve_timing(m.corridor, timing, 0.0)
        except KeyError as exc:
            raise TraceError(f"{exc.args[0]}, or a recorded SPaT log ({'/'.join(SPAT_LOG_SUFFIXES[:4])})") from None
        except ValueError as exc:
            raise TraceError(str(exc)) from None
    length_m = m.corridor.length_m
    speed_limit_mps = m.corridor.zone_speed_limit_mps(speed_limit_mps)  # the corridor's own limit where its file states one
    on = m.on_route
    if on.sum() < 2:
        raise TraceError(f"{trace.source}: fewer than two fixes within {ON_ROUTE_M:g} m of corridor {m.corridor.name} "
                         f"({how_far(trace.lat_deg, trace.lon_deg, [m.corridor.name])}); to score it, {MAKE_CORRIDOR}")  # fmt: skip
    if (~on).any():
        lines = trace.lines[~on]
        notes.append(f"{int((~on).sum())} fix(es) more than 30 m off the route dropped (first at line {lines[0]})")
    t, st = trace.t_s[on], m.station_m[on]
    v_fix = trace.speed_mps[on]
    have = np.isfinite(v_fix)
    if have.all():
        speed_source = "gps"
        v = v_fix.copy()
    else:
        v_pos = speed_from_stations_mps(t, st)
        v = np.where(have, v_fix, v_pos)
        speed_source = "positions" if not have.any() else "gps+positions"
        if have.any():
            notes.append(f"{int((~have).sum())} fix(es) without a speed: speed from positions there")
    if smooth_s is None:
        smooth_s = SMOOTH_S

    # the zone, or the distance a partial drive covered (advisory.evaluation.compare, as the service)
    drive = drive_in_zone(t, st, v, length_m, params, speed_limit_mps, smooth_s=smooth_s, keep_series=True)
    if drive is None:
        raise TraceError(f"{trace.source}: the fixes never reach the zone of {m.corridor.name} (station 0)")
    zone, t_in = drive.zone, drive.entry_s
    if not zone.entry_seen:
        notes.append(f"the trace starts {st[0]:.0f} m inside the zone: entry extrapolated back to {t_in - t[0]:+.1f} s")
    notes += drive.notes
    if not drive.complete and not drive.partial:
        notes.append(f"the fixes cover stations {max(st.min(), 0):.0f}-{min(st.max(), length_m):.0f} m of 0-{length_m:.0f} m: the drive is incomplete, comparisons are indicative")

    own_plan = m.corridor.plan()
    if timing is None and own_plan is not None:
        timing = own_plan.name
        notes.append(f"timing: the corridor's plan {timing!r} (pattern in force at the zone entry)")
    result = DriveResult(trace, choice, m, speed_source, float(smooth_s), t_in, entry_unix_s, timing, drive, notes=notes, vehicle=vehicle,
                         decay_multiplier=decay_multiplier)  # fmt: skip
    if timing is None:
        notes.append(NO_TIMING_NOTE)
        if compare:
            _compare_on_recorded_stops(result, params, speed_limit_mps)
        return result
    if log is not None:
        _compare_on_log(result, log, params, speed_limit_mps, compare)
        return result
    anchor = t_in if entry_unix_s is None else entry_unix_s
    result.entry_unix_s = anchor
    try:
        feed: FeedScenario = make_scenario(m.corridor, resolve_timing(m.corridor, timing, anchor), anchor)
        scenario = advisory_scenario_at(feed, t_in, speed_limit_mps)
    except KeyError as exc:
        raise TraceError(str(exc.args[0])) from None
    except ValueError as exc:
        raise TraceError(str(exc)) from None
    # the regular driver and the DP optimum enter when and as fast as the recorded drive did
    scenario = replace(scenario, initial_speed_mps=float(min(max(zone.v_mps[0], 0.0), scenario.speed_limit_mps)))
    result.scenario = scenario
    check = drive.red_check(scenario.signals)
    result.red_crossings, result.red_unknown = check.crossings, check.unknown
    for u in result.red_unknown:
        notes.append(f"light {u.light} ({u.position_m:.0f} m) was passed during a {u.gap_to_s - u.gap_from_s:.0f} s gap in the fixes "
                     f"({t_in + u.gap_from_s:.1f}-{t_in + u.gap_to_s:.1f} Unix s) while it changed: whether it was red is unknown")  # fmt: skip
    for c in result.red_crossings:
        notes.append(f"crossed light {c.light} ({c.position_m:.0f} m) at {t_in + c.t_s:.1f} (Unix s), {c.into_red_s:.1f} s into red, at {c.speed_mps * 3.6:.0f} km/h: "
                     "this drive is not reported as a saving")
    if not compare:
        return result
    from advisory.optimizer import dp

    result.comparison = compare_drive(drive, lambda _entry_s: scenario, params, speed_limit_mps, keep_series=True)
    result.scenario = scenario = result.comparison.lights
    if drive.partial:
        notes.append("DP optimum: not computed for a partial drive (it is an optimum over the whole zone)")
        return result
    solvable, stage_m, moved_m = dp_scenario(scenario)
    if moved_m > 0:
        notes.append(f"DP optimum on {stage_m:g} m stages with the stop lines moved to the grid (at most {moved_m:.1f} m)")
    try:
        sol = dp.solve(solvable, params, dp.GridSpec(stage_m=stage_m))
    except dp.InfeasibleError as exc:
        notes.append(f"DP optimum: {exc}")
    else:
        result.dp = DriverResult(sol.trajectory, score_in_end_state(sol.trajectory, params, speed_limit_mps, keep_series=True))
    return result
