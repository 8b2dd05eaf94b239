"""Prometheus metrics of one app instance (its own registry, so several apps can live in one process)."""

from __future__ import annotations

from collections.abc import Callable

from prometheus_client import CollectorRegistry, Counter, Gauge, Histogram, ProcessCollector, generate_latest
from prometheus_client.exposition import CONTENT_TYPE_LATEST

__all__ = ["Metrics", "CONTENT_TYPE_LATEST"]

LATENCY_BUCKETS_S = (0.0005, 0.001, 0.0025, 0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0, 2.5)


class Metrics:
    def __init__(self, open_trips: Callable[[], int]) -> None:
        r = self.registry = CollectorRegistry(auto_describe=True)
        self._children: dict[tuple, object] = {}
        self.requests = Counter("ecodrive_http_requests", "HTTP requests by route and status", ["method", "route", "status"], registry=r)
        self.request_s = Histogram("ecodrive_http_request_seconds", "HTTP request handling time", ["route"], buckets=LATENCY_BUCKETS_S, registry=r)
        self.fixes = Counter("ecodrive_fixes", "GPS fixes by outcome", ["outcome"], registry=r)
        self.advice = Counter("ecodrive_advice", "advisories by action and source", ["action", "source"], registry=r)
        self.advice_s = Histogram("ecodrive_advice_compute_seconds", "time to compute one advisory from a fix", buckets=LATENCY_BUCKETS_S, registry=r)
        self.trips_created = Counter("ecodrive_trips_created", "trips created", registry=r)
        self.trips_closed = Counter("ecodrive_trips_closed", "trips closed", ["how"], registry=r)
        self.rate_limited = Counter("ecodrive_rate_limited", "requests refused by a rate limit", registry=r)
        self.ws_open = Gauge("ecodrive_ws_connections", "open WebSocket streams", registry=r)
        self.trips_open = Gauge("ecodrive_trips_open", "open trips", registry=r)
        self.trips_open.set_function(open_trips)
        ProcessCollector(registry=r)  # process_resident_memory_bytes, process_open_fds, process_max_fds, CPU seconds (Linux /proc)

    def observe_advice(self, trip, advice, outcome: str, seconds: float) -> None:
        self.child(self.fixes, outcome).inc()
        self.child(self.advice, advice.action, advice.source).inc()
        self.advice_s.observe(seconds)

    def child(self, metric, *labels: str):
        """``metric.labels(*labels)``, memoised: the hot path pays a dict lookup, not prometheus' label checks."""
        key = (id(metric), labels)
        child = self._children.get(key)
        if child is None:
            child = self._children[key] = metric.labels(*labels)
        return child

    def render(self) -> bytes:
        return generate_latest(self.registry)
