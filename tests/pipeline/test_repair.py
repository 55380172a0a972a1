"""The exact collision repair (service.pipeline.collisions.repair) on hand-made layers with known answers."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import trimesh

from service.geometry.closest import ClosestPoint
from service.geometry.intersections import intersecting_pairs
from service.geometry.kept_queries import KeptQueries
from service.pipeline.collisions.repair import (
    Inner,
    _faces_around,
    lifts,
    repair_layer,
)
from service.pipeline.collisions.settings import SETTINGS
from tests.meshes import sheet

_sheet = sheet


def _everywhere(n: int) -> np.ndarray:
    return np.ones(n, dtype=bool)


def test_a_sheet_crossing_an_inner_sheet_is_lifted_above_it_and_only_there():
    inner_v, inner_f = _sheet(20, 0.4, lambda v: 0.0 * v[:, 0])
    # The outer sheet lies 1 cm above but dips 6 mm through the inner one in a 3 cm wide dent.
    outer_v, outer_f = _sheet(
        24, 0.36, lambda v: 0.01 - 0.016 * np.exp(-(v[:, 0] ** 2 + v[:, 1] ** 2) / 0.03**2)
    )
    assert len(intersecting_pairs(outer_v, outer_f, inner_v, inner_f)) > 0
    n = len(outer_v)
    inner = [Inner(ClosestPoint.build(inner_v, inner_f), False, _everywhere(n), _everywhere(n))]
    settings = SETTINGS
    r = repair_layer(outer_v, outer_f, inner, settings)
    assert r.crossing_pairs == 0
    assert len(intersecting_pairs(r.vertices, outer_f, inner_v, inner_f)) == 0
    assert r.vertices[:, 2].min() >= settings.margin - 1e-9
    # Vertices far from the dent (over 8 cm from its centre) never move.
    far = np.linalg.norm(outer_v[:, :2], axis=1) > 0.08
    np.testing.assert_array_equal(r.vertices[far], outer_v[far])
    assert r.moved.any() and not r.moved[far].any()


def test_lifted_corners_end_margin_above_the_inner_triangle_along_its_layers_normal():
    rng = np.random.default_rng(3)
    settings = replace(SETTINGS, lift=1.0)  # no cap
    f = np.array([[0, 1, 2]])
    checked = 0
    for _ in range(300):
        # A wide inner triangle, tilted at random, and a small outer one at random around its middle:
        # every corner's closest point is on the inner triangle's face.
        tilt = np.linalg.qr(rng.normal(size=(3, 3)))[0]
        inner_v = np.array([[-1.0, -1, 0], [1, -1, 0], [0, 1, 0]]) * 0.2 @ tilt.T
        outer_v = rng.normal(scale=0.02, size=(3, 3))
        if not len(intersecting_pairs(outer_v, f, inner_v, f)):
            continue
        checked += 1
        layer = Inner(ClosestPoint.build(inner_v, f), False, _everywhere(3), _everywhere(3))
        crossing = (outer_v, layer)
        at, moves = lifts(outer_v, [f], [np.array([[0, 0]])], [(layer, np.array([0]))], settings)
        normal = layer.mesh.fn[0]
        top = (inner_v @ normal).max()
        below = outer_v @ normal < top + settings.margin
        np.testing.assert_array_equal(at, np.flatnonzero(below))  # only the corners below move
        np.testing.assert_allclose(np.cross(moves, normal), 0.0, atol=1e-12)  # along the normal
        lifted = outer_v.copy()
        lifted[at] += moves
        np.testing.assert_allclose(lifted[at] @ normal, top + settings.margin, atol=1e-12)
        assert not len(intersecting_pairs(lifted, f, inner_v, f))
    assert checked > 20
    capped = replace(SETTINGS, lift=0.001)
    outer_v, layer = crossing
    at, moves = lifts(outer_v, [f], [np.array([[0, 0]])], [(layer, np.array([0]))], capped)
    assert len(at) and np.linalg.norm(moves, axis=1).max() <= capped.lift + 1e-12


def test_a_corner_lifts_along_the_outer_side_of_a_reversed_inner_face():
    f = np.array([[0, 1, 2]])
    inner_v = np.array([[-0.1, -0.1, 0], [0.1, -0.1, 0], [0, 0.1, 0]])
    outer_v = np.array([[0.0, 0, -0.01], [0.01, 0, 0.01], [0, 0.01, 0.01]])
    mesh = ClosestPoint.build(inner_v, f)
    for turned, up in ((None, 1.0), (np.array([True]), -1.0)):
        layer = Inner(mesh, False, _everywhere(3), _everywhere(3), reversed_faces=turned)
        pair = [np.array([[0, 0]])]
        at, moves = lifts(outer_v, [f], pair, [(layer, np.array([0]))], replace(SETTINGS, lift=1.0))
        assert len(at) and np.all(np.sign(moves[:, 2]) == up)


def test_a_corner_in_several_pairs_takes_its_largest_lift():
    f = np.array([[0, 1, 2]])
    # Two wide flat inner triangles at heights 1 cm and 3 cm, both crossed by one steep outer triangle.
    low = np.array([[-1.0, -1, 0.01], [1, -1, 0.01], [0, 1, 0.01]]) * [0.05, 0.05, 1]
    inner_v, inner_f = np.concatenate([low, low + [0, 0, 0.02]]), np.array([[0, 1, 2], [3, 4, 5]])
    outer_v = np.array([[0.0, 0.0, 0.0], [0.01, 0.0, 0.05], [0.0, 0.01, 0.05]])
    assert len(intersecting_pairs(outer_v, f, inner_v, inner_f)) == 2
    layer = Inner(ClosestPoint.build(inner_v, inner_f), False, _everywhere(3), _everywhere(3))
    settings = replace(SETTINGS, lift=1.0)
    at, moves = lifts(outer_v, [f], [np.array([[0, 0], [0, 1]])], [(layer, np.array([0, 1]))], settings)
    np.testing.assert_array_equal(at, [0])  # the two corners above both stay
    np.testing.assert_allclose(moves, [[0.0, 0.0, 0.03 + settings.margin]], atol=1e-12)


def test_a_fold_poking_between_the_corners_of_a_coarse_outer_sheet_is_lifted_clear_at_once():
    # A 5 mm wide ridge 2 cm high under an outer sheet of 4 cm triangles 1 cm above the flat part: the
    # ridge pokes between corners past every margin, as a jacket's armpit fold through a tank top.
    inner_v, inner_f = _sheet(80, 0.4, lambda v: 0.02 * np.exp(-((v[:, 0] / 0.005) ** 2)))
    outer_v, outer_f = _sheet(9, 0.36, lambda v: 0.01 + 0.0 * v[:, 0])
    assert len(intersecting_pairs(outer_v, outer_f, inner_v, inner_f)) > 0
    n = len(outer_v)
    inner = [Inner(ClosestPoint.build(inner_v, inner_f), False, _everywhere(n), _everywhere(n))]
    lifted = repair_layer(outer_v, outer_f, inner, replace(SETTINGS, repair_rounds=3))
    assert lifted.crossing_pairs == 0
    assert len(intersecting_pairs(lifted.vertices, outer_f, inner_v, inner_f)) == 0
    kicked = repair_layer(outer_v, outer_f, inner, replace(SETTINGS, repair_rounds=3, lift=0.0))
    assert kicked.crossing_pairs > 0  # kicked along its own normal, 2 mm a round, it is still through


def test_an_uncovered_inner_layer_leaves_the_vertices_below_it_alone():
    inner_v, inner_f = _sheet(10, 0.4, lambda v: 0.0 * v[:, 0])
    outer_v, outer_f = _sheet(8, 0.1, lambda v: -0.01 + 0.0 * v[:, 0])  # 1 cm below, no crossing
    n = len(outer_v)
    covered = Inner(ClosestPoint.build(inner_v, inner_f), False, _everywhere(n), _everywhere(n))
    r = repair_layer(outer_v, outer_f, [covered])
    assert r.vertices[:, 2].min() > 0  # on the wrong side of a covering layer: moved out
    open_layer = Inner(covered.mesh, False, _everywhere(n), np.zeros(n, dtype=bool))
    r = repair_layer(outer_v, outer_f, [open_layer])
    np.testing.assert_array_equal(r.vertices, outer_v)  # beyond its opening: nothing to do


def test_nothing_ends_inside_a_closed_body():
    body = trimesh.creation.icosphere(subdivisions=4, radius=0.1)
    # A sheet cutting 3 cm deep into the sphere of radius 10 cm.
    v, f = _sheet(30, 0.3, lambda v: 0.07 + 0.0 * v[:, 0])
    n = len(v)
    inner = [Inner(ClosestPoint.build(body.vertices, body.faces), True, _everywhere(n), _everywhere(n))]
    r = repair_layer(v, f, inner, replace(SETTINGS, repair_rounds=10))
    assert r.crossing_pairs == 0
    assert np.linalg.norm(r.vertices, axis=1).min() >= 0.1 + SETTINGS.margin - 2e-4
    assert len(intersecting_pairs(r.vertices, f, body.vertices, body.faces)) == 0


def test_degenerate_triangles_stay_finite_through_the_repair():
    inner_v, inner_f = _sheet(20, 0.4, lambda v: 0.0 * v[:, 0])
    outer_v, outer_f = _sheet(12, 0.2, lambda v: -0.003 + 0.0 * v[:, 0])  # 3 mm below: all inside
    outer_v[outer_f[5, 1]] = outer_v[outer_f[5, 0]]  # a zero-area triangle
    n = len(outer_v)
    inner = [Inner(ClosestPoint.build(inner_v, inner_f), False, _everywhere(n), _everywhere(n))]
    r = repair_layer(outer_v, outer_f, inner)
    assert np.all(np.isfinite(r.vertices))
    assert r.crossing_pairs == 0 and r.inside == 0


def test_kept_queries_answer_as_fresh_ones_after_some_vertices_move():
    inner_v, inner_f = _sheet(20, 0.4, lambda v: 0.01 * np.sin(20 * v[:, 0]))
    outer_v, _ = _sheet(24, 0.36, lambda v: 0.005 + 0.0 * v[:, 0])
    n = len(outer_v)
    near = np.arange(n) % 3 > 0
    layer = Inner(ClosestPoint.build(inner_v, inner_f), False, near, _everywhere(n))
    kept = KeptQueries(layer.mesh, n)
    ask = np.flatnonzero(near)
    kept.at(outer_v, ask)
    moved = outer_v.copy()
    moved[::5] += [0.0, 0.0, 0.003]
    asked = []
    query = layer.mesh.query
    layer.mesh.query = lambda points, *split: asked.append(len(points)) or query(points, *split)
    signed, point, normal, _ = kept.at(moved, ask)
    assert asked == [len(np.intersect1d(ask, np.arange(0, n, 5)))]  # only the points that moved
    fresh = query(moved[near])
    np.testing.assert_array_equal(signed, fresh.signed)
    np.testing.assert_array_equal(point, fresh.point)
    np.testing.assert_array_equal(normal, fresh.normal)


def test_a_query_subset_holding_every_violation_repairs_as_all_near_vertices_do():
    inner_v, inner_f = _sheet(20, 0.4, lambda v: 0.0 * v[:, 0])
    outer_v, outer_f = _sheet(
        24, 0.36, lambda v: 0.01 - 0.016 * np.exp(-(v[:, 0] ** 2 + v[:, 1] ** 2) / 0.03**2)
    )
    n = len(outer_v)
    mesh = ClosestPoint.build(inner_v, inner_f)
    full = repair_layer(outer_v, outer_f, [Inner(mesh, False, _everywhere(n), _everywhere(n))])
    dent = outer_v[:, 2] < 0.008  # every vertex the dent brings within the margin, and more
    part = repair_layer(outer_v, outer_f, [Inner(mesh, False, _everywhere(n), _everywhere(n), dent)])
    assert full.crossing_pairs == part.crossing_pairs == 0
    np.testing.assert_array_equal(part.vertices, full.vertices)


def test_vertices_left_out_of_the_queries_are_asked_once_their_triangles_cross():
    inner_v, inner_f = _sheet(20, 0.4, lambda v: 0.0 * v[:, 0])
    outer_v, outer_f = _sheet(
        24, 0.36, lambda v: 0.01 - 0.016 * np.exp(-(v[:, 0] ** 2 + v[:, 1] ** 2) / 0.03**2)
    )
    n = len(outer_v)
    nothing = np.zeros(n, dtype=bool)  # a wrong hint: no vertex asked at first
    layer = Inner(ClosestPoint.build(inner_v, inner_f), False, _everywhere(n), _everywhere(n), nothing)
    r = repair_layer(outer_v, outer_f, [layer])
    assert r.crossing_pairs == 0
    assert len(intersecting_pairs(r.vertices, outer_f, inner_v, inner_f)) == 0


def test_pruning_triangles_clear_of_the_inner_layer_changes_nothing(monkeypatch):
    import service.pipeline.collisions.repair as repair

    inner_v, inner_f = _sheet(20, 0.4, lambda v: 0.01 * np.sin(25 * v[:, 0]))
    outer_v, outer_f = _sheet(
        24, 0.36, lambda v: 0.012 - 0.02 * np.exp(-(v[:, 0] ** 2 + v[:, 1] ** 2) / 0.04**2)
    )
    n = len(outer_v)
    layer = [Inner(ClosestPoint.build(inner_v, inner_f), False, _everywhere(n), _everywhere(n))]
    pruned = repair_layer(outer_v, outer_f, layer)
    cleared = repair.clear_of(outer_v, outer_f, _asked(layer[0], outer_v))
    assert 0 < cleared.sum() < len(outer_f)  # the case prunes some triangles and keeps others
    monkeypatch.setattr(repair, "clear_of", lambda x, faces, kept: np.zeros(len(faces), dtype=bool))
    full = repair_layer(outer_v, outer_f, layer)
    assert pruned.crossing_pairs == full.crossing_pairs and pruned.rounds == full.rounds
    np.testing.assert_array_equal(pruned.vertices, full.vertices)


def _asked(layer: Inner, x: np.ndarray) -> KeptQueries:
    kept = KeptQueries(layer.mesh, len(x))
    kept.at(x, np.arange(len(x)))
    return kept


def test_faces_around_are_those_with_a_vertex_in_the_grown_box():
    inner_v, inner_f = _sheet(12, 0.4, lambda v: 0.0 * v[:, 0])
    mesh = ClosestPoint.build(inner_v, inner_f)
    corners = np.array([[-0.05, -0.02, 0.01], [0.03, 0.04, 0.0]])
    lo, hi = corners.min(axis=0) - 0.01, corners.max(axis=0) + 0.01
    inside = np.all((inner_v >= lo) & (inner_v <= hi), axis=1)
    got = _faces_around(mesh, corners, 0.01)
    np.testing.assert_array_equal(got, np.flatnonzero(inside[inner_f].any(axis=1)))
    assert 0 < len(got) < len(inner_f)


def test_triangles_the_canonical_fields_miss_are_near_in_world():
    """A coarse sheet crossing a closed ball, and another farther than reach, with no vertex called
    near (as where the body map squeezes a heavy armpit): the crossing triangles' corners are near,
    every vertex left out is farther than reach, a vertex deep inside the ball is near, the far sheet
    is not, and what was near stays near."""
    from service.pipeline.collisions.passes import _FinalLayer, near_in_world

    ball = trimesh.creation.icosphere(subdivisions=4, radius=0.1)
    body = _FinalLayer(ClosestPoint.build(np.asarray(ball.vertices), np.asarray(ball.faces)), True, 0.0)
    reach = SETTINGS.reach
    # 6 cm triangles through the ball's top: some corners lie farther than reach from the sphere.
    v, f = _sheet(4, 0.24, lambda v: 0.09 + 0.0 * v[:, 0])
    crossing = intersecting_pairs(v, f, body.mesh.vertices, body.mesh.faces)
    assert len(crossing)
    near = near_in_world(v, f, body, np.zeros(len(v), dtype=bool), reach)
    assert near[f[crossing[:, 0]]].all()
    assert (np.abs(body.mesh.query(v[~near]).signed) > reach).all()
    far_v, far_f = _sheet(6, 0.24, lambda v: 0.1 + reach + 0.02 + 0.0 * v[:, 0])  # 5.7 cm edges
    assert not near_in_world(far_v, far_f, body, np.zeros(len(far_v), dtype=bool), reach).any()
    inside = np.array([[0.0, 0.0, 0.0], [0.001, 0.0, 0.0], [0.0, 0.001, 0.0], [0.5, 0.5, 0.5]])
    tri = np.array([[0, 1, 2]])
    assert near_in_world(inside, tri, body, np.zeros(4, dtype=bool), reach)[:3].all()
    kept = np.zeros(len(far_v), dtype=bool)
    kept[:5] = True
    np.testing.assert_array_equal(near_in_world(far_v, far_f, body, kept, reach), kept)
