"""`replay --server URL`: feed a trace's fixes to a running advisory service and record what it said.

The trace's timestamps are shifted so that the replay happens *now*: the service checks fix times
against its clock (by default no more than 300 s old, 30 s ahead). At ``speedup`` N the fixes are sent N
times faster than recorded while their timestamps keep the recorded spacing, so the first fix is sent
``duration * (1 - 1/N)`` seconds late and the last one on time; the trip is created with the corridor,
timing and ``entry_unix_s`` of the trace (shifted the same way), so the service's simulated lights are
the ones the trace drove through. Every advisory is kept; the timeline shows each change of advice
(action, reason or target speed) and each spoken message: what the phone would have said, and when, in
seconds after the zone entry.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import TextIO

import httpx

from replay.trace_io import GpsTrace, TraceError

MAX_LAG_S = 270.0
"""Oldest fix time sent, behind the service's clock (its default limit is 300 s). [s]"""
LEAD_S = 0.5
MAX_RETRIES = 5


@dataclass
class Event:
    t_entry_s: float  # fix time after the zone entry [s]
    sent_after_s: float  # wall time after the first fix was sent [s]
    station_m: float | None
    speed_mps: float | None
    action: str
    reason: str
    message: str
    speak: bool

    def as_dict(self) -> dict:
        return dict(self.__dict__)


@dataclass
class Timeline:
    url: str
    trip_id: str
    speedup: float
    corridor: str
    timing: str
    sent: int = 0
    ok: int = 0
    ignored: dict[str, int] = field(default_factory=dict)
    retries: int = 0
    events: list[Event] = field(default_factory=list)
    advisories: list[dict] = field(default_factory=list)
    score: dict | None = None
    wall_s: float = 0.0

    def as_dict(self) -> dict:
        return {
            "url": self.url, "trip_id": self.trip_id, "speedup": self.speedup, "corridor": self.corridor, "timing": self.timing,
            "fixes_sent": self.sent, "fixes_used": self.ok, "ignored": self.ignored, "retries": self.retries, "wall_s": self.wall_s,
            "timeline": [e.as_dict() for e in self.events], "service_score": self.score,
        }  # fmt: skip

    @staticmethod
    def line(e: Event) -> str:
        where = f"{e.station_m:6.0f} m" if e.station_m is not None else "     - m"
        speed = f"{e.speed_mps * 3.6:5.1f} km/h" if e.speed_mps is not None else "      - km/h"
        return f"  {e.t_entry_s:+7.1f} s  {where}  {speed}  {e.action:<10} {'(spoken) ' if e.speak else ''}{e.message}"

    def render(self, events: bool = True) -> str:
        out = [f"Live replay on {self.url}: trip {self.trip_id}, {self.corridor} / {self.timing}, x{self.speedup:g}"]
        if events:
            out.append("  t after entry  station  speed      advice")
            out += [self.line(e) for e in self.events]
        ign = ", ".join(f"{k} {v}" for k, v in self.ignored.items()) or "none"
        out.append(f"  {self.sent} fixes sent in {self.wall_s:.1f} s, {self.ok} used, ignored: {ign}; {len(self.events)} changes of advice; {self.retries} retries")
        if self.score and self.score.get("savings_frac"):
            s = self.score["savings_frac"]
            from replay.cli import savings_text

            out.append(f"  service's trip score vs its regular driver: {savings_text(s)}")
        return "\n".join(out)


def _post(client: httpx.Client, path: str, timeline: Timeline | None = None, **kw) -> httpx.Response:
    for _ in range(MAX_RETRIES):
        r = client.post(path, **kw)
        if r.status_code != 429:
            return r
        if timeline is not None:
            timeline.retries += 1
        time.sleep(min(float(r.headers.get("Retry-After", "1")), 2.0))
    return r


