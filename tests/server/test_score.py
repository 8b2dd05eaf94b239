"""The trip score compares like with like (issue 15, "Trip score"): each finding as a test.

Drives are made from the project's own drivers (the paper's regular driver, the closed-loop advisor
follower), sampled at 1 Hz like a phone, and sent through the service in-process (injected clock) or scored
with ``server.score.trip_score`` directly. Expected answers are independent: the drivers' exact energies,
the zone's length, a red phase the drive provably enters.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from fastapi.testclient import TestClient

from advisory.drivers.closed_loop import simulate
from advisory.drivers.regular import regular_driver
from advisory.physics.params import SPEED_LIMIT_MPS
from advisory.trajectory import Trajectory
from server.app import create_app
from server.config import Settings
from server.score import trip_score
from spat_feed.road.corridors import load_corridor
from spat_feed.prediction.observe import PlanReading
from spat_feed.transport.scenarios import advisory_scenario_at, make_scenario

E = 1_800_000_000.0  # the trips' zone entry [Unix s]
PAPER_TIMINGS = [f"{x}_{y}" for x in (-30, -15, 0, 15) for y in (-30, -15, 0, 15)]
KMH50 = 50 / 3.6


def fixes_of(traj: Trajectory, before_s: float = 8.0, after_s: float = 5.0, phase_s: float = 0.37, noise_mps: float = 0.0, seed: int = 0):
    """1 Hz fixes (t, v, station) of a zone trajectory (time 0 = entry), with ``before_s`` of cruising at the entry
    speed before the zone and ``after_s`` at the exit speed after it; optional white speed noise."""
    t = np.arange(-before_s + phase_s, traj.duration_s + after_s, 1.0)
    inside = np.clip(t, 0.0, traj.t_s[-1])
    v = traj.speed_at(inside)
    x = np.where(t < 0, traj.v_mps[0] * t, np.where(t > traj.t_s[-1], traj.x_m[-1] + traj.v_mps[-1] * (t - traj.t_s[-1]), traj.position_at(inside)))
    if noise_mps:
        v = np.maximum(v + np.random.default_rng(seed).normal(0.0, noise_mps, t.size), 0.0)
    return t, v, x


def settings(**kw) -> Settings:
    return Settings(corridors=("paper_s400",), default_corridor="paper_s400", tables=False, speech=False, max_fix_past_s=600.0,
                    rate_per_s=1000.0, rate_burst=1000.0, create_rate_per_client_per_s=1000.0, create_burst_per_client=1000.0, **kw)  # fmt: skip


def drive_through_service(client, now, corridor, t, v, x, timing="15_15", entry=E):
    created = client.post("/v1/trips", json={"corridor": corridor.name, "timing": timing, "entry_unix_s": entry}).json()
    auth = {"Authorization": f"Bearer {created['token']}"}
    out = []
    for tk, vk, xk in zip(t, v, x, strict=True):
        lat, lon = corridor.position(float(xk))
        now[0] = entry + tk + 0.05
        r = client.post(f"/v1/trips/{created['trip_id']}/fixes", json={"t_unix_s": entry + tk, "lat_deg": lat, "lon_deg": lon, "speed_mps": float(vk)}, headers=auth)
        assert r.status_code == 200, r.text
        out.append(r.json())
    return out, client.post(f"/v1/trips/{created['trip_id']}/end", headers=auth).json()


@pytest.fixture(scope="module")
def service():
    now = [E]
    with TestClient(create_app(settings(), clock=lambda: now[0])) as client:
        yield client, now


@pytest.mark.parametrize("timing", ["15_15", "-30_0", "0_0", "-30_-30"])
def test_entering_at_50_kmh_and_following_the_advice_is_not_scored_a_loss(service, timing):
    """Finding: a driver entering at 50 km/h who followed the advice was told energy -177 % (the regular driver
    always entered at 55 mph). Now the regular driver enters as fast as the car: following the advice saves.

    Tolerance: where the exact model gives the follower a material saving (> 1 %), the service's cost saving is
    at least 0 and within 3 points of the exact one (1 Hz fixes round off braking peaks; measured 1.6-2.2
    points under); on the green wave (-30_-30), where follower and regular driver differ only in how fast
    they accelerate (exact +0.1 %), within 1 % either way (measured +0.2 %)."""
    client, now = service
    corridor = load_corridor("paper_s400")
    sc = replace(advisory_scenario_at(make_scenario(corridor, timing, E), E), initial_speed_mps=KMH50)
    follower = simulate(sc).trajectory
    from advisory.evaluation.endstate import score_in_end_state
    from advisory.physics.params import model_params

    p = model_params("paper_54kwh")
    exact = 1 - score_in_end_state(follower, p, SPEED_LIMIT_MPS).cost_usd / score_in_end_state(regular_driver(sc), p, SPEED_LIMIT_MPS).cost_usd
    _, score = drive_through_service(client, now, corridor, *fixes_of(follower), timing=timing)
    assert score["complete"] and score["entry_speed_mps"] == pytest.approx(KMH50, abs=0.5)  # interpolated between 1 Hz fixes
    assert score["regular"]["distance_m"] == pytest.approx(600, abs=3) and score["driven"]["distance_m"] == pytest.approx(600, abs=6)
    got = score["savings_frac"]["cost"]
    if exact > 0.01:
        assert got >= 0 and got == pytest.approx(exact, abs=0.03), (got, exact)
    else:
        assert abs(got) <= 0.01, (got, exact)


def test_the_regular_drivers_own_noisy_drive_scores_about_zero():
    """Finding: the regular driver's drive with 0.2 m/s of GPS speed noise scored energy -11 %, wear -21 %.

    Tolerance, over the paper's 16 timings x 3 noise draws (1 Hz, white 0.2 m/s): the mean of each saving
    within ±1 % and every single drive within ±4 %. What is left is kinetic-energy churn of the ~0.1 m/s of
    noise that the 1 s smoothing leaves, charged at the drivetrain and regen efficiencies, and the noise of
    the entry speed; it weighs most on the green wave, whose energy is the smallest (measured: means -0.1 %
    energy, -0.4 % wear, -0.2 % cost, sd 0.7-0.9 %, worst single drive 2.1 %)."""
    savings = []
    for timing in PAPER_TIMINGS:
        fs = make_scenario("paper_s400", timing, E)
        reg = regular_driver(advisory_scenario_at(fs, E))
        for seed in range(3):
            t, v, x = fixes_of(reg, phase_s=0.1 + 0.3 * seed, noise_mps=0.2, seed=seed)
            s = trip_score("r", fs, "paper_54kwh", E + t, v, x, SPEED_LIMIT_MPS)
            assert s.complete and not s.red_light_crossings
            savings.append([s.savings_frac[k] for k in ("energy", "wear", "cost")])
    savings = np.array(savings)
    assert np.all(np.abs(savings.mean(axis=0)) <= 0.01), savings.mean(axis=0)
    assert np.all(np.abs(savings) <= 0.04), np.abs(savings).max(axis=0)


def test_only_the_zone_counts_fixes_beyond_its_ends_are_not_clamped():
    """Finding: fixes up to 30 m outside the zone were clamped to its ends and counted (620-645 m on 600 m)."""
    fs = make_scenario("paper_s400", "-30_0", E)
    reg = regular_driver(advisory_scenario_at(fs, E))
    t, v, x = fixes_of(reg, before_s=1.4, after_s=3.5)  # the last fix ~45 m past the exit, the first ~30 m before the entry
    assert x[0] < -25 and x[-1] > 640
    s = trip_score("z", fs, "paper_54kwh", E + t, v, x, SPEED_LIMIT_MPS)
    assert s.complete and s.driven.distance_m == pytest.approx(600.0, abs=1.0)
    assert s.driven.duration_s == pytest.approx(reg.duration_s, abs=0.05)
    assert s.entry_unix_s == pytest.approx(E, abs=0.01)


def test_a_teleport_is_rejected_with_a_reason_and_not_scored(service):
    """Findings: a speed from two fixes 580 m apart (580 m/s) was believed; a three-fix teleport scored 99.97 %."""
    client, now = service
    corridor = load_corridor("paper_s400")
    fs = make_scenario(corridor, "-30_0", E)
    reg = regular_driver(advisory_scenario_at(fs, E))
    t, v, x = fixes_of(reg)
    x = x.copy()
    jump = np.flatnonzero((x > 100) & (x < 300))[:3]
    x[jump] = 590.0  # three fixes at the zone's end
    v = v.copy()
    out, score = drive_through_service(client, now, corridor, t, v, x, timing="-30_0")
    rejected = [a for a in out if a["fix_status"] == "implausible"]
    assert len(rejected) == 3 and all("jump" in a["fix_note"] and "m/s" in a["fix_note"] for a in rejected)
    assert abs(score["savings_frac"]["energy"]) < 0.05 and "3 fix(es) ignored as implausible" in score["note"]
    # a position-derived speed from two fixes 580 m apart: the second fix is rejected, no 580 m/s speed is used
    created = client.post("/v1/trips", json={"corridor": "paper_s400", "timing": "-30_0", "entry_unix_s": E}).json()
    auth = {"Authorization": f"Bearer {created['token']}"}
    for k, station in enumerate((5.0, 585.0)):
        lat, lon = corridor.position(station)
        now[0] = E + 10 + k
        a = client.post(f"/v1/trips/{created['trip_id']}/fixes", json={"t_unix_s": E + 10 + k, "lat_deg": lat, "lon_deg": lon}, headers=auth).json()
    assert a["fix_status"] == "implausible" and a["speed_mps"] is None


def test_a_red_light_crossing_is_flagged_and_never_a_saving(service):
    """Finding: a drive crossing a stop line during red was scored as a saving with no note."""
    client, now = service
    corridor = load_corridor("paper_s400")
    # field_test: light 1 (100 m) is red from 15 s before entry to 15 s after; cruising at 50 km/h reaches it at 7.2 s
    cruise = Trajectory(np.array([0.0, 600 / KMH50]), np.array([0.0, 600.0]), np.array([KMH50, KMH50]))
    _, score = drive_through_service(client, now, corridor, *fixes_of(cruise), timing="field_test")
    assert score["savings_frac"] is None and "red light" in score["note"]
    c, c2 = score["red_light_crossings"]  # light 2 turns red 30 s after entry: reached at 36 s
    assert c2["light"] == 2 and c2["into_red_s"] == pytest.approx(600 / KMH50 * 500 / 600 - 30, abs=0.3)
    assert c["light"] == 1 and c["intersection_id"] == corridor.intersections[0].id
    assert c["t_unix_s"] == pytest.approx(E + 100 / KMH50, abs=0.3) and c["into_red_s"] == pytest.approx(15 + 100 / KMH50, abs=0.3)
    # the regular driver itself, noise and all, never gets flagged (it stops 1 m short and leaves on green)
    reg = regular_driver(advisory_scenario_at(make_scenario(corridor, "field_test", E), E))
    _, score = drive_through_service(client, now, corridor, *fixes_of(reg, noise_mps=0.2), timing="field_test")
    assert score["red_light_crossings"] == [] and score["savings_frac"] is not None


def test_a_light_passed_in_a_gap_between_fixes_is_not_judged_unless_the_whole_gap_decides():
    """Finding: a resumed Redis demo trip was scored "red crossed" across the outage's gap in fixes (the speed
    interpolated from the stop to the first fix after the outage put the car over the line while still red)."""
    corridor = load_corridor("paper_s400")
    fs = make_scenario(corridor, "field_test", E)  # light 1 (100 m) red until 15 s after entry, then green for 30 s
    reg = regular_driver(advisory_scenario_at(fs, E))  # waits at light 1 (99 m) until it turns green

    def score(t, v, x, lose):
        keep = ~((t > lose[0]) & (t < lose[1]))
        return trip_score("gap", fs, "paper_54kwh", E + t[keep], v[keep], x[keep], SPEED_LIMIT_MPS)

    t, v, x = fixes_of(reg)
    # stopped at the red before the outage, past the line after it; the light turned green inside: unknown
    s = score(t, v, x, (10.0, 25.0))
    assert s.red_light_crossings == [] and s.savings_frac is not None
    (u,) = s.red_light_unknown
    assert (u.light, u.gap_from_unix_s, u.gap_to_unix_s) == (1, pytest.approx(E + 9.37), pytest.approx(E + 25.37))
    assert "gap in the fixes" in s.note and "unknown" in s.note
    # red all through the gap: crossed on red whenever in the gap (a gap never excuses a red)
    cruise = Trajectory(np.array([0.0, 600 / KMH50]), np.array([0.0, 600.0]), np.array([KMH50, KMH50]))
    s = score(*fixes_of(cruise), (3.0, 12.0))
    assert [c.light for c in s.red_light_crossings] == [1, 2] and s.red_light_unknown == [] and s.savings_frac is None
    assert 2.37 <= s.red_light_crossings[0].t_unix_s - E <= 12.37
    # green all through the gap (-30_15: light 1 green from the entry for 30 s): nothing to judge, nothing unknown
    fs_green = make_scenario(corridor, "-30_15", E)
    t, v, x = fixes_of(cruise)
    keep = ~((t > 3.0) & (t < 12.0))
    s = trip_score("gap", fs_green, "paper_54kwh", E + t[keep], v[keep], x[keep], SPEED_LIMIT_MPS)
    assert 1 not in [c.light for c in s.red_light_crossings] and s.red_light_unknown == []


def test_gaps_anywhere_never_make_a_red_crossing_nor_hide_one():
    """Gaps of 6 and 15 s cut every 2 s of a drive: the regular driver (noisy GPS, stops at both reds) is never
    scored "red crossed"; a car cruising through both reds has each light it reached judged red or unknown."""
    fs = make_scenario("paper_s400", "field_test", E)
    reg = regular_driver(advisory_scenario_at(fs, E))
    cruise = Trajectory(np.array([0.0, 600 / KMH50]), np.array([0.0, 600.0]), np.array([KMH50, KMH50]))
    for drive, runs_reds in ((reg, False), (cruise, True)):
        t, v, x = fixes_of(drive, noise_mps=0.3, seed=3)
        for start in np.arange(-4.0, drive.duration_s, 2.0):
            for length in (6.0, 15.0):
                keep = ~((t > start) & (t < start + length))
                s = trip_score("gap", fs, "paper_54kwh", E + t[keep], v[keep], x[keep], SPEED_LIMIT_MPS)
                red, unknown = {c.light for c in s.red_light_crossings}, {u.light for u in s.red_light_unknown}
                if not runs_reds:
                    assert not red, (start, length, s.red_light_crossings)
                else:
                    reached = {k + 1 for k, line in enumerate((100.0, 500.0)) if x[keep].max() > line + 10}
                    assert reached <= red | unknown, (start, length, reached, red, unknown)


def test_observed_phases_give_the_same_score_as_the_plans():
    """A trip on live SPaT is scored against the phases it observed; observed from the plans, they are the plans."""
    from server.trips import ObservedLights

    fs = make_scenario("paper_s400", "15_15", E)
    reg = regular_driver(advisory_scenario_at(fs, E))
    t, v, x = fixes_of(reg)
    plans = fs.fixed_plans()
    readings = {ix.id: PlanReading(plans[(ix.id, ix.signal_groups[0].id)]) for ix in fs.corridor.intersections}
    seen = ObservedLights()
    for tk in E - 60 + np.arange(0.0, 200.0):
        seen.add(float(tk), readings)
    assert all(len(runs) <= 8 for runs in seen.runs.values())  # compact: one run per phase
    a = trip_score("p", fs, "paper_54kwh", E + t, v, x, SPEED_LIMIT_MPS)
    b = trip_score("o", fs, "paper_54kwh", E + t, v, x, SPEED_LIMIT_MPS, observed=seen.runs)
    assert b.regular == a.regular and b.savings_frac == a.savings_frac and "observed" in b.note
