"""The city path on loopback: a recorded day played by the feed process into a real MQTT broker (mosquitto),
the advisory service subscribed to it, trips on the Antwerp corridor reading the controller's SPaT.

Needs ``mosquitto`` (``scripts/system-deps.sh`` installs it); skipped with the reason when it is missing.
"""

from __future__ import annotations

import shutil
import socket
import subprocess
import time
from pathlib import Path

import httpx
import pytest

from spat_feed.road.corridors import load_corridor_dir
from spat_feed.timing.messages import PREDICTED_REGION_ID, UNKNOWN_MAX_END_S, to_unix_s
from spat_feed.transport.mqtt import MqttPublisher, MqttSubscriber
from spat_feed.transport.store import SpatStore
from spat_feed.transport.player import read_spat_log

from tests.conftest import recorded_spat_slice
from tests.procs import REPO, Proc, free_port

LIVE_DIR = REPO / "spat_feed" / "presets" / "live"
WAIT_S = 30.0  # bounds only: a broken path fails instead of hanging
MOSQUITTO = shutil.which("mosquitto") or next((p for p in ("/usr/sbin/mosquitto",) if Path(p).exists()), None)

pytestmark = pytest.mark.skipif(MOSQUITTO is None, reason="mosquitto not installed (sh scripts/system-deps.sh installs it)")


class Broker:
    """mosquitto on a loopback port, anonymous, no persistence; can be killed and started again on the same port."""

    def __init__(self, folder: Path) -> None:
        self.folder, self.port, self.proc = folder, free_port(), None
        self.conf = folder / "mosquitto.conf"
        self.conf.write_text(f"listener {self.port} 127.0.0.1\nallow_anonymous true\npersistence false\n")

    @property
    def url(self) -> str:
        return f"mqtt://127.0.0.1:{self.port}/test/spat"

    def start(self) -> Broker:
        log = (self.folder / "mosquitto.log").open("ab")
        self.proc = subprocess.Popen([MOSQUITTO, "-c", str(self.conf)], stdout=log, stderr=subprocess.STDOUT)
        log.close()
        deadline = time.monotonic() + WAIT_S
        while time.monotonic() < deadline:
            with socket.socket() as s:
                if s.connect_ex(("127.0.0.1", self.port)) == 0:
                    return self
            time.sleep(0.05)
        raise RuntimeError(f"mosquitto did not listen: {(self.folder / 'mosquitto.log').read_text()}")

    def kill(self) -> None:
        if self.proc is not None and self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait(timeout=10)
        self.proc = None


@pytest.fixture
def broker(tmp_path):
    b = Broker(tmp_path).start()
    yield b
    b.kill()


def until(what, check, timeout_s: float = WAIT_S, every_s: float = 0.1):
    deadline = time.monotonic() + timeout_s
    while True:
        value = check()
        if value:
            return value
        if time.monotonic() > deadline:
            raise AssertionError(f"not within {timeout_s} s: {what}")
        time.sleep(every_s)


def metric(text: str, name: str, **labels: str) -> float:
    want = ",".join(f'{k}="{v}"' for k, v in labels.items())
    for line in text.splitlines():
        if line.startswith(f"{name}{{") and all(f'{k}="{v}"' in line for k, v in labels.items()):
            return float(line.rsplit(" ", 1)[1])
        if not labels and line.startswith(f"{name} "):
            return float(line.rsplit(" ", 1)[1])
    return 0.0 if want else float("nan")


