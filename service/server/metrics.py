"""Prometheus metrics, one registry per app (tests build many apps in one process)."""

from __future__ import annotations

from prometheus_client import CollectorRegistry, Counter, Gauge, Histogram, generate_latest
from prometheus_client.exposition import CONTENT_TYPE_LATEST

# Seconds: from a cache hit (~1 ms) to the slowest outfit worth waiting for.
BUCKETS = (0.005, 0.01, 0.025, 0.05, 0.1, 0.15, 0.25, 0.5, 1, 2.5, 5, 10, 30, 60, 120)
CONTENT_TYPE = CONTENT_TYPE_LATEST


class Metrics:
    def __init__(self) -> None:
        self.registry = CollectorRegistry()
        r = self.registry
        self.requests = Counter(
            "ulnef_http_requests", "HTTP requests by route template and status.",
            ["method", "route", "status"], registry=r,
        )  # fmt: skip
        self.latency = Histogram(
            "ulnef_http_request_seconds", "HTTP request latency by route template.",
            ["method", "route"], buckets=BUCKETS, registry=r,
        )  # fmt: skip
        self.stage = Histogram(
            "ulnef_outfit_stage_seconds", "Seconds per pipeline stage (the report's `seconds` keys).",
            ["stage"], buckets=BUCKETS, registry=r,
        )  # fmt: skip
        self.cache = Counter("ulnef_outfit_cache", "Outfit cache lookups.", ["result"], registry=r)
        self.cache_entries = Gauge("ulnef_outfit_cache_entries", "Outfits in the cache.", registry=r)
        self.cache_bytes = Gauge("ulnef_outfit_cache_bytes", "Bytes of GLB in the cache.", registry=r)
        self.queue_depth = Gauge("ulnef_queue_depth", "Outfits running or waiting for a worker.", registry=r)
        self.running = Gauge("ulnef_queue_running", "Outfits being computed.", registry=r)
        self.rejected = Counter(
            "ulnef_outfit_rejected",
            "Outfit requests refused or abandoned, by reason.",
            ["reason"],
            registry=r,
        )
        self.fallbacks = Counter(
            "ulnef_outfit_numerical_fallback", "Garments served unfitted after a numerical fault.", registry=r
        )
        self.with_crossings = Counter(
            "ulnef_outfit_with_crossings",
            "Outfits served with layers still crossing after the repair (report collision_free false).",
            registry=r,
        )
        self.ready = Gauge("ulnef_ready", "1 once models are loaded and the self-test passed.", registry=r)

    def observe_stages(self, seconds: dict[str, float]) -> None:
        for stage, value in seconds.items():
            self.stage.labels(stage).observe(value)

    def render(self) -> bytes:
        return generate_latest(self.registry)
