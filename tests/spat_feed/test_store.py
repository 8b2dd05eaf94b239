"""The shared SPaT store's time rules, the per-intersection simulator and the recorded-log player (pure, in process)."""

from __future__ import annotations

import json
import logging
import math

import pytest

from spat_feed.road.corridors import load_corridor, paper_corridor, preset_names
from spat_feed.timing.messages import UNKNOWN_MAX_END_S, plan_from_movement, to_unix_s
from spat_feed.prediction.observe import light_view
from spat_feed.transport.player import JsonlRecorder, LogPlayer, read_spat_log
from spat_feed.transport.recorded import RecordedLogError
from spat_feed.transport.simulator import IntersectionSimulator, shared_scenario, simulated_plans
from spat_feed.transport.store import SpatStore, TimeRules

from tests.conftest import recorded_spat_slice

T0 = 1_790_000_000.0


class Clock:
    def __init__(self, t: float) -> None:
        self.t = t

    def __call__(self) -> float:
        return self.t


def states(t: float, corridor_names=("paper_s200",)):
    return IntersectionSimulator([load_corridor(n) for n in corridor_names]).states_at(t)


def test_rejects_duplicate_out_of_order_and_clock_ahead_and_counts_them():
    clock = Clock(T0)
    store = SpatStore(TimeRules(stale_after_s=2.0, clock_tolerance_s=1.0), clock)
    first = states(T0)[0]
    assert store.offer(first) == "ok"
    assert store.offer(first) == "duplicate"
    assert store.offer(states(T0 - 0.5)[0]) == "out_of_order"
    assert store.offer(states(T0 + 1.5)[0]) == "clock_ahead"  # dated 1.5 s after its arrival
    assert store.offer(states(T0 + 0.8)[0]) == "ok"  # within the tolerance
    assert store.stats[1].messages == 2
    assert dict(store.stats[1].rejected) == {"duplicate": 1, "out_of_order": 1, "clock_ahead": 1}
    assert SpatStore(only=[2], clock=clock).offer(first) == "unknown_intersection"


def test_stale_after_the_stale_age_on_the_controllers_timestamp():
    clock = Clock(T0)
    store = SpatStore(TimeRules(stale_after_s=2.0), clock)
    assert store.status(1) == "no_spat"
    store.offer(states(T0)[0])
    clock.t = T0 + 1.9
    assert store.reading(1).fresh and store.status(1) == "ok"
    clock.t = T0 + 2.1
    r = store.reading(1)
    assert not r.fresh and r.status == "stale" and r.age_s == pytest.approx(2.1)
    # old data arriving now is as old as its timestamp says
    store2 = SpatStore(TimeRules(stale_after_s=2.0, clock_tolerance_s=5.0), clock)
    store2.offer(states(clock.t - 3.0)[0])
    assert store2.status(1) == "stale"


def test_a_controller_clock_off_ours_is_clock_skew_never_fresh():
    clock = Clock(T0)
    store = SpatStore(TimeRules(stale_after_s=2.0, clock_tolerance_s=1.0, skew_window_s=30.0), clock)
    for k in range(10):  # the controller's clock runs 1.5 s behind ours: every state arrives 1.5 s "late"
        clock.t = T0 + k
        assert store.offer(states(T0 + k - 1.5)[0]) == "ok"
    r = store.reading(1)
    assert r.status == "clock_skew" and not r.fresh and r.clock_offset_s == pytest.approx(1.5)
    # a clock that is right again, for a whole window, is trusted again
    for k in range(10, 45):
        clock.t = T0 + k
        store.offer(states(T0 + k)[0])
    assert store.status(1) == "ok"
    # a controller whose clock runs ahead: every state rejected, the intersection reports the skew
    ahead = SpatStore(TimeRules(clock_tolerance_s=1.0), clock)
    assert ahead.offer(states(clock.t + 3.0)[0]) == "clock_ahead"
    assert ahead.status(1) == "clock_skew"


def test_network_delay_is_not_skew():
    clock = Clock(T0)
    store = SpatStore(TimeRules(clock_tolerance_s=1.0), clock)
    for k in range(30):  # delays of 0.05-1.6 s: the floor (0.05 s) is the clock offset
        clock.t = T0 + k + (0.05 if k % 3 == 0 else 1.6)
        store.offer(states(T0 + k)[0])
    assert store.reading(1).clock_offset_s == pytest.approx(0.05)