def test_recorded_day_through_mqtt_reaches_trips_and_survives_a_broker_restart(start_proc, tmp_path, broker):
    log_path = recorded_spat_slice(tmp_path, 1200)
    recorded = read_spat_log(log_path)
    feed = start_proc(Proc(["-m", "spat_feed", "--corridors", "none", "--log", str(log_path), "--loop", "--mqtt", broker.url], tmp_path / "feed.log"))
    svc = start_proc(Proc(["-m", "server", "--log-level", "info", "--no-access-log"], tmp_path / "service.log", {
        "ECO_CORRIDORS": "paper_s200", "ECO_CORRIDOR_DIR": str(LIVE_DIR), "ECO_DEFAULT_CORRIDOR": "antwerp_k648",
        "ECO_SPAT_MQTT_URL": broker.url, "ECO_TABLES": "false", "ECO_SPEECH": "false", "ECO_METRICS_ACCESS": "public",
        "ECO_RATE_PER_S": "50", "ECO_RATE_BURST": "60"}))  # fmt: skip
    corridor = load_corridor_dir(LIVE_DIR)["antwerp_k648"]
    with httpx.Client(base_url=svc.base_url, timeout=10.0) as client:
        r = client.post("/v1/trips", json={"corridor": "antwerp_k648"})
        assert r.status_code == 201, r.text
        trip_id, auth = r.json()["trip_id"], {"Authorization": f"Bearer {r.json()['token']}"}

        def fix(station_m: float = 100.0) -> dict:
            lat, lon = corridor.position(station_m)
            r = client.post(f"/v1/trips/{trip_id}/fixes", json={"t_unix_s": time.time(), "lat_deg": lat, "lon_deg": lon, "speed_mps": 12.0}, headers=auth)
            assert r.status_code == 200, r.text
            return r.json()

        def fix_when(fresh: bool):
            advice = fix()
            return advice if advice["spat_fresh"] is fresh else None

        advice = until("fresh SPaT from the broker", lambda: fix_when(True))
        assert advice["next_intersection_id"] == 648 and advice["reason"] not in ("no_spat", "stale_spat", "clock_skew")
        # (ok: the latest message younger than the stale age; asked until so, a loaded machine may lag a moment)
        health = until("health ok with fresh SPaT", lambda: (h := client.get("/health").json())["status"] == "ok" and h)
        assert [{k: i[k] for k in ("id", "status")} for i in health["spat_health"]["intersections"]] == [{"id": 648, "status": "ok"}]
        assert [s["kind"] for s in health["spat_health"]["sources"]] == ["simulator", "mqtt"]

        # the trip sees the controller's states: the phases and windows of one recorded snapshot, moved onto now
        asked = time.time()
        spat = client.get(f"/v1/trips/{trip_id}/spat", headers=auth).json()
        (seen,) = spat["intersections"]
        assert seen["id"] == 648 and spat["fresh"] == {"648": True}
        stamp = _unix(seen["timestamp"])
        assert asked - 3.0 < stamp < time.time() + 1.0  # moved onto now (fresh: younger than the stale age)

        def shape(states, stamp_s):
            out = []
            for m in states:
                ev = m["stateTimeSpeed"][0] if isinstance(m, dict) else m.state_time_speed[0]
                if isinstance(m, dict):
                    t = ev["timing"]
                    out.append((m["signalGroup"], ev["eventState"], round(_unix(t["minEndTime"]) - stamp_s, 2), round(_unix(t["maxEndTime"]) - stamp_s, 2)))
                else:
                    out.append((m.signal_group, ev.event_state.value, round(to_unix_s(ev.timing.min_end_time) - stamp_s, 2), round(to_unix_s(ev.timing.max_end_time) - stamp_s, 2)))
            return out

        # (a group the latest snapshot omits is served from the one before, while not stale: issue 31, per-group
        # freshness; its windows count from that snapshot's stamp, so only the latest's own groups are compared)
        seen_shape = shape(seen["states"], stamp)

        def carried_by(rec) -> bool:
            own = shape(rec.states, to_unix_s(rec.timestamp))
            return own == seen_shape[: len(own)] and not {g for g, *_ in own} & {g for g, *_ in seen_shape[len(own) :]}

        assert any(carried_by(rec) for rec in recorded), seen_shape

        # J2735 out: the broker's payloads and the trip's SPaT carry each movement's predicted likelyTime and
        # confidence (where a published window bounds the change, from the first message on), marked as ours
        def predicted(events_and_stamps) -> list[bool]:
            return [{"likelyTime", "confidence"} <= ev["timing"].keys() and ev["regional"][0]["regionId"] == PREDICTED_REGION_ID
                    for ev, stamp_s in events_and_stamps if _unix(ev["timing"]["maxEndTime"]) - stamp_s < UNKNOWN_MAX_END_S]  # fmt: skip

        mine = SpatStore()
        sub = MqttSubscriber(broker.url, mine, (648,))
        sub.start()
        payload = until("a payload from the broker", lambda: mine.reading(648)).intersection.model_dump(mode="json", by_alias=True, exclude_none=True)
        sub.stop()
        for got in (predicted((m["stateTimeSpeed"][0], _unix(payload["timestamp"])) for m in payload["states"]),
                    predicted((m["stateTimeSpeed"][0], stamp) for m in seen["states"])):  # fmt: skip
            assert got and all(got), got

        # the broker dies: stale within the stale age (2 s), said plainly; health degraded; one WARNING logged
        last_fresh = fix()
        messages_before_kill = metric(client.get("/metrics").text, "ecodrive_spat_messages_total", intersection="648")
        broker.kill()
        t_kill = time.time()
        answers: list[dict] = []

        def stale_fix():
            answers.append(fix())
            return answers[-1] if answers[-1]["spat_fresh"] is False else None

        advice = until("stale after the broker died", stale_fix, every_s=0.05)
        # every fix stamped later than the stale age + one SPaT period after the kill is answered stale (by the fix's
        # own stamp, not by when its answer came: nothing here depends on how fast this machine serves requests)
        late_fresh = [round(a["t_unix_s"] - t_kill, 2) for a in answers if a["spat_fresh"] and a["t_unix_s"] > t_kill + 2.0 + 1.5]
        assert not late_fresh, f"fresh advice {late_fresh} s after the broker died"
        # no new speed advice on stale data: nothing, or the last fresh advice held through a short dropout
        assert advice["reason"] == "stale_spat" and "Signal data" in advice["message"], advice
        assert advice["action"] in ("none", last_fresh["action"]) and advice["target_speed_mps"] in (None, last_fresh["target_speed_mps"])
        health = client.get("/health").json()
        assert health["status"] == "degraded" and health["spat_health"]["intersections"][0]["status"] == "stale"
        until("WARNING in the service log", lambda: "SPaT of intersection 648: stale" in (tmp_path / "service.log").read_text())

        # back on the same port: publisher and subscriber reconnect by themselves, fresh again
        broker.start()
        until("fresh again after the broker restart", lambda: fix()["spat_fresh"], every_s=0.2)
        until("health ok again", lambda: client.get("/health").json()["status"] == "ok")
        metrics = client.get("/metrics").text
        assert metric(metrics, "ecodrive_spat_source_reconnects_total", kind="mqtt") >= 1
        assert metric(metrics, "ecodrive_spat_messages_total", intersection="648") > messages_before_kill >= 1
        assert metric(metrics, "ecodrive_advice_total", reason="stale_spat") >= 1
    feed.kill()


