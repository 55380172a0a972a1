"""Tests of ``training/garments/cut.py``: clipping by a linear field is exact, so areas and the cut
line are checked against closed forms to float precision."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from service.geometry.mesh import boundary_loops, face_normals, is_edge_manifold
from tests.meshes import grid_mesh
from training.garments.cut import clip_mesh, compact, largest_component

# Cut lines that pass through no vertex of grid_mesh(7): its coordinates are k / 7.
PLANES = [  # (a, b, c): values = a x + b y - c on the unit square; kept area {values <= 0}
    ((1.0, 0.0, 0.5), 0.5),
    ((1.0, 0.5, 0.6), 0.6 - 0.25),  # x <= 0.6 - y / 2
    ((-1.0, 0.0, -0.3), 0.7),  # x >= 0.3
    ((1.0, 1.0, 0.5), 0.125),  # the corner triangle x + y <= 0.5
]


def areas(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    return 0.5 * np.linalg.norm(face_normals(vertices, faces, normalize=False), axis=1)


def plane_values(vertices: np.ndarray, plane: tuple[float, float, float]) -> np.ndarray:
    a, b, c = plane
    return a * vertices[:, 0] + b * vertices[:, 1] - c


@pytest.mark.parametrize(("plane", "area"), PLANES)
def test_clip_grid_keeps_exact_area(plane, area):
    vertices, faces = grid_mesh(7)
    v, f = clip_mesh(vertices, faces, plane_values(vertices, plane))
    assert abs(areas(v, f).sum() - area) < 1e-9
    assert plane_values(v, plane).max() < 1e-12  # nothing outside is kept


@pytest.mark.parametrize(("plane", "area"), PLANES)
def test_clip_boundary_lies_on_zero_set(plane, area):
    vertices, faces = grid_mesh(7)
    v, f = clip_mesh(vertices, faces, plane_values(vertices, plane))
    (loop,) = boundary_loops(f)
    p = v[loop]
    on_square = np.any((np.abs(p[:, :2]) < 1e-15) | (np.abs(p[:, :2] - 1) < 1e-15), axis=1)
    cut = loop[~on_square]
    assert len(cut) >= 2
    # The field is linear, so its value at the new vertices equals the interpolated one.
    assert np.abs(plane_values(v[cut], plane)).max() < 1e-12
    # New vertices are exactly the cut: every kept original vertex is strictly inside.
    original = {tuple(x) for x in vertices.tolist()}
    new = np.array([tuple(x) not in original for x in v.tolist()])
    assert np.abs(plane_values(v[new], plane)).max() < 1e-12
    assert set(np.flatnonzero(new)) <= set(loop.tolist())


@pytest.mark.parametrize(("plane", "area"), PLANES)
def test_clip_preserves_orientation_and_manifoldness(plane, area):
    vertices, faces = grid_mesh(7)
    v, f = clip_mesh(vertices, faces, plane_values(vertices, plane))
    assert np.all(face_normals(v, f)[:, 2] > 0.999)
    assert is_edge_manifold(f)
    assert len(boundary_loops(f)) == 1
    assert areas(v, f).min() > 1e-6  # no slivers when no vertex is near the cut


def test_clip_sphere_cap():
    sphere = trimesh.creation.icosphere(subdivisions=3)
    vertices, faces = np.asarray(sphere.vertices), np.asarray(sphere.faces)
    height = 0.3 + 1e-3  # no vertex on the cut
    v, f = clip_mesh(vertices, faces, vertices[:, 2] - height)
    assert is_edge_manifold(f)
    (loop,) = boundary_loops(f)
    assert np.abs(v[loop, 2] - height).max() < 1e-12
    centroids = v[f].mean(axis=1)
    assert np.all(np.einsum("ij,ij->i", face_normals(v, f), centroids) > 0)  # still outward
    # The clipped boundary loop runs clockwise seen from +z (the kept part lies below it).
    x, y = v[loop, 0], v[loop, 1]
    assert np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y) < 0


def test_clip_keeps_everything_or_nothing():
    vertices, faces = grid_mesh(3)
    v, f = clip_mesh(vertices, faces, vertices[:, 0] - 2.0)
    np.testing.assert_array_equal(v, vertices)
    np.testing.assert_array_equal(f, faces)
    v, f = clip_mesh(vertices, faces, vertices[:, 0] + 2.0)
    assert v.shape == (0, 3) and f.shape == (0, 3)


def test_clip_checks_value_shape():
    vertices, faces = grid_mesh(2)
    with pytest.raises(ValueError, match=r"values must be \(9,\), got \(8,\)"):
        clip_mesh(vertices, faces, np.zeros(8))


def test_clip_through_grid_vertices_leaves_no_slivers():
    """A cut through a column of vertices snaps to them: no slivers, the exact half kept.
    (Regression: values near 0 used to be pushed to +eps, leaving ~1e-9 edges and ~5e-11 areas.)"""
    vertices, faces = grid_mesh(10)
    v, f = clip_mesh(vertices, faces, vertices[:, 0] - 0.5)
    assert areas(v, f).min() > 1e-6
    assert abs(areas(v, f).sum() - 0.5) < 1e-12


def test_largest_component_picks_the_bigger_grid():
    small_v, small_f = grid_mesh(3)
    big_v, big_f = grid_mesh(5)
    big_v = big_v + [2.0, 0.0, 0.0]
    for first, second in (((small_v, small_f), (big_v, big_f)), ((big_v, big_f), (small_v, small_f))):
        vertices = np.concatenate([first[0], second[0]])
        faces = np.concatenate([first[1], second[1] + len(first[0])])
        v, f = largest_component(vertices, faces)
        assert f.shape == big_f.shape
        np.testing.assert_array_equal(v, big_v)
        np.testing.assert_array_equal(v[f], big_v[big_f])


def test_compact_drops_unused_vertices():
    vertices = np.arange(15, dtype=np.float64).reshape(5, 3)
    v, f = compact(vertices, np.array([[4, 1, 3]]))
    np.testing.assert_array_equal(v, vertices[[1, 3, 4]])
    np.testing.assert_array_equal(v[f], vertices[[[4, 1, 3]]])