def test_sweep_warns_once_per_outage(caplog):
    clock = Clock(T0)
    store = SpatStore(TimeRules(stale_after_s=2.0), clock)
    store.offer(states(T0)[0])
    with caplog.at_level(logging.INFO, logger="spat_feed.transport.store"):
        clock.t = T0 + 5
        assert store.sweep([1, 9]) == {1: "stale", 9: "no_spat"}
        store.sweep([1, 9])
        clock.t = T0 + 6
        store.offer(states(T0 + 6)[0])
        store.sweep([1])
    warnings = [r for r in caplog.records if r.levelno == logging.WARNING]
    assert len(warnings) == 2 and "intersection 1: stale" in warnings[0].getMessage()
    assert any("fresh again" in r.getMessage() for r in caplog.records if r.levelno == logging.INFO)


def test_simulator_publishes_each_intersection_once_with_the_shared_plans():
    corridors = [load_corridor(n) for n in preset_names()]
    sim = IntersectionSimulator(corridors)
    out = sim.states_at(T0)
    assert sorted(s.id for s in out) == [1, 2, 7001, 7002]  # the paper corridors share their lights 1 and 2
    # what a trip entering now sees is what the simulator publishes
    sc = shared_scenario(paper_corridor(400.0), T0)
    plans = simulated_plans(corridors, T0)
    assert sc.fixed_plans()[(2, 2)] == plans[(2, 2)]
    # the message changes only in its timestamp between state changes (rendered once, reused)
    a, b = sim.states_at(T0 + 0.1), sim.states_at(T0 + 0.2)
    assert [x.states for x in a] == [x.states for x in b] and a[0].timestamp != b[0].timestamp
    assert IntersectionSimulator(corridors).states_at(T0 + 0.2)[0].model_dump() == b[0].model_dump()


def test_one_intersection_id_with_two_plans_is_refused(tmp_path):
    from importlib import resources

    from spat_feed.road.corridors import load_corridor_dir

    presets = resources.files("spat_feed") / "presets"
    corridor = (presets / "oakland_7th_westbound.json").read_text().replace('"id": 7001', '"id": 1').replace('"id": 7002', '"id": 2')
    plan = (presets / "plans" / "oakland_7th_westbound_plausible.json").read_text().replace('"intersection_id": 7001', '"intersection_id": 1')
    (tmp_path / "c.json").write_text(corridor)
    (tmp_path / "p.json").write_text(plan.replace('"intersection_id": 7002', '"intersection_id": 2'))
    oakland_as_1_2 = load_corridor_dir(tmp_path)["oakland_7th_westbound"]
    with pytest.raises(ValueError, match="one intersection id is one controller"):
        IntersectionSimulator([paper_corridor(200.0), oakland_as_1_2])


def test_log_player_maps_the_recorded_clock_onto_now(tmp_path):
    log = read_spat_log(recorded_spat_slice(tmp_path))
    t_first = to_unix_s(log[0].timestamp)
    player = LogPlayer(log, start_unix_s=T0, speedup=2.0)
    assert player.due(T0 - 0.01) == []
    first = player.due(T0)
    assert len(first) == 1 and to_unix_s(first[0].timestamp) == pytest.approx(T0, abs=1e-3)
    rec = log[10]
    due = player.due(T0 + (to_unix_s(rec.timestamp) - t_first) / 2.0)
    played = due[-1]
    assert to_unix_s(played.timestamp) == pytest.approx(T0 + (to_unix_s(rec.timestamp) - t_first) / 2.0, abs=1e-3)
    for m_rec, m_play in zip(rec.states, played.states):
        assert m_rec.signal_group == m_play.signal_group and m_rec.state_time_speed[0].event_state == m_play.state_time_speed[0].event_state
        tr, tp = m_rec.state_time_speed[0].timing, m_play.state_time_speed[0].timing
        rel_min = to_unix_s(tr.min_end_time) - to_unix_s(rec.timestamp)
        assert to_unix_s(tp.min_end_time) - to_unix_s(played.timestamp) == pytest.approx(rel_min / 2.0, abs=1e-3)
        rel_max = to_unix_s(tr.max_end_time) - to_unix_s(rec.timestamp)
        expect = rel_max if rel_max >= UNKNOWN_MAX_END_S else rel_max / 2.0  # "unknown" stays unknown at any speed
        assert to_unix_s(tp.max_end_time) - to_unix_s(played.timestamp) == pytest.approx(expect, abs=1e-3)
    # looping: the second pass plays one recorded second after the end, timestamps still increasing
    looping = LogPlayer(log, start_unix_s=T0, speedup=10.0, loop=True)
    span = (to_unix_s(log[-1].timestamp) - t_first + 1.0) / 10.0
    got = looping.due(T0 + 2.5 * span)
    assert looping.passes == 2 and len(got) > 2 * len(log)
    stamps = [to_unix_s(s.timestamp) for s in got]
    assert stamps == sorted(stamps)
    once = LogPlayer(log, start_unix_s=T0, speedup=10.0)
    once.due(T0 + 10 * span)
    assert once.done


