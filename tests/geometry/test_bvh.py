"""The hierarchy of boxes behind ``ClosestPoint.query``: its structure, and answers kept exact when the
tree is reused for other vertex positions of the same faces."""

import numpy as np
import trimesh

from service.geometry import bvh_kernel
from service.geometry.closest import ClosestPoint, closest_point_reference

FIELDS = ("face", "bary", "point", "distance", "signed", "normal")


def _sphere(subdivisions=4):
    s = trimesh.creation.icosphere(subdivisions=subdivisions, radius=0.2)
    return np.asarray(s.vertices), np.asarray(s.faces, dtype=np.int64)


def test_every_triangle_sits_in_one_leaf_and_every_box_holds_its_triangles():
    v, f = _sphere()
    left, start, count, order = bvh_kernel.build(v, f, bvh_kernel.LEAF)
    assert sorted(order.tolist()) == list(range(len(f)))
    leaves = left < 0
    assert count[leaves].max() <= bvh_kernel.LEAF and count[leaves].min() >= 1
    assert count[leaves].sum() == len(f)
    spans = sorted(zip(start[leaves].tolist(), count[leaves].tolist(), strict=True))
    assert all(s + c == s2 for (s, c), (s2, _) in zip(spans, spans[1:], strict=False))
    tri = bvh_kernel.corners(v, f, order)
    np.testing.assert_array_equal(tri, v[f[order]])
    lo, hi = bvh_kernel.boxes(tri, left, start, count)
    tlo, thi = bvh_kernel.triangle_boxes(tri)
    assert np.all(tri > tlo[:, None]) and np.all(tri < thi[:, None])
    for n in np.flatnonzero(leaves):
        corners = tri[start[n] : start[n] + count[n]].reshape(-1, 3)
        assert np.all(corners > lo[n]) and np.all(corners < hi[n])
    for n in np.flatnonzero(~leaves):  # parents before children, each holding both
        c = left[n]
        assert c > n
        assert np.all(lo[n] <= np.minimum(lo[c], lo[c + 1])) and np.all(hi[n] >= np.maximum(hi[c], hi[c + 1]))


def test_a_tree_kept_from_other_vertices_answers_as_the_reference():
    """The tree is built on the first vertices a faces array comes with, and kept with its topology;
    on a mesh of the same faces bent out of that shape (as a garment on another body), the answers are
    still every triangle's closest, bit for bit, only found later."""
    v, f = _sphere()
    first = ClosestPoint.build(v, f)
    first.query(v[:5])
    assert first.topology.tree is not None
    rng = np.random.default_rng(4)
    bent = v * np.array([1.6, 0.7, 1.0]) + 0.05 * np.sin(8 * v[:, [1, 2, 0]])
    mesh = ClosestPoint.build(bent, f.copy())  # the same faces, another array: the same topology
    assert mesh.boxes[-1] is first.topology.tree[-1]  # the kept tree, new boxes
    assert not np.array_equal(mesh.boxes[1], first.boxes[1])
    points = np.concatenate([bent[rng.integers(0, len(bent), 300)], rng.normal(scale=0.25, size=(600, 3))])
    got, ref = mesh.query(points), closest_point_reference(points, bent, f)
    for name in FIELDS:
        np.testing.assert_array_equal(getattr(got, name), getattr(ref, name), err_msg=name)


def test_a_nan_point_is_answered_as_the_reference():
    v, f = _sphere(2)
    points = np.array([[0.3, 0.0, 0.0], [np.nan, 0.0, 0.0]])
    got, ref = ClosestPoint.build(v, f).query(points), closest_point_reference(points, v, f)
    assert got.face.tolist() == ref.face.tolist()
    np.testing.assert_array_equal(got.bary, ref.bary)
    np.testing.assert_array_equal(got.point, ref.point)
