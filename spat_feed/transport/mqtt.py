"""SPaT over MQTT: one topic per intersection, the latest state retained; a publisher and a subscriber (paho-mqtt).

Cities publish live traffic-light data over MQTT (Hamburg's SensorThings/MQTT service, for one). Our layout:

* **Topic** ``<prefix>/<intersection id>``, default prefix ``ecodrive/spat`` (e.g. ``ecodrive/spat/648``).
* **Payload**: one :class:`~spat_feed.timing.messages.IntersectionState` as JSON, camelCase, UTC times ending in
  ``Z`` (the schema of ``GET /spat``'s items, docs/SPAT.md). A whole
  :class:`~spat_feed.timing.messages.SpatMessage` is accepted too.
* **QoS 0, retained**: SPaT is a latest-value stream; a lost message is replaced by the next one (0.1-1 s), and
  a new subscriber gets each intersection's last state at once (the store's time rules judge its age).

URL: ``mqtt://[user:password@]host[:port][/prefix]`` (port 1883 by default); ``mqtts://...[?ca=FILE]`` over TLS
(port 8883), the broker's certificate checked against ``FILE`` (else the system's CAs) and its host name.

:class:`MqttSubscriber` runs paho's network thread (reconnecting with backoff by itself) and offers every
state to a :class:`~spat_feed.transport.store.SpatStore`, which is thread-safe; malformed payloads are counted there,
and payloads over ``MAX_SPAT_BYTES`` are dropped unparsed (``too_large``).
"""

from __future__ import annotations

import logging
import re
import threading
import time
from dataclasses import dataclass
from urllib.parse import parse_qs, unquote, urlsplit

import paho.mqtt.client as paho
from pydantic import ValidationError

from spat_feed.timing.messages import IntersectionState, SpatMessage
from spat_feed.transport.store import MAX_SPAT_BYTES, SpatStore

log = logging.getLogger("spat_feed.transport.mqtt")

DEFAULT_PREFIX = "ecodrive/spat"


@dataclass(frozen=True, slots=True)
class MqttTarget:
    """Where the broker is and the topic prefix."""

    host: str
    port: int = 1883
    prefix: str = DEFAULT_PREFIX
    username: str | None = None
    password: str | None = None
    ca_file: str | None = None  # mqtts: the CA that signed the broker's certificate (None: the system's)
    tls: bool = False

    def topic(self, intersection_id: int | str) -> str:
        return f"{self.prefix}/{intersection_id}"


def parse_mqtt_url(url: str) -> MqttTarget:
    """``mqtt://user:pw@host:1884/city/spat`` -> :class:`MqttTarget`; ``mqtts://...[?ca=FILE]``: over TLS (port 8883).

    Examples
    --------
    >>> parse_mqtt_url("mqtt://127.0.0.1:1884/city/spat")
    MqttTarget(host='127.0.0.1', port=1884, prefix='city/spat', username=None, password=None, ca_file=None, tls=False)
    >>> parse_mqtt_url("mqtt://broker").prefix
    'ecodrive/spat'
    >>> t = parse_mqtt_url("mqtts://svc:pw@broker/ecodrive/spat?ca=/run/ca.crt"); (t.port, t.tls, t.ca_file)
    (8883, True, '/run/ca.crt')
    """
    parts = urlsplit(url)
    if parts.scheme not in ("mqtt", "mqtts") or not parts.hostname:
        raise ValueError(f"not an MQTT URL {url!r}: expected mqtt[s]://host[:port][/prefix]")
    tls = parts.scheme == "mqtts"
    ca = parse_qs(parts.query).get("ca", [None])[0]
    prefix = parts.path.strip("/") or DEFAULT_PREFIX
    if any(c in prefix for c in "+#"):
        raise ValueError(f"the topic prefix {prefix!r} may not hold MQTT wildcards")
    user = unquote(parts.username) if parts.username else None
    password = unquote(parts.password) if parts.password else None
    return MqttTarget(parts.hostname, parts.port or (8883 if tls else 1883), prefix, user, password, ca, tls)


def redacted(url: str) -> str:
    """The URL without its password (for logs and ``/health``).

    Examples
    --------
    >>> redacted("mqtt://k648:s3cret@broker:1883/ecodrive/spat")
    'mqtt://k648:***@broker:1883/ecodrive/spat'
    """
    return re.sub(r"^(mqtts?://[^:@/]+):[^@/]*@", r"\1:***@", url)