def test_jsonl_log_round_trip_and_errors_name_the_line(tmp_path):
    path = tmp_path / "rec.jsonl.gz"
    rec = JsonlRecorder(path)
    for k in range(5):
        for s in states(T0 + k):
            rec(s)
    rec.close()
    back = read_spat_log(path)
    assert [s.model_dump() for s in back] == [s.model_dump() for k in range(5) for s in states(T0 + k)]
    bad = tmp_path / "bad.jsonl"
    bad.write_text(json.dumps(states(T0)[0].model_dump(mode="json", by_alias=True)) + "\n{not json\n")
    with pytest.raises(RecordedLogError, match=r"bad.jsonl, line 2"):
        read_spat_log(bad)
    with pytest.raises(RecordedLogError, match="unknown log format"):
        (tmp_path / "x.txt").write_text("")
        read_spat_log(tmp_path / "x.txt")


def test_simulator_and_its_recording_give_identical_trip_views(tmp_path):
    """The same timing from the simulator and from a log of it: every light's view is the same at every instant."""
    corridor = load_corridor("paper_s400")
    sim = IntersectionSimulator([corridor], n_events=3)
    path = tmp_path / "sim.jsonl"
    rec = JsonlRecorder(path)
    for k in range(0, 1300):  # 130 s at 10 Hz
        for s in sim.states_at(T0 + 0.1 * k):
            rec(s)
    rec.close()
    clock = Clock(T0)
    live, played = SpatStore(clock=clock), SpatStore(clock=clock)
    player = LogPlayer(read_spat_log(path), start_unix_s=T0)
    for k in range(0, 1300):
        clock.t = T0 + 0.1 * k
        live.offer_many(sim.states_at(clock.t))
        played.offer_many(player.due(clock.t))
        if k % 7:
            continue
        for ix in corridor.intersections:
            sg = ix.signal_groups[0].id
            (pa, ra), (pb, rb) = live.plan(ix.id, sg), played.plan(ix.id, sg)
            assert pa == pb and ra.fresh and rb.fresh
            view_a = light_view(ix, _reading(pa, ra), 50.0, clock.t)
            view_b = light_view(ix, _reading(pb, rb), 50.0, clock.t)
            assert view_a == view_b and view_a.red_windows_s


def _reading(plan, r):
    from spat_feed.prediction.observe import PlanReading

    return PlanReading(plan, fresh=r.fresh, age_s=r.age_s)


