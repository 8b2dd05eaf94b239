"""`ecodrive spat-eval LOG [--json] [--driver careful|lenient] [--hindsight-cache FILE] [--forecast F [--jitter-s S]]`: the advisor on a
recorded controller, judged on what really happened.

The log (the ``../shared/data/spat`` CSV, or our JSON lines: any format
:func:`spat_feed.transport.player.read_spat_log` reads) is replayed through the service's own SPaT path, as
``make antwerp`` feeds it: each snapshot (a J2735 intersection state) is offered to a
:class:`~spat_feed.transport.store.SpatStore` at its own time on an injected clock (the service's time rules:
stale after ``stale_after_s`` = 2 s), and whenever the driver asks (each whole second) the advisor's reading of a
group is the store's ``plan_reading(intersection, group)`` at that instant (its plan, freshness, age and the
store's own :class:`~spat_feed.prediction.history.IntersectionHistory`), turned into a view by
:func:`spat_feed.prediction.observe.light_view`; the virtual driver of :func:`advisory.drivers.closed_loop.simulate`
follows the advice, seeing the light's real colour. So whatever the store does (partial messages, stale data,
what it learns), spat-eval measures. The readings come from one pass through one store
(:func:`replay_store`: a reading at ``t`` depends on the messages up to ``t`` only), every whole second from
the first snapshot; entries are whole seconds from it. The truth is the log itself: a phase switches midway
between the last snapshot in it and the first after it; red is every J2735 stop state (unavailable and dark
are not red: one recording publishes the non-red state of some groups as unavailable). Amber (J2735 clearance)
is green for the rules and a warning to the driver's eye; a group whose log never shows amber is given
:data:`AMBER_S` before each red.

Drivers (``--driver``, :data:`advisory.drivers.closed_loop.DRIVERS`): ``careful`` (the default) stops for any
amber it can stop for at 4 m/s² and launches at 1.5 m/s²; ``lenient`` clears an amber it would cross before
the red and launches at 2 m/s² (this command's driver before issue 31). Both follow the advice with a 1 s
reaction. The comparison is the same person with and without advice: each approach's regular driver is
:meth:`DriverModel.regular <advisory.drivers.closed_loop.DriverModel.regular>` of the chosen driver, the
paper's regular driver with that driver's amber rule and launch rate (a careful regular driver stops for the
amber too, and is slower off the line). The hindsight DP keeps its own limits (amber is green for it) within
that regular driver's trip time.

Approaches: each signal group in turn as the one light (entry ``approach_m`` before its stop line, zone end
``exit_m`` past it), and pairs of groups in series as a two-light corridor (``spacing_m`` apart), entered at
the limit at instants spread evenly over the recording. Each is scored against the paper's regular driver
on the same truth and against a DP that knows the truth (``hindsight``; 20 m stages, see below).

Output keys: ``driver``, ``approaches``, ``red_entries`` (advised crossings while the recorded phase is red),
``hard_brakes`` (runs that needed more than 4 m/s²), ``saving_frac`` (mean cost saving against the regular
driver), ``hindsight_saving_frac`` (the DP's), ``kept_frac`` (their ratio), ``worst_cost_frac`` (the
costliest approach against the regular driver), ``costlier_than_regular_by_10pct`` and its share of the
approaches ``costlier_than_regular_by_10pct_frac`` (advised cost > 1.1 x the regular driver's on the same
truth), ``advice_availability_frac`` (share of approach seconds with speed advice), ``time_lost_s`` (mean,
against the regular driver; each approach's time includes getting back to the limit past the zone end),
``worst_time_lost_s``, ``time_lost_over_60s`` and ``time_lost_over_60s_all`` (below), the same per kind
(single / pair) under ``by_kind``, ``worst`` (the approaches behind the two counts above, one by one: groups,
entry time, time lost, cost against the regular driver, the regular driver's own delay; :func:`worst`) and
``store_verdicts`` (what the store said to each message: ``ok``, ``duplicate``, ...).

``time_lost_over_60s``: the approaches whose advised car took more than 60 s longer than the regular driver on
the same truth, counted only where the regular driver did not itself lose the cycle, i.e. where its own delay
(its time, back at the limit, minus the zone's length at the limit: ``regular_delay_s`` of a row) is at most
60 s. Where the regular driver itself waited more than a minute (a skipped phase, a red held long), the
approach is a long wait with or without advice; it counts only in ``time_lost_over_60s_all`` (every approach
losing more than 60 s against the regular driver).

Measured (``ecodrive spat-eval FILE --json --driver D``, the store keeping each group's latest state; careful /
lenient): 2019-05-01 saving 16.4 / 16.5 % against hindsight 25.0 / 24.0 % (65 / 69 % kept), 0.6 / 0.3 % of
approaches above +10 %, 11 / 8 losing > 60 s; 2019-05-17 18.0 / 17.4 % against 27.9 / 26.6 % (64 / 66 %), 1.5 /
1.8 %, 14 / 20; US 1136 (state only) 15.3 / 14.3 % against 28.9 / 24.4 % (53 / 58 %), 1.9 / 3.3 %, 2 / 3; no red
entry, no hard brake. Every key: ``docs/ADVISOR.md``.

``--forecast`` (:data:`FORECASTS`, for research; default ``predictor``, what ships): each light's forecast made
from the truth instead (:mod:`spat_feed.prediction.oracle`, :func:`oracle_reading`), the rest of the path as it is
(the store's reading, its freshness and published state, ``light_view``, the safety rule). ``truth``: the changes
that really came, published exactly (the advisor's exact-timing rules); ``truth-jitter --jitter-s S``: a calibrated
forecast of spread S about the truth (its median off by 0.8 S on average); ``truth-spread --jitter-s S``: one of
spread S centred on the truth. They split the kept share into what the decision loses when the forecast is right
and what the forecast's error costs (docs/ADVISOR.md, "What is lost to the forecast, and what to the decision").
The output's ``setup`` names the forecast; the hindsight cache serves every forecast.

The hindsight DP is :func:`advisory.drivers.closed_loop.hindsight_optimum`; approaches where it fails are left out
of the hindsight mean (``hindsight_invalid``). 20 m stages instead of the study's 10 m keep a recording within
minutes on two cores; at 20 m the DP costs ~0.5 % more (a slightly lenient yardstick).

``--hindsight-cache FILE`` (:class:`HindsightCache`): the hindsight DP is most of a run's time and does not depend
on the advisor, so its result per approach is kept in a JSON file, written after a run and read at the next; the
output is bit-identical with or without it. An entry is keyed by what the DP and its regular driver depend on
(:func:`hindsight_context`): the log's bytes (SHA-256) and ``--limit-s``, the Setup's geometry and speed limit,
the regular driver's parameters, the DP grid, and a fingerprint of the code they run (physics, optimizer,
regular driver, the truth's reading of the log); then the approach's groups and entry time. The advisor, the store's
rules and ``--every-s`` are not in the key, so one file serves every advisor variant.
"""

