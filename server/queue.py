"""Queue-aware advice in the service: every trip's position is a probe of the traffic on its corridor.

:class:`QueueBoard` keeps, per corridor, where each trip was at its last fix (station, speed, time; this worker's
trips: a fix older than ``MAX_AGE_S`` is forgotten, so an ended or silent trip drops out by itself), when each
light's current red was first seen on, and each light's last red that has ended (its queue goes on discharging after
the green: :meth:`QueueBoard.past_red`). For a fix on the route it hands the advisor the observation as the car meets
the lights in traffic (:func:`advisory.advice.queue.estimate` and :func:`~advisory.advice.queue.apply`: each red the car
faces ends when the queue in front of it has crossed the line), or, for a car standing in a queue or closing in on a
slower connected car, the service's own advice until it is over the next light's line: no speed, "Queue ahead.
Follow the car in front." (reason ``queue``), or, at a fix where it closes in on a slower connected car, a lift-off
to that car's speed (:func:`advisory.advice.queue_words.ease_to_car_ahead`); the advisor then plans afresh. Not where the cars ahead leave it no time
to cross before the next light's red (``QueueEstimate.stop_behind``, :func:`advisory.advice.queue.behind_s`): that
car is advised by the advisor, which sees the line closed to it until the red's end, and prepares to stop. The trips behind a car are probes too:
with the flow they give the followers a slower plan would hold up (``Observation.followers``), which the advisor and
:meth:`QueueBoard.check` price (docs/TRAFFIC.md, "Queue-aware advice", item 4), and the platoon behind the car at the
green line it has just passed (the service hands :meth:`QueueBoard.see` that light) and at the next one, which a slow
plan is not to cut off before the red (:meth:`QueueBoard.lost_behind`; item 5).

On when ``ECO_QUEUE_AWARE=1``; ``ECO_QUEUE_ARRIVALS_VPH`` (the flow arriving at each light per lane, e.g. from
detector counts) and ``ECO_QUEUE_CONNECTED_SHARE`` (the share of those cars that are connected) let it count the cars
that are not connected (docs/TRAFFIC.md).

A fix looks only at the cars that can change its estimate (:class:`Lane`: the probes ordered by station): the ones
between it and the farthest light in its view (and the nearest one ahead), and the ones behind that can reach its next
line while it may be held there; the answer is the one the loop over every car of the corridor gave
(``tests/server/test_queue_index.py``), at a cost that grows with the cars near it, not with the corridor's.

Where the probes and red starts are kept (``shared``): in this worker with the in-process store (one process: it
sees every trip); with the Redis store (several workers, ``ECO_STORE_URL``) in :class:`server.storage.queue_store.SharedBoard`
tables, which every worker publishes its changes to and loads the others' from in the background every
``ECO_QUEUE_SYNC_S``, so that a fix on one worker counts the cars that the others serve (no Redis call on a fix's path;
Redis unreachable: this worker's own probes, said in ``/health`` and ``/metrics``).
"""

from __future__ import annotations

import heapq
import math
from bisect import bisect_left
from dataclasses import replace

import numpy as np
from numba import njit

from advisory.advice.behind import PACED_REASON, cut_behind, gives_up_green, paced_for_behind
from advisory.advice.queue import PastRed, Probe, Probes, QueueEstimate, QueueModel, apply, estimate, followers_held_up, normal_drive_s, plan_of
from advisory.advice.queue_words import drive_normally, ease_to_car_ahead, said_truly, seen_at_line, tail_glide
from advisory.advice.views import Advice, AdvisorParams, LightView, Observation
from server.storage.queue_store import SharedBoard

MAX_AGE_S = 3.0
"""A trip's position older than this is no longer a probe. [s]"""
QUEUE_MESSAGE = "Queue ahead. Follow the car in front."
SILENT = ("too_close", "short_wait", "far_ahead")  # the advisor's silences: the driver goes on with the plan it follows


