"""Garment traits read off the geometry (``collisions.traits``): what they say of each bundled garment
and of a dress, and that the decisions made from them are, for all 42 ordered pairs of the bundled
catalog, exactly those the category rules they replace made."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from service.pipeline.collisions.layering import LayeringRule
from service.pipeline.collisions.squeeze import asks_segment_test
from service.pipeline.collisions.traits import BodyLevels, traits_of, tucked, worn_alike


@pytest.fixture(scope="module")
def catalog_rule():
    from service.pipeline.body import DEFAULT_BETA, BodyModel
    from service.pipeline.catalog import load_catalog

    body = BodyModel.load()
    return LayeringRule(body.vertices(np.asarray(DEFAULT_BETA)), body.faces), dict(load_catalog())


@pytest.fixture(scope="module")
def dress(catalog_rule):
    """A strapless dress from ``tests/garment_files.py`` (welded, on the mean body), as the rule sees it."""
    from types import SimpleNamespace

    from service.pipeline.body import BodyModel
    from tests.garment_files import dress_tube, welded

    v, f, _ = dress_tube(BodyModel.load(), edge=0.025)
    v, f = welded(v, f)
    return SimpleNamespace(id="dress", vertices=v, faces=f, layer_rank=3)


def test_the_body_levels_are_the_crotch_and_the_armpits(catalog_rule):
    rule, _ = catalog_rule
    levels = BodyLevels.of(rule.body)
    # The mean body's pelvis is near z = 0: the crotch just above, the armpits ~51 cm higher.
    assert 0.0 < levels.crotch < 0.1 and 0.45 < levels.armpit - levels.crotch < 0.6
    assert levels.crotch < levels.chest < levels.armpit


TRAITS = {  # (holds legs apart, has sleeves, wraps legs, covers chest, hangs free below the hips)
    "tank_top": (False, False, False, True, False),
    "tshirt": (False, False, False, True, False),  # short sleeves, cut by the slices at a slant
    "long_sleeve": (False, True, False, True, False),
    "jacket": (False, True, False, True, False),
    "pants": (True, False, True, False, False),
    "shorts": (True, False, True, False, False),
    "skirt": (False, False, True, False, True),
}


def test_the_traits_of_the_bundled_garments(catalog_rule):
    rule, catalog = catalog_rule
    chest = BodyLevels.of(rule.body).chest
    for gid, expected in TRAITS.items():
        t = traits_of(rule, catalog[gid])
        got = (t.holds_legs_apart, t.has_sleeves, t.wraps_legs, t.covers_chest, t.hangs_free_below_hips)
        assert got == expected, gid
        assert t.holds_legs_apart == rule.holds_legs_apart(catalog[gid])
        assert t.lowest <= t.torso_top <= t.highest
        # Margins of the chest's level: bottoms' waistbands 13 cm under it, tops' armholes 15 cm over.
        assert abs(t.torso_top - chest) > 0.12, gid


def _old_asks_segment_test(inner, outer, holds_legs_apart) -> bool:
    """``squeeze.asks_segment_test`` as it was, by category (issue 54 replaced it)."""
    if inner.layer_rank < outer.layer_rank:
        return False
    if inner.category == outer.category:
        return True
    return inner.category == "top" and outer.category == "bottom" and holds_legs_apart(outer)


def test_the_traits_decide_every_bundled_pair_as_the_categories_did(catalog_rule):
    rule, catalog = catalog_rule
    pairs = list(itertools.permutations(sorted(catalog), 2))
    assert len(pairs) == 42
    traits = {g: traits_of(rule, garment) for g, garment in catalog.items()}
    for a, b in pairs:
        ga, gb = catalog[a], catalog[b]
        # PairCaches._junction: a top in a bottom is gathered up, never the bottom let down.
        assert tucked(traits[a], traits[b]) == (ga.category == "top" and gb.category == "bottom"), (a, b)
        assert worn_alike(traits[a], traits[b]) == (ga.category == gb.category), (a, b)
        old = _old_asks_segment_test(ga, gb, rule.holds_legs_apart)
        assert asks_segment_test(ga, gb, lambda g: traits[g.id]) == old, (a, b)


def test_a_dress_covers_the_chest_and_hangs_free_below_the_hips(catalog_rule, dress):
    rule, catalog = catalog_rule
    t = traits_of(rule, dress)
    assert t.covers_chest and t.hangs_free_below_hips and t.wraps_legs
    assert not t.holds_legs_apart and not t.has_sleeves
    tops = [g for g in TRAITS if TRAITS[g][3]]
    traits = {g: traits_of(rule, catalog[g]) for g in catalog}
    for top in tops:  # worn like a top: nothing is tucked into a dress, nor a dress into a top
        assert worn_alike(t, traits[top]) and not tucked(traits[top], t) and not tucked(t, traits[top])
    for bottom in ("pants", "shorts", "skirt"):  # a bottom over a dress would have it tucked in
        b = traits[bottom]
        assert not worn_alike(t, b) and tucked(t, b) and not tucked(b, t)
    # The layering rule refuses pants and shorts over it (its skirt wraps both legs), as over a skirt.
    refused = {b for b in ("pants", "shorts", "skirt") if rule.refusals([dress, catalog[b]])}
    assert refused == {"pants", "shorts"}
    assert not any(rule.refusals([catalog[g], dress]) for g in catalog)
    assert not any(rule.refusals([dress, catalog[g]]) for g in tops)