from __future__ import annotations

import argparse
import hashlib
import inspect
import json
import math
import os
import multiprocessing as mp
import sys
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, replace
from functools import lru_cache
from pathlib import Path

import numpy as np

from advisory.advice.views import AdvisorParams, LightView, Observation
from advisory.drivers.closed_loop import DRIVERS, hindsight_optimum, red_light_violations, simulate
from advisory.drivers.regular import regular_driver
from advisory.evaluation.endstate import score_in_end_state
from advisory.optimizer.dp import GridSpec
from advisory.physics.params import model_params
from advisory.signals import Scenario, TimelineSignal
from spat_feed.road.corridors import IntersectionSpec, SignalGroupSpec
from spat_feed.timing.messages import IntersectionState, MovementState, to_unix_s
from spat_feed.prediction import oracle
from spat_feed.prediction.observe import HORIZON_S, PlanReading, light_view
from spat_feed.timing.plans import STOP_STATES, PhaseClass, phase_class
from spat_feed.transport.store import DEFAULT_STALE_AFTER_S, SpatStore, TimeRules

HINDSIGHT_GRID = GridSpec(stage_m=20.0)
HARD_BRAKE_MPS2 = 4.0
LOST_S = 60.0
"""An approach losing more than this against the regular driver counts in ``time_lost_over_60s``. [s]"""
AMBER_S = 3.0
"""Amber before each red of a group whose log never shows one (Belgian urban signals: 3 s at 50 km/h). [s]"""


@dataclass(frozen=True, slots=True)
class Setup:
    """Approach geometry and sampling. Units in names."""

    speed_limit_mps: float = 50 / 3.6  # an urban arterial
    approach_m: float = 300.0
    spacing_m: float = 300.0
    exit_m: float = 100.0
    every_s: float = 180.0  # single-light entries this far apart (pairs twice as far)
    horizon_s: float = 240.0  # an approach needs this much recording after its entry
    stale_after_s: float = DEFAULT_STALE_AFTER_S  # the store's (the service's ``spat_stale_after_s``)
    driver: str = "careful"  # the virtual driver (advisory.drivers.closed_loop.DRIVERS); the regular driver is the same person
    forecast: str = "predictor"  # each light's forecast (FORECASTS): the service's predictor, or an oracle's made from the truth
    jitter_s: float = 0.0  # the spread of ``truth-jitter``'s and ``truth-spread``'s forecasts [s]
    seed: int = 0  # their draws