class Lane:
    """One corridor's probes (``table``: trip -> ``(t_unix_s, station_m, speed_mps)``, the board's dict or the shared
    board's :class:`~server.storage.queue_store.Noted`) indexed for :meth:`QueueBoard.see`, so that a fix looks only at the cars
    that can change its estimate instead of at every car on the corridor:

    * ``order``: ``(station_m, seq, trip, speed_mps)`` sorted by station; ``seq`` is the table's insertion order, so
      cars at one station come in the order a loop over the table meets them (the nearest car ahead is the same one);
    * ``rows``: the table's ``station_m``, ``t_unix_s`` and ``speed_mps`` in that order, and each car's advised motion
      at that fix (``plan_mps``, ``plan_mode``: :func:`advisory.advice.queue.plan_of`, where this worker advised it at
      that fix, :meth:`tell`; NaN and 0: none), as five rows of an array, so that a fix makes its run of cars probes at
      once (:meth:`near`);
    * ``by_time``: ``(t_unix_s, trip)`` as a heap, to forget the stale probes without looking at the others (an entry
      left by a later fix of the same trip is skipped when it comes up);
    * ``top_mps``: at least the fastest probe's speed (exact after a rebuild, raised by each fix), which bounds how far
      a car can have moved since its fix and how far behind it can still reach a line in time (:meth:`near`, :meth:`QueueBoard.estimate`).

    Every change to the table goes through :meth:`put`, :meth:`drop` and :meth:`expire`; a table replaced as a whole
    (the shared board's sync: its ``loads`` counter moved) is indexed again at the next call (:meth:`fresh`)."""

    __slots__ = ("table", "loads", "order", "rows", "entry", "seq", "next_seq", "by_time", "top_mps", "plans")

    def __init__(self, table: dict) -> None:
        self.table = table
        self.loads = -1
        self.plans: dict[str, tuple[float, float, int]] = {}
        """trip -> the advised motion of its fix at that time: ``(t_unix_s, plan_mps, plan_mode)`` (:meth:`tell`)."""
        self.fresh()

    def fresh(self) -> None:
        """Index the table again if it was replaced since the last call."""
        loads = getattr(self.table, "loads", 0)
        if loads == self.loads:
            return
        self.loads = loads
        self.seq = {tid: k for k, tid in enumerate(self.table)}
        self.next_seq = len(self.seq)
        self.entry = {tid: (s, self.seq[tid], tid, v) for tid, (_, s, v) in self.table.items()}
        self.order = sorted(self.entry.values())
        plans = [self._plan(tid) for _, _, tid, _ in self.order]
        self.rows = np.array([[s for s, _, _, _ in self.order], [self.table[tid][0] for _, _, tid, _ in self.order],
                              [v for _, _, _, v in self.order], [p for p, _ in plans], [m for _, m in plans]], dtype=float).reshape(5, len(self.order))  # fmt: skip
        self.by_time = [(t, tid) for tid, (t, _, _) in self.table.items()]
        heapq.heapify(self.by_time)
        self.top_mps = max((v for _, _, v in self.table.values()), default=0.0)

    def _plan(self, trip_id: str) -> tuple[float, int]:
        """The trip's advised motion at its probe's fix (:meth:`tell`), ``(nan, 0)`` where none was told at that fix."""
        told = self.plans.get(trip_id)
        probe = self.table.get(trip_id)
        return (told[1], told[2]) if told is not None and probe is not None and told[0] == probe[0] else (math.nan, 0)

    def tell(self, trip_id: str, t_unix_s: float, plan: tuple[float, int]) -> None:
        """The trip was advised ``plan`` (:func:`advisory.advice.queue.plan_of`) at its fix at ``t_unix_s``: its
        probe carries that motion while that fix is its last (a later fix's probe carries none until told)."""
        self.plans[trip_id] = (t_unix_s, *plan)
        entry = self.entry.get(trip_id)
        if entry is not None and self.table[trip_id][0] == t_unix_s:
            self.rows[3:, bisect_left(self.order, entry)] = plan

    def _unindex(self, trip_id: str) -> None:
        entry = self.entry.pop(trip_id, None)
        if entry is not None:
            k = bisect_left(self.order, entry)
            del self.order[k]
            self.rows = np.delete(self.rows, k, axis=1)
            del self.seq[trip_id]

    def put(self, trip_id: str, probe: tuple[float, float, float]) -> None:
        """The trip's probe replaces its last one (in the table and the index)."""
        t, s, v = probe
        old = self.entry.get(trip_id)
        if old is not None:
            was = bisect_left(self.order, old)
            del self.order[was]
            seq = self.seq[trip_id]
        else:
            seq = self.seq[trip_id] = self.next_seq
            self.next_seq += 1
        self.table[trip_id] = probe
        entry = self.entry[trip_id] = (s, seq, trip_id, v)
        k = bisect_left(self.order, entry)
        self.order.insert(k, entry)
        rows = self.rows
        if old is None:
            self.rows = np.insert(rows, k, (s, t, v, math.nan, 0.0), axis=1)
        else:  # the cars between its old place and its new one move up or down by one
            if k > was:
                rows[:, was:k] = rows[:, was + 1 : k + 1]
            elif k < was:
                rows[:, k + 1 : was + 1] = rows[:, k:was].copy()
            rows[:, k] = (s, t, v, math.nan, 0.0)
        heapq.heappush(self.by_time, (t, trip_id))
        if v > self.top_mps:
            self.top_mps = v

    def drop(self, trip_id: str) -> None:
        """The trip is no probe any more (off the route, ended)."""
        self.table.pop(trip_id, None)
        self.plans.pop(trip_id, None)
        self._unindex(trip_id)

    def expire(self, t_unix_s: float, max_age_s: float) -> None:
        """Forget the probes older than ``max_age_s`` at ``t_unix_s`` (``t_unix_s - t > max_age_s``, as a loop over the
        table would; a deletion the shared board does not send on: Redis drops stale probes itself)."""
        heap = self.by_time
        while heap and t_unix_s - heap[0][0] > max_age_s:
            t, trip_id = heapq.heappop(heap)
            probe = self.table.get(trip_id)
            if probe is not None and probe[0] == t:
                del self.table[trip_id]
                self.plans.pop(trip_id, None)
                self._unindex(trip_id)

    def near(self, here_m: float, t_unix_s: float, lo_m: float, hi_m: float) -> Probes:
        """The cars that were, at their last fix, between ``lo_m - top_mps x MAX_AGE_S`` and ``hi_m`` ahead of station
        ``here_m`` (a superset of those that can be in ``[lo_m, hi_m)`` now, rather a few too many), each where it is at
        ``t_unix_s`` (:func:`probe_at`, the run at once: :func:`_probes_at`), with its advised motion at that fix
        (:meth:`tell`); none at ``here_m`` itself (this car)."""
        order = self.order
        first = bisect_left(order, (here_m + lo_m - self.top_mps * MAX_AGE_S - 1e-6,))
        end = bisect_left(order, (here_m + hi_m + 1e-6,), first)
        mine = bisect_left(order, (here_m,), first, end)  # the cars at here_m (this one), a run of the order: left out
        past = mine
        while past < end and order[past][0] == here_m:
            past += 1
        return Probes(*_probes_at(self.rows, first, mine, past, end, here_m, t_unix_s))