def test_the_store_learns_each_group_and_hands_it_to_the_observation(tmp_path):
    """What a group has been seen to do travels with its reading (PlanReading.cycle), as a receiver fed the
    same messages directly learns it (durations, how soon after a resumed minEndTime phases end, and the changes of
    other groups its phases follow); the controller's clock offset comes along (feed minus ours)."""
    from spat_feed.timing.messages import plan_from_movement
    from spat_feed.prediction.history import IntersectionHistory

    log = read_spat_log(recorded_spat_slice(tmp_path, 30000))
    clock = Clock(T0)
    store = SpatStore(TimeRules(clock_tolerance_s=1.0), clock)
    direct = IntersectionHistory()
    player = LogPlayer(log, start_unix_s=T0, speedup=1.0)
    linked = 0
    for played_at, state in player:
        clock.t = played_at + 0.6  # every state arrives 0.6 s after its timestamp: a controller 0.6 s behind
        assert store.offer(state) == "ok"
        t = to_unix_s(state.timestamp)
        direct.record(t, {m.signal_group: plan_from_movement(m, t) for m in reversed(state.states)})  # a group's first movement
        for g in (1, 3, 4, 5):
            assert store.plan_reading(648, g).cycle == direct.stats(g)
            linked += direct.stats(g).linked_end_unix_s is not None
    reading = store.plan_reading(648, 1)
    assert reading.fresh and reading.plan is not None
    assert reading.cycle.cycle_s is not None and len(reading.cycle.durations_s) >= 2 and linked > 0
    assert reading.clock_offset_s == pytest.approx(-0.6)
    assert store.plan_reading(648, 99).plan is None and store.plan_reading(9, 1).fresh is False


# per signal group: J2735 movements update independently -----------------------------------------------------------


@pytest.fixture(scope="module")
def k648_2019_05_01(recorded_snapshots):
    """The whole 2019-05-01 recording of K648 (its snapshots 4- omit group 3; 1,384 carry 9 of its 10 groups)."""
    from tests.conftest import SHARED_DATA

    path = SHARED_DATA / "spat" / "antwerp-2019-05-01.csv.gz"
    if not path.exists():
        pytest.skip(f"{path} not present")
    return recorded_snapshots(path)


def _offered(snaps, lag_s: float):
    """A store (stale after 2 s) offered each snapshot ``lag_s`` after its stamp, all accepted: (store, clock, stamps)."""
    stamps = [to_unix_s(s.timestamp) for s in snaps]
    clock = Clock(stamps[0])
    store = SpatStore(TimeRules(stale_after_s=2.0), clock)
    for snap, stamp in zip(snaps, stamps):
        clock.t = stamp + lag_s
        assert store.offer(snap) == "ok"
    return store, clock, stamps


def test_a_partial_message_keeps_the_omitted_groups_plan_with_its_own_age(k648_2019_05_01):
    snaps = k648_2019_05_01[:5]
    assert snaps[3].movement(3) is not None and snaps[4].movement(3) is None  # group 3 last heard in snapshot 3
    store, clock, stamps = _offered(snaps, 0.2)
    clock.t = stamps[4] + 0.5
    plan, reading = store.plan(648, 3)
    assert plan == plan_from_movement(snaps[3].movement(3), stamps[3])  # the omitted group's latest plan, held
    assert reading.fresh and reading.age_s == pytest.approx(clock.t - stamps[3]) and reading.timestamp_unix_s == stamps[3]
    seen = store.plan_reading(648, 3)
    assert seen.plan == plan and seen.fresh and seen.age_s == pytest.approx(clock.t - stamps[3])
    assert store.plan_reading(648, 1).age_s == pytest.approx(0.5)  # the groups the message carried: its own age
    assert store.reading(648).intersection.movement(3) == snaps[3].movement(3)  # the intersection: every group held


def test_an_omitted_group_goes_stale_alone(k648_2019_05_01):
    snaps = k648_2019_05_01[:8]
    store, clock, stamps = _offered(snaps, 0.1)
    plan, reading = store.plan(648, 3)  # not heard for 4.1 s, while the others are heard every second
    assert plan is not None and not reading.fresh and reading.status == "stale" and reading.age_s == pytest.approx(clock.t - stamps[3])
    assert not store.plan_reading(648, 3).fresh and store.status(648, 3) == "stale"
    assert store.plan_reading(648, 1).fresh and store.status(648, 1) == "ok" and store.status(648) == "ok"
    assert store.reading(648).intersection.movement(3) is None  # a fresh intersection does not serve a stale group


