"""One SUMO run of a corridor with traffic: connected cars advised by ecodrive, by SUMO's GLOSA device, or not at all.

:func:`run` starts SUMO in process (``libsumo``) on a :class:`~ecodrive.traffic.network.TrafficNetwork` with the flows
of :func:`~ecodrive.traffic.network.write_routes`, steps it (``step_s``, SUMO's default Euler update), and records every car's station and speed after each step and each light's
state. Which cars are connected is a function of the seed and the car's index in its flow only
(:func:`connected_ids`), so the three runs of one scenario share them, as they share SUMO's ``--seed``, the demand
and therefore the arrivals (checked by :mod:`ecodrive.traffic_eval`: every car's scheduled departure must agree).

``mode``:

* ``"advised"``: the service's own path, in process, no HTTP: a :class:`server.advising.Engine` whose
  :class:`server.spat.SpatHub` has no simulator (every light is read from its store, as for MQTT), on a clock that is
  the simulation's. Every simulated second :class:`~spat_feed.transport.sumo.SumoSpatSource` offers SUMO's lights to
  that store; each connected car has a trip (``Engine.create_trip`` when it enters the network, ``end_trip`` past the
  zone's end) and posts a GPS fix a second (``Engine.apply_fix``: the trip's token and rate bucket, map matching of
  the car's real lat/lon on the corridor, its speed, the SPaT readings at the fix's time, the advisor with the trip's
  memory); :class:`~ecodrive.traffic.driver.AdvisedDriver` acts on the advice (``vehicle.setSpeed``; SUMO's speed
  mode left at its default, every safety check on, but for SUMO's own stop at an amber while the virtual driver
  clears one it chose to go through: :data:`SPEED_MODE_CLEARING`). The person drives the car from its departure
  (its eyes on the lights and the car in front); its phone posts fixes from ``RunSetup.fix_from_m`` on.
* ``"blind"``: the same with the service's queue-aware advice off (``advised`` has it on unless
  ``RunSetup.queue_aware`` is False; the service is told the demand per lane and the penetration, as an operator's
  detector counts and fleet share would tell it).
* ``"glosa"``: the connected cars carry SUMO's GLOSA device (``--device.glosa.explicit``), ``use-queue`` on, each
  light heard from the service's approach (``server.advising.approach_m``) or the light before it, as the advisor hears it (the light's ``device.glosa.range``
  parameter, :mod:`ecodrive.traffic.network`); SUMO's other GLOSA settings at their defaults (``max-speedfactor``
  1.1: it may speed up to 110 % of the limit for a green; ``min-speed`` 5 m/s).
* ``"unadvised"``: SUMO drives every car.
"""

from __future__ import annotations

import asyncio
import math
import tempfile
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from advisory.advice.views import Advice, AdvisorParams
from ecodrive.traffic.driver import AdvisedDriver, LightNow
from ecodrive.traffic.network import DRIVEN_VTYPE, TrafficNetwork, write_routes
from spat_feed.timing.plans import PhaseClass, phase_class
from spat_feed.transport.sumo import SumoLight, SumoSpatSource, link_state

MODES = ("advised", "blind", "glosa", "unadvised")
LINE_TOL_M = 0.05
"""A front this far past a stop line has crossed it (SUMO stops a car with its front on the line, to rounding). [m]"""
MAIN_FLOW = "main"
LOOK_AHEAD_M = 250.0
"""How far ahead a connected car's driver looks for the car in front. [m]"""
SPEED_MODE_DEFAULT = 31
"""SUMO's default speed mode: safe speed, acceleration and deceleration limits, right of way, brake for red and amber."""
SPEED_MODE_CLEARING = SPEED_MODE_DEFAULT & ~16
"""The same without bit 4 (SUMO's own driver braking for a red or an amber it can stop for): set while the virtual
driver goes on through an amber it chose to clear, so that SUMO does not stop it at 4 m/s² (its rule for any amber it
can stop for); the car in front is still kept (bit 0)."""


