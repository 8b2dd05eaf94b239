"""The queue board's index (``server.queue.Lane``): a fix looks only at the cars that can change its estimate, with the
same advice as the plain loop over every car of the corridor (the board before the index, kept here as the reference)."""

from __future__ import annotations

import random
import types

import numpy as np
import pytest

from advisory.advice.views import LightView, Observation
from advisory.advice.queue import Probe, estimate
from server.queue import MAX_AGE_S, QueueBoard, probe_at
from server.storage.queue_store import Corridors, Noted

STOP_LINES_M = (200.0, 600.0, 1000.0, 1400.0)
LIMIT_MPS = 13.4


class LoopBoard(QueueBoard):
    """The board as it was: every car of the corridor a probe at every fix, the stale ones swept by a loop over them all
    (``QueueBoard.see`` before the index; what it does with the estimate is the board's own :meth:`QueueBoard.answer`)."""

    def __init__(self, arrivals_vph: float | None, connected_share: float) -> None:
        super().__init__(arrivals_vph=arrivals_vph, connected_share=connected_share)
        self.cars: dict[str, tuple[float, float, float]] = {}

    def see(self, corridor: str, trip_id: str, t_unix_s: float, obs: Observation, last_reason: str | None = None):
        cars = self.cars
        if not obs.on_route or obs.position_m is None or not obs.lights:
            cars.pop(trip_id, None)
            self._queued.pop(trip_id, None)
            return obs, None
        here = float(obs.position_m)
        cars[trip_id] = (t_unix_s, here, float(obs.speed_mps))
        for tid in [tid for tid, (t, _, _) in cars.items() if t_unix_s - t > MAX_AGE_S]:
            del cars[tid]
        probes = [probe_at(p, here, t_unix_s) for tid, p in cars.items() if tid != trip_id and p[1] != here]
        est = estimate(obs, probes, self.model, self.arrivals_vps, self.connected_share, self.red_elapsed(obs, t_unix_s), self.past_red(obs, t_unix_s))
        return self.answer(trip_id, obs, est, last_reason)

    def forget(self, corridor: str, trip_id: str) -> None:
        self.cars.pop(trip_id, None)
        self._queued.pop(trip_id, None)


def observation_at(station_m: float, speed_mps: float, t_unix_s: float, rng: random.Random, on_route: bool = True,
                   stop_lines_m: tuple[float, ...] = STOP_LINES_M, in_view: int | None = None) -> Observation:  # fmt: skip
    """A car at ``station_m`` on a corridor of fixed-time lights (60 s cycles, 30 s red, offsets 15 s apart), the next
    ``in_view`` ahead in view (default: one or two; cars beyond the farthest light in view count too: a slower one close
    ahead); now and then a light's SPaT publishes a queue length."""
    lights: list[LightView] = []
    in_view = in_view or rng.choice((1, 2))
    for k, stop_m in enumerate(stop_lines_m):
        if stop_m <= station_m or len(lights) == in_view:
            continue
        phase_s = (t_unix_s + 15.0 * k) % 60.0  # red during [0, 30) of the cycle
        start = -phase_s if phase_s < 30.0 else 60.0 - phase_s
        reds = tuple((start + 60.0 * j, start + 30.0 + 60.0 * j) for j in range(3))
        queue = rng.choice((None, None, None, 15.0, 40.0))
        lights.append(LightView(k + 1, stop_m - station_m, red_windows_s=reds, queue_m=queue))
    return Observation(speed_mps, LIMIT_MPS, tuple(lights), position_m=station_m, on_route=on_route)