def test_malformed_duplicate_out_of_order_and_skewed_messages_are_rejected_and_counted(start_proc, tmp_path, broker):
    svc = start_proc(Proc(["-m", "server", "--log-level", "warning", "--no-access-log"], tmp_path / "service.log", {
        "ECO_CORRIDORS": "paper_s200", "ECO_CORRIDOR_DIR": str(LIVE_DIR), "ECO_DEFAULT_CORRIDOR": "antwerp_k648",
        "ECO_SPAT_MQTT_URL": broker.url, "ECO_TABLES": "false", "ECO_SPEECH": "false", "ECO_METRICS_ACCESS": "public"}))  # fmt: skip
    log_path = recorded_spat_slice(tmp_path, 40)
    recorded = read_spat_log(log_path)
    until("the service subscribed", lambda: httpx.get(svc.base_url + "/health").json()["spat_health"]["sources"][-1]["connected"])
    pub = MqttPublisher(broker.url)
    pub.start()
    assert pub.wait_connected(WAIT_S)
    from spat_feed.transport.player import map_times

    now = time.time()
    t0 = to_unix_s(recorded[0].timestamp)
    good = map_times(recorded[0], now - t0, t0)
    older = map_times(recorded[0], now - 1.0 - t0, t0)
    ahead = map_times(recorded[1], now + 30.0 - t0, t0)
    topic = pub.target.topic(648)
    for payload in (good.model_dump_json(by_alias=True), good.model_dump_json(by_alias=True), older.model_dump_json(by_alias=True),
                    ahead.model_dump_json(by_alias=True), b"{not json", b'{"id": 648, "timestamp": "yesterday"}'):  # fmt: skip
        pub.client.publish(topic, payload, qos=1).wait_for_publish(5)
    with httpx.Client(base_url=svc.base_url, timeout=10.0) as client:

        def counts():
            text = client.get("/metrics").text
            return {reason: metric(text, "ecodrive_spat_rejected_total", reason=reason) for reason in ("duplicate", "out_of_order", "clock_ahead", "malformed")}

        def all_counted():
            c = counts()
            return c if c["malformed"] >= 2 and c["clock_ahead"] >= 1 else None

        got = until("every bad message counted", all_counted)
        assert got == {"duplicate": 1.0, "out_of_order": 1.0, "clock_ahead": 1.0, "malformed": 2.0}
        text = client.get("/metrics").text
        assert metric(text, "ecodrive_spat_messages_total", intersection="648") == 1.0
    pub.stop()