@dataclass(frozen=True, slots=True)
class RunSetup:
    """One scenario. Units in names."""

    demand_vph_per_lane: float = 600.0
    penetration_frac: float = 0.5
    seed: int = 1
    duration_s: float = 600.0  # cars depart during this long
    drain_s: float = 240.0  # then the simulation runs this much longer for the last ones to leave
    step_s: float = 0.5
    ballistic: bool = False  # SUMO's ballistic update; off: its default (Euler). Ballistic jammed a queue at 900 veh/h on 7th Street: gaps
    # under half a metre, every car creeping at 0.2-0.5 m/s for minutes, the front one with no leader on a green (SUMO 1.28, Krauss)
    cross_demand_vph: float = 0.0  # each cross street, each way (the actuated controllers' rival demand)
    fix_from_m: float = -250.0  # a connected car's phone posts fixes from this station on (the service advises from its approach_m before 0)
    queue_aware: bool = True  # the advised run's service with queue-aware advice (server.queue), told the demand and penetration
    departures_s: tuple[float, ...] = ()  # instead of the Poisson flow, cars departing at these instants (tests)
    connected: tuple[str, ...] | None = None  # instead of the penetration's draw, these cars are connected (tests)
    spat_queue: bool = False  # SUMO's lights publish each approach's jam as J2735 queueLength (detectors at the line)


@dataclass
class CarTrace:
    """One car's run: scheduled departure, and after each step its time, station and speed; lights crossed."""

    vid: str
    connected: bool
    depart_s: float = math.nan  # when its flow scheduled it (SUMO's departure minus its insertion delay) [sim s]
    t: list = field(default_factory=list)
    x: list = field(default_factory=list)
    v: list = field(default_factory=list)
    crossings: list = field(default_factory=list)  # (light index, time, J2735 state class in effect)
    advice: dict = field(default_factory=dict)  # advised run: action -> count of fixes
    overrides: int = 0
    surprises: int = 0


@dataclass
class RunResult:
    mode: str
    setup: RunSetup
    cars: dict[str, CarTrace]
    spat_verdicts: dict[str, int]
    spat_mismatches: int  # published current state != SUMO's (advised runs: every publication checked)
    sim_end_s: float
    collisions: list = field(default_factory=list)  # SUMO's (time, collider, victim, type, speeds)
    teleports: int = 0
    queue_held: int = 0  # fixes the service answered "follow the car in front" (queue-aware advice)
    reds: tuple = ()  # per light, the run's red intervals [start, end) in simulation time: the steps SUMO ran under red (amber is not red)


def connected_ids(seed: int, penetration_frac: float, n: int) -> list[str]:
    """Ids of the connected cars among the first ``n`` of the corridor's flow: car ``k`` is connected when the
    ``k``-th draw of a generator seeded by (seed, 28) is below ``penetration_frac``: the same cars in every run.

    Examples
    --------
    >>> connected_ids(1, 0.0, 50), len(connected_ids(1, 1.0, 50))
    ([], 50)
    """
    draws = np.random.default_rng([int(seed), 28]).random(n)
    return [f"{MAIN_FLOW}.{k}" for k in np.flatnonzero(draws < penetration_frac)]


def _sumo_lights(network: TrafficNetwork) -> list[SumoLight]:
    return [SumoLight(lt.intersection_id, lt.signal_group, lt.tls_id, lt.link_index, lt.name, "corridor through") for lt in network.lights]


