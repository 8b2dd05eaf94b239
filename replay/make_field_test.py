"""Make the field-test traces in ``replay/data/`` (paper Sec. 4.4): ``python -m replay.make_field_test``.

Two drives through the paper's field-test timing (light 1 turns green 15 s and light 2 turns red 30 s
after entry; ``spat_feed`` timing ``field_test``) on the ``paper_s400`` corridor (light 1 at 100 m,
light 2 at 500 m, zone end at 600 m; the paper does not give its field test's spacing, 400 m is our
pick), entering the zone at ``ENTRY_UNIX_S``:

* ``field_test_regular.csv``: the paper's regular driver (``advisory.drivers.regular.regular_driver``);
* ``field_test_advised.csv`` (and ``.gpx``): a human following the advisor, simulated in closed loop
  (``advisory.drivers.closed_loop.simulate`` with the DP lookup tables) with human imperfections: 1.5 s reaction,
  tracking error 0.5 m/s (redrawn at every advice), drifting 1 m/s above low advised speeds.

Both get ``APPROACH_S`` of driving at the limit before the zone and ``AFTER_S`` after it (accelerating
back to the limit at 2 m/s²), are sampled at 1 Hz at a random sub-second phase, and get GPS noise from
``GpsNoise``: horizontal position error as a first-order Gauss-Markov process per axis (σ 2.5 m,
correlation time 10 s, plus 0.5 m white), speed-over-ground error the same way (σ 0.3 m/s, 2 s, plus
0.1 m/s white; a third of it at a standstill, never negative). The seed is fixed: rerunning gives the
same files byte for byte.
"""

from __future__ import annotations

import argparse
import math
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from advisory.drivers.closed_loop import DriverModel, simulate
from advisory.physics.params import model_params
from advisory.drivers.regular import regular_driver
from advisory.advice.tables import AdviceTables, TableGrid
from advisory.trajectory import Trajectory
from spat_feed.road.corridors import WGS84
from spat_feed.transport.scenarios import make_scenario

DATA = Path(__file__).resolve().parent / "data"
CORRIDOR = "paper_s400"
TIMING = "field_test"
VEHICLE = "paper_54kwh"
ENTRY_UNIX_S = 1_714_557_600.0  # 2024-05-01T10:00:00Z
APPROACH_S = 8.0
AFTER_S = 10.0
SEED = 20240501
HUMAN = DriverModel(reaction_s=1.5, noise_mps=0.5, drift_mps=1.0, seed=4)


@dataclass(frozen=True, slots=True)
class GpsNoise:
    """1 Hz GPS error model: Gauss-Markov (AR(1)) plus white noise. [m], [s], [m/s]"""

    pos_sigma_m: float = 2.5
    pos_tau_s: float = 10.0
    pos_white_m: float = 0.5
    speed_sigma_mps: float = 0.3
    speed_tau_s: float = 2.0
    speed_white_mps: float = 0.1
    standstill_frac: float = 1 / 3


def _ar1(rng: np.random.Generator, n: int, sigma: float, tau_s: float, dt_s: float = 1.0) -> np.ndarray:
    phi = math.exp(-dt_s / tau_s)
    out = np.empty(n)
    out[0] = rng.normal(0.0, sigma)
    for k in range(1, n):
        out[k] = phi * out[k - 1] + rng.normal(0.0, sigma * math.sqrt(1.0 - phi * phi))
    return out


