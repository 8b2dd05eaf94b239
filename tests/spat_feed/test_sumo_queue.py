"""SUMO's stop-line queues as J2735 ``queueLength`` (``SumoSpatSource(queues=True)``), read by the store into the
advisor's view of each light (issue 28: the queue from ``queueLength`` when the SPaT carries it)."""

from __future__ import annotations

import pytest

libsumo = pytest.importorskip("libsumo")

from ecodrive.traffic.network import build_network, write_routes  # noqa: E402
from spat_feed.road.corridors import load_corridor  # noqa: E402
from spat_feed.timing.plans import PhaseClass, phase_class, state_at  # noqa: E402
from spat_feed.transport.store import SpatStore  # noqa: E402
from spat_feed.transport.sumo import JAM_GAP_M, SumoLight, SumoSpatSource  # noqa: E402


def test_sumo_queues_build_in_the_red_clear_in_the_green_and_reach_the_store(tmp_path):
    """paper_s400 at 600 veh/h, fixed time, 300 s: each second the source publishes each light's jam, and the store's
    reading of the light carries it. Against SUMO's own count of halting vehicles on the approach lane
    (``lane.getLastStepHaltingNumber``, independent of the source): no queue without halting cars, never more metres
    than the halting cars can fill (a 5 m car plus a gap of at most ``JAM_GAP_M`` each), and at every red's end a
    queue stands (~30 s of red at 600 veh/h: a few cars, Poisson arrivals); after 20 s of green it has gone."""
    net = build_network(load_corridor("paper_s400"), tmp_path)
    routes = write_routes(net, tmp_path / "q.rou.xml", 600.0, 300.0)
    libsumo.start(["sumo", "-n", str(net.net_file), "-r", str(routes), "--step-length", "0.5", "--seed", "3", "--no-step-log", "true", "--no-warnings", "true"])
    try:
        lights = [SumoLight(lt.intersection_id, lt.signal_group, lt.tls_id, lt.link_index, lt.name) for lt in net.lights]
        src = SumoSpatSource(libsumo, lights, net.t0_unix_s, queues=True)
        now = [net.t0_unix_s]
        store = SpatStore(clock=lambda: now[0])
        seen = []  # (t, light index, red now, seconds in its state, published queue [m], halting cars)
        while libsumo.simulation.getTime() < 300.0:
            libsumo.simulationStep()
            src.observe()
            t = libsumo.simulation.getTime()
            if abs(t - round(t)) > 1e-9:
                continue
            now[0] = net.t0_unix_s + t
            src.publish(store)
            for i, lt in enumerate(lights):
                (lane,) = {link[0] for link in libsumo.trafficlight.getControlledLinks(lt.tls_id)[lt.link_index]}
                reading = store.plan_reading(lt.intersection_id, lt.signal_group)
                red = phase_class(state_at(reading.plan, now[0] - 1e-3)) is PhaseClass.RED
                since = now[0] - src._seen[(lt.tls_id, lt.link_index)][1]
                seen.append((t, i, red, since, reading.queue_m, libsumo.lane.getLastStepHaltingNumber(lane)))
    finally:
        libsumo.close()
    assert all(q is not None for *_, q, _ in seen)
    for t, i, red, since, q, halting in seen:
        assert q <= halting * (5.0 + JAM_GAP_M) + 0.5, (t, i, q, halting)
        if halting == 0:
            assert q == 0.0, (t, i, q)
    red_ends = [(t, i, q) for (t, i, red, since, q, _), nxt in zip(seen, seen[len(net.lights):]) if red and not nxt[2] and nxt[1] == i and t > 60.0]
    assert len(red_ends) >= 6 and all(q >= 5.0 for _, _, q in red_ends), red_ends  # a car at least
    assert sum(q for _, _, q in red_ends) / len(red_ends) >= 15.0, red_ends  # a few on average
    assert all(q == 0.0 for _, _, red, since, q, _ in seen if not red and 20.0 <= since < 1e9), "a queue left after 20 s of green"