def replay_live(
    trace: GpsTrace, result, url: str, *, speedup: float = 1.0, vehicle: str | None = None, api_key: str | None = None,
    progress: TextIO | None = None, clock=time.time,
) -> Timeline:  # fmt: skip
    """Send ``trace``'s fixes to the service at ``url`` (see the module docstring); returns the timeline."""
    t = trace.t_s
    duration = float(t[-1] - t[0])
    lag = duration * (1.0 - 1.0 / speedup)
    if lag > MAX_LAG_S:
        raise TraceError(f"a {duration:.0f} s trace at --speedup {speedup:g} would send fixes {lag:.0f} s old (limit {MAX_LAG_S:g} s): lower --speedup")
    shift = clock() + LEAD_S - lag - float(t[0])
    anchor = result.entry_unix_s if result.entry_unix_s is not None else result.zone_entry_unix_s
    zone_entry = result.zone_entry_unix_s + shift
    headers = {"Authorization": f"Bearer {api_key}"} if api_key else {}
    body = {"corridor": result.matched.corridor.name, "entry_unix_s": anchor + shift}
    if result.timing:
        body["timing"] = result.timing
    if vehicle:
        body["vehicle"] = vehicle
    with httpx.Client(base_url=url.rstrip("/"), timeout=10.0) as client:
        try:
            r = _post(client, "/v1/trips", json=body, headers=headers)
        except httpx.HTTPError as exc:
            raise TraceError(f"--server {url}: {exc}") from None
        if r.status_code != 201:
            raise TraceError(f"--server {url}: creating the trip failed ({r.status_code}): {r.text[:300]}")
        trip = r.json()
        tl = Timeline(url, trip["trip_id"], speedup, trip["corridor"], trip["timing"])
        auth = {"Authorization": f"Bearer {trip['token']}"}
        if progress is not None:
            print(f"Replaying {t.size} fixes ({duration:.0f} s) to {url} at x{speedup:g}: trip {tl.trip_id}", file=progress, flush=True)
        start = time.monotonic()
        last_key = None
        for k in range(t.size):
            due = start + LEAD_S / speedup + (t[k] - t[0]) / speedup
            wait = due - time.monotonic()
            if wait > 0:
                time.sleep(wait)
            fix = {"t_unix_s": float(t[k] + shift), "lat_deg": float(trace.lat_deg[k]), "lon_deg": float(trace.lon_deg[k])}
            if math.isfinite(trace.speed_mps[k]):
                fix["speed_mps"] = float(trace.speed_mps[k])
            if math.isfinite(trace.accuracy_m[k]):
                fix["accuracy_m"] = float(trace.accuracy_m[k])
            r = _post(client, f"/v1/trips/{tl.trip_id}/fixes", tl, json=fix, headers=auth)
            tl.sent += 1
            if r.status_code != 200:
                tl.ignored[f"http_{r.status_code}"] = tl.ignored.get(f"http_{r.status_code}", 0) + 1
                continue
            adv = r.json()
            tl.advisories.append(adv)
            if adv["fix_status"] != "ok":
                tl.ignored[adv["fix_status"]] = tl.ignored.get(adv["fix_status"], 0) + 1
                continue
            tl.ok += 1
            key = (adv["action"], adv["reason"], adv.get("target_speed_mps"))
            if key != last_key or adv["speak"]:
                last_key = key
                e = Event(round(fix["t_unix_s"] - zone_entry, 2), round(time.monotonic() - start, 3), adv.get("station_m"), adv.get("speed_mps"),
                          adv["action"], adv["reason"], adv["message"], bool(adv["speak"]))  # fmt: skip
                tl.events.append(e)
                if progress is not None:
                    print(Timeline.line(e), file=progress, flush=True)
        tl.wall_s = time.monotonic() - start
        r = _post(client, f"/v1/trips/{tl.trip_id}/end", tl, headers=auth)
        tl.score = r.json() if r.status_code == 200 else {"error": r.status_code, "body": r.text[:300]}
    return tl