def test_time_rules_per_group(k648_2019_05_01):
    """A message is judged group by group: one with a newer stamp is not out of order for the groups it omits, and
    an older one that carries a group newer news of it than the store holds is that group's latest."""
    full, partial = k648_2019_05_01[3], k648_2019_05_01[4]  # partial omits group 3
    t_full, t_partial = to_unix_s(full.timestamp), to_unix_s(partial.timestamp)
    clock = Clock(t_partial + 0.2)
    store = SpatStore(TimeRules(stale_after_s=2.0, clock_tolerance_s=2.0), clock)
    assert store.offer(partial) == "ok"
    assert store.offer(full) == "ok"  # late, but group 3's only news
    assert store.plan(648, 3)[0] == plan_from_movement(full.movement(3), t_full)
    assert store.plan(648, 1)[0] == plan_from_movement(partial.movement(1), t_partial)  # not overwritten by the older
    assert store.offer(full) == "duplicate" and store.offer(partial) == "duplicate"
    assert store.offer(k648_2019_05_01[2]) == "out_of_order"  # older than every group it carries
    assert store.reading(648).timestamp_unix_s == t_partial
    assert dict(store.stats[648].rejected) == {"duplicate": 2, "out_of_order": 1}


def test_a_real_recording_through_the_store_keeps_every_steady_group_planned(k648_2019_05_01):
    """2019-05-01: every group the controller publishes at least every 2 s has a fresh plan at every second, though
    1,384 messages carry 9 of its 10 groups and 150 one (the store kept only the last message: 1-3 % of seconds
    without a plan)."""
    snaps = k648_2019_05_01
    stamps = [to_unix_s(s.timestamp) for s in snaps]
    heard: dict[int, list[float]] = {}
    for snap, stamp in zip(snaps, stamps):
        for m in snap.states:
            heard.setdefault(m.signal_group, []).append(stamp)
    steady = sorted(g for g, ts in heard.items() if max(b - a for a, b in zip(ts, ts[1:])) <= 2.0)
    assert steady and sum(len(s.states) < len(heard) for s in snaps) > 1000  # (1, 4, 6; partial messages)
    clock = Clock(stamps[0])
    store = SpatStore(TimeRules(stale_after_s=2.0), clock)
    missing: dict[int, int] = {}
    i, t = 0, math.ceil(stamps[0])
    while t <= stamps[-1]:
        while i < len(snaps) and stamps[i] <= t:
            clock.t = stamps[i]
            assert store.offer(snaps[i]) == "ok"
            i += 1
        clock.t = t
        for g in steady:
            r = store.plan_reading(648, g)
            if r.plan is None or not r.fresh:
                missing[g] = missing.get(g, 0) + 1
        t += 1
    assert missing == {}


def _covered(true_windows, served_windows, tol=0.1):
    """Every true red instant lies in some served window (windows relative to the same instant), up to ``tol`` (the
    least network delay: the offset's floor cannot tell it from the clock's)."""
    for a, b in true_windows:
        pieces = sorted((max(a, c), min(b, d)) for c, d in served_windows if min(b, d) > max(a, c))
        t = a
        for c, d in pieces:
            if c > t + tol:
                return False
            t = max(t, d)
        if t < min(b, 1e9) - tol:
            return False
    return True


@pytest.mark.parametrize("step_s", [1.5, -1.5])
def test_a_controller_clock_that_moves_1p5_s_is_flagged_within_5_s_never_shifted_into_a_red(step_s):
    """Issue 30: a clock that steps 1.5 s behind (or ahead) after 40 s right: clock_skew within 5 s, whatever the 30 s
    window still holds; until then every fresh reading's red windows cover the light's true reds (10 Hz)."""
    corridor = load_corridor("paper_s200")
    ix, sg = corridor.intersections[0], corridor.intersections[0].signal_groups[0].id
    clock = Clock(T0)
    store = SpatStore(TimeRules(stale_after_s=2.0, clock_tolerance_s=1.0, skew_window_s=30.0), clock)
    sim = IntersectionSimulator([corridor])
    flagged_at, fresh_checked, held_behind = None, 0, 0.0
    for k in range(700):  # 70 s at 10 Hz, each message 20-80 ms on the way; the clock moves at 40 s
        t = T0 + k / 10
        behind = step_s if t >= T0 + 40.0 else 0.0
        clock.t = t + 0.02 + 0.06 * ((k * 7) % 10) / 10
        if store.offer(sim.states_at(t - behind)[0]) == "ok":  # (a clock stepping back: out_of_order for 1.5 s)
            held_behind = behind
        reading = store.plan_reading(1, sg)
        if t >= T0 + 40.0 and flagged_at is None and store.status(1) == "clock_skew":
            flagged_at = t - (T0 + 40.0)
        if reading.fresh:
            served = light_view(ix, reading, 0.0, clock.t)
            truth = light_view(ix, type(reading)(reading.plan, clock_offset_s=-held_behind), 0.0, clock.t)  # read on its own clock
            assert _covered(truth.red_windows_s, served.red_windows_s), (k, truth.red_windows_s, served.red_windows_s)
            fresh_checked += 1
    assert flagged_at is not None and flagged_at <= 5.0, flagged_at
    assert fresh_checked >= 400
    assert store.status(1) == "clock_skew" and not store.plan_reading(1, sg).fresh
    health = store.reading(1)
    assert health.status == "clock_skew" and health.clock_offset_s == pytest.approx(step_s, abs=0.1)