def _client(target: MqttTarget, name: str) -> paho.Client:
    client = paho.Client(paho.CallbackAPIVersion.VERSION2, client_id=f"{name}-{threading.get_ident() % 100000}-{time.monotonic_ns() % 10**6}", protocol=paho.MQTTv311)
    if target.username:
        client.username_pw_set(target.username, target.password)
    if target.tls:
        client.tls_set(ca_certs=target.ca_file)  # the broker's certificate and host name verified
    client.reconnect_delay_set(min_delay=1, max_delay=5)
    return client


def parse_payload(payload: bytes) -> list[IntersectionState]:
    """The intersection states of one MQTT payload; ``ValueError`` with a short reason if it is none."""
    try:
        if payload.lstrip()[:1] == b"{" and b'"intersections"' in payload:
            return list(SpatMessage.model_validate_json(payload).intersections)
        return [IntersectionState.model_validate_json(payload)]
    except ValidationError as exc:
        raise ValueError("; ".join(f"{'.'.join(map(str, e['loc']))}: {e['msg']}" for e in exc.errors(include_url=False)[:3])) from None


class _Connection:
    """paho's client with its network thread, connection state and counters."""

    def __init__(self, url: str, name: str) -> None:
        self.target = parse_mqtt_url(url)
        self.url = redacted(url)
        self.client = _client(self.target, name)
        self.connected = threading.Event()
        self.connects = 0
        self.disconnects = 0
        self.client.on_connect = self._on_connect
        self.client.on_disconnect = self._on_disconnect

    def _on_connect(self, client, userdata, flags, reason_code, properties) -> None:
        if reason_code.is_failure:
            log.warning("MQTT broker %s refused the connection: %s", self.url, reason_code)
            return
        self.connects += 1
        if self.connects > 1:
            log.warning("MQTT broker %s: connected again", self.url)
        self.connected.set()
        self.on_connected()

    def on_connected(self) -> None:
        """Hook: (re)subscribe."""

    def _on_disconnect(self, client, userdata, flags, reason_code, properties) -> None:
        if self.connected.is_set():
            self.disconnects += 1
            log.warning("MQTT broker %s: connection lost (%s); reconnecting", self.url, reason_code)
        self.connected.clear()

    def start(self) -> None:
        self.client.connect_async(self.target.host, self.target.port, keepalive=10)
        self.client.loop_start()

    def stop(self) -> None:
        self.client.disconnect()
        self.client.loop_stop()
        self.connected.clear()

    def wait_connected(self, timeout_s: float) -> bool:
        return self.connected.wait(timeout_s)


class MqttPublisher(_Connection):
    """Publishes intersection states, each to its intersection's topic (QoS 0, retained)."""

    def __init__(self, url: str) -> None:
        super().__init__(url, "ecodrive-pub")
        self.published = 0

    def __call__(self, state: IntersectionState) -> None:
        """Publish one state (dropped while disconnected: SPaT is a latest-value stream)."""
        if not self.connected.is_set():
            return
        payload = state.model_dump_json(by_alias=True, exclude_none=True)
        self.client.publish(self.target.topic(state.id), payload, qos=0, retain=True)
        self.published += 1


class MqttSubscriber(_Connection):
    """Subscribes to ``<prefix>/<id>`` for each intersection in ``intersection_ids`` (all: ``<prefix>/+``)
    and offers every state received to ``store``."""

    def __init__(self, url: str, store: SpatStore, intersection_ids: tuple[int, ...] | None = None, max_bytes: int = MAX_SPAT_BYTES) -> None:
        super().__init__(url, "ecodrive-sub")
        self.store = store
        self.max_bytes = max_bytes
        self.topics = [self.target.topic(i) for i in intersection_ids] if intersection_ids else [self.target.topic("+")]
        self.messages = 0
        self.client.on_message = self._on_message

    def on_connected(self) -> None:
        self.client.subscribe([(t, 0) for t in self.topics])

    def _on_message(self, client, userdata, msg) -> None:
        self.messages += 1
        received = self.store.clock()
        if len(msg.payload) > self.max_bytes:  # never parsed: a flood of large payloads costs a length check each
            ident = msg.topic.rpartition("/")[2]
            self.store.reject("too_large", int(ident) if ident.isdigit() else None, f"{msg.topic}: {len(msg.payload)} bytes")
            return
        try:
            states = parse_payload(msg.payload)
        except ValueError as exc:
            self.store.reject("malformed", None, f"{msg.topic}: {exc}")
            log.info("malformed SPaT on %s: %s", msg.topic, exc)
            return
        ident = msg.topic.rpartition("/")[2]
        for state in states:
            if str(state.id) != ident:  # a controller may write its own topic only (the broker's ACL): its own states only
                self.store.reject("wrong_topic", int(ident) if ident.isdigit() else None, f"{msg.topic}: intersection {state.id}")
                continue
            self.store.offer(state, received)