def run(network: TrafficNetwork, setup: RunSetup, mode: str, folder: str | Path | None = None, advisor: AdvisorParams | None = None,
        fresh_process: bool = True) -> RunResult:  # fmt: skip
    """One run (see the module docstring). A ``"glosa"`` run goes to a fresh Python process (``fresh_process``):
    libsumo keeps the GLOSA device's state from one simulation to the next in a process, so a second GLOSA run
    repeated the first one's cars (SUMO 1.28: paper_s400, 300 veh/h, GLOSA at 10 % after a run at 50 % gave the 50 %
    run's trajectories, to the metre; at 10 % alone it changes nothing)."""
    if mode not in MODES:
        raise ValueError(f"mode must be one of {MODES}, not {mode!r}")
    if mode == "glosa" and fresh_process:
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor

        with ProcessPoolExecutor(max_workers=1, mp_context=multiprocessing.get_context("spawn")) as pool:
            return pool.submit(run, network, setup, mode, folder, advisor, False).result()
    import libsumo as conn

    with tempfile.TemporaryDirectory(prefix="ecodrive-sumo-") as tmp:
        folder = Path(folder or tmp)
        routes = write_routes(network, folder / f"routes_{setup.seed}.rou.xml", setup.demand_vph_per_lane, setup.duration_s, setup.cross_demand_vph,
                              setup.departures_s)  # fmt: skip
        n_max = int(setup.demand_vph_per_lane * network.lanes * setup.duration_s / 3600.0 * 3 + 50 + len(setup.departures_s))
        connected = set(connected_ids(setup.seed, setup.penetration_frac, n_max) if setup.connected is None else setup.connected)
        cmd = ["sumo", "-n", str(network.net_file), "-r", str(routes), "--step-length", f"{setup.step_s:g}", "--step-method.ballistic", str(setup.ballistic).lower(),
               "--seed", str(int(setup.seed)), "--no-step-log", "true", "--no-warnings", "true", "--time-to-teleport", "-1", "--collision.action", "warn", "--collision.mingap-factor", "0",
               "--end", f"{setup.duration_s + setup.drain_s:g}", "--device.rerouting.probability", "0"]  # fmt: skip
        if mode == "glosa" and connected:
            cmd += ["--device.glosa.explicit", ",".join(sorted(connected)), "--device.glosa.use-queue", "true",
                    "--device.glosa.range", "1e6"]  # each light's own range: the network's (from the approach or the light before)
        conn.start(cmd)
        try:
            if mode in ("advised", "blind"):
                return replace(asyncio.run(_loop_advised(conn, network, setup, connected, advisor, mode == "advised" and setup.queue_aware)), mode=mode)
            return _loop(conn, network, setup, connected, mode, None)
        finally:
            conn.close()


class _Sim:
    """State shared by the loop: SUMO, the lights, the cars' traces."""

    def __init__(self, conn, network: TrafficNetwork, setup: RunSetup, connected: set[str]) -> None:
        self.conn = conn
        self.network = network
        self.setup = setup
        self.connected = connected
        self.lights = _sumo_lights(network)
        self.source = SumoSpatSource(conn, self.lights, network.t0_unix_s, queues=setup.spat_queue)
        self.cars: dict[str, CarTrace] = {}
        self.live: set[str] = set()
        self.stop_lines = [lt.stop_line_m for lt in network.lights]
        self.classes: list[PhaseClass] = [PhaseClass.GREEN] * len(self.lights)
        self.states = ["G"] * len(self.lights)
        self.coming: list[tuple[PhaseClass, float]] = [(PhaseClass.GREEN, math.inf)] * len(self.lights)
        self.shows_amber = [True] * len(self.lights)  # each light's program shows an amber before each red (its source's)
        self.collisions: list[tuple] = []  # (time, collider, victim, type, their speeds)
        self.teleports = 0
        self.reds: list[list[list[float]]] = [[] for _ in self.lights]  # per light, [start, end) of the steps run under red

    def after_step(self) -> float:
        """Read SUMO after a step: new cars, each car's position and speed, lights crossed; the simulation time."""
        conn, v_ = self.conn, self.conn.vehicle
        t = float(conn.simulation.getTime())
        for i, lt in enumerate(self.lights):
            self.states[i] = conn.trafficlight.getRedYellowGreenState(lt.tls_id)[lt.link_index]
            self.classes[i] = phase_class(link_state(self.states[i]))  # what the step that just ended used
            state, ends = self.source.coming_state(lt)
            self.coming[i] = (phase_class(state), ends)  # what the next step uses: what a driver sees now
            self.shows_amber[i] = self.source.amber_s(lt) != 0.0
            if self.classes[i] is PhaseClass.RED:  # the step that just ended, (t - step, t], ran under red
                reds = self.reds[i]
                if reds and abs(reds[-1][1] - (t - self.setup.step_s)) < 1e-6:
                    reds[-1][1] = t
                else:
                    reds.append([t - self.setup.step_s, t])
        self.source.observe()
        for vid in conn.simulation.getDepartedIDList():
            if not vid.startswith(MAIN_FLOW + "."):
                continue
            car = self.cars[vid] = CarTrace(vid, vid in self.connected)
            car.depart_s = float(v_.getDeparture(vid)) - float(v_.getDepartDelay(vid))
            self.live.add(vid)
            v_.subscribe(vid, (0x42, 0x40))  # VAR_POSITION, VAR_SPEED
        for vid in conn.simulation.getArrivedIDList():
            self.live.discard(vid)
        for c in conn.simulation.getCollisions():
            self.collisions.append((t, c.collider, c.victim, c.type, round(c.colliderSpeed, 2), round(c.victimSpeed, 2)))
        self.teleports += conn.simulation.getStartingTeleportNumber()
        results = v_.getAllSubscriptionResults()
        x0 = self.network.x0_m
        for vid in self.live:
            r = results.get(vid)
            if r is None:
                continue
            car = self.cars[vid]
            x = float(r[0x42][0]) - x0
            if car.x:
                for i, line in enumerate(self.stop_lines):
                    if car.x[-1] <= line + LINE_TOL_M < x:  # the front crossed the line in the step that just ended (under the state read now)
                        car.crossings.append((i, t, self.classes[i].value))
            car.t.append(t)
            car.x.append(x)
            car.v.append(float(r[0x40]))
        return t

    def red_intervals(self) -> tuple[tuple[tuple[float, float], ...], ...]:
        """Per light, the run's red intervals ``[start, end)`` (simulation time): a front crossing its line within one
        crossed under red (as ``CarTrace.crossings`` counts it)."""
        return tuple(tuple((a, b) for a, b in reds) for reds in self.reds)

    def leader(self, vid: str) -> tuple[float, float, float] | None:
        """The car in front of ``vid`` within :data:`LOOK_AHEAD_M`, as its driver sees it: (gap beyond the standstill
        gap, speed, acceleration in the last step: negative while it brakes), or None."""
        found = self.conn.vehicle.getLeader(vid, LOOK_AHEAD_M)
        if not found or not found[0]:
            return None
        return float(found[1]), float(self.conn.vehicle.getSpeed(found[0])), float(self.conn.vehicle.getAcceleration(found[0]))

    def light_now(self, x_m: float) -> LightNow | None:
        """The next light ahead of station ``x_m`` as the driver sees it now."""
        for i, line in enumerate(self.stop_lines):
            if line + LINE_TOL_M >= x_m:  # (a car whose front stands at the line has not crossed it)
                cls, ends = self.coming[i]
                return LightNow(i, line, cls is PhaseClass.RED, cls is PhaseClass.AMBER, ends if cls is PhaseClass.AMBER else math.inf, self.shows_amber[i])
        return None