FORECASTS = ("predictor", "truth", "truth-jitter", "truth-spread")
"""Where each light's forecast comes from (``--forecast``): ``predictor``, the service's (its store's reading and
history); ``truth``, the changes that really came, published exactly
(:func:`spat_feed.prediction.oracle.exact_reading`); ``truth-jitter``, a calibrated forecast of spread ``jitter_s``
about the truth (its centre off by a draw of that spread); ``truth-spread``, one of that spread centred on the truth
(:func:`spat_feed.prediction.oracle.jitter_reading`)."""


@dataclass
class GroupLog:
    """One signal group's snapshots: times [Unix s] and J2735 movement states, and its truth."""

    key: tuple[int, int]  # (intersection id, signal group)
    t_s: np.ndarray
    movements: list[MovementState]
    truth: TimelineSignal  # position 0: placed by the approach


def group_logs(snapshots) -> list[GroupLog]:
    """Per (intersection, signal group): its snapshots and the truth (switches midway between snapshots)."""
    rows: dict[tuple[int, int], list[tuple[float, MovementState]]] = {}
    for ix in snapshots:
        t = to_unix_s(ix.timestamp)
        for m in ix.states:
            rows.setdefault((ix.id, m.signal_group), []).append((t, m))
    out = []
    for key, items in sorted(rows.items()):
        t = np.array([r[0] for r in items])
        red = np.array([r[1].state_time_speed[0].event_state in STOP_STATES for r in items])
        reds, start = [], (-math.inf if red[0] else None)
        for i in range(1, len(items)):
            if red[i] != red[i - 1]:
                mid = 0.5 * (t[i - 1] + t[i])
                if red[i]:
                    start = mid
                else:
                    reds.append((start, mid))
                    start = None
        if start is not None:
            reds.append((start, math.inf))
        amber = np.array([phase_class(r[1].state_time_speed[0].event_state) is PhaseClass.AMBER for r in items])
        edges = np.flatnonzero(np.diff(amber.astype(int))) + 1  # snapshots where amber begins or ends
        mids = [-math.inf] + [0.5 * (t[i - 1] + t[i]) for i in edges] + [math.inf]
        ambers = tuple((mids[k], mids[k + 1]) for k in range(len(mids) - 1) if amber[0 if k == 0 else edges[k - 1]])
        if not amber.any():  # a group that never publishes its amber (its non-red state as unavailable): it had one
            ends = [-math.inf] + [b for _, b in reds]
            ambers = tuple((max(a - AMBER_S, e), a) for (a, _), e in zip(reds, ends) if math.isfinite(a))
        out.append(GroupLog(key, t, [r[1] for r in items], TimelineSignal(0.0, tuple(reds), ambers)))
    return out


@dataclass
class StoreReplay:
    """What the service's :class:`~spat_feed.transport.store.SpatStore` answers, every whole second from ``t0_s``.

    ``readings[key][k]`` is ``store.plan_reading(*key)`` at ``t0_s + k``, every message up to that instant offered
    at its own time (:func:`replay_store`); ``verdicts`` counts what the store said to each message."""

    t0_s: float
    rules: TimeRules
    readings: dict[tuple[int, int], list[PlanReading]]
    verdicts: Counter

    def reading(self, key: tuple[int, int], t_s: float) -> PlanReading:
        """The store's reading of ``key`` (intersection, signal group) at ``t_s``, a whole second from ``t0_s``."""
        k = t_s - self.t0_s
        i = round(k)
        seq = self.readings[key]
        if abs(k - i) > 1e-6 or not 0 <= i < len(seq):
            raise ValueError(f"spat-eval: no store reading at {t_s:.3f} (whole seconds from {self.t0_s:.3f}, {len(seq)} of them)")
        return seq[i]