def test_spat_texts_over_the_limit_are_dropped_unparsed_and_counted(tmp_path):
    """Issue 30: log lines (JSON lines and CSV) and feed texts over MAX_SPAT_BYTES are skipped unread, ``too_large``."""
    from spat_feed.transport.client import SpatClient
    from spat_feed.transport.store import MAX_SPAT_BYTES

    good = states(T0)[0].model_dump_json(by_alias=True)
    huge = "{" + " " * (3 * MAX_SPAT_BYTES) + "}"
    path = tmp_path / "log.jsonl"
    path.write_text(f"{good}\n{huge}\n{states(T0 + 1)[0].model_dump_json(by_alias=True)}\n")
    told: list[str] = []
    assert len(read_spat_log(path, told.append)) == 2 and len(told) == 1 and "line 2" in told[0]
    csv_path = tmp_path / "log.csv"
    csv_path.write_text("generated_utc,intersection,signal_group,phase,min_end_utc,max_end_utc\n"
                        "2019-05-01T16:04:25.609Z,K648,1,6,2019-05-01T16:04:38.009Z,2019-05-01T16:07:13.009Z\n"
                        f"2019-05-01T16:04:26.609Z,K648,1,6,{'x' * (MAX_SPAT_BYTES + 5)},2019-05-01T16:07:13.009Z\n"
                        "2019-05-01T16:04:27.609Z,K648,1,6,2019-05-01T16:04:38.009Z,2019-05-01T16:07:13.009Z\n")  # fmt: skip
    told.clear()
    assert len(read_spat_log(csv_path, told.append)) == 2 and "line 3" in told[0]
    store = SpatStore(clock=Clock(T0))
    client = SpatClient("http://127.0.0.1:9", store=store)
    parsed = client.handle_text('{"timestamp": "2026-01-01T00:00:00Z", "intersections": [' + " " * MAX_SPAT_BYTES + "]}")
    assert not parsed.intersections and "too large" in parsed.errors[0]
    assert store.rejected["too_large"] == 1 and store.rejected["malformed"] == 0


def test_a_feed_websocket_message_over_the_limit_is_dropped_unread_and_counted():
    import asyncio

    from websockets.asyncio.server import serve

    from spat_feed.transport.client import SpatClient
    from spat_feed.transport.store import MAX_SPAT_BYTES

    async def main() -> SpatStore:
        async def handler(ws):
            await ws.send("x" * (MAX_SPAT_BYTES + 1))
            await asyncio.sleep(1.0)

        async with serve(handler, "127.0.0.1", 0) as server:
            port = server.sockets[0].getsockname()[1]
            store = SpatStore()
            async with SpatClient(f"ws://127.0.0.1:{port}/spat/stream", store=store, backoff_initial_s=5.0, backoff_max_s=5.0):
                for _ in range(100):
                    if store.rejected["too_large"]:
                        break
                    await asyncio.sleep(0.05)
        return store

    store = asyncio.run(main())
    assert store.rejected["too_large"] == 1 and store.rejected["malformed"] == 0


