"""``service/geometry/closest.py``: the lazily built query against the all-triangles reference, the
compiled query (``closest_kernel``) against the numpy one that tests every candidate, the kernel's
triangle test against Ericson's vectorised one, and the bincount sums against the ``np.add.at`` they
replace."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from service.geometry.closest import ClosestPoint, closest_on_triangles, closest_point_reference
from service.geometry.mesh import (
    face_normals,
    face_normals_reference,
    vertex_normals,
    vertex_normals_reference,
)
from service.geometry.mesh_topology import (
    LazyPseudoNormals,
    MeshTopology,
    PseudoNormals,
    _sum_into,
    _unique_edges,
    mesh_topology,
)


def test_unique_edges_is_np_unique():
    rng = np.random.default_rng(8)
    for n_v in (50, 1 << 16, (1 << 16) + 1):
        ends = np.sort(rng.integers(0, n_v, (3000, 2)), axis=1)
        keys, inverse = _unique_edges(ends[:, 0], ends[:, 1], n_v)
        expected = np.unique(ends[:, 0] * n_v + ends[:, 1], return_inverse=True)
        np.testing.assert_array_equal(keys, expected[0])
        np.testing.assert_array_equal(inverse, expected[1])


def test_ring_lists_each_vertexs_faces_in_order():
    v, f, _ = _bumpy_sphere(4)
    ring = ClosestPoint.build(v, f).ring
    for i in range(len(v)):
        around = np.flatnonzero((f == i).any(axis=1))
        np.testing.assert_array_equal(ring[i], np.r_[around, [-1] * (ring.shape[1] - len(around))])


def _pseudo_normals_add_at(vertices, faces, fn):
    """PseudoNormals.build as first written, with np.add.at: the reference of the bincount sums."""
    vertex = np.zeros((len(vertices), 3))
    for k in range(3):
        a = vertices[faces[:, (k + 1) % 3]] - vertices[faces[:, k]]
        b = vertices[faces[:, (k + 2) % 3]] - vertices[faces[:, k]]
        cos = np.einsum("fd,fd->f", a, b) / np.maximum(
            np.linalg.norm(a, axis=1) * np.linalg.norm(b, axis=1), 1e-300
        )
        np.add.at(vertex, faces[:, k], np.arccos(np.clip(cos, -1, 1))[:, None] * fn)
    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    keys = np.minimum(e[:, 0], e[:, 1]) * len(vertices) + np.maximum(e[:, 0], e[:, 1])
    edge_keys, inverse, count = np.unique(keys, return_inverse=True, return_counts=True)
    edge = np.zeros((len(edge_keys), 3))
    np.add.at(edge, inverse, np.tile(fn, (3, 1)))
    return vertex, edge_keys, edge, count


def _bumpy_sphere(seed: int):
    rng = np.random.default_rng(seed)
    sphere = trimesh.creation.icosphere(subdivisions=3, radius=0.1)
    v = np.asarray(sphere.vertices) * (1 + 0.1 * rng.random((len(sphere.vertices), 1)))
    return v, np.asarray(sphere.faces), rng


def test_sum_into_is_add_at_bit_for_bit():
    rng = np.random.default_rng(0)
    index, values = rng.integers(0, 50, 5000), rng.normal(size=(5000, 3))
    expected = np.zeros((60, 3))
    np.add.at(expected, index, values)
    np.testing.assert_array_equal(_sum_into(index, values, 60), expected)


def test_pseudo_normals_match_the_add_at_build():
    sphere = _bumpy_sphere(1)[:2]
    box = trimesh.creation.box().subdivide()
    box.update_faces(box.face_normals[:, 2] < 0.5)  # open: edges with one triangle
    for v, f in (sphere, (np.asarray(box.vertices), np.asarray(box.faces))):
        fn = face_normals(v, f)
        got = PseudoNormals.build(v, f, fn)
        vertex, edge_keys, edge, count = _pseudo_normals_add_at(v, f, fn)
        np.testing.assert_array_equal(got.vertex, vertex)
        np.testing.assert_array_equal(got.edge_keys, edge_keys)
        np.testing.assert_array_equal(got.edge, edge)
        np.testing.assert_array_equal(got.edge_faces, count)
    once = trimesh.grouping.group_rows(box.edges_sorted, require_count=1)
    rim = {tuple(sorted(e)) for e in box.edges[once]}
    n_v = len(box.vertices)
    got = ClosestPoint.build(box.vertices, box.faces).boundary_edges
    assert sorted(got.tolist()) == got.tolist() and {(k // n_v, k % n_v) for k in got.tolist()} == rim


def test_query_matches_the_reference_inside_and_outside():
    v, f, rng = _bumpy_sphere(2)
    mesh = ClosestPoint.build(v, f)
    points = rng.normal(size=(300, 3)) * 0.06
    got, ref = mesh.query(points), closest_point_reference(points, v, f)
    np.testing.assert_allclose(got.distance, ref.distance, atol=1e-12)
    np.testing.assert_array_equal(np.sign(got.signed), np.sign(ref.signed))
    assert (got.signed < 0).any() and (got.signed > 0).any()


def test_blocked_threaded_query_is_the_single_block_query_bit_for_bit(monkeypatch):
    import service.geometry.closest as closest

    sphere = trimesh.creation.icosphere(subdivisions=3, radius=0.1)
    points = np.random.default_rng(3).normal(scale=0.12, size=(5000, 3))
    monkeypatch.setattr(closest, "MIN_SPLIT", 10**9)
    whole = ClosestPoint.build(sphere.vertices, sphere.faces).query(points)
    monkeypatch.setattr(closest, "MIN_SPLIT", 512)
    for block in (700, 4096, 10**9):  # 8 blocks on the threads, 2, and 2 (never fewer than the threads)
        monkeypatch.setattr(closest, "QUERY_BLOCK", block)
        blocked = ClosestPoint.build(sphere.vertices, sphere.faces).query(points)
        for name in ("face", "bary", "point", "distance", "signed", "normal"):
            np.testing.assert_array_equal(getattr(blocked, name), getattr(whole, name))


def test_asked_ahead_answers_are_the_ones_asked_when_needed():
    from service.geometry.kept_queries import KeptQueries, ask_ahead

    sphere = trimesh.creation.icosphere(subdivisions=3, radius=0.1)
    x = np.random.default_rng(4).normal(scale=0.12, size=(3000, 3))
    ask = np.flatnonzero(np.linalg.norm(x, axis=1) < 0.15)
    turned = np.zeros(len(sphere.faces), dtype=bool)
    turned[::7] = True  # the reversed faces' sign is kept the same way too
    now = KeptQueries(ClosestPoint.build(sphere.vertices, sphere.faces), len(x), turned)
    ahead = KeptQueries(ClosestPoint.build(sphere.vertices, sphere.faces), len(x), turned)
    ask_ahead(ahead, x, ask).result()
    assert not np.isnan(ahead.points[ask]).any() and np.isnan(np.delete(ahead.points, ask, axis=0)).all()
    for got, ref in zip(ahead.at(x, ask), now.at(x, ask), strict=True):
        np.testing.assert_array_equal(got, ref)
    # nothing is asked again: the kept answers were the ones read
    ahead.mesh = None
    ahead.at(x, ask)


FIELDS = ("face", "bary", "point", "distance", "signed", "normal")


def _assert_same(got, ref):
    for name in FIELDS:
        np.testing.assert_array_equal(getattr(got, name), getattr(ref, name), err_msg=name)


def _probe_points(v, f, rng, n=600):
    """Points on vertices, edges and faces (ties between triangles), just off and inside the
    surface, and up to 10 sizes away."""
    size = np.ptp(v, axis=0).max()
    face = rng.integers(0, len(f), n)
    on_face = np.einsum("nk,nkd->nd", rng.dirichlet([1, 1, 1], n), v[f[face]])
    on_edge = 0.5 * (v[f[face, 0]] + v[f[face, 1]])
    near = on_face + rng.normal(scale=0.02 * size, size=(n, 3))
    far = v.mean(axis=0) + rng.normal(size=(n, 3)) * 10.0 ** rng.uniform(-1, 1, (n, 1)) * size
    return np.concatenate([v[rng.integers(0, len(v), n)], on_edge, on_face, near, far])


def test_query_is_the_reference_query_bit_for_bit():
    """The compiled loop answers as the numpy reference: closed and open meshes, a mesh far from the
    origin, points on vertices and edges (exact ties, settled by ring order)."""
    v, f, rng = _bumpy_sphere(5)
    box = trimesh.creation.box().subdivide().subdivide()
    box.update_faces(box.face_normals[:, 2] < 0.5)  # an open box: its top is a rim
    box.remove_unreferenced_vertices()
    meshes = [(v, f), (np.asarray(box.vertices), np.asarray(box.faces)), (v + 500.0, f)]
    for vertices, faces in meshes:
        mesh = ClosestPoint.build(vertices, faces)
        points = _probe_points(vertices, faces, rng)
        got = mesh.query(points)
        _assert_same(got, mesh.query_reference(points))
        rim = mesh.on_boundary(got)
        np.testing.assert_array_equal(rim, mesh.on_boundary_reference(got))
        assert rim.any() == (faces is not f)  # the open box's rim is reached, the spheres have none


def test_query_is_the_reference_query_on_degenerate_triangles():
    """Collapsed and zero-area triangles and vertices that no triangle uses, some points' k nearest
    among them (both then answer the reference's way)."""
    v, f, rng = _bumpy_sphere(6)
    f = f.copy()
    f[:40, 2] = f[:40, 1]  # an edge twice
    f[40:60, 1:] = f[40:60, :1]  # a point
    v = v.copy()
    v[f[60:90, 2]] = 0.5 * (v[f[60:90, 0]] + v[f[60:90, 1]])  # collinear corners
    loose = v.mean(axis=0) + np.array([1.0, 0.0, 0.0]) + rng.normal(scale=1e-3, size=(6, 3))
    v = np.concatenate([v, loose])
    mesh = ClosestPoint.build(v, f)
    points = np.concatenate([_probe_points(v, f, rng), loose + 1e-4])
    _assert_same(mesh.query(points), mesh.query_reference(points))


def test_the_kernels_triangle_test_is_ericsons_bit_for_bit():
    """``closest_kernel``'s scalar test against the vectorised ``closest_on_triangles``: random
    triangles from fat to slivers (and collapsed ones), 1 cm to 1 km off the origin, points from on
    them to 1000 m away, every Voronoi region hit."""
    from numba import njit

    from service.geometry.closest_kernel import barycentric

    @njit
    def run(p, tri, out):
        for i in range(len(p)):
            barycentric(p[i, 0], p[i, 1], p[i, 2], tri[i, 0], tri[i, 1], tri[i, 2], out[i])

    rng = np.random.default_rng(7)
    n = 60_000
    origin = rng.normal(size=(n, 1, 3)) * 10.0 ** rng.integers(0, 4, (n, 1, 1))
    edge = rng.normal(scale=0.01, size=(n, 2, 3))
    fat = 10.0 ** rng.uniform(-9, 0, (n, 1))  # of the second edge across the first
    edge[:, 1] = rng.uniform(-0.5, 1.5, (n, 1)) * edge[:, 0] + fat * edge[:, 1]
    edge[: n // 100, 1] = 0.0  # collapsed: an edge twice
    tri = np.concatenate([origin, origin + edge], axis=1)  # (n, 3, 3)
    direction = rng.normal(size=(n, 3))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    points = tri.mean(axis=1) + direction * 0.01 * 10.0 ** rng.uniform(-8, 5, (n, 1))
    w = np.empty((n, 3))
    run(points, tri, w)
    expected = closest_on_triangles(points, tri[:, 0], tri[:, 1], tri[:, 2])
    np.testing.assert_array_equal(w, expected)
    regions = {tuple(row) for row in (expected > 0).astype(int)}
    assert len(regions) == 7  # 3 vertices, 3 edges, the face


def _open_box():
    box = trimesh.creation.box(extents=(0.3, 0.2, 0.1))
    keep = np.flatnonzero(box.face_normals[:, 2] < 0.5)  # no lid: a rim
    return np.asarray(box.vertices, dtype=np.float64), np.asarray(box.faces[keep], dtype=np.int64)


def test_lazy_pseudo_normals_are_the_built_ones_bit_for_bit():
    for v, f in (_bumpy_sphere(3)[:2], _open_box()):
        fn = face_normals(v, f)
        full = PseudoNormals.build(v, f, fn)
        lazy = LazyPseudoNormals.of(v, f, fn, MeshTopology.build(f, len(v)))
        rng = np.random.default_rng(3)
        # Piecemeal, repeats included, as the queries ask: then every vertex and edge.
        for _ in range(3):
            some = rng.integers(0, len(v), 7)
            np.testing.assert_array_equal(lazy.vertex_at(some), full.vertex[some])
            some = rng.integers(0, len(full.edge_keys), 7)
            np.testing.assert_array_equal(lazy.edge_at(some), full.edge[some])
        np.testing.assert_array_equal(lazy.vertex_at(np.arange(len(v))), full.vertex)
        np.testing.assert_array_equal(lazy.edge_at(np.arange(len(full.edge_keys))), full.edge)
        np.testing.assert_array_equal(lazy.edge_keys, full.edge_keys)
        np.testing.assert_array_equal(lazy.edge_faces, full.edge_faces)


def test_query_with_lazy_pseudo_normals_is_the_one_with_built_ones():
    for v, f in (_bumpy_sphere(3)[:2], _open_box()):
        mesh, built = ClosestPoint.build(v, f), ClosestPoint.build(v, f)
        built.pseudo = PseudoNormals.build(built.vertices, built.faces, built.fn)
        points = np.random.default_rng(4).normal(size=(400, 3)) * 0.1
        got, ref = mesh.query(points), built.query(points)
        for name in ("face", "bary", "point", "distance", "signed", "normal"):
            np.testing.assert_array_equal(getattr(got, name), getattr(ref, name))
        np.testing.assert_array_equal(mesh.on_boundary(got), built.on_boundary(ref))


def test_kept_topology_is_a_fresh_one_and_kept_by_content():
    v, f, _ = _bumpy_sphere(3)
    kept = mesh_topology(f, len(v))
    assert mesh_topology(f.copy().astype(np.int32), len(v)) is kept
    fresh = MeshTopology.build(f.astype(np.int64), len(v))
    names = ("ring", "corners", "edge_keys", "edge_sides", "edge_faces")
    names += ("boundary_edges", "boundary_vertices")
    for name in names:
        np.testing.assert_array_equal(getattr(kept, name), getattr(fresh, name))
    other = f[:, [0, 2, 1]]
    assert mesh_topology(other, len(v)) is not kept


def test_face_keys_follow_the_content_and_are_kept_only_for_frozen_arrays():
    import hashlib

    from service.geometry.mesh_topology import faces_key, frozen

    _, f, _ = _bumpy_sphere(3)
    f = np.ascontiguousarray(f, dtype=np.int64)
    digest = hashlib.sha1(f.tobytes()).digest()
    writeable = f.copy()
    assert faces_key(writeable) == digest
    writeable[0, 0] += 1  # a writeable array is hashed on every call: its new content, a new key
    assert faces_key(writeable) != digest
    kept = frozen(f.copy())
    assert faces_key(kept) == faces_key(kept) == digest
    with pytest.raises(ValueError):
        kept[0, 0] = 1  # and a frozen one cannot change under its kept key
    view = kept[::2]  # a view of it (not the array its key is kept for): hashed
    assert faces_key(view) == hashlib.sha1(np.ascontiguousarray(view).tobytes()).digest()


def test_the_catalog_and_the_body_share_frozen_face_arrays():
    from service.pipeline.body import BodyModel
    from service.pipeline.catalog import load_catalog
    from service.process.paths import models_dir

    catalog = load_catalog(models_dir() / "garments")
    body = BodyModel.load(models_dir() / "body" / "anny_shape.npz")
    for faces in [g.faces for g in catalog.values()] + [body.faces]:
        assert not faces.flags.writeable
        # C order (the files hold some in Fortran order): every np.ascontiguousarray of it is itself,
        # not a copy that would be hashed and gathered afresh on every call.
        assert np.ascontiguousarray(faces, dtype=np.int64) is faces


def test_face_normals_are_the_reference_bit_for_bit():
    rng = np.random.default_rng(5)
    v = rng.normal(size=(500, 3)) * 10.0 ** rng.integers(-4, 3, size=(500, 1))
    f = rng.integers(0, 500, size=(1000, 3))
    f[:5, 1] = f[:5, 0]  # degenerate: zero normals
    for normalize in (True, False):
        np.testing.assert_array_equal(face_normals(v, f, normalize), face_normals_reference(v, f, normalize))


def test_vertex_normals_are_the_reference_bit_for_bit():
    rng = np.random.default_rng(6)
    v = rng.normal(size=(500, 3)) * 10.0 ** rng.integers(-4, 3, size=(500, 1))
    f = rng.integers(0, 480, size=(1000, 3))  # vertices 480.. in no face: zero normals
    f[:5, 1] = f[:5, 0]
    normals = vertex_normals(v, f)
    np.testing.assert_array_equal(normals, vertex_normals_reference(v, f))
    length = np.linalg.norm(normals, axis=1)
    assert np.all(normals[480:] == 0) and (length[:480] > 0).sum() > 400
    np.testing.assert_allclose(length[length > 0], 1)
