"""The per-fix metrics kept as plain numbers (server.web.metrics: ``Metrics.count``, ``Latency``) read as prometheus_client's
own counters and histograms would: the same samples for the same increments and observations."""

from __future__ import annotations

import random

from prometheus_client import CollectorRegistry, Histogram, generate_latest

from advisory.advice.views import Advice
from server.web.metrics import LATENCY_BUCKETS_S, Latency, Metrics


def samples(text: bytes, name: str) -> list[str]:
    return sorted(line for line in text.decode().splitlines() if line.startswith(name) and "_created" not in line)


def test_latency_reads_as_prometheus_histogram_on_every_bucket_edge():
    """prometheus_client's Histogram (the independent answer) and Latency given the same values, each bound exactly
    (``le`` is inclusive), between and beyond them, under two labels."""
    rng = random.Random(3)
    values = [*LATENCY_BUCKETS_S, 0.0, 1e-9, 3.0, 1e6] + [rng.expovariate(1 / b) for b in LATENCY_BUCKETS_S for _ in range(40)]
    theirs, ours = CollectorRegistry(), CollectorRegistry()
    reference = Histogram("t_seconds", "doc", ["route"], buckets=LATENCY_BUCKETS_S, registry=theirs)
    latency = Latency("t_seconds", "doc", ("route",), registry=ours)
    for k, v in enumerate(values):
        route = "/a" if k % 3 else "/b"
        reference.labels(route).observe(v)
        latency.observe(v, route)
    assert samples(generate_latest(ours), "t_seconds") == samples(generate_latest(theirs), "t_seconds")
    assert len(samples(generate_latest(ours), "t_seconds")) == 2 * (len(LATENCY_BUCKETS_S) + 3)  # (+Inf, _count, _sum)


def test_counts_are_in_the_metrics_when_read_and_keep_adding_up():
    """``count`` adds to the counter when the metrics are read (``render``), and what is counted after a read is added
    at the next one: 3 fixes, read, 2 more: 5."""
    m = Metrics(lambda: 0)
    advice = Advice("cruise", "green_wave", source="dp_table")
    for _ in range(3):
        m.observe_advice(None, advice, "ok", 0.0003)
    m.count(m.fixes, "duplicate")
    first = m.render()
    assert 'ecodrive_fixes_total{outcome="ok"} 3.0' in first.decode()
    assert 'ecodrive_fixes_total{outcome="duplicate"} 1.0' in first.decode()
    assert 'ecodrive_advice_total{action="cruise",reason="green_wave",source="dp_table"} 3.0' in first.decode()
    assert "ecodrive_advice_compute_seconds_count 3.0" in first.decode()
    for _ in range(2):
        m.observe_advice(None, advice, "ok", 0.002)
    second = m.render().decode()
    assert 'ecodrive_fixes_total{outcome="ok"} 5.0' in second
    assert 'ecodrive_advice_compute_seconds_bucket{le="0.001"} 3.0' in second and 'ecodrive_advice_compute_seconds_bucket{le="0.0025"} 5.0' in second