def forged_green(state, stamp_unix_s: float, green_s: float = 60.0):
    """``state`` rewritten as a forger would: stamped ``stamp_unix_s``, every signal group green for ``green_s``."""
    from spat_feed.timing.messages import IntersectionState, from_unix_s

    data = json.loads(state.model_dump_json(by_alias=True, exclude_none=True))
    data["timestamp"] = from_unix_s(stamp_unix_s).isoformat().replace("+00:00", "Z")
    end = from_unix_s(stamp_unix_s + green_s).isoformat().replace("+00:00", "Z")
    for m in data["states"]:
        m["stateTimeSpeed"] = [{"eventState": "protected-Movement-Allowed", "timing": {"minEndTime": end, "maxEndTime": end}}]
    return IntersectionState.model_validate(data)


def test_a_red_that_turns_green_before_its_published_minimum_is_implausible_never_served():
    """Issue 30: the forged message (stamped 0.95 s ahead, green for 60 s, while the controller's red holds): rejected
    ``implausible`` whatever credentials it came with; the red stays served. A green after the red's minimum is news."""
    from spat_feed.timing.plans import PhaseClass, phase_class, state_at

    corridor = load_corridor("paper_s200")
    sg = corridor.intersections[0].signal_groups[0].id
    sim, clock = IntersectionSimulator([corridor]), Clock(T0)
    t = next(T0 + k for k in range(200) if (lambda p, t: phase_class(state_at(p, t)) is PhaseClass.RED and p.changes[0].min_end_s > t + 5.0)(
        plan_from_movement(sim.states_at(T0 + k)[0].movement(sg), T0 + k), T0 + k))  # fmt: skip
    store = SpatStore(TimeRules(clock_tolerance_s=1.0), clock)
    clock.t = t + 0.05
    assert store.offer(sim.states_at(t)[0]) == "ok"
    red_ends = store.plan_reading(1, sg).plan.changes[0].min_end_s
    assert store.offer(forged_green(sim.states_at(t)[0], clock.t + 0.95)) == "implausible"
    reading = store.plan_reading(1, sg)
    assert reading.fresh and phase_class(state_at(reading.plan, clock.t + 1.0)) is PhaseClass.RED
    assert store.stats[1].rejected["implausible"] == 1 and store.stats[1].implausible_unix_s == clock.t
    clock.t = red_ends + 0.2  # the red's minimum passed: a green is what the controller may do
    assert store.offer(forged_green(sim.states_at(t)[0], red_ends + 0.1)) == "ok"


def test_a_controllers_own_messages_are_never_implausible_around_its_changes():
    """Every 0.1 s of two cycles, the simulator's own states (a green about to end, a red about to end, the instant
    of a change): all stored. A held green ending within ``PLAUSIBLE_SLACK_S`` once read as a red the new green
    contradicted (the live feed's messages were rejected in the half second before each red)."""
    corridor = load_corridor("paper_s200")
    sim, clock = IntersectionSimulator([corridor]), Clock(T0)
    store = SpatStore(TimeRules(clock_tolerance_s=1.0), clock)
    verdicts = []
    for k in range(1200):
        clock.t = T0 + 0.1 * k
        verdicts += [store.offer(s) for s in sim.states_at(clock.t)]
    assert set(verdicts) == {"ok"}


def test_a_published_queue_reaches_the_light_view_fresh_only():
    """A movement's J2735 ``queueLength`` (its ``maneuverAssistList``) reaches the advisor's view of that light (the
    longest of its connections), per signal group (another group publishes none), and not once the reading is stale."""
    clock = Clock(T0)
    store = SpatStore(TimeRules(stale_after_s=2.0), clock)
    ix = states(T0)[0]
    g = ix.states[0].signal_group
    assists = [{"connectionID": 1, "queueLength": 12}, {"connectionID": 2, "queueLength": 35}]
    queued = type(ix.states[0]).model_validate({**ix.states[0].model_dump(by_alias=True), "maneuverAssistList": assists})
    assert store.offer(ix.model_copy(update={"states": [queued, *ix.states[1:]]})) == "ok"
    assert store.plan_reading(ix.id, g).queue_m == 35.0
    assert all(store.plan_reading(ix.id, m.signal_group).queue_m is None for m in ix.states[1:])
    spec = paper_corridor(200.0).intersections[0]
    assert light_view(spec, store.plan_reading(ix.id, g), 0.0, T0).queue_m == 35.0
    clock.t = T0 + 3.0
    assert light_view(spec, store.plan_reading(ix.id, g), 0.0, T0 + 3.0).queue_m is None
