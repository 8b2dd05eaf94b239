"""The service on a user's own corridor and plan files (ECO_CORRIDOR_DIR) and on the shipped OSM corridor:
listed, advised from the DP tables through all the lights, scored against the regular driver."""

from __future__ import annotations

import json

import numpy as np
import pytest
from fastapi.testclient import TestClient

from advisory.drivers.regular import regular_driver
from server.app import create_app
from server.config import Settings
from spat_feed.road.corridors import CHAMPS_ELYSEES, straight_corridor
from spat_feed.transport.scenarios import advisory_scenario_at, make_scenario

STOP_LINES_M = (150.0, 420.0, 700.0, 1000.0, 1300.0)
T0 = 1_800_000_000.0  # a Friday, 08:00 UTC


def five_light_files(folder) -> None:
    corridor = straight_corridor("five", CHAMPS_ELYSEES, STOP_LINES_M, 1450.0, description="five lights")
    (folder / "five.json").write_text(corridor.model_dump_json(indent=1), encoding="utf-8")
    cycles = (60, 90, 120, 60, 90)
    lights = [{"intersection_id": k + 1, "red_s": c // 2, "green_s": c - c // 2 - 3, "amber_s": 3, "offset_s": 31 * k} for k, c in enumerate(cycles)]
    plan = {"kind": "signal_plan", "name": "fixed", "corridor": "five", "time_zone": "UTC", "patterns": {"all_day": {"lights": lights}}}
    (folder / "five-plan.json").write_text(json.dumps(plan), encoding="utf-8")


def test_service_serves_a_corridor_folder_and_the_oakland_preset(tmp_path):
    five_light_files(tmp_path)
    now = [T0]
    settings = Settings(corridors=("paper_s200", "oakland_7th_westbound"), corridor_dir=tmp_path, default_corridor="paper_s200",
                        speech=False, tables_dir=tmp_path / "tables", rate_per_s=1000.0, rate_burst=1000.0)  # fmt: skip
    with TestClient(create_app(settings, clock=lambda: now[0])) as client:
        listed = {c["name"]: c for c in client.get("/v1/corridors").json()}
        assert set(listed) == {"paper_s200", "oakland_7th_westbound", "five"}
        assert listed["five"]["intersection_ids"] == [1, 2, 3, 4, 5] and listed["five"]["plans"] == ["fixed"]
        assert listed["oakland_7th_westbound"]["units"] == "imperial" and listed["oakland_7th_westbound"]["default_plan"] == "plausible"
        assert set(client.get("/health").json()["tables"]) >= {"paper_s200", "oakland_7th_westbound", "five"}
        bad = client.post("/v1/trips", json={"corridor": "five", "timing": "15_15"})
        assert bad.status_code == 422 and bad.json()["error"] == "timing_mismatch" and "5" in bad.json()["message"]
        unknown = client.post("/v1/trips", json={"corridor": "five", "timing": "/etc/passwd.json"})
        assert unknown.status_code == 422 and unknown.json()["error"] == "unknown_timing"

        created = client.post("/v1/trips", json={"corridor": "five"}).json()
        assert created["timing"] == "fixed"
        auth = {"Authorization": f"Bearer {created['token']}"}
        # drive the regular driver's own trajectory through the five lights, one fix a second
        from spat_feed.road.corridors import load_corridor_dir

        corridor = load_corridor_dir(tmp_path)["five"]
        scenario = advisory_scenario_at(make_scenario(corridor, "fixed", T0), T0)
        traj = regular_driver(scenario)
        sources, lights_seen = [], set()
        for t in np.arange(0.0, traj.duration_s, 1.0):
            now[0] = T0 + t
            lat, lon = corridor.position(float(traj.position_at(t)))
            r = client.post(f"/v1/trips/{created['trip_id']}/fixes", json={"t_unix_s": now[0], "lat_deg": lat, "lon_deg": lon,
                                                                            "speed_mps": float(traj.speed_at(t))}, headers=auth)  # fmt: skip
            assert r.status_code == 200
            advice = r.json()
            assert advice["target_speed_mps"] is None or advice["target_speed_mps"] <= scenario.speed_limit_mps + 1e-9
            sources.append(advice["source"])
            lights_seen.add(advice["next_intersection_id"])
        assert lights_seen >= {1, 2, 3, 4, 5} and sources.count("dp_table") > 0
        score = client.post(f"/v1/trips/{created['trip_id']}/end", headers=auth).json()
        assert (traj.v_mps == 0).any()  # the plan makes the regular driver stop
        assert score["regular"]["duration_s"] == pytest.approx(traj.duration_s, abs=1.0)  # through all five lights
        assert abs(score["savings_frac"]["energy"]) < 0.05  # the drive was the regular driver's own
