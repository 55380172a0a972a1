"""``service/closest.py``: the lazily built query against the all-triangles reference, and the
bincount sums against the ``np.add.at`` they replace."""

from __future__ import annotations

import numpy as np
import trimesh

from service.closest import ClosestPoint, PseudoNormals, _sum_into, closest_point_reference
from service.mesh import face_normals


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
    edge_keys, inverse = np.unique(keys, return_inverse=True)
    edge = np.zeros((len(edge_keys), 3))
    np.add.at(edge, inverse, np.tile(fn, (3, 1)))
    return vertex, edge


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
    v, f, _ = _bumpy_sphere(1)
    fn = face_normals(v, f)
    got = PseudoNormals.build(v, f, fn)
    vertex, edge = _pseudo_normals_add_at(v, f, fn)
    np.testing.assert_array_equal(got.vertex, vertex)
    np.testing.assert_array_equal(got.edge, edge)


def test_query_matches_the_reference_inside_and_outside():
    v, f, rng = _bumpy_sphere(2)
    mesh = ClosestPoint.build(v, f)
    points = rng.normal(size=(300, 3)) * 0.06
    got, ref = mesh.query(points), closest_point_reference(points, v, f)
    np.testing.assert_allclose(got.distance, ref.distance, atol=1e-12)
    np.testing.assert_array_equal(np.sign(got.signed), np.sign(ref.signed))
    assert (got.signed < 0).any() and (got.signed > 0).any()


def test_blocked_threaded_query_is_the_single_block_query_bit_for_bit(monkeypatch):
    import service.closest as closest

    sphere = trimesh.creation.icosphere(subdivisions=3, radius=0.1)
    points = np.random.default_rng(3).normal(scale=0.12, size=(5000, 3))
    monkeypatch.setattr(closest, "QUERY_BLOCK", 10**9)
    whole = ClosestPoint.build(sphere.vertices, sphere.faces).query(points)
    monkeypatch.setattr(closest, "QUERY_BLOCK", 700)  # 8 blocks on the threads
    blocked = ClosestPoint.build(sphere.vertices, sphere.faces).query(points)
    for name in ("face", "bary", "point", "distance", "signed", "normal"):
        np.testing.assert_array_equal(getattr(blocked, name), getattr(whole, name))
