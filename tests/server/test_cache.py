"""The outfit LRU cache: bounded by entries and by bytes, least recently used out first."""

from __future__ import annotations

from service.pipeline.tryon import OutfitResult, OutfitSpec
from service.server.cache import OutfitCache


def item(n: int) -> OutfitResult:
    return OutfitResult(b"x" * n, {})


def test_evicts_least_recently_used_by_count():
    cache = OutfitCache(max_entries=2, max_bytes=1000)
    cache.put("a", item(1))
    cache.put("b", item(1))
    assert cache.get("a") is not None  # a is now the most recent
    cache.put("c", item(1))
    assert cache.get("b") is None and cache.get("a") and cache.get("c")


def test_evicts_by_bytes_and_skips_items_over_the_budget():
    cache = OutfitCache(max_entries=10, max_bytes=100)
    cache.put("a", item(60))
    cache.put("b", item(60))
    assert cache.get("a") is None and len(cache) == 1 and cache.nbytes == 60
    cache.put("huge", item(101))
    assert cache.get("huge") is None and cache.get("b") is not None


def test_disabled_cache_keeps_nothing():
    cache = OutfitCache(max_entries=0, max_bytes=100)
    cache.put("a", item(1))
    assert cache.get("a") is None


def test_outfit_ids_depend_on_request_and_model_version():
    spec = OutfitSpec(("tshirt", "jacket"), gender=0.5, height_cm=170.0, weight_kg=70.0)
    same = OutfitSpec(("tshirt", "jacket"), gender=0.5, height_cm=170, weight_kg=70)
    assert spec.outfit_id("v1") == same.outfit_id("v1")
    assert spec.outfit_id("v1") != spec.outfit_id("v2")
    assert spec.outfit_id("v1") != OutfitSpec(("jacket", "tshirt"), 0.5, 170.0, 70.0).outfit_id("v1")
    assert len(spec.outfit_id("v1")) == 32