def _unix(text: str) -> float:
    from datetime import datetime

    return datetime.fromisoformat(text.replace("Z", "+00:00")).timestamp()


def _p99(values: list[float]) -> float:
    values = sorted(values)
    return values[min(len(values) - 1, int(0.99 * len(values)))]


def test_8_mb_payloads_once_a_second_are_dropped_unparsed_and_never_slow_the_service(start_proc, tmp_path, broker):
    """Issue 30: a source flooding 8 MB payloads once a second (over MAX_SPAT_BYTES: rejected ``too_large``, never
    parsed) while the service answers ``/health``, quiet and flood windows alternated in the same run (the machine's
    other load falls on both). Measured: p99 flooding / quiet x1.2-1.5 on 2 shared cores, x2.04 once on a clean clone
    beside other jobs; parsed, each payload held the GIL ~0.5 s: x10.6. The test asks for under x5, a margin no
    loaded machine closes and a parsed payload cannot meet (the issue's x2 is the bench figure it prints). Three rounds
    (were five): p99 over ~1,250 requests in each state (was ~2,100), x0.89-1.11 measured with three."""
    import threading

    rounds = 3
    svc = start_proc(Proc(["-m", "server", "--log-level", "warning", "--no-access-log"], tmp_path / "service.log", {
        "ECO_CORRIDORS": "paper_s200", "ECO_CORRIDOR_DIR": str(LIVE_DIR), "ECO_DEFAULT_CORRIDOR": "antwerp_k648",
        "ECO_SPAT_MQTT_URL": broker.url, "ECO_TABLES": "false", "ECO_SPEECH": "false", "ECO_METRICS_ACCESS": "public"}))  # fmt: skip
    until("the service subscribed", lambda: httpx.get(svc.base_url + "/health").json()["spat_health"]["sources"][-1]["connected"])
    pub = MqttPublisher(broker.url)
    pub.start()
    assert pub.wait_connected(WAIT_S)
    import json

    one = json.loads(read_spat_log(recorded_spat_slice(tmp_path, 2))[0].model_dump_json(by_alias=True, exclude_none=True))
    movement = json.dumps(one["states"][0]).encode()  # a real movement, repeated to 8 MiB: costly to parse
    n = 8 * 2**20 // (len(movement) + 2)
    one["states"] = []
    head = json.dumps(one).encode()[:-2]  # ... "states": [
    big = head + b", ".join([movement] * n) + b"]}"  # parsing it held the GIL ~0.5 s
    assert len(big) > 7 * 2**20
    flooding, stop, sent = threading.Event(), threading.Event(), [0]

    def flood() -> None:
        while not stop.is_set():
            if flooding.is_set():
                pub.client.publish(pub.target.topic(648), big, qos=0)
                sent[0] += 1
            stop.wait(1.0)

    flooder = threading.Thread(target=flood, daemon=True)
    flooder.start()
    quiet, loud = [], []
    try:
        with httpx.Client(base_url=svc.base_url, timeout=10.0) as client:
            for _ in range(rounds):  # rounds of 2.5 s quiet, 2.5 s flooding (the first payload at once)
                for on, bucket in ((False, quiet), (True, loud)):
                    (flooding.set if on else flooding.clear)()
                    end = time.monotonic() + 2.5
                    while time.monotonic() < end:
                        t = time.perf_counter()
                        assert client.get("/health").status_code == 200
                        bucket.append(time.perf_counter() - t)
                        time.sleep(0.005)
            flooding.clear()
            counted = until("the payloads counted too_large",
                            lambda: (n := metric(client.get("/metrics").text, "ecodrive_spat_rejected_total", reason="too_large")) >= sent[0] - 1 and n)
    finally:
        stop.set()
        flooder.join(5)
        pub.stop()
    assert sent[0] >= 2 * rounds and counted >= sent[0] - 1
    ratio = _p99(loud) / _p99(quiet)
    print(f"/health p99 quiet {_p99(quiet) * 1e3:.2f} ms ({len(quiet)}), flooding {_p99(loud) * 1e3:.2f} ms ({len(loud)}): x{ratio:.2f}; {sent[0]} x 8 MiB")
    assert ratio <= 5.0


