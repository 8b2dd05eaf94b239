"""Prometheus metrics of one app instance (its own registry, so several apps can live in one process)."""

from __future__ import annotations

import math
from bisect import bisect_left
from collections.abc import Callable
from itertools import accumulate

from prometheus_client import CollectorRegistry, Counter, Gauge, ProcessCollector, generate_latest
from prometheus_client.core import CounterMetricFamily, GaugeMetricFamily, HistogramMetricFamily
from prometheus_client.exposition import CONTENT_TYPE_LATEST
from prometheus_client.utils import floatToGoString

__all__ = ["Metrics", "CONTENT_TYPE_LATEST"]

LATENCY_BUCKETS_S = (0.0005, 0.001, 0.0025, 0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0, 2.5)


class SpatCollector:
    """SPaT per intersection and per source, read from the hub at each scrape (nothing on the hot path):
    ``ecodrive_spat_age_seconds``, ``ecodrive_spat_fresh`` (1 when ok), ``ecodrive_spat_clock_offset_seconds``, ``ecodrive_spat_messages_total``
    (``rate()`` gives messages/s), ``ecodrive_spat_rejected_total`` by reason, and per source
    ``ecodrive_spat_source_connected`` and ``ecodrive_spat_source_reconnects_total``."""

    def __init__(self, hub: Callable[[], object | None]) -> None:
        self.hub = hub

    def collect(self):
        hub = self.hub()
        if hub is None:
            return
        store = hub.store
        age = GaugeMetricFamily("ecodrive_spat_age_seconds", "age of the latest SPaT state (controller timestamp)", labels=["intersection"])
        fresh = GaugeMetricFamily("ecodrive_spat_fresh", "1 when the intersection's SPaT is fresh (status ok)", labels=["intersection", "status"])
        messages = CounterMetricFamily("ecodrive_spat_messages", "SPaT states accepted", labels=["intersection"])
        rejected = CounterMetricFamily("ecodrive_spat_rejected", "SPaT states rejected, by reason", labels=["intersection", "reason"])
        offset = GaugeMetricFamily("ecodrive_spat_clock_offset_seconds", "arrival - controller timestamp (its floor; clock_skew beyond the tolerance)", labels=["intersection"])
        readings = store.readings()
        for ident in sorted(set(hub.needed) | set(store.stats)):
            label = str(ident)
            r = readings.get(ident)
            if r is not None:
                age.add_metric([label], r.age_s)
                offset.add_metric([label], r.clock_offset_s)
            status = store.status(ident)
            fresh.add_metric([label, status], 1.0 if status == "ok" else 0.0)
            st = store.stats.get(ident)
            messages.add_metric([label], st.messages if st else 0)
            for reason, n in (st.rejected.items() if st else ()):
                rejected.add_metric([label, reason], n)
        for reason in ("malformed", "too_large"):  # those not told to an intersection (malformed: never)
            n = store.rejected[reason] - sum(st.rejected[reason] for st in list(store.stats.values()))
            if n:
                rejected.add_metric(["", reason], n)
        connected = GaugeMetricFamily("ecodrive_spat_source_connected", "1 when the SPaT source is connected (or playing)", labels=["kind"])
        reconnects = CounterMetricFamily("ecodrive_spat_source_reconnects", "reconnections of the SPaT source", labels=["kind"])
        for source in hub.sources():
            connected.add_metric([source["kind"]], 1.0 if source["connected"] else 0.0)
            if "reconnects" in source:
                reconnects.add_metric([source["kind"]], source["reconnects"])
        yield from (age, fresh, offset, messages, rejected, connected, reconnects)


class QueueBoardCollector:
    """The queue board's storage (server.storage.queue_store), read at each scrape: ``ecodrive_queue_board_shared`` (1 while every
    worker's probes are shared through Redis, 0 while this worker counts its own trips only) and
    ``ecodrive_queue_board_sync_failures_total``. Nothing when queue-aware advice is off or the store is in process."""

    def __init__(self, board: Callable[[], object | None]) -> None:
        self.board = board

    def collect(self):
        board = self.board()
        shared = getattr(board, "shared", None)
        if shared is None:
            return
        up = GaugeMetricFamily("ecodrive_queue_board_shared", "1 while the queue board holds every worker's probes (Redis), 0: this worker's trips only")
        up.add_metric([], 1.0 if shared.down is None else 0.0)
        failures = CounterMetricFamily("ecodrive_queue_board_sync_failures", "the queue board's calls to Redis that failed")
        failures.add_metric([], shared.failures)
        yield from (up, failures)


