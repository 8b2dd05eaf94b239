"""Queue-aware advice in the service: every trip's position is a probe of the traffic on its corridor.

:class:`QueueBoard` keeps, per corridor, where each trip was at its last fix (station, speed, time; this worker's
trips: a fix older than ``MAX_AGE_S`` is forgotten, so an ended or silent trip drops out by itself) and when each
light's current red was first seen on. For a fix on the route it hands the advisor the observation as the car meets
the lights in traffic (:func:`advisory.advice.queue.estimate` and :func:`~advisory.advice.queue.apply`: each red the car
faces ends when the queue in front of it has crossed the line), or, for a car standing in a queue or closing in on a
slower connected car, the service's own advice until it is over the next light's line: no speed, "Queue ahead.
Follow the car in front." (reason ``queue``); the advisor then plans afresh. Not where the cars ahead leave it no time
to cross before the next light's red (``QueueEstimate.stop_behind``, :func:`advisory.advice.queue.behind_s`): that
car is advised by the advisor, which sees the line closed to it until the red's end, and prepares to stop. The trips behind a car are probes too:
with the flow they give the followers a slower plan would hold up (``Observation.followers``), which the advisor and
:meth:`QueueBoard.check` price (docs/TRAFFIC.md, "Queue-aware advice", item 4).

On when ``ECO_QUEUE_AWARE=1``; ``ECO_QUEUE_ARRIVALS_VPH`` (the flow arriving at each light per lane, e.g. from
detector counts) and ``ECO_QUEUE_CONNECTED_SHARE`` (the share of those cars that are connected) let it count the cars
that are not connected (docs/TRAFFIC.md).

Where the probes and red starts are kept (``shared``): in this worker with the in-process store (one process: it
sees every trip); with the Redis store (several workers, ``ECO_STORE_URL``) in :class:`server.queue_store.SharedBoard`
tables, which every worker publishes its changes to and loads the others' from in the background every
``ECO_QUEUE_SYNC_S``, so that a fix on one worker counts the cars that the others serve (no Redis call on a fix's path;
Redis unreachable: this worker's own probes, said in ``/health`` and ``/metrics``).
"""

from __future__ import annotations

from advisory.advice.advisor import Advice, AdvisorParams, Observation
from advisory.advice.queue import Probe, QueueModel, apply, drive_normally, estimate, gives_up_green
from server.queue_store import SharedBoard

MAX_AGE_S = 3.0
"""A trip's position older than this is no longer a probe. [s]"""
QUEUE_MESSAGE = "Queue ahead. Follow the car in front."


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
        self._queued: dict[str, int] = {}  # trip -> the light whose queue it stands in
        self.held = 0  # fixes answered "follow the car in front"

    def see(self, corridor: str, trip_id: str, t_unix_s: float, obs: Observation, last_reason: str | None = None) -> tuple[Observation, Advice | None]:
        """Note the car's fix; the observation the advisor should get, or the service's advice for a car in a queue
        or behind a slower one (spoken when the trip's last advice, ``last_reason``, was another). After such advice
        the advisor plans afresh (:meth:`fresh`)."""
        cars = self._cars.setdefault(corridor, {})
        if not obs.on_route or obs.position_m is None or not obs.lights:
            cars.pop(trip_id, None)
            self._queued.pop(trip_id, None)
            return obs, None
        here = float(obs.position_m)
        cars[trip_id] = (t_unix_s, here, float(obs.speed_mps))
        for tid in [tid for tid, (t, _, _) in cars.items() if t_unix_s - t > MAX_AGE_S]:
            del cars[tid]
        nxt = obs.lights[0]
        if nxt.red_now:
            since = self._red_since.setdefault(nxt.intersection_id, t_unix_s)
        else:
            self._red_since.pop(nxt.intersection_id, None)
            since = None
        # ahead, and behind (followers); each where it is now: its last fix (up to a second older than this one, as
        # the fixes of a corridor arrive one after the other) advanced at its speed
        probes = [Probe(s + v * (t_unix_s - t) - here, v) for tid, (t, s, v) in cars.items() if tid != trip_id and s != here]
        est = estimate(obs, probes, self.model, self.arrivals_vps, self.connected_share, None if since is None else t_unix_s - since)
        if est.stop_behind:  # the cars ahead take the last of the green: following them would take it into the red
            self._queued.pop(trip_id, None)  # (the advisor plans its stop: the line is closed to it until the red's end)
        elif est.in_queue or est.follow_mps is not None:  # in the queue of the next light, or closing in on a slower car:
            self._queued[trip_id] = nxt.intersection_id  # it follows the car in front until over that light's line
        elif self._queued.get(trip_id) not in (None, nxt.intersection_id):
            del self._queued[trip_id]
        if trip_id in self._queued:
            self.held += 1
            countdown = nxt.seconds_to_green() if nxt.red_now else nxt.seconds_to_red()
            return obs, Advice("none", "queue", light_red=nxt.red_now, seconds_to_change_s=countdown, message=QUEUE_MESSAGE, speak=last_reason != "queue",
                               light_id=nxt.intersection_id)  # fmt: skip
        return apply(obs, est), None

    def check(self, obs: Observation, advice: Advice, params: AdvisorParams) -> Advice:
        """The advisor's advice, or "drive normally" where it gives up green time that a normal drive uses, priced with
        the followers it holds up (:func:`advisory.advice.queue.gives_up_green`)."""
        if gives_up_green(obs, advice, params, model=self.model):
            return drive_normally(advice, params.units)
        return advice

    @staticmethod
    def fresh(last_reason: str | None) -> bool:
        """The advisor plans afresh (no memory of a plan) on the first fix after the car was told to follow."""
        return last_reason == "queue"

    def forget(self, corridor: str, trip_id: str) -> None:
        """The trip has ended: it is no probe any more (on every worker, with the shared board)."""
        self._cars.get(corridor, {}).pop(trip_id, None)
        self._queued.pop(trip_id, None)

    def state(self) -> str:
        """Where the probes come from (``/health``): ``local`` (this process, which serves every trip), ``shared``
        (every worker's, through Redis) or ``own_trips_only`` (Redis unreachable: this worker's)."""
        return "local" if self.shared is None else self.shared.state()