def replay_store(snapshots: Sequence[IntersectionState], keys: Sequence[tuple[int, int]], rules: TimeRules, tail_s: float = 600.0) -> StoreReplay:
    """One pass of the log through a :class:`SpatStore` as the service is fed (``offer`` of each snapshot at its
    own time on an injected clock), reading ``plan_reading`` of every key at each whole second from the first
    snapshot to ``tail_s`` after the last (a reading at ``t`` depends on the messages up to ``t`` only)."""
    stamps = [to_unix_s(ix.timestamp) for ix in snapshots]
    t0 = stamps[0]
    now = [t0]
    store = SpatStore(rules, clock=lambda: now[0])
    verdicts: Counter = Counter()
    readings: dict[tuple[int, int], list[PlanReading]] = {key: [] for key in keys}
    i = 0
    for k in range(int(math.floor(stamps[-1] - t0 + tail_s)) + 1):
        t = t0 + k
        while i < len(snapshots) and stamps[i] <= t:
            now[0] = stamps[i]  # arrives at its own time (the player maps the recorded clock onto now)
            verdicts[store.offer(snapshots[i])] += 1
            i += 1
        now[0] = t
        for key in keys:
            readings[key].append(store.plan_reading(*key))
    return StoreReplay(t0, rules, readings, verdicts)


_LOGS: list[GroupLog] = []
_REPLAY: StoreReplay | None = None
_HINDSIGHT: dict[str, float | None] = {}
"""The hindsight results known before this run (:class:`HindsightCache`, this log and setup): approach key -> saving."""


def load(snapshots: Sequence[IntersectionState], stale_after_s: float = DEFAULT_STALE_AFTER_S) -> list[GroupLog]:
    """Make ``snapshots`` (in time order) the log that :func:`approach` drives through: the truth per group and the
    store's readings (the service's time rules, ``stale_after_s``); returns the groups."""
    global _LOGS, _REPLAY
    _LOGS = group_logs(snapshots)
    _REPLAY = replay_store(snapshots, [g.key for g in _LOGS], TimeRules(stale_after_s))
    return _LOGS


@lru_cache(maxsize=64)
def _spec(n: int, position_m: float) -> IntersectionSpec:
    return IntersectionSpec(id=n + 1, name=f"light {n + 1}", stop_line_m=position_m, lat_deg=0.0, lon_deg=0.0,
                            approach_heading_deg=0.0, signal_groups=(SignalGroupSpec(id=1),))  # fmt: skip


def oracle_reading(log: GroupLog, reading: PlanReading, t_unix_s: float, setup: Setup) -> PlanReading:
    """The store's ``reading`` of ``log``'s group at ``t_unix_s`` with the forecast ``setup.forecast`` says
    (:data:`FORECASTS`; the predictor's: as it is). The oracle's truth is the log's, the hindsight DP's; a red the
    reading still publishes lasts until the group's next snapshot (:func:`spat_feed.prediction.oracle.truth_phases`)."""
    if setup.forecast == "predictor":
        return reading
    i = int(np.searchsorted(log.t_s, t_unix_s, side="right"))
    args = (log.truth.reds_s, log.truth.ambers_s, t_unix_s, HORIZON_S)
    next_s = float(log.t_s[i]) if i < len(log.t_s) else math.inf
    if setup.forecast == "truth":
        return oracle.exact_reading(reading, *args, next_reading_unix_s=next_s)
    return oracle.jitter_reading(reading, *args, setup.jitter_s, (setup.seed, *log.key), next_s, centred=setup.forecast == "truth-spread")