class Latency:
    """A histogram by labels kept as plain bucket counts: one ``bisect`` and two additions an observation, where
    prometheus_client's ``Histogram`` takes a labelled child, a lock and a loop over its buckets (~3.4 us). A scrape reads
    the same ``_bucket`` (cumulative, ``le`` as prometheus_client writes it), ``_count`` and ``_sum`` samples. [s]"""

    def __init__(self, name: str, documentation: str, labelnames: tuple[str, ...] = (), buckets=LATENCY_BUCKETS_S, registry=None) -> None:
        self.name, self.documentation, self.labelnames = name, documentation, tuple(labelnames)
        self.bounds = tuple(float(b) for b in buckets)
        self.le = [floatToGoString(b) for b in (*self.bounds, math.inf)]
        self.series: dict[tuple[str, ...], list] = {}  # labels -> counts per bucket (+Inf last), then the sum
        if registry is not None:
            registry.register(self)

    def observe(self, seconds: float, *labels: str) -> None:
        counts = self.series.get(labels)
        if counts is None:
            counts = self.series[labels] = [0] * (len(self.bounds) + 1) + [0.0]
        counts[bisect_left(self.bounds, seconds)] += 1  # (the first bound >= seconds: le is inclusive)
        counts[-1] += seconds

    def describe(self):
        return [HistogramMetricFamily(self.name, self.documentation, labels=self.labelnames)]

    def collect(self):
        family = HistogramMetricFamily(self.name, self.documentation, labels=self.labelnames)
        for labels, counts in list(self.series.items()):
            family.add_metric(list(labels), list(zip(self.le, accumulate(counts[:-1]))), counts[-1])
        yield family


class Metrics:
    def __init__(self, open_trips: Callable[[], int], spat_hub: Callable[[], object | None] | None = None,
                 queue_board: Callable[[], object | None] | None = None) -> None:  # fmt: skip
        r = self.registry = CollectorRegistry(auto_describe=True)
        self._children: dict[tuple, object] = {}
        self._counts: dict[tuple, int] = {}  # (counter, labels) -> increments not yet added to it (:meth:`count`)
        self.requests = Counter("ecodrive_http_requests", "HTTP requests by route and status", ["method", "route", "status"], registry=r)
        self.request_s = Latency("ecodrive_http_request_seconds", "HTTP request handling time", ("route",), registry=r)
        self.fixes = Counter("ecodrive_fixes", "GPS fixes by outcome", ["outcome"], registry=r)
        self.advice = Counter("ecodrive_advice", "advisories by action, source and reason (no_spat, stale_spat, clock_skew, low_confidence, ...)", ["action", "source", "reason"], registry=r)
        self.advice_s = Latency("ecodrive_advice_compute_seconds", "time to compute one advisory from a fix", registry=r)
        self.trips_created = Counter("ecodrive_trips_created", "trips created", registry=r)
        self.trips_closed = Counter("ecodrive_trips_closed", "trips closed", ["how"], registry=r)
        self.rate_limited = Counter("ecodrive_rate_limited", "requests refused by a rate limit", registry=r)
        self.ws_open = Gauge("ecodrive_ws_connections", "open WebSocket streams", registry=r)
        self.trips_open = Gauge("ecodrive_trips_open", "open trips", registry=r)
        self.trips_open.set_function(open_trips)
        if spat_hub is not None:
            r.register(SpatCollector(spat_hub))
        if queue_board is not None:
            r.register(QueueBoardCollector(queue_board))
        ProcessCollector(registry=r)  # process_resident_memory_bytes, process_open_fds, process_max_fds, CPU seconds (Linux /proc)

    def observe_advice(self, trip, advice, outcome: str, seconds: float) -> None:
        self.count(self.fixes, outcome)
        self.count(self.advice, advice.action, advice.source, advice.reason)
        self.advice_s.observe(seconds)

    def count(self, counter: Counter, *labels: str) -> None:
        """``counter.labels(*labels).inc()``, batched: an int in a dict here, added to the counter when the metrics are
        read (:meth:`render`). Per fix and per request: ~1 us against ~11 for prometheus_client's child and lock per
        increment, on every fix (issue 30: CPU per fix)."""
        key = (counter, labels)
        self._counts[key] = self._counts.get(key, 0) + 1

    def child(self, metric, *labels: str):
        """``metric.labels(*labels)``, memoised: the hot path pays a dict lookup, not prometheus' label checks."""
        key = (id(metric), labels)
        child = self._children.get(key)
        if child is None:
            child = self._children[key] = metric.labels(*labels)
        return child

    def render(self) -> bytes:
        counts, self._counts = self._counts, {}
        for (counter, labels), n in counts.items():
            self.child(counter, *labels).inc(n)
        return generate_latest(self.registry)