def test_forged_spat_is_refused_by_the_shipped_broker_and_by_the_plausibility_rule(start_proc, tmp_path):
    """Issue 30: the broker configuration we ship (spat_feed.transport.broker: no anonymous client, each topic written by
    its controller only, the service read-only) and the forged message of the issue (stamped 0.95 s ahead, green for
    60 s, while K648's recorded red holds): an anonymous publisher is refused; another intersection's credentials
    publish into nothing; K648's own (a compromised controller) is rejected ``implausible``, said in /health and
    /metrics, the red still served; K648's credentials can speak for K648 only (``wrong_topic``)."""
    from spat_feed.transport.broker import write_broker_config
    from spat_feed.transport.player import map_times
    from spat_feed.timing.plans import PhaseClass, phase_class

    from tests.spat_feed.test_store import forged_green

    auth = tmp_path / "mqtt-auth"
    port = free_port()
    conf = write_broker_config(auth, {"k648": (648,), "k649": (649,)}, ("service",), port=port)
    assert "allow_anonymous false" in conf.read_text()
    broker = Broker(tmp_path)
    broker.port, broker.conf = port, conf
    broker.start()
    url = {u: (auth / f"{u}.url").read_text().strip() for u in ("k648", "k649", "service")}
    try:
        svc = start_proc(Proc(["-m", "server", "--log-level", "warning", "--no-access-log"], tmp_path / "service.log", {
            "ECO_CORRIDORS": "paper_s200", "ECO_CORRIDOR_DIR": str(LIVE_DIR), "ECO_DEFAULT_CORRIDOR": "antwerp_k648",
            "ECO_SPAT_MQTT_URL": url["service"], "ECO_TABLES": "false", "ECO_SPEECH": "false", "ECO_METRICS_ACCESS": "public"}))  # fmt: skip
        until("the service subscribed", lambda: httpx.get(svc.base_url + "/health").json()["spat_health"]["sources"][-1]["connected"])
        assert url["service"].split(":")[2].split("@")[0] not in httpx.get(svc.base_url + "/health").text  # no password shown
        recorded = read_spat_log(recorded_spat_slice(tmp_path, 400))
        red = next(s for s in recorded if (m := s.movement(1)) is not None and phase_class(m.state_time_speed[0].event_state) is PhaseClass.RED
                   and to_unix_s(m.state_time_speed[0].timing.min_end_time) - to_unix_s(s.timestamp) > 10.0)  # fmt: skip
        t0 = to_unix_s(red.timestamp)

        def now_red():
            return map_times(red, time.time() - t0, t0)

        anonymous = MqttPublisher(f"mqtt://127.0.0.1:{port}/ecodrive/spat")
        anonymous.start()
        assert not anonymous.wait_connected(2.0)  # refused: not authorised
        anonymous.stop()
        k648, k649 = MqttPublisher(url["k648"]), MqttPublisher(url["k649"])
        for pub in (k648, k649):
            pub.start()
            assert pub.wait_connected(WAIT_S)
        with httpx.Client(base_url=svc.base_url, timeout=10.0) as client:

            def count(name: str, **labels) -> float:
                return metric(client.get("/metrics").text, name, intersection="648", **labels)

            k648.client.publish(k648.target.topic(648), now_red().model_dump_json(by_alias=True), qos=1).wait_for_publish(5)
            until("K648's red stored", lambda: count("ecodrive_spat_messages_total") == 1.0)
            forged = forged_green(now_red(), time.time() + 0.95).model_dump_json(by_alias=True)
            k649.client.publish(k649.target.topic(648), forged, qos=1).wait_for_publish(5)  # K649 writing K648's topic
            k648.client.publish(k648.target.topic(648), now_red().model_dump_json(by_alias=True), qos=1).wait_for_publish(5)
            until("K648's next red stored", lambda: count("ecodrive_spat_messages_total") == 2.0)
            assert count("ecodrive_spat_rejected_total", reason="implausible") == 0.0  # K649's never reached the service
            k648.client.publish(k648.target.topic(648), forged_green(now_red(), time.time() + 0.95).model_dump_json(by_alias=True), qos=1).wait_for_publish(5)
            until("the controller's own forged green rejected", lambda: count("ecodrive_spat_rejected_total", reason="implausible") == 1.0)
            assert count("ecodrive_spat_messages_total") == 2.0 and count("ecodrive_spat_fresh", status="ok") == 1.0  # its red still served
            health = client.get("/health").json()
            item = next(i for i in health["spat_health"]["intersections"] if i["id"] == 648)
            assert item["rejected"] == {"implausible": 1} and item["implausible_s_ago"] >= 0.0 and health["status"] == "degraded"
            # K648's credentials, K649's state on K648's topic: not K648's to say
            k648.client.publish(k648.target.topic(648), now_red().model_copy(update={"id": 649}).model_dump_json(by_alias=True), qos=1).wait_for_publish(5)
            until("another intersection's state on K648's topic rejected", lambda: count("ecodrive_spat_rejected_total", reason="wrong_topic") == 1.0)
        for pub in (k648, k649):
            pub.stop()
    finally:
        broker.kill()