@njit(cache=True)
def _probes_at(rows: np.ndarray, first: int, mine: int, past: int, end: int, here_m: float,
               t_unix_s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:  # fmt: skip
    """The cars of columns ``first:end`` of a lane's ``rows`` but ``mine:past`` (this car) as probes for the fix at
    ``here_m`` at ``t_unix_s``, compiled: how far ahead each is and its speed, as :func:`probe_at` has them, and its
    advised motion (:meth:`Lane.tell`)."""
    n = (mine - first) + (end - past)
    ahead_m, speed_mps, plan_mps, plan_mode = np.empty(n), np.empty(n), np.empty(n), np.empty(n, dtype=np.int64)
    k = 0
    for j in range(first, end):
        if mine <= j < past:
            continue
        dt_s = t_unix_s - rows[1, j]
        ahead_m[k] = rows[0, j] + rows[2, j] * (0.0 if 0.0 > dt_s else dt_s) - here_m
        speed_mps[k] = rows[2, j]
        plan_mps[k] = rows[3, j]
        plan_mode[k] = int(rows[4, j])
        k += 1
    return ahead_m, speed_mps, plan_mps, plan_mode


def probe_at(probe: tuple[float, float, float], here_m: float, t_unix_s: float) -> Probe:
    """A car's last fix ``(t_unix_s, station_m, speed_mps)`` as a probe for a fix at ``here_m`` at ``t_unix_s``: where
    it is now, its last fix (up to a second older, as a corridor's fixes arrive one after the other; never moved
    back for one stamped later) advanced at its speed (a car 2.5 s behind is not read 3.5 s behind)."""
    t, s, v = probe
    dt_s = t_unix_s - t
    return Probe(s + v * (0.0 if 0.0 > dt_s else dt_s) - here_m, v)  # max(dt_s, 0.0), without the call


def _normally(advice: Advice, params: AdvisorParams, real: Observation, last: dict | None) -> Advice:
    """The service's "drive normally" in place of ``advice`` (:func:`advisory.advice.queue_words.drive_normally`), spoken
    where the trip's ``last`` answer was not already "drive normally" (as the advisor speaks its own: on a change)."""
    out = drive_normally(advice, params.units, real.lights[0])
    said = last is not None and (last.get("action"), last.get("reason")) == (out.action, out.reason)
    return replace(out, speak=False) if said else out


class QueueBoard:
    """Probes per corridor and red starts per intersection (see the module docstring)."""

    def __init__(self, model: QueueModel | None = None, arrivals_vph: float | None = None, connected_share: float = 1.0,
                 shared: SharedBoard | None = None) -> None:  # fmt: skip
        self.model = model or QueueModel()
        self.arrivals_vps = None if arrivals_vph is None else arrivals_vph / 3600.0
        self.connected_share = connected_share
        self.shared = shared
        """Every worker's probes and red starts (the Redis store), or None: this worker's dicts."""
        self._cars: dict[str, dict[str, tuple[float, float, float]]] = shared.cars if shared is not None else {}
        self._red_since: dict[int, float] = shared.red_since if shared is not None else {}
        self._red_ended: dict[int, tuple[float, float, float]] = shared.red_ended if shared is not None else {}
        """intersection -> its last red that has ended: ``(start, end, jam)``, times [s], ``jam`` the queue [m] this worker
        last saw published in it (NaN: none), for :meth:`past_red`."""
        self._in_red: dict[int, tuple[float, float, float]] = {}
        """intersection -> this worker's last fix in its current red: its time, when the red then surely ended (inf:
        not known) [s], the queue [m] last published in it (NaN: none)."""
        self._queued: dict[str, int] = {}  # trip -> the light whose queue it stands in
        self._behind: dict[str, tuple[Probe, ...]] = {}  # trip -> the connected cars its last fix found it holds up (:meth:`check`)
        self._seen: dict[str, tuple[Observation, QueueEstimate]] = {}  # trip -> its last fix's lights as they are, and its queue estimate (:meth:`check`)
        self._for_queue: dict[str, bool] = {}  # trip -> the plan it follows was made for the queue in front (:meth:`check`)
        self._passed: dict[str, tuple[tuple[LightView, Probes, PastRed | None], ...]] = {}
        """trip -> the light it passed last and the next one, each with the connected cars behind that may still cross it
        in the green the car crosses it in, and the passed one's last red (:meth:`note_behind`, :meth:`cuts_behind`)."""
        self._lanes: dict[str, Lane] = {}  # corridor -> its probes indexed (Lane)
        self._view_m: dict[str, float] = {}  # trip -> how far behind it the route begins for the service (:meth:`see`) [m]
        self._fix: dict[str, tuple[Lane, float, float]] = {}  # trip -> its last fix's lane, time [s] and speed limit [m/s] (:meth:`tell`)
        self._plan: dict[str, tuple[float, int]] = {}  # trip -> the motion its last spoken or shown advice asks (:meth:`tell`)
        self.held = 0  # fixes answered "follow the car in front"

    def see(self, corridor: str, trip_id: str, t_unix_s: float, obs: Observation, last_reason: str | None = None,
            passed: LightView | None = None, params: AdvisorParams | None = None, told_mps: float | None = None,
            view_from_m: float = -math.inf) -> tuple[Observation, Advice | None]:  # fmt: skip
        """Note the car's fix; the observation the advisor should get, or the service's advice for a car in a queue
        or behind a slower one (spoken when the trip's last advice, ``last_reason``, was another, or the speed it told,
        ``told_mps``, moved by ``params.speak_change_mps``). After such advice the advisor plans afresh
        (:meth:`fresh`). ``passed``: the light whose line the car passed last (distance negative), for the cars behind
        that still have to cross it (:meth:`check`). ``params``: the trip's advisor settings (units, speed steps).
        ``view_from_m``: the station where the route begins for the service (the approach's start): a connected car
        behind it is no probe yet, and the cars behind are expected from the flow there
        (:func:`advisory.advice.queue.unseen_behind`)."""
        lane = self.lane(corridor)
        if not obs.on_route or obs.position_m is None or not obs.lights:
            lane.drop(trip_id)
            self._queued.pop(trip_id, None)
            self._behind.pop(trip_id, None)
            self._seen.pop(trip_id, None)
            self._for_queue.pop(trip_id, None)
            self._passed.pop(trip_id, None)
            self._view_m.pop(trip_id, None)
            self._fix.pop(trip_id, None)
            self._plan.pop(trip_id, None)
            return obs, None
        here = float(obs.position_m)
        self._view_m[trip_id] = max(here - view_from_m, 0.0)
        lane.put(trip_id, (t_unix_s, here, float(obs.speed_mps)))
        self._fix[trip_id] = (lane, t_unix_s, obs.speed_limit_mps)
        lane.expire(t_unix_s, MAX_AGE_S)
        self.note_behind(lane, trip_id, here, t_unix_s, obs, passed)
        est = self.estimate(lane, here, t_unix_s, obs, self.red_elapsed(obs, t_unix_s), self._view_m[trip_id])
        return self.answer(trip_id, obs, est, last_reason, params, told_mps)

    def red_elapsed(self, obs: Observation, t_unix_s: float) -> float | None:
        """How long the next light's current red has been on at ``t_unix_s`` (from the first fix that saw it on, on any
        trip), None when it is not red. At the first fix that sees it off the red is kept (:meth:`past_red`) with its
        start, its end (when the last fix in it had it surely end, between that fix and this one: with few connected
        cars the first fix on the green can come long after it) and the queue last published in it.

        A red is one the light shows: an actuated green past its minimum, which the sure view takes as red from now
        (it may end any second) but the late view still has green, is none. And a red seen where the last fix in the
        red kept had it surely end before now is a new one: a green came between that no fix saw (with few connected
        cars the next fix on a light can come a cycle later), and the red kept has ended. Before, a red was counted
        from a fix on such a green and kept from cycle to cycle, and the cars not connected arriving "over the red"
        with it: 19 cars where 5 stood (paper_s400 actuated 900 veh/h, 10 %, seed 5, ``main.91``,
        docs/history/TRAFFIC.md)."""
        nxt = obs.lights[0]
        key = nxt.intersection_id
        shown = nxt.red_now and (nxt.late_red_windows_s is None or any(a <= 0.0 < b for a, b in nxt.late_red_windows_s))
        seen, since = self._in_red.get(key), self._red_since.get(key)
        stale = shown and seen is not None and seen[1] < t_unix_s and since is not None and since <= seen[0]
        if not shown or stale:
            began = self._red_since.pop(key, None)
            last_t, last_end, jam = self._in_red.pop(key, (began, t_unix_s, math.nan))
            if began is not None:
                self._red_ended[key] = (began, max(min(last_end, t_unix_s), last_t, began), jam)
            if not shown:
                return None
        jam = nxt.queue_m if nxt.fresh and nxt.queue_m is not None else self._in_red.get(key, (0.0, 0.0, math.nan))[2]
        self._in_red[key] = (t_unix_s, t_unix_s + nxt.seconds_to_green(), jam)
        return t_unix_s - self._red_since.setdefault(key, t_unix_s)

    def past_red(self, obs: Observation, t_unix_s: float) -> PastRed | None:
        """The next light's last red, from ``t_unix_s`` (its queue goes on discharging after its end:
        :func:`advisory.advice.queue.past_queue`), None while it is red or where no red of it was seen end."""
        nxt = obs.lights[0]
        return None if nxt.red_now else self._last_red(nxt.intersection_id, t_unix_s)

    def _last_red(self, intersection_id: int, t_unix_s: float) -> PastRed | None:
        """The last red of a light seen end (:meth:`red_elapsed`), from ``t_unix_s``; None where none was."""
        ended = self._red_ended.get(intersection_id)
        if ended is None:
            return None
        began, end, jam = ended
        return PastRed(began - t_unix_s, end - t_unix_s, None if math.isnan(jam) else jam)

    def note_behind(self, lane: Lane, trip_id: str, here_m: float, t_unix_s: float, obs: Observation, passed: LightView | None) -> None:
        """Keep, for :meth:`check`, the lights whose green the cars behind this one still have to cross: the one it
        passed last (``passed``) and the next one, each with the connected cars behind that can reach its line within
        its next red's start (none farther than that time at the faster of the limit and the fastest car), and the
        passed one with its last red seen end (its queue may still be crossing)."""
        noted = []
        for light in (passed, obs.lights[0]):
            if light is None:
                continue
            windows = light.red_windows_s if light.likely_red_windows_s is None else light.likely_red_windows_s
            start = max((a for a, b in windows[:2] if math.isfinite(a)), default=math.inf)  # at most the red after the next one
            if not 0.0 < start < math.inf:
                continue
            reach_m = start * max(lane.top_mps, obs.speed_limit_mps, 1.0) * (1.0 + 1e-9) + 1e-6
            near = lane.near(here_m, t_unix_s, min(light.distance_m, 0.0) - reach_m, 0.0)
            behind = near.where(near.ahead_m < 0.0)
            noted.append((light, behind, self._last_red(light.intersection_id, t_unix_s) if light is passed else None))
        self._passed[trip_id] = tuple(noted)

    def answer(self, trip_id: str, obs: Observation, est: QueueEstimate, last_reason: str | None, params: AdvisorParams | None = None,
               told_mps: float | None = None) -> tuple[Observation, Advice | None]:  # fmt: skip
        """For the car's queue estimate: the observation with the queues in it, or "follow the car in front" while it
        stands in the next light's queue or closes in on a slower car, until it is over that light's line; at a fix
        where it closes in on a slower connected car, lifting off to that car's speed (:func:`advisory.advice.queue_words.ease_to_car_ahead`). The
        connected cars it holds up are kept for :meth:`check`."""
        nxt = obs.lights[0]
        self._behind[trip_id] = est.behind
        self._seen[trip_id] = (obs, est)
        if est.stop_behind:  # the cars ahead take the last of the green: following them would take it into the red
            self._queued.pop(trip_id, None)  # (the advisor plans its stop: the line is closed to it until the red's end)
        elif est.in_queue or est.follow_mps is not None:  # in the queue of the next light, or closing in on a slower car:
            self._queued[trip_id] = nxt.intersection_id  # it follows the car in front until over that light's line
        elif self._queued.get(trip_id) not in (None, nxt.intersection_id):
            del self._queued[trip_id]
        if trip_id in self._queued:
            self.held += 1
            countdown = nxt.seconds_to_green() if nxt.red_now else nxt.seconds_to_red()
            follow = Advice("none", "queue", light_red=nxt.red_now, seconds_to_change_s=countdown, message=QUEUE_MESSAGE, speak=last_reason != "queue",
                            light_id=nxt.intersection_id)  # fmt: skip
            if est.in_queue or est.follow_mps is None:
                self.tell(trip_id, follow)
                return obs, follow
            params = params or AdvisorParams()
            eased = ease_to_car_ahead(follow, obs.speed_mps, est.follow_mps, params)
            if eased is not follow and last_reason == "queue" and told_mps is not None:  # said already: again where the speed moved
                eased = replace(eased, speak=abs(told_mps - eased.target_speed_mps) >= params.speak_change_mps)
            self.tell(trip_id, eased)
            return obs, eased
        return apply(obs, est), None

    def tell(self, trip_id: str, advice: Advice) -> None:
        """The trip's fix (the last :meth:`see` noted) was answered ``advice``: its probe carries the motion it asks
        (:func:`advisory.advice.queue.plan_of`, :meth:`Lane.tell`), which the cars behind it follow in
        :func:`advisory.advice.queue.behind_s`; at an advisor's silence (``too_close``, ...) the motion of the advice
        before it, which the driver goes on with."""
        fix = self._fix.get(trip_id)
        if fix is None:
            return
        lane, t_unix_s, limit_mps = fix
        if advice.action == "none" and advice.reason in SILENT:
            plan = self._plan.get(trip_id, (math.nan, 0))
        else:
            plan = self._plan[trip_id] = plan_of(advice, limit_mps)
        lane.tell(trip_id, t_unix_s, plan)

    def lane(self, corridor: str) -> Lane:
        """The corridor's probes, indexed (:class:`Lane`; indexed again when the shared board replaced them)."""
        lane = self._lanes.get(corridor)
        if lane is None:
            lane = self._lanes[corridor] = Lane(self._cars.setdefault(corridor, {}))
        else:
            lane.fresh()
        return lane

    def estimate(self, lane: Lane, here_m: float, t_unix_s: float, obs: Observation, red_elapsed_s: float | None,
                 view_m: float = math.inf) -> QueueEstimate:  # fmt: skip
        """:func:`advisory.advice.queue.estimate` over the cars that can change it, the same answer as over every car of
        the corridor, each where it is at the fix (``tests/server/test_queue_index.py``): the cars ahead up to the
        farthest light of ``obs`` plus what one following them across it keeps behind them (a jam spacing and a
        headway: :func:`~advisory.advice.queue.behind_s`), or up to the time gap a car ahead sets the pace within,
        whichever is farther; then, for the followers, the cars behind that can reach the next line within the window
        :func:`~advisory.advice.queue.followers` counts them in (this car's own normal drive to it or the instant the
        queue ahead lets it cross, whichever is later, plus ``follow_gap_s``): none farther than that window at the
        faster of the limit and the fastest car (a normal drive is never faster); the connected ones behind the route's
        start (``view_m`` behind this car) expected from the flow."""
        m = self.model
        far_m = max(light.distance_m for light in obs.lights) + m.jam_spacing_m + m.headway_s * lane.top_mps
        reach_m = max(far_m, obs.speed_mps * m.follow_gap_s + m.jam_spacing_m)
        near = lane.near(here_m, t_unix_s, 0.0, reach_m)
        ahead = near.where(near.ahead_m > 0.0)
        est = estimate(obs, ahead, m, self.arrivals_vps, self.connected_share, red_elapsed_s, self.past_red(obs, t_unix_s))
        line_m, limit_mps = obs.lights[0].distance_m, max(obs.speed_limit_mps, 1.0)
        mine_s = normal_drive_s(line_m, obs.speed_mps, limit_mps, m.drive_accel_mps2)
        window_m = (max(est.free_at_s[0], mine_s) + m.follow_gap_s) * max(lane.top_mps, limit_mps) * (1.0 + 1e-9) + 1e-6
        near = lane.near(here_m, t_unix_s, line_m - window_m, 0.0)
        behind = near.where(near.ahead_m < 0.0)
        n_behind, held = followers_held_up(obs, behind, est.free_at_s[0], m, self.arrivals_vps, self.connected_share, view_m)
        return replace(est, followers=n_behind, behind=held)

    def check(self, obs: Observation, advice: Advice, params: AdvisorParams, trip_id: str | None = None, last: dict | None = None) -> Advice:
        """The advisor's advice (planned on ``obs``, the lights as the queue holds them), or:

        * the glide that meets the queue's tail and follows it through where the advisor asks a stop that only the
          queue asks for (:func:`advisory.advice.queue_words.tail_glide`; spoken when the trip's ``last`` answer was not it);
        * "drive normally" where it gives up green time that a normal drive, behind the queue, uses, priced with the
          followers it holds up (:func:`advisory.advice.behind.gives_up_green`), the connected ones where the trip's last
          fix (:meth:`see`) found them;
        * "drive normally" at the line (the advisor silent there, ``too_close``) where the plan the driver follows was
          made for the queue and the light itself is green (:func:`advisory.advice.queue_words.seen_at_line`);

        its countdown, whichever it is, the light's own, and the queue said where the queue holds the car
        (:func:`advisory.advice.queue_words.said_truly`): the advisor sees the queue as a red."""
        real, est = self._seen.get(trip_id, (obs, None)) if trip_id is not None else (obs, None)
        out = self._checked(obs, real, est, advice, params, trip_id, last)
        if trip_id is not None:
            self.tell(trip_id, out)
        if trip_id is not None and not (out.action == "none" and out.reason in SILENT):  # the plan the driver follows now
            self._for_queue[trip_id] = out.reason == "queue" or (bool(obs.lights) and obs.lights[0] != real.lights[0])
        return out

    def _checked(self, obs: Observation, real: Observation, est: QueueEstimate | None, advice: Advice, params: AdvisorParams,
                 trip_id: str | None, last: dict | None) -> Advice:  # fmt: skip
        """:meth:`check`'s answer (``real``: the lights as they are, ``est``: the trip's queue estimate at this fix)."""
        if est is not None and (glide := tail_glide(real, est, advice, params, self.model)) is not None:
            was = last is not None and last.get("reason") == "queue" and last.get("target_speed_mps") is not None
            if was and abs(last["target_speed_mps"] - glide.target_speed_mps) < params.speak_change_mps:
                glide = replace(glide, speak=False)
            return glide
        behind = self._behind.get(trip_id, ()) if trip_id is not None else ()
        for_queue = self._for_queue.get(trip_id, False) if trip_id is not None else False
        at_line = bool(real.lights) and seen_at_line(real.lights[0], advice, for_queue, obs.speed_mps, obs.speed_limit_mps, params, self.model)
        if at_line or gives_up_green(obs, advice, params, model=self.model, behind=behind, queue=est, real=real):
            return _normally(advice, params, real, last)
        paced = paced_for_behind(lambda plan: self.lost_behind(real, plan, params, trip_id, est), obs, advice, params)
        if paced is None:
            return _normally(advice, params, real, last)
        if paced is not advice:  # spoken once: again only where its speed moves by speak_change_mps (not as the car reaches it)
            told = None if last is None else last.get("target_speed_mps")
            said = last is not None and last.get("reason") == PACED_REASON and told is not None
            paced = replace(paced, speak=not (said and abs(told - paced.target_speed_mps) < params.speak_change_mps))
        return said_truly(paced, real.lights, obs.lights, params.units)

    def lost_behind(self, obs: Observation, advice: Advice, params: AdvisorParams, trip_id: str | None, est: QueueEstimate | None = None) -> float:
        """The wait [s] that ``advice`` makes the cars behind lose at the light the car passed last and the next one
        (:func:`advisory.advice.behind.cut_behind`, the next one behind the queue in front, ``est``), as its last fix
        found them (:meth:`note_behind`), with the connected ones not yet on the route expected from the flow."""
        noted = self._passed.get(trip_id, ()) if trip_id is not None else ()
        view_m = self._view_m.get(trip_id, math.inf) if trip_id is not None else math.inf
        return sum(cut_behind(light, obs, advice, params, behind, self.arrivals_vps, self.connected_share, past, self.model, est, view_m)
                   for light, behind, past in noted)  # fmt: skip

    @staticmethod
    def fresh(last_reason: str | None) -> bool:
        """The advisor plans afresh (no memory of a plan) on the first fix after the car was told to follow."""
        return last_reason == "queue"

    def forget(self, corridor: str, trip_id: str) -> None:
        """The trip has ended: it is no probe any more (on every worker, with the shared board)."""
        self.lane(corridor).drop(trip_id)
        self._queued.pop(trip_id, None)
        self._behind.pop(trip_id, None)
        self._seen.pop(trip_id, None)
        self._for_queue.pop(trip_id, None)
        self._passed.pop(trip_id, None)
        self._view_m.pop(trip_id, None)
        self._fix.pop(trip_id, None)
        self._plan.pop(trip_id, None)

    def state(self) -> str:
        """Where the probes come from (``/health``): ``local`` (this process, which serves every trip), ``shared``
        (every worker's, through Redis) or ``own_trips_only`` (Redis unreachable: this worker's)."""
        return "local" if self.shared is None else self.shared.state()
