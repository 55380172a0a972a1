"""benchmarks/loadgen: the load mixes are valid requests, targets are loopback only, stats are right."""

from __future__ import annotations

import asyncio

import numpy as np
import pytest

from benchmarks.loadgen import (
    Catalog,
    Result,
    Stats,
    back_off,
    check_loopback,
    make_requests,
    random_body,
)
from benchmarks.memory import covering_outfits
from service.pipeline.body import BodyModel, shape_from_measurements

LISTING = {"garments": [
    {"id": "pants", "category": "bottom", "layer_rank": 0},
    {"id": "jacket", "category": "top", "layer_rank": 3},
    {"id": "tshirt", "category": "top", "layer_rank": 1},
    {"id": "skirt", "category": "bottom", "layer_rank": 0},
    {"id": "tank_top", "category": "top", "layer_rank": 0},
    {"id": "long_sleeve", "category": "top", "layer_rank": 2},
    {"id": "shorts", "category": "bottom", "layer_rank": 0},
]}  # fmt: skip
TOP_ORDER = ["tank_top", "tshirt", "long_sleeve", "jacket"]


@pytest.fixture(scope="module")
def catalog() -> Catalog:
    return Catalog.from_listing(LISTING)


def test_catalog_orders_tops_by_layer_rank(catalog):
    assert catalog.tops == tuple(TOP_ORDER)
    assert catalog.bottoms == ("pants", "skirt", "shorts")


@pytest.mark.parametrize("n", [1, 2, 3, 4])
def test_random_outfits_stack_tops_and_hold_one_bottom(catalog, n):
    rng = np.random.default_rng(n)
    positions = set()
    for _ in range(50):
        outfit = catalog.random_outfit(rng, n)
        assert len(outfit) == n == len(set(outfit))
        tops = [g for g in outfit if g in TOP_ORDER]
        bottoms = [g for g in outfit if g in catalog.bottoms]
        assert len(bottoms) <= 1 and len(tops) + len(bottoms) == n
        assert tops == sorted(tops, key=TOP_ORDER.index)
        positions.update(outfit.index(b) for b in bottoms)
    if n > 1:
        assert len(positions) > 1, "bottoms go both under (tucked) and over tops"


def test_outfit_size_out_of_range(catalog):
    with pytest.raises(ValueError, match="cannot make an outfit of 6"):
        catalog.random_outfit(np.random.default_rng(0), 6)


def test_random_bodies_are_inside_the_supported_range():
    body = BodyModel.load()
    rng = np.random.default_rng(0)
    for _ in range(20):
        b = random_body(rng, body)
        beta = shape_from_measurements(body, b["gender"], b["height_cm"], b["weight_kg"])
        assert beta.shape == (3,)


def test_requests_follow_the_api_contract(catalog):
    (request,) = make_requests(np.random.default_rng(0), catalog, BodyModel.load(), 1, [3])
    assert set(request) == {"garments", "body", "options"}
    assert set(request["body"]) == {"gender", "height_cm", "weight_kg"} and len(request["garments"]) == 3


def test_covering_outfits_use_every_garment_once(catalog):
    outfits = covering_outfits(catalog.tops, catalog.bottoms)
    used = [g for o in outfits for g in o]
    assert sorted(used) == sorted(TOP_ORDER + list(catalog.bottoms)) and max(map(len, outfits)) <= 4


@pytest.mark.parametrize("url", ["http://127.0.0.1:8000/", "http://localhost:1", "http://[::1]:80", "http://127.8.0.1"])
def test_loopback_targets_accepted(url):
    assert check_loopback(url) == url.rstrip("/")


@pytest.mark.parametrize("url", ["http://10.0.0.1:8000", "http://example.com", "http://192.168.1.2", "http://0.0.0.0"])
def test_other_targets_refused(url):
    with pytest.raises(ValueError, match="only loopback targets"):
        check_loopback(url)


def test_stats_percentiles_throughput_and_failures():
    ok = [Result(1, s / 1000, 200) for s in range(1, 101)]
    failed = [Result(2, 0.5, 503), Result(2, 0.5, 503), Result(1, 9.0, 0, error="ReadTimeout")]
    stats = Stats.of(ok + failed, wall_s=10.0)
    assert (stats.sent, stats.ok, stats.rejected, stats.errors) == (103, 100, 2, 1)
    assert stats.p50_ms == pytest.approx(50.5) and stats.p99_ms == pytest.approx(99.01)
    assert stats.throughput == pytest.approx(10.0) and stats.statuses == "0x1, 503x2"


def test_back_off_waits_what_retry_after_says_at_most_five_seconds(monkeypatch):
    slept = []

    async def fake_sleep(seconds):
        slept.append(seconds)

    monkeypatch.setattr("benchmarks.loadgen.asyncio.sleep", fake_sleep)
    for result in (Result(1, 0.1, 503, retry_after_s=2.0), Result(1, 0.1, 429, retry_after_s=60.0),
                   Result(1, 0.1, 504), Result(1, 0.1, 200), Result(1, 0.1, 422)):
        asyncio.run(back_off(result))
    assert slept == [2.0, 5.0, 1.0]