@pytest.mark.parametrize(("arrivals_vph", "share", "shared"), [(None, 1.0, False), (600.0, 0.5, False), (None, 1.0, True)])
def test_the_index_gives_the_advice_of_the_loop_over_every_car(arrivals_vph, share, shared):
    """300 cars on four lights, 6,000 fixes in random order (fix times out of order across trips, cars standing, ties
    at whole metres, fixes off the route, trips ended; with ``shared`` the table replaced now and then as the shared
    board's sync does): every fix gets the same observation or "follow" advice from both boards, and the same connected
    cars behind it that a slower plan holds up."""
    rng = random.Random(7)
    tables = types.SimpleNamespace(cars=Corridors(c=Noted(newer=True)), red_since=Noted(newer=False), red_ended=Noted(newer=True)) if shared else None
    board = QueueBoard(arrivals_vph=arrivals_vph, connected_share=share, shared=tables)  # type: ignore[arg-type]
    loop = LoopBoard(arrivals_vph, share)
    where = {f"t{i}": rng.uniform(-150.0, 1500.0) for i in range(300)}
    last: dict[str, str | None] = {}
    clock = 1000.0
    held = behind = 0
    for n in range(6000):
        trip = rng.choice(list(where))
        clock += 0.01
        t = clock + rng.uniform(-2.0, 0.5)
        speed = rng.choice((0.0, 0.5, rng.uniform(0.0, 16.0), rng.uniform(8.0, 20.0)))
        where[trip] += speed * rng.uniform(0.0, 1.0)
        station = float(round(where[trip])) if rng.random() < 0.3 else where[trip]
        if where[trip] > 1500.0:
            where[trip] = rng.uniform(-150.0, 100.0)
        if rng.random() < 0.01:  # the trip ends
            board.forget("c", trip)
            loop.forget("c", trip)
            continue
        obs = observation_at(station, speed, t, rng, on_route=rng.random() > 0.03)
        got = board.see("c", trip, t, obs, last.get(trip))
        want = loop.see("c", trip, t, obs, last.get(trip))
        assert got == want, (n, trip)
        if obs.on_route and obs.lights:  # and the same connected cars held up, for the check of the advisor's plan
            assert board._behind[trip] == loop._behind[trip], (n, trip)
            behind += len(board._behind[trip])
        held += got[1] is not None
        last[trip] = got[1].reason if got[1] is not None else None
        if shared and n % 500 == 499:  # the sync: the table replaced by what Redis holds (here: what it held a while ago)
            snapshot = dict(loop.cars)
            for table in (tables.cars["c"], tables.red_since, tables.red_ended):
                table.take()
            tables.cars["c"].load(snapshot)
            tables.red_since.load(dict(loop._red_since))
            tables.red_ended.load(dict(loop._red_ended))
            loop.cars = dict(snapshot)
    assert board.held == loop.held == held > 100
    assert behind > 100
    assert dict(board._cars["c"]) == loop.cars
    lane = board.lane("c")
    assert lane.order == sorted(lane.entry.values()) and {tid for _, _, tid, _ in lane.order} == set(loop.cars)
    assert lane.rows[:3].tolist() == [[s for s, _, _, _ in lane.order], [loop.cars[tid][0] for _, _, tid, _ in lane.order], [v for _, _, _, v in lane.order]]
    # and each car's advised motion at its last fix (Lane.tell: here the service's own "follow" and lift-offs), NaN where none
    np.testing.assert_array_equal(lane.rows[3:].T, [lane._plan(tid) for _, _, tid, _ in lane.order])
    assert np.isfinite(lane.rows[3]).any()


def test_a_fix_looks_at_the_cars_near_it_only():
    """On a long corridor of evenly spread cars a fix's probes are the cars up to its farthest light ahead and the ones
    behind that can reach its next line in time, not every car."""
    board = QueueBoard()
    lane = board.lane("c")
    for i in range(2000):  # a car every 2.5 m over 5 km, at 10 m/s
        lane.put(f"t{i}", (100.0, 2.5 * i, 10.0))
    near = lane.near(2500.0, 100.5, -100.0, 300.0)  # raw stations in [-100 - 10 x MAX_AGE_S, 300] m (the bounds round outwards), each 5 m on
    assert [p.ahead_m for p in near] == [2.5 * k + 5.0 for k in range(-int((100.0 + 10.0 * MAX_AGE_S) / 2.5), 121) if k != 0]
    lane.expire(100.0 + MAX_AGE_S + 0.1, MAX_AGE_S)
    assert not lane.order and not board._cars["c"]