def approach(job: tuple[tuple[int, ...], float, Setup]) -> dict | None:
    """One approach: groups ``job[0]`` in series entered at Unix time ``job[1]``; None if the truth runs out."""
    groups, entry_s, setup = job
    if _REPLAY is None or _REPLAY.rules.stale_after_s != setup.stale_after_s:
        raise RuntimeError("spat-eval: load() the log with the setup's stale_after_s first")
    v_lim = setup.speed_limit_mps
    positions = [setup.approach_m + k * setup.spacing_m for k in range(len(groups))]
    zone_m = positions[-1] + setup.exit_m
    truths = tuple(replace(_LOGS[g].truth.shifted(entry_s), position_m=p) for g, p in zip(groups, positions))
    if any(not math.isfinite(s.next_green_start_s(setup.horizon_s)) for s in truths):
        return None
    scenario = Scenario("+".join(str(_LOGS[g].key[1]) for g in groups), truths, zone_m, v_lim, v_lim)

    def feed(t_s: float, x_m: float, v_mps: float) -> Observation:
        views: list[LightView] = []
        for n, (g, p) in enumerate(zip(groups, positions)):
            if p > x_m and len(views) < 2:
                reading = oracle_reading(_LOGS[g], _REPLAY.reading(_LOGS[g].key, entry_s + t_s), entry_s + t_s, setup)
                views.append(light_view(_spec(n, p), reading, x_m, entry_s + t_s, speed_mps=v_mps))
        return Observation(v_mps, v_lim, tuple(views), position_m=x_m)

    params = model_params()
    driver = DRIVERS[setup.driver]
    run = simulate(scenario, AdvisorParams(units="kmh"), None, driver, feed=feed)
    regular = regular_driver(scenario, driver.regular())  # the same person without advice
    reg = score_in_end_state(regular, params, v_lim)
    adv = score_in_end_state(run.trajectory, params, v_lim)
    at_m = np.interp([t for t, _ in run.advice], run.trajectory.t_s, run.trajectory.x_m)
    ahead = [a for (_, a), x in zip(run.advice, at_m) if x < positions[-1]]
    out = {
        "kind": "single" if len(groups) == 1 else "pair",
        "groups": [int(_LOGS[g].key[1]) for g in groups],
        "entry_unix_s": entry_s,
        "red_entry": bool(red_light_violations(run.trajectory, scenario)),
        "hard_brake": bool(run.trajectory.accel_mps2.min() < -HARD_BRAKE_MPS2 - 1e-9),
        "saving_frac": 1.0 - adv.cost_usd / reg.cost_usd,
        "cost_usd": adv.cost_usd,
        "regular_cost_usd": reg.cost_usd,
        "time_lost_s": adv.time_s - reg.time_s,
        "regular_delay_s": reg.time_s - zone_m / v_lim,  # the regular driver's own wait against the zone at the limit
        "advice_s": int(sum(a.target_speed_mps is not None for a in ahead)),
        "approach_s": len(ahead),
        "hindsight_saving_frac": None,
    }
    key = approach_key(groups, entry_s)
    if key in _HINDSIGHT:
        out["hindsight_saving_frac"] = _HINDSIGHT[key]
        return out
    best = hindsight_optimum(scenario, params, HINDSIGHT_GRID, regular)
    if best is not None:
        out["hindsight_saving_frac"] = 1.0 - score_in_end_state(best, params, v_lim).cost_usd / reg.cost_usd
    return out


def approach_key(groups: Sequence[int], entry_s: float) -> str:
    """The cache key of one approach: its groups (intersection/signal group, in series) and its exact entry time."""
    return "+".join(f"{_LOGS[g].key[0]}/{_LOGS[g].key[1]}" for g in groups) + f"@{entry_s!r}"


_HINDSIGHT_CODE = ("advisory/optimizer", "advisory/physics", "advisory/drivers/regular.py", "advisory/evaluation/endstate.py",
                   "advisory/signals.py", "advisory/trajectory.py")  # fmt: skip
"""The code the hindsight DP and the regular driver run, besides the functions :func:`code_fingerprint` reads."""


def code_fingerprint() -> str:
    """SHA-256 (16 hex digits) of the code a hindsight result depends on: the files of :data:`_HINDSIGHT_CODE`, and
    the source of ``hindsight_optimum``, ``red_light_violations``, the truth's reading (``group_logs``,
    ``phase_class``) with :data:`AMBER_S` and the stop states. Not the advisor's."""
    from advisory.drivers import closed_loop
    from spat_feed.timing import plans

    root = Path(__file__).resolve().parents[1]
    h = hashlib.sha256()
    for name in _HINDSIGHT_CODE:
        path = root / name
        for f in sorted(path.glob("*.py")) if path.is_dir() else [path]:
            h.update(f.relative_to(root).as_posix().encode() + b"\0" + f.read_bytes())
    for fn in (closed_loop.hindsight_optimum, closed_loop.red_light_violations, group_logs, plans.phase_class):
        h.update(inspect.getsource(fn).encode())
    h.update(repr((AMBER_S, sorted(s.value for s in plans.STOP_STATES))).encode())
    return h.hexdigest()[:16]


def hindsight_context(path: str, setup: Setup, limit_s: float | None) -> dict:
    """What a hindsight result depends on beyond its approach: the log's bytes and slice, the Setup's geometry, the
    regular driver's parameters, the DP grid and the code (:func:`code_fingerprint`)."""
    with open(path, "rb") as fh:
        digest = hashlib.file_digest(fh, "sha256").hexdigest()
    return {
        "log_sha256": digest,
        "limit_s": limit_s,
        **{k: getattr(setup, k) for k in ("speed_limit_mps", "approach_m", "spacing_m", "exit_m")},
        "regular_driver": repr(DRIVERS[setup.driver].regular()),
        "grid": repr(HINDSIGHT_GRID),
        "code": code_fingerprint(),
    }


class HindsightCacheError(ValueError):
    """The cache file exists but is not one this command wrote."""