def extended(traj: Trajectory, v_lim_mps: float, approach_s: float = APPROACH_S, after_s: float = AFTER_S, accel_mps2: float = 2.0):
    """Functions t -> (station, speed) from ``-approach_s`` to ``duration + after_s`` (time 0 = zone entry)."""
    t_end = traj.duration_s
    x_end, v_end = float(traj.x_m[-1]), float(traj.v_mps[-1])
    t_acc = (v_lim_mps - v_end) / accel_mps2

    def at(t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        t = np.asarray(t, dtype=float)
        x = np.empty_like(t)
        v = np.empty_like(t)
        before, inside, after = t < 0, (t >= 0) & (t <= t_end), t > t_end
        x[before], v[before] = v_lim_mps * t[before], v_lim_mps
        x[inside], v[inside] = traj.position_at(t[inside]), traj.speed_at(t[inside])
        tau = t[after] - t_end
        ta = np.minimum(tau, t_acc)
        x[after] = x_end + v_end * ta + 0.5 * accel_mps2 * ta**2 + v_lim_mps * (tau - ta)
        v[after] = v_end + accel_mps2 * ta
        return x, v

    return at, -approach_s, t_end + after_s


def gps_fixes(traj: Trajectory, corridor, rng: np.random.Generator, noise: GpsNoise = GpsNoise(), v_lim_mps: float = 24.5872):
    """1 Hz noisy fixes of ``traj``: (t from entry [s], lat, lon, speed [m/s], heading [deg], true station [m])."""
    at, t0, t1 = extended(traj, v_lim_mps)
    t = np.arange(t0 + rng.uniform(0.0, 1.0), t1, 1.0)
    x, v = at(t)
    n = t.size
    east = _ar1(rng, n, noise.pos_sigma_m, noise.pos_tau_s) + rng.normal(0.0, noise.pos_white_m, n)
    north = _ar1(rng, n, noise.pos_sigma_m, noise.pos_tau_s) + rng.normal(0.0, noise.pos_white_m, n)
    dv = _ar1(rng, n, noise.speed_sigma_mps, noise.speed_tau_s) + rng.normal(0.0, noise.speed_white_mps, n)
    dv = np.where(v < 0.1, noise.standstill_frac * np.abs(dv), dv)
    speed = np.maximum(v + dv, 0.0)
    lat = np.empty(n)
    lon = np.empty(n)
    heading = np.empty(n)
    for k in range(n):
        la, lo = corridor.position(float(x[k]))
        la2, lo2 = corridor.position(float(x[k]) + 1.0)
        az, _, _ = WGS84.inv(lo, la, lo2, la2)
        lo_n, la_n, _ = WGS84.fwd(lo, la, 90.0, east[k])
        lo_n, la_n, _ = WGS84.fwd(lo_n, la_n, 0.0, north[k])
        lat[k], lon[k], heading[k] = la_n, lo_n, az % 360.0
    return t, lat, lon, speed, heading, x


def _iso(t_unix_s: float) -> str:
    return datetime.fromtimestamp(t_unix_s, tz=timezone.utc).isoformat(timespec="milliseconds").replace("+00:00", "Z")


def write_csv(path: Path, header: dict[str, str], fixes) -> Path:
    t, lat, lon, speed, heading, _ = fixes
    lines = [f"# {k}: {v}" for k, v in header.items()]
    lines.append("time,lat,lon,speed_mps,heading_deg,accuracy_m")
    for k in range(t.size):
        lines.append(f"{_iso(ENTRY_UNIX_S + t[k])},{lat[k]:.7f},{lon[k]:.7f},{speed[k]:.2f},{heading[k]:.1f},3.5")
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


def write_gpx(path: Path, header: dict[str, str], fixes) -> Path:
    import gpxpy.gpx

    t, lat, lon, speed, heading, _ = fixes
    gpx = gpxpy.gpx.GPX()
    gpx.description = "\n".join(f"{k}: {v}" for k, v in header.items())
    trk = gpxpy.gpx.GPXTrack(name=path.stem)
    seg = gpxpy.gpx.GPXTrackSegment()
    for k in range(t.size):
        when = datetime.fromtimestamp(round(ENTRY_UNIX_S + t[k], 3), tz=timezone.utc)
        seg.points.append(gpxpy.gpx.GPXTrackPoint(round(lat[k], 7), round(lon[k], 7), time=when, speed=round(float(speed[k]), 2)))
    trk.segments.append(seg)
    gpx.tracks.append(trk)
    path.write_text(gpx.to_xml(version="1.0"), encoding="utf-8")
    return path


def drives():
    """(regular trajectory, advised closed-loop result, scenario, corridor) of the field test."""
    params = model_params(VEHICLE)
    feed = make_scenario(CORRIDOR, TIMING, ENTRY_UNIX_S)
    scenario = feed.advisory_scenario()
    tables = AdviceTables.build(scenario, params, TableGrid())
    advised = simulate(scenario, tables=tables, driver=HUMAN)
    return regular_driver(scenario), advised, scenario, feed.corridor


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m replay.make_field_test", description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=DATA)
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    regular, advised, scenario, corridor = drives()
    rng = np.random.default_rng(SEED)
    common = {"corridor": CORRIDOR, "timing": TIMING, "entry_unix_s": f"{ENTRY_UNIX_S:.0f}", "vehicle": VEHICLE}
    made = []
    for name, traj, driver in (
        ("field_test_regular", regular, "the paper's regular driver (advisory.drivers.regular)"),
        ("field_test_advised", advised.trajectory, f"closed-loop advisor follower {HUMAN}"),
    ):
        fixes = gps_fixes(traj, corridor, rng, v_lim_mps=scenario.speed_limit_mps)
        header = {**common, "driver": driver, "made_by": f"python -m replay.make_field_test (seed {SEED}); see replay/data/README.md"}
        made.append(write_csv(args.out / f"{name}.csv", header, fixes))
        if name == "field_test_advised":
            made.append(write_gpx(args.out / f"{name}.gpx", header, fixes))
    for path in made:
        print(path)  # noqa: T201
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