def _loop(conn, network, setup, connected, mode, hook) -> RunResult:
    sim = _Sim(conn, network, setup, connected)
    end = setup.duration_s + setup.drain_s
    t = sim.after_step()
    while t < end - 1e-9 and (t < setup.duration_s or conn.simulation.getMinExpectedNumber() > 0):
        if hook is not None:
            hook(sim, t)
        conn.simulationStep()
        t = sim.after_step()
    return RunResult(mode, setup, sim.cars, dict(sim.source.verdicts), 0, t, sim.collisions, sim.teleports, reds=sim.red_intervals())


async def _loop_advised(conn, network: TrafficNetwork, setup: RunSetup, connected: set[str], advisor: AdvisorParams | None, queue_aware: bool) -> RunResult:
    from server.advising import Engine
    from server.config import Settings
    from server.gps import Fix
    from server.schemas import TripCreate
    from server.spat import SpatHub
    from spat_feed.prediction.observe import observation

    corridor = network.corridor
    sim = _Sim(conn, network, setup, connected)
    now = [network.t0_unix_s]
    clock = lambda: now[0]  # noqa: E731  (the service's clock is the simulation's)
    settings = Settings(spat_simulate=False, tables=False, speech=False, default_corridor=corridor.name, rate_per_s=1e6, rate_burst=1e6,
                        create_rate_per_s=1e6, create_burst=1e6, create_rate_per_client_per_s=1e6, create_burst_per_client=1e6,
                        max_trips_per_client=0, queue_aware=queue_aware, queue_arrivals_vph=setup.demand_vph_per_lane,
                        queue_connected_share=setup.penetration_frac)  # fmt: skip
    corridors = {corridor.name: corridor}
    hub = SpatHub(settings, corridors, clock)
    engine = Engine(settings, corridors, params=advisor, spat=hub, clock=clock)
    trips: dict[str, object] = {}
    drivers: dict[str, AdvisedDriver] = {}
    index = {ix.id: n for n, ix in enumerate(corridor.intersections)}
    mismatches = 0
    end = setup.duration_s + setup.drain_s
    t = sim.after_step()
    dt = setup.step_s
    while t < end - 1e-9 and (t < setup.duration_s or conn.simulation.getMinExpectedNumber() > 0):
        now[0] = network.t0_unix_s + t
        second = abs(t - round(t)) < 1e-6
        if second:  # SUMO's lights into the service's store, once a simulated second
            sim.source.publish(hub.store)
            for i, lt in enumerate(sim.lights):
                reading = hub.store.reading(lt.intersection_id)
                published = reading.intersection.movement(lt.signal_group).state_time_speed[0].event_state if reading is not None else None
                mismatches += published is not link_state(sim.states[i])
        for vid in sorted(sim.live & connected):
            car = sim.cars[vid]
            if not car.x:
                continue
            x, v = car.x[-1], car.v[-1]
            if x > corridor.length_m:
                if vid in trips:
                    await engine.end_trip(trips.pop(vid))
                    conn.vehicle.setSpeed(vid, -1.0)
                    car.overrides, car.surprises = drivers[vid].overrides, drivers[vid].surprises
                    if drivers[vid].clearing:
                        conn.vehicle.setSpeedMode(vid, SPEED_MODE_DEFAULT)
                        drivers[vid].clearing = False
                continue
            if vid not in drivers:  # the person drives from the start; the phone posts fixes from fix_from_m on
                drivers[vid] = AdvisedDriver(tuple(sim.stop_lines), advisor or AdvisorParams(), vid=vid)
                # the virtual driver decides about an amber: SUMO's own driver, which stops for any amber its 4 m/s² can
                # stop for in the very step it begins (the virtual one sees it a step later), waits one step for it
                conn.vehicle.setType(vid, DRIVEN_VTYPE)
            if vid not in trips and x >= setup.fix_from_m:
                trips[vid] = await engine.create_trip(TripCreate(corridor=corridor.name), client=vid)
            driver = drivers[vid]
            if second and vid in trips:
                trip = trips[vid]
                lat, lon = corridor.position(min(max(x, 0.0), corridor.length_m)) if x >= 0 else _before_entry(corridor, x)
                fix = Fix(now[0], lat, lon, speed_mps=v, accuracy_m=5.0)
                out = await engine.apply_fix(trip.id, trip.token, lambda fix=fix: fix)
                advice = Advice(out["action"], out["reason"], out["target_speed_mps"], out["light_red"], out["seconds_to_change_s"])
                car.advice[out["action"]] = car.advice.get(out["action"], 0) + 1
                views = {}
                if out["on_route"]:
                    obs = observation(corridor, out["station_m"], v, now[0], trip.spat.readings(now[0]), corridor.advisory_limit_mps(max(out["station_m"], 0.0)))
                    views = {index[lv.intersection_id]: lv for lv in obs.lights}
                driver.heard(now[0], x, advice, views)
            limit = corridor.speed_limit_mps_over(max(x, 0.0), max(x, 0.0))
            was_clearing = driver.clearing
            cmd = driver.command(now[0], x, v, dt, limit, sim.light_now(x), sim.leader(vid))
            if driver.clearing != was_clearing:  # through an amber the driver chose to clear: SUMO must not stop it there
                conn.vehicle.setSpeedMode(vid, SPEED_MODE_CLEARING if driver.clearing else SPEED_MODE_DEFAULT)
            conn.vehicle.setSpeed(vid, -1.0 if cmd is None else cmd)
        conn.simulationStep()
        t = sim.after_step()
    for vid, trip in trips.items():
        await engine.end_trip(trip)
    held = engine.queue.held if engine.queue is not None else 0
    return RunResult("advised", setup, sim.cars, dict(sim.source.verdicts), mismatches, t, sim.collisions, sim.teleports, held, sim.red_intervals())


def _before_entry(corridor, x_m: float) -> tuple[float, float]:
    """Lat/lon ``-x_m`` metres before the zone entry, on the line of the route's first stretch."""
    from spat_feed.road.corridors import WGS84

    a, b = corridor.polyline[0], corridor.polyline[1]
    az, _, _ = WGS84.inv(a.lon_deg, a.lat_deg, b.lon_deg, b.lat_deg)
    lon, lat, _ = WGS84.fwd(a.lon_deg, a.lat_deg, az, x_m)
    return float(lat), float(lon)
