"""Folds and what the untangling reads from them: faces that face the body (a fold's middle sheet, a garment
worn inside out), the measure's crossing parity there, and the squeeze pressing deeper where a pass left
faults. Hand-made layers over a flat body (the plane z = 0, outside +z)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import trimesh

from service.geometry.anchors import BodyAnchors
from service.geometry.closest import ClosestPoint
from service.geometry.fold_side import FoldSides
from service.geometry.intersections import intersecting_pairs, segment_crossings_reference
from service.geometry.kept_queries import KeptQueries
from service.pipeline.collisions.passes import _deepen
from service.pipeline.collisions.repair import Inner, RepairResult, repair_layer
from service.pipeline.collisions.settings import SETTINGS
from service.pipeline.collisions.squeeze import Outer, squeeze_layer
from service.pipeline.quality import PENETRATION_BAND, Layer, penetration
from tests.meshes import grid_mesh


def _sheet(n: int, size: float, z: float, inside_out: bool = False):
    v, f = grid_mesh(n)
    v = (v - [0.5, 0.5, 0]) * [size, size, 0] + [0, 0, z]
    return v, (f[:, ::-1].copy() if inside_out else f)


def _box_body():
    box = trimesh.creation.box(extents=[1.0, 1.0, 0.2])
    return np.asarray(box.vertices) - [0, 0, 0.1], np.asarray(box.faces)  # top face at z = 0


def _z_fold(n_y: int = 8):
    """A strip (x, z) bottom sheet z = 10 mm over x in [-0.1, 0.03], back along z = 13 mm to x = -0.03
    (the middle sheet, facing the body), forward along z = 16 mm to x = 0.1; extruded over y in
    [-0.05, 0.05]. Returns vertices, faces, and (F,) which sheet each face is on (0, 1, 2; -1: a turn)."""
    path = [(-0.1 + 0.01 * k, 0.010) for k in range(14)]  # bottom, to x = 0.03
    path += [(0.032, 0.0115)]
    path += [(0.03 - 0.01 * k, 0.013) for k in range(7)]  # middle, back to x = -0.03
    path += [(-0.032, 0.0145)]
    path += [(-0.03 + 0.01 * k, 0.016) for k in range(14)]  # top, to x = 0.1
    path = np.array(path)
    sheet = np.array([0] * 13 + [-1, -1] + [1] * 6 + [-1, -1] + [2] * 13)  # per segment
    ys = np.linspace(-0.05, 0.05, n_y + 1)
    v = np.array([(x, y, z) for x, z in path for y in ys])
    idx = np.arange(len(v)).reshape(len(path), n_y + 1)
    faces, on = [], []
    for s in range(len(path) - 1):
        for j in range(n_y):
            a, b, c, d = idx[s, j], idx[s + 1, j], idx[s + 1, j + 1], idx[s, j + 1]
            faces += [(a, b, c), (a, c, d)]  # normal +z where the path runs along +x
            on += [sheet[s]] * 2
    return v, np.array(faces), np.array(on)


def test_the_middle_sheet_of_a_fold_faces_the_body_and_nothing_else_does():
    body_v, body_f = _box_body()
    v, f, sheet = _z_fold()
    anchors = BodyAnchors.build(v, ClosestPoint.build(body_v, body_f))
    turned = anchors.reversed_faces(v, f, body_v, body_f)
    assert turned[sheet == 1].all()
    assert not turned[(sheet == 0) | (sheet == 2)].any()
    # The same garment inside out: every flat face turned, the middle sheet not.
    turned = anchors.reversed_faces(v, f[:, ::-1], body_v, body_f)
    assert turned[(sheet == 0) | (sheet == 2)].all() and not turned[sheet == 1].any()


def test_kept_queries_turn_the_sign_and_normal_over_on_reversed_faces_only():
    v, f = _sheet(10, 0.2, 0.01)
    mesh = ClosestPoint.build(v, f)
    reversed_faces = np.zeros(len(f), dtype=bool)
    reversed_faces[: len(f) // 2] = True
    rng = np.random.default_rng(0)
    x = rng.uniform([-0.1, -0.1, 0.0], [0.1, 0.1, 0.02], size=(200, 3))
    kept = KeptQueries(mesh, len(x), reversed_faces)
    signed, point, normal, rim = kept.at(x, np.arange(len(x)))
    q = mesh.query(x)
    sign = np.where(reversed_faces[q.face], -1.0, 1.0)
    assert (sign < 0).any() and (sign > 0).any()
    np.testing.assert_array_equal(signed, sign * q.signed)
    np.testing.assert_array_equal(normal, sign[:, None] * q.normal)
    np.testing.assert_array_equal(point, q.point)
    np.testing.assert_array_equal(rim, mesh.on_boundary(q))


def test_kept_queries_with_sides_read_the_side_by_crossing_parity_on_faces_flagged_as_facing_the_body():
    body_v, body_f = _box_body()
    body = ClosestPoint.build(body_v, body_f)
    v, f, sheet = _z_fold()
    mesh = ClosestPoint.build(v, f)
    flagged = np.ones(len(f), dtype=bool)  # the middle sheet rightly, the others as at an armpit
    rng = np.random.default_rng(3)
    x = rng.uniform([-0.09, -0.04, 0.0], [0.09, 0.04, 0.03], size=(400, 3))
    sides = FoldSides.build(v, f, body, band=0.05)
    kept = KeptQueries(mesh, len(x), flagged, sides)
    signed, _, normal, _ = kept.at(x, np.arange(len(x)))
    q = mesh.query(x)
    # The reference: the segment from each point's closest body point, against every triangle.
    inside = segment_crossings_reference(v, f, body.query(x).point, x) % 2 == 0
    np.testing.assert_array_equal(signed < 0, inside)
    np.testing.assert_allclose(np.abs(signed), q.distance, rtol=0, atol=1e-15)
    turned = np.where((signed < 0) == (q.signed < 0), 1.0, -1.0)
    np.testing.assert_array_equal(normal, turned[:, None] * q.normal)
    # Where the fold stacks three sheets, the parity is the analytic side: under the bottom one and
    # between the middle and top ones inside, between the bottom and middle ones and over all outside.
    over_fold = np.abs(x[:, 0]) < 0.025
    z = x[:, 2]
    expected = (z < 0.010) | ((z > 0.013) & (z < 0.016))
    assert over_fold.sum() > 50
    np.testing.assert_array_equal(inside[over_fold], expected[over_fold])
    # Turning every flagged face over instead gets the flat sheets wrong.
    flipped = KeptQueries(mesh, len(x), flagged).at(x, np.arange(len(x)))[0]
    assert ((flipped < 0) != inside).sum() > 100


def test_the_repair_pushes_out_a_layer_inside_a_garment_whose_faces_are_wrongly_flagged_as_facing_the_body():
    """At an armpit the body-normal test flags faces of a sleeve's underside that lie the usual way:
    a layer under them is inside, though turning them over says outside."""
    body_v, body_f = _box_body()
    inner_v, inner_f = _sheet(20, 0.4, 0.01)  # the usual way, normals away from the body
    outer_v, outer_f = _sheet(16, 0.3, 0.006)  # 4 mm under it, inside
    outer_v += [0.0037, 0.0023, 0]  # off the inner grid's edges: a segment through an edge crosses nothing
    n = len(outer_v)
    every = np.ones(n, dtype=bool)
    settings = SETTINGS
    mesh = ClosestPoint.build(inner_v, inner_f)
    flagged = np.ones(len(inner_f), dtype=bool)
    sides = FoldSides.build(inner_v, inner_f, ClosestPoint.build(body_v, body_f), PENETRATION_BAND)
    layer = Inner(mesh, False, every, every, reversed_faces=flagged, sides=sides)
    r = repair_layer(outer_v, outer_f, [layer], settings)
    assert r.crossing_pairs == 0 and r.inside == 0
    assert r.vertices[:, 2].min() >= 0.01 + 0.9 * settings.margin
    # Turned over, the faces say the layer is 4 mm outside, past the margin: it stays inside.
    r = repair_layer(outer_v, outer_f, [Inner(mesh, False, every, every, reversed_faces=flagged)], settings)
    assert r.vertices[:, 2].max() < 0.01


def _points_layer(points: np.ndarray) -> Layer:
    """A "garment" of tiny triangles, one at each point (its first corner)."""
    tri = np.array([[0, 0, 0], [1e-4, 0, 0], [0, 1e-4, 0]])
    v = (points[:, None] + tri[None]).reshape(-1, 3)
    return Layer("outer", v, np.arange(len(v)).reshape(-1, 3))


def test_penetration_reads_crossing_parity_where_the_closest_face_faces_the_body():
    body = Layer("body", *_box_body())
    # A garment worn inside out, 1 cm off the body: its normals point at the body.
    inner = Layer("inner", *_sheet(10, 0.2, 0.01, inside_out=True))
    # Over it; between it and the body (off the sheet's grid lines: a segment through an edge is no
    # proper crossing).
    points = np.array([[0.003, 0.004, 0.015], [0.023, 0.013, 0.005]])
    outer = _points_layer(points)

    def h_at(i, j):
        return np.full(len(outer.vertices), -1.0)

    every = np.ones(len(inner.faces), dtype=bool)
    assert penetration([body, inner, outer], h_at, lambda i: every)["outer"] == 0.5  # the second point
    # The face's own sign has it the other way round.
    assert penetration([body, inner, outer], h_at)["outer"] == 0.5
    plain = ClosestPoint.build(inner.vertices, inner.faces).query(points).signed
    assert plain[0] < 0 < plain[1]
    # Between a fold's middle sheet (facing the body) and its top sheet: two sheets under it, inside,
    # though turning the middle sheet's sign over would say outside.
    fold_v, fold_f, sheet = _z_fold()
    fold = Layer("inner", fold_v, fold_f)
    between = _points_layer(np.array([[0.003, 0.004, 0.0138], [0.003, 0.004, 0.0175]]))  # and over all
    q = ClosestPoint.build(fold_v, fold_f).query(between.vertices[::3])
    assert list(sheet[q.face]) == [1, 2]
    measured = penetration([body, fold, between], lambda i, j: np.full(6, -1.0), lambda i: sheet == 1)
    assert measured["outer"] == 0.5


def test_the_repair_lifts_a_layer_off_a_garment_worn_inside_out_instead_of_through_it():
    inner_v, inner_f = _sheet(20, 0.4, 0.01, inside_out=True)
    outer_v, outer_f = _sheet(16, 0.3, 0.011)  # 1 mm over it: within the margin
    n = len(outer_v)
    every = np.ones(n, dtype=bool)
    settings = SETTINGS
    mesh = ClosestPoint.build(inner_v, inner_f)
    turned = Inner(mesh, False, every, every, reversed_faces=np.ones(len(inner_f), dtype=bool))
    r = repair_layer(outer_v, outer_f, [turned], settings)
    assert r.crossing_pairs == 0 and r.inside == 0
    assert r.vertices[:, 2].min() >= 0.01 + 0.9 * settings.margin
    # The crossing parity reads the same side: one sheet between the layer and the body (the layer
    # moved off the inner grid's edges: a segment through an edge crosses nothing).
    off = outer_v + [0.0037, 0.0023, 0]
    flipped = repair_layer(off, outer_f, [turned], settings)
    body = ClosestPoint.build(*_box_body())
    turned.sides = FoldSides.build(inner_v, inner_f, body, PENETRATION_BAND)
    by_parity = repair_layer(off, outer_f, [turned], settings)
    assert by_parity.moved.all()
    np.testing.assert_array_equal(by_parity.vertices, flipped.vertices)
    # Read by the faces' own sign the layer is "inside" and goes down through the garment.
    r = repair_layer(outer_v, outer_f, [Inner(mesh, False, every, every)], settings)
    assert r.vertices[:, 2].min() < 0.01


def test_the_repair_reports_where_its_faults_are_on_the_inner_layer():
    inner_v, inner_f = _sheet(20, 0.4, 0.0)
    outer_v, outer_f = _sheet(24, 0.36, 0.01)
    dent = np.exp(-(outer_v[:, 0] ** 2 + outer_v[:, 1] ** 2) / 0.03**2)
    outer_v[:, 2] -= 0.016 * dent  # 6 mm through the inner sheet
    n = len(outer_v)
    every = np.ones(n, dtype=bool)
    mesh = ClosestPoint.build(inner_v, inner_f)
    # Uncovered: only the crossings' vertices move, after the first round, so one round leaves faults.
    nowhere = np.zeros(n, dtype=bool)
    one_round = replace(SETTINGS, repair_rounds=1)
    r = repair_layer(outer_v, outer_f, [Inner(mesh, False, every, nowhere)], one_round)
    crossing = intersecting_pairs(r.vertices, outer_f, inner_v, inner_f)
    assert r.crossing_pairs == len(crossing) > 0
    # The corners of every inner triangle crossed, and of those closest to vertices under the sheet.
    crossed = set(inner_f[crossing[:, 1]].ravel())
    under = mesh.query(r.vertices[mesh.query(r.vertices).signed < 0]).face
    assert crossed <= set(r.faults[0]) <= crossed | set(inner_f[under].ravel())
    done = repair_layer(outer_v, outer_f, [Inner(mesh, False, every, every)])
    assert done.crossing_pairs == 0 and done.inside == 0 and len(done.faults[0]) == 0


def test_a_vertex_with_a_larger_margin_is_pressed_that_much_deeper():
    settings = SETTINGS
    body = ClosestPoint.build(*_sheet(30, 0.5, 0.0))
    outer = ClosestPoint.build(*_sheet(24, 0.4, 0.02))
    v, f = _sheet(20, 0.3, 0.03)
    every = np.ones(len(v), dtype=bool)
    margin = np.full(len(v), settings.margin)
    deep = np.linalg.norm(v[:, :2], axis=1) < 0.05
    margin[deep] = 0.006
    # No spreading: each vertex where it was sent.
    squeeze = replace(SETTINGS, squeeze_ring=0, squeeze_smoothing=0, squeeze_relax=0)
    r = squeeze_layer(v, f, [Outer(outer, every, every)], body, settings.margin, squeeze, margin=margin)
    depth = 0.02 - r.vertices[:, 2]
    np.testing.assert_allclose(depth[deep], 0.006, atol=1e-9)
    np.testing.assert_allclose(depth[~deep], settings.margin, atol=1e-9)


def test_a_pass_with_faults_deepens_the_squeeze_around_them_on_the_inner_garment():
    v, f = grid_mesh(10)
    deep = [np.full(len(v), 0.002), np.full(len(v), 0.002)]
    pressed: dict = {}
    faulty = RepairResult(v, np.zeros(len(v), dtype=bool), 1, 3, 0, [], [np.zeros(0, int), np.array([60])])
    clean = RepairResult(v, np.zeros(len(v), dtype=bool), 1, 0, 0, [], [np.zeros(0, int)])
    _deepen([clean, faulty], [f, f], deep, pressed)
    # Garment 0 under garment 1, around its vertex 60 (SETTINGS.deepen_ring rings along the edges); garment 1
    # untouched.
    rings = np.zeros(len(v), dtype=bool)
    rings[60] = True
    edges = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    for _ in range(SETTINGS.deepen_ring):
        reached = rings[edges].any(axis=1)
        rings[edges[reached].ravel()] = True
    assert set(pressed) == {(0, 1)}
    np.testing.assert_array_equal(pressed[(0, 1)], rings)
    np.testing.assert_allclose(deep[0][rings], 0.002 + SETTINGS.deepen)
    np.testing.assert_array_equal(deep[0][~rings], 0.002)
    np.testing.assert_array_equal(deep[1], 0.002)


def test_the_compiled_reversed_faces_are_the_numpy_ones_bit_for_bit():
    body_v, body_f = _box_body()
    v, f, _ = _z_fold()
    anchors = BodyAnchors.build(v, ClosestPoint.build(body_v, body_f))
    rng = np.random.default_rng(3)
    crumpled = v + rng.normal(scale=0.01, size=v.shape)  # faces turned every which way
    ref = anchors.reversed_faces_reference(crumpled, f, body_v, body_f)
    assert 0.1 < ref.mean() < 0.9
    np.testing.assert_array_equal(anchors.reversed_faces(crumpled, f, body_v, body_f), ref)
    normals = ClosestPoint.build(body_v, body_f).fn
    np.testing.assert_array_equal(anchors.reversed_faces(crumpled, f, body_v, body_f, normals), ref)
