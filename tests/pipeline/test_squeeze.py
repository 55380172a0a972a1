"""The squeeze (service.pipeline.collisions.squeeze) on hand-made layers with known answers."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from service.geometry.closest import ClosestPoint
from service.geometry.intersections import intersecting_pairs
from service.pipeline.collisions.settings import SETTINGS, CollisionSettings
from service.pipeline.collisions.squeeze import Outer, squeeze_layer
from tests.meshes import grid_mesh


def _sheet(n: int, size: float, z: float):
    v, f = grid_mesh(n)
    return (v - [0.5, 0.5, 0]) * [size, size, 0] + [0, 0, z], f


def _squeeze(inner_z: float, outer_z: float, settings: CollisionSettings | None = None):
    body = ClosestPoint.build(*_sheet(30, 0.5, 0.0))
    outer = ClosestPoint.build(*_sheet(24, 0.4, outer_z))
    v, f = _sheet(20, 0.3, inner_z)
    covered = v[:, 0] < 0  # the outer layer covers the half x < 0 (a waistband along x = 0)
    near = np.ones(len(v), dtype=bool)
    settings = settings or SETTINGS
    return v, f, outer, squeeze_layer(v, f, [Outer(outer, near, covered)], body, settings.margin, settings)


def test_a_loose_inner_layer_is_pressed_under_the_outer_one_where_it_covers_it():
    # The inner sheet hangs 1 cm outside the outer one (2 cm off the body, the outer at 1 cm).
    settings = SETTINGS
    v, f, outer, r = _squeeze(0.02, 0.01, settings)
    assert r.outside == 0
    x = r.vertices
    covered = v[:, 0] < 0
    # Under the outer layer by the margin (to the bisection's resolution), never onto the body.
    assert np.all(x[covered, 2] <= 0.01 - 0.9 * settings.margin)
    assert np.all(x[:, 2] >= settings.margin - 1e-9)
    # Straight towards the body: no sideways motion of the pressed vertices.
    np.testing.assert_allclose(x[covered, :2], v[covered, :2], atol=1e-12)
    # Beyond the diffusion rings the uncovered half never moves.
    far = v[:, 0] > 0.1
    np.testing.assert_array_equal(x[far], v[far])
    assert r.moved[covered].all() and not r.moved[far].any()
    # The pressed part no longer crosses the outer layer where it covers it.
    inside = np.flatnonzero(np.all(x[f][:, :, 0] < -0.05, axis=1))
    assert len(intersecting_pairs(x, f[inside], outer.vertices, outer.faces)) == 0


def test_an_inner_layer_already_inside_is_left_alone():
    v, _, _, r = _squeeze(0.005, 0.01)
    assert r.outside == 0 and not r.moved.any()
    np.testing.assert_array_equal(r.vertices, v)


def test_an_outer_layer_on_the_skin_leaves_the_inner_one_at_the_margin_for_the_repair():
    # No room under an outer layer 1 mm off the body: the inner one goes to the body margin and stays
    # outside it, counted, for the repair to lift the outer layer over it.
    settings = SETTINGS
    v, _, _, r = _squeeze(0.02, 0.001, settings)
    covered = v[:, 0] < -0.03
    np.testing.assert_allclose(r.vertices[covered, 2], settings.margin, atol=1e-9)
    assert r.outside > 0


def test_the_floor_keeps_room_for_the_garments_under_the_squeezed_one():
    # The third garment of a stack stops 6 mm off the body, where an outer layer on the skin leaves it.
    settings = SETTINGS
    body = ClosestPoint.build(*_sheet(30, 0.5, 0.0))
    outer = ClosestPoint.build(*_sheet(24, 0.4, 0.001))
    v, f = _sheet(20, 0.3, 0.02)
    everywhere = np.ones(len(v), dtype=bool)
    r = squeeze_layer(v, f, [Outer(outer, everywhere, everywhere)], body, 3 * settings.margin, settings)
    np.testing.assert_allclose(r.vertices[:, 2], 3 * settings.margin, atol=1e-9)


def test_cloth_hanging_far_outside_is_pulled_in_when_the_outer_layer_lies_between_it_and_its_body_point():
    # An inner sheet 8 cm off the body, 7 cm outside the outer sheet: beyond the band, and the field
    # says "not covered" (a loose sleeve under a narrower one). The segment from each vertex's body
    # point to it crosses the outer sheet once: it is under it.
    settings = SETTINGS
    body = ClosestPoint.build(*_sheet(30, 0.5, 0.0))
    outer = ClosestPoint.build(*_sheet(24, 0.4, 0.01))
    v, f = _sheet(20, 0.3, 0.08)
    near, covered = np.ones(len(v), dtype=bool), np.zeros(len(v), dtype=bool)
    alone = squeeze_layer(v, f, [Outer(outer, near, covered)], body, settings.margin, settings)
    np.testing.assert_array_equal(alone.vertices, v)
    anchors = v * [1, 1, 0]
    r = squeeze_layer(v, f, [Outer(outer, near, covered)], body, settings.margin, settings, anchors)
    assert r.outside == 0
    assert np.all(r.vertices[:, 2] <= 0.01 - 0.9 * settings.margin)
    assert np.all(r.vertices[:, 2] >= settings.margin - 1e-9)
    assert len(intersecting_pairs(r.vertices, f, outer.vertices, outer.faces)) == 0
    # Where the segment passes no outer cloth (the outer sheet is cut away), nothing moves.
    holed = ClosestPoint.build(*_sheet(24, 0.4, 0.01))
    keep = np.all(holed.vertices[holed.faces][:, :, 0] < 0, axis=1)  # the outer covers x < 0 only
    half = ClosestPoint.build(holed.vertices, holed.faces[keep])
    r = squeeze_layer(v, f, [Outer(half, near, covered)], body, settings.margin, settings, anchors)
    far = v[:, 0] > 0.1
    np.testing.assert_array_equal(r.vertices[far], v[far])
    assert np.all(r.vertices[v[:, 0] < -0.05, 2] <= 0.01 - 0.9 * settings.margin)


def test_the_segment_test_finds_cloth_the_fields_put_far_from_the_outer_layer():
    # The same hanging sheet, where the outer layer's fields (read at another mesh: the outer garment
    # before it was let down) put no vertex within reach of it: the segment test is asked anyway, and
    # the sheet comes in as when every vertex was near.
    settings = SETTINGS
    body = ClosestPoint.build(*_sheet(30, 0.5, 0.0))
    outer = ClosestPoint.build(*_sheet(24, 0.4, 0.01))
    v, f = _sheet(20, 0.3, 0.08)
    nowhere = np.zeros(len(v), dtype=bool)
    anchors = v * [1, 1, 0]
    r, near = (
        squeeze_layer(v, f, [Outer(outer, n, nowhere)], body, settings.margin, settings, anchors)
        for n in (nowhere, ~nowhere)
    )
    assert r.outside == 0 and np.array_equal(r.vertices, near.vertices)
    assert len(intersecting_pairs(r.vertices, f, outer.vertices, outer.faces)) == 0


def test_the_segment_test_is_asked_for_looser_tops_and_for_tops_tucked_into_legged_bottoms():
    from service.pipeline.body import DEFAULT_BETA, BodyModel
    from service.pipeline.catalog import load_catalog
    from service.pipeline.collisions.layering import LayeringRule
    from service.pipeline.collisions.squeeze import asks_segment_test
    from service.pipeline.collisions.traits import traits_of

    catalog = dict(load_catalog())
    body = BodyModel.load()
    rule = LayeringRule(body.vertices(np.asarray(DEFAULT_BETA)), body.faces)
    asked = {
        (a, b) for a in catalog for b in catalog
        if a != b and asks_segment_test(catalog[a], catalog[b], lambda g: traits_of(rule, g))
    }  # fmt: skip
    assert {("jacket", "tshirt"), ("long_sleeve", "tank_top"), ("tshirt", "tank_top")} <= asked  # looser tops
    assert {("tshirt", "pants"), ("long_sleeve", "shorts"), ("jacket", "pants")} <= asked  # tucked in
    assert {("shorts", "pants"), ("pants", "skirt")} <= asked  # a bottom in a bottom: the ranks tie
    # Not the usual orders (the benchmarks' outfits), not a top in a skirt, not a tank top in pants
    # (its rank is below theirs: its hem stays above the crotch).
    not_asked = {
        ("tshirt", "jacket"), ("pants", "tshirt"), ("tank_top", "tshirt"), ("long_sleeve", "jacket"),
        ("shorts", "tank_top"), ("jacket", "skirt"), ("tshirt", "skirt"), ("tank_top", "pants"),
    }  # fmt: skip
    assert not not_asked & asked


def test_with_past_rim_cloth_beyond_the_outer_layers_rim_is_not_pulled_under_it():
    # The fields call the whole inner sheet covered; the outer sheet ends at |x|, |y| = 0.1.
    body = ClosestPoint.build(*_sheet(30, 0.6, 0.0))
    outer = ClosestPoint.build(*_sheet(24, 0.2, 0.01))
    v, f = _sheet(40, 0.3, 0.015)
    every = np.ones(len(v), dtype=bool)
    # No spreading: only the pulled vertices move.
    plain = replace(SETTINGS, squeeze_ring=0, squeeze_smoothing=0, squeeze_relax=0)
    past = np.abs(v[:, :2]).max(axis=1) > 0.1
    layer = [Outer(outer, every, every)]
    default = squeeze_layer(v, f, layer, body, plain.margin, plain)
    rim = squeeze_layer(v, f, layer, body, plain.margin, plain, past_rim=True)
    assert default.moved[past].any()
    assert not rim.moved[past].any()
    # Under the outer layer both press the cloth to the margin.
    assert np.all(rim.vertices[~past, 2] <= 0.01 - 0.9 * plain.margin)
    np.testing.assert_allclose(rim.vertices[~past], default.vertices[~past], atol=1e-12)