class HindsightCache:
    """The hindsight results of earlier runs, in a JSON file: ``{"format", "version", "contexts": {id: {"context",
    "hindsight_saving_frac": {approach key: saving or null}}}}``, one context per log, slice, setup and code
    (:func:`hindsight_context`; ``id`` is its SHA-256). Floats go through JSON exactly (shortest repr)."""

    FORMAT = "ecodrive spat-eval hindsight cache"
    VERSION = 1

    def __init__(self, path: str | os.PathLike) -> None:
        self.path = Path(path)
        self.contexts: dict[str, dict] = {}
        if not self.path.exists():
            return
        try:
            data = json.loads(self.path.read_text(encoding="utf-8"))
            ok = isinstance(data, dict) and data.get("format") == self.FORMAT and isinstance(data.get("contexts"), dict)
        except (UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise HindsightCacheError(f"hindsight cache {self.path}: not JSON ({exc})") from exc
        if not ok:
            raise HindsightCacheError(f"hindsight cache {self.path}: not a spat-eval hindsight cache (no format {self.FORMAT!r}); "
                                      "give another file, or remove it")  # fmt: skip
        if data.get("version") == self.VERSION:  # an older layout is dropped, and rewritten at the end of the run
            self.contexts = data["contexts"]

    @staticmethod
    def context_id(context: dict) -> str:
        return hashlib.sha256(json.dumps(context, sort_keys=True).encode()).hexdigest()[:16]

    def results(self, context: dict) -> dict[str, float | None]:
        """The known results for ``context`` (approach key -> hindsight saving); empty if none."""
        return dict(self.contexts.get(self.context_id(context), {}).get("hindsight_saving_frac", {}))

    def save(self, context: dict, results: dict[str, float | None]) -> None:
        """Add ``results`` under ``context`` and write the file (whole, through a temporary file beside it), with
        whatever another run wrote to it meanwhile (a run with another driver or log, at the same time)."""
        self.contexts = {**HindsightCache(self.path).contexts, **self.contexts}
        entry = self.contexts.setdefault(self.context_id(context), {"context": context, "hindsight_saving_frac": {}})
        entry["hindsight_saving_frac"].update(results)
        tmp = self.path.with_name(self.path.name + ".tmp")
        tmp.write_text(json.dumps({"format": self.FORMAT, "version": self.VERSION, "contexts": self.contexts}), encoding="utf-8")
        os.replace(tmp, self.path)


def jobs(logs: Sequence[GroupLog], setup: Setup, anchor_s: float | None = None) -> list:
    """Single groups every ``every_s``, and each group with the next one as a pair every ``2 every_s``, from 5 s
    after every group has been heard; each entry a whole number of seconds after ``anchor_s`` (the store
    replay's first second) when given."""
    t0 = max(float(g.t_s[0]) for g in logs) + 5.0
    if anchor_s is not None:
        t0 = anchor_s + math.ceil(t0 - anchor_s - 1e-6)
    t1 = min(float(g.t_s[-1]) for g in logs) - setup.horizon_s
    snap = (lambda t: t) if anchor_s is None else (lambda t: t0 + round(t - t0))
    out = []
    for n in range(len(logs)):
        out += [((n,), float(snap(t)), setup) for t in np.arange(t0 + n * setup.every_s / len(logs), t1, setup.every_s)]
    for n in range(len(logs) - 1):
        out += [((n, n + 1), float(snap(t)), setup) for t in np.arange(t0 + n * setup.every_s / len(logs), t1, 2 * setup.every_s)]
    return out


def summarize(rows: list[dict]) -> dict:
    """The JSON keys (see the module) over ``rows``."""
    if not rows:
        return {"approaches": 0}
    hind = [r for r in rows if r["hindsight_saving_frac"] is not None]
    saving = float(np.mean([r["saving_frac"] for r in rows]))
    hindsight = float(np.mean([r["hindsight_saving_frac"] for r in hind])) if hind else float("nan")
    return {
        "approaches": len(rows),
        "red_entries": int(sum(r["red_entry"] for r in rows)),
        "hard_brakes": int(sum(r["hard_brake"] for r in rows)),
        "saving_frac": saving,
        "hindsight_saving_frac": hindsight,
        "kept_frac": saving / hindsight if hind and hindsight > 0 else None,
        "kept_frac_same_approaches": float(np.mean([r["saving_frac"] for r in hind]) / hindsight) if hind and hindsight > 0 else None,
        "hindsight_invalid": len(rows) - len(hind),
        "worst_cost_frac": float(max(-r["saving_frac"] for r in rows)),
        "costlier_than_regular_by_10pct": int(sum(r["saving_frac"] < -0.10 for r in rows)),
        "costlier_than_regular_by_10pct_frac": float(sum(r["saving_frac"] < -0.10 for r in rows) / len(rows)),
        "advice_availability_frac": float(sum(r["advice_s"] for r in rows) / max(sum(r["approach_s"] for r in rows), 1)),
        "time_lost_s": float(np.mean([r["time_lost_s"] for r in rows])),
        "worst_time_lost_s": float(max(r["time_lost_s"] for r in rows)),
        "time_lost_over_60s": int(sum(r["time_lost_s"] > LOST_S and r["regular_delay_s"] <= LOST_S for r in rows)),
        "time_lost_over_60s_all": int(sum(r["time_lost_s"] > LOST_S for r in rows)),
    }


def worst(rows: list[dict]) -> list[dict]:
    """The approaches behind ``time_lost_over_60s_all`` and ``costlier_than_regular_by_10pct``, to trace one by one:
    groups, entry time [Unix s], time lost [s], cost against the regular driver [-] (``cost_frac``, +0.1 = 10 %
    costlier) and the regular driver's own delay [s]; the longest time lost first."""
    bad = [r for r in rows if r["time_lost_s"] > LOST_S or r["saving_frac"] < -0.10]
    return [{"groups": r["groups"], "entry_unix_s": r["entry_unix_s"], "time_lost_s": round(r["time_lost_s"], 2),
             "cost_frac": round(-r["saving_frac"], 4), "regular_delay_s": round(r["regular_delay_s"], 2)}
            for r in sorted(bad, key=lambda r: -r["time_lost_s"])]  # fmt: skip


def _read_head(path: str, limit_s: float) -> list:
    """The snapshots of the log's first ``limit_s`` seconds (a CSV is read no further; JSON lines whole)."""
    import csv
    import gzip

    from spat_feed.transport.player import read_spat_log
    from spat_feed.transport.recorded import iter_spat_csv

    if not str(path).lower().removesuffix(".gz").endswith(".csv"):
        states = read_spat_log(path)
        return [ix for ix in states if (ix.timestamp - states[0].timestamp).total_seconds() <= limit_s]
    out = []
    with (gzip.open(path, "rt", encoding="utf-8", newline="") if str(path).endswith(".gz") else open(path, encoding="utf-8", newline="")) as fh:
        for ix in iter_spat_csv(csv.DictReader(fh), source=str(path)):
            if out and (ix.timestamp - out[0].timestamp).total_seconds() > limit_s:
                break
            out.append(ix)
    return sorted(out, key=lambda ix: ix.timestamp)


def evaluate_log(path: str, setup: Setup | None = None, workers: int = 2, limit_s: float | None = None, progress: bool = True,
                 rows_out: list | None = None, hindsight_cache: str | os.PathLike | None = None) -> dict:  # fmt: skip
    """Replay the log at ``path`` (any format :func:`spat_feed.transport.player.read_spat_log` reads; optionally
    only its first ``limit_s`` seconds); the summary (and the rows, appended to ``rows_out`` if given).
    ``hindsight_cache``: a :class:`HindsightCache` file, read before and written after (same output, less time)."""
    global _HINDSIGHT
    from tqdm import tqdm

    from spat_feed.transport.player import read_spat_log

    setup = setup or Setup()
    if setup.driver not in DRIVERS:
        raise ValueError(f"unknown driver {setup.driver!r} (one of {', '.join(DRIVERS)})")
    if setup.forecast not in FORECASTS or setup.forecast.startswith("truth-") != (setup.jitter_s > 0.0):
        raise ValueError(f"forecast {setup.forecast!r} with jitter {setup.jitter_s} s: one of {', '.join(FORECASTS)}, a spread > 0 with truth-jitter "
                         "and truth-spread only")  # fmt: skip
    cache = HindsightCache(hindsight_cache) if hindsight_cache is not None else None
    context = hindsight_context(path, setup, limit_s) if cache is not None else None
    snapshots = read_spat_log(path) if limit_s is None else _read_head(path, limit_s)
    load(snapshots, setup.stale_after_s)
    todo = jobs(_LOGS, setup, _REPLAY.t0_s)
    _HINDSIGHT = cache.results(context) if cache is not None else {}
    if progress and cache is not None:
        known = sum(approach_key(g, t) in _HINDSIGHT for g, t, _ in todo)
        print(f"spat-eval: hindsight of {known} of {len(todo)} approaches from {cache.path}", file=sys.stderr)
    bar = dict(total=len(todo), desc=f"spat-eval {path.rsplit('/', 1)[-1]}", disable=not progress, file=sys.stderr)
    try:
        if workers > 1:
            with mp.get_context("fork").Pool(workers) as pool:
                rows = list(tqdm(pool.imap(approach, todo, chunksize=4), **bar))
        else:
            rows = [approach(j) for j in tqdm(todo, **bar)]
    finally:
        _HINDSIGHT = {}
    if cache is not None:
        cache.save(context, {approach_key(g, t): r["hindsight_saving_frac"] for (g, t, _), r in zip(todo, rows) if r is not None})
    rows = [r for r in rows if r is not None]
    if rows_out is not None:
        rows_out.extend(rows)
    out = {"log": path, "driver": setup.driver, **summarize(rows)}
    out["by_kind"] = {k: summarize([r for r in rows if r["kind"] == k]) for k in ("single", "pair")}
    out["worst"] = worst(rows)
    out["store_verdicts"] = dict(_REPLAY.verdicts)
    out["setup"] = {k: getattr(setup, k) for k in Setup.__slots__}
    return out


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="ecodrive spat-eval", description=__doc__.split("\n\n")[0])
    ap.add_argument("logs", nargs="+", metavar="LOG", help="recorded SPaT: the shared CSV (.csv[.gz]) or our JSON lines (.jsonl[.gz])")
    ap.add_argument("--json", action="store_true", help="print the summary as JSON")
    ap.add_argument("--driver", choices=sorted(DRIVERS), default=Setup().driver,
                    help="the virtual driver, and the regular driver it is judged against (default %(default)s)")  # fmt: skip
    ap.add_argument("--forecast", choices=FORECASTS, default=Setup().forecast,
                    help="each light's forecast: the service's predictor (default), or an oracle's for research: 'truth' (the changes "
                         "that really came, published exactly), 'truth-jitter' (a calibrated forecast of spread --jitter-s about "
                         "the truth), 'truth-spread' (one of that spread centred on the truth)")  # fmt: skip
    ap.add_argument("--jitter-s", type=float, default=None, metavar="SIGMA_S", help="the spread of truth-jitter's and truth-spread's forecasts [s]")
    ap.add_argument("--seed", type=int, default=0, help="the draws of truth-jitter and truth-spread (default %(default)s)")
    ap.add_argument("--every-s", type=float, default=Setup().every_s, help="seconds between single-light entries (default %(default)s)")
    ap.add_argument("--limit-s", type=float, default=None, help="use only the first seconds of each log")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--hindsight-cache", metavar="FILE", default=None,
                    help="keep each approach's hindsight DP result in this JSON file (read if present, written after the run): "
                         "the same output, minutes faster when only the advisor changed")  # fmt: skip
    args = ap.parse_args(argv)
    if args.forecast.startswith("truth-") != (args.jitter_s is not None) or (args.jitter_s is not None and not args.jitter_s > 0.0):
        ap.error(f"--forecast {args.forecast}: --jitter-s SIGMA_S > 0 goes with truth-jitter and truth-spread, and only with them")
    from spat_feed.transport.recorded import RecordedLogError

    results = []
    for path in args.logs:
        try:
            setup = Setup(every_s=args.every_s, driver=args.driver, forecast=args.forecast, jitter_s=args.jitter_s or 0.0, seed=args.seed)
            results.append(evaluate_log(path, setup, args.workers, args.limit_s, progress=True, hindsight_cache=args.hindsight_cache))
        except (OSError, RecordedLogError, HindsightCacheError) as exc:
            print(f"ecodrive spat-eval: {exc}", file=sys.stderr)
            return 2
    if args.json:
        print(json.dumps(results[0] if len(results) == 1 else results, indent=2))
        return 0
    for r in results:
        print(f"{r['log']} ({r['driver']} driver, {r['setup']['forecast']} forecast): {r['approaches']} approaches; red entries {r['red_entries']}, hard brakes {r['hard_brakes']}; "
              f"saving {100 * r['saving_frac']:.1f} % vs hindsight DP {100 * r['hindsight_saving_frac']:.1f} % "
              f"(kept {100 * (r['kept_frac'] or 0):.0f} %); worst {100 * r['worst_cost_frac']:+.1f} % cost; "
              f"speed advice {100 * r['advice_availability_frac']:.0f} % of approach seconds; time lost {r['time_lost_s']:+.1f} s; "
              f"> +10 % cost {100 * r['costlier_than_regular_by_10pct_frac']:.1f} %; > 60 s lost {r['time_lost_over_60s']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