@pytest.mark.skipif(shutil.which("openssl") is None, reason="openssl not installed")
def test_the_shipped_broker_over_tls_takes_its_users_and_refuses_plain_mqtt(tmp_path):
    """``--tls`` (a broker reached across networks): a controller's message reaches the reader over mqtts:// with the
    broker's certificate checked; a client speaking plain MQTT to it never connects."""
    from spat_feed.transport.broker import write_broker_config

    auth, port = tmp_path / "mqtt-auth", free_port()
    conf = write_broker_config(auth, {"k648": (648,)}, ("service",), port=port, host="127.0.0.1", tls=True)
    broker = Broker(tmp_path)
    broker.port, broker.conf = port, conf
    broker.start()
    try:
        url = {u: (auth / f"{u}.url").read_text().strip() for u in ("k648", "service")}
        assert url["service"].startswith("mqtts://") and "?ca=" in url["service"]
        store = SpatStore()
        sub, pub = MqttSubscriber(url["service"], store, (648,)), MqttPublisher(url["k648"])
        for c in (sub, pub):
            c.start()
            assert c.wait_connected(WAIT_S)
        pub.client.publish(pub.target.topic(648), b"{}", qos=1).wait_for_publish(5)
        until("the message over TLS", lambda: sub.messages == 1)
        plain = MqttPublisher(url["k648"].replace("mqtts://", "mqtt://").split("?")[0])
        plain.start()
        assert not plain.wait_connected(2.0)
        for c in (sub, pub, plain):
            c.stop()
    finally:
        broker.kill()
