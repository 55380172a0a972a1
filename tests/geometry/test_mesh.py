"""Tests of ``service/geometry/mesh.py`` on meshes whose answers are known by construction."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from service.geometry.mesh import (
    boundary_edges,
    boundary_loops,
    check_mesh,
    connected_components,
    edges,
    face_normals,
    is_edge_manifold,
    signed_volume,
    unique_edges,
    vertex_normals,
)


def grid_mesh(nx: int, ny: int) -> tuple[np.ndarray, np.ndarray]:
    """Unit square in z = 0 split into nx x ny quads, two triangles each, normals +z."""
    x, y = np.meshgrid(np.linspace(0, 1, nx + 1), np.linspace(0, 1, ny + 1), indexing="ij")
    vertices = np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], axis=1)
    idx = np.arange(x.size).reshape(nx + 1, ny + 1)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    faces = np.concatenate([np.stack([a, b, c], axis=1), np.stack([a, c, d], axis=1)])
    return vertices, faces


def open_cylinder(n_around: int, n_rows: int) -> tuple[np.ndarray, np.ndarray]:
    """Unit-radius tube along z in [0, 1] without caps, normals outward."""
    theta = 2 * np.pi * np.arange(n_around) / n_around
    z = np.linspace(0, 1, n_rows + 1)
    t, zz = np.meshgrid(theta, z, indexing="ij")  # (n_around, n_rows + 1)
    vertices = np.stack([np.cos(t).ravel(), np.sin(t).ravel(), zz.ravel()], axis=1)
    idx = np.arange(t.size).reshape(n_around, n_rows + 1)
    nxt = np.roll(idx, -1, axis=0)
    a, b, c, d = idx[:, :-1].ravel(), nxt[:, :-1].ravel(), nxt[:, 1:].ravel(), idx[:, 1:].ravel()
    faces = np.concatenate([np.stack([a, b, c], axis=1), np.stack([a, c, d], axis=1)])
    return vertices, faces


def half_edge_set(faces: np.ndarray) -> set[tuple[int, int]]:
    return {(int(a), int(b)) for a, b in edges(faces)}


def loop_half_edges(loop: np.ndarray) -> set[tuple[int, int]]:
    return {(int(a), int(b)) for a, b in zip(loop, np.roll(loop, -1), strict=True)}


def test_grid_has_one_boundary_loop_following_the_faces():
    vertices, faces = grid_mesh(4, 3)
    loops = boundary_loops(faces)
    assert len(loops) == 1
    loop = loops[0]
    assert len(loop) == 2 * (4 + 3)
    assert len(set(loop.tolist())) == len(loop)
    assert loop_half_edges(loop) <= half_edge_set(faces)
    # Faces point to +z, so the boundary runs counter-clockwise seen from +z: positive shoelace area.
    x, y = vertices[loop, 0], vertices[loop, 1]
    assert 0.5 * np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y) == pytest.approx(1.0)


def test_boundary_edges_are_the_loop_edges():
    _, faces = grid_mesh(3, 3)
    (loop,) = boundary_loops(faces)
    assert {(int(a), int(b)) for a, b in boundary_edges(faces)} == loop_half_edges(loop)


def test_open_cylinder_has_two_opposite_loops():
    vertices, faces = open_cylinder(12, 3)
    loops = boundary_loops(faces)
    assert sorted(len(loop) for loop in loops) == [12, 12]
    assert all(loop_half_edges(loop) <= half_edge_set(faces) for loop in loops)
    by_z = {round(float(vertices[loop, 2].mean()), 6): loop for loop in loops}
    assert set(by_z) == {0.0, 1.0}
    for z, turn in ((0.0, 1.0), (1.0, -1.0)):  # outward normals: bottom runs +theta, top runs -theta
        p = vertices[by_z[z]]
        assert np.all(p[:, 2] == z)
        winding = np.sum(p[:, 0] * np.roll(p[:, 1], -1) - np.roll(p[:, 0], -1) * p[:, 1])
        assert np.sign(winding) == turn


def test_closed_sphere_has_no_boundary():
    sphere = trimesh.creation.icosphere(subdivisions=2)
    assert boundary_loops(np.asarray(sphere.faces)) == []
    assert len(boundary_edges(np.asarray(sphere.faces))) == 0


def test_bow_tie_boundary_raises():
    # Two triangles sharing vertex 0 only: two boundary edges leave vertex 0.
    faces = np.array([[0, 1, 2], [0, 3, 4]])
    with pytest.raises(ValueError, match="non-manifold boundary at vertex 0"):
        boundary_loops(faces)


def test_edge_manifold_detects_a_flipped_face():
    _, faces = grid_mesh(3, 3)
    sphere = trimesh.creation.icosphere(subdivisions=1)
    assert is_edge_manifold(faces)
    assert is_edge_manifold(np.asarray(sphere.faces))
    flipped = faces.copy()
    flipped[4] = flipped[4, ::-1]
    assert not is_edge_manifold(flipped)


def test_edge_with_three_faces_is_not_manifold():
    faces = np.array([[0, 1, 2], [1, 0, 3], [0, 4, 1]])
    assert not is_edge_manifold(faces)


def test_signed_volume_of_unit_cube():
    cube = trimesh.creation.box(extents=(1.0, 1.0, 1.0))
    vertices, faces = np.asarray(cube.vertices), np.asarray(cube.faces)
    assert signed_volume(vertices, faces) == pytest.approx(1.0, abs=1e-12)
    assert signed_volume(vertices + [3.0, -2.0, 5.0], faces) == pytest.approx(1.0, abs=1e-12)
    assert signed_volume(vertices, faces[:, ::-1]) == pytest.approx(-1.0, abs=1e-12)
    assert signed_volume(2.0 * vertices, faces) == pytest.approx(8.0, abs=1e-12)


def test_vertex_normals_of_sphere_point_outward():
    sphere = trimesh.creation.icosphere(subdivisions=3, radius=2.0)
    vertices, faces = np.asarray(sphere.vertices), np.asarray(sphere.faces)
    normals = vertex_normals(vertices, faces)
    np.testing.assert_allclose(np.linalg.norm(normals, axis=1), 1.0, atol=1e-12)
    radial = vertices / np.linalg.norm(vertices, axis=1, keepdims=True)
    assert np.einsum("ij,ij->i", normals, radial).min() > 0.99
    assert np.einsum("ij,ij->i", vertex_normals(vertices, faces[:, ::-1]), radial).max() < -0.99


def test_face_normals_length_is_twice_the_area():
    vertices, faces = grid_mesh(2, 5)
    n = face_normals(vertices, faces, normalize=False)
    np.testing.assert_allclose(n[:, :2], 0.0, atol=1e-15)
    np.testing.assert_allclose(n[:, 2], 2 * (1 / 10) / 2, rtol=1e-12)


def test_unique_edges_of_grid():
    _, faces = grid_mesh(3, 2)
    e = unique_edges(faces)
    # Horizontal + vertical + one diagonal per quad.
    assert len(e) == 3 * 3 + 4 * 2 + 3 * 2
    assert np.all(e[:, 0] < e[:, 1])


def test_connected_components_labels_disjoint_grids():
    vertices, faces = grid_mesh(2, 2)
    faces2 = np.concatenate([faces, faces + len(vertices)])
    labels = connected_components(faces2, 2 * len(vertices) + 1)  # plus one isolated vertex
    assert len(np.unique(labels)) == 3
    assert len(np.unique(labels[: len(vertices)])) == 1
    assert labels[0] != labels[len(vertices)]


@pytest.mark.parametrize(
    ("vertices", "faces", "message"),
    [
        (np.zeros((4, 2)), np.array([[0, 1, 2]]), r"vertices must be \(V, 3\), got \(4, 2\)"),
        (np.zeros(12), np.array([[0, 1, 2]]), r"vertices must be \(V, 3\)"),
        (np.array([[0, 0, 0], [1, 0, 0], [0, np.nan, 0]]), np.array([[0, 1, 2]]), "vertices must be finite"),
        (np.zeros((3, 3)), np.array([0, 1, 2]), r"faces must be \(F, 3\), got \(3,\)"),
        (np.zeros((3, 3)), np.array([[0, 1, 2, 0]]), r"faces must be \(F, 3\)"),
        (np.zeros((3, 3)), np.array([[0, 1, 3]]), "faces index outside vertices"),
        (np.zeros((3, 3)), np.array([[0, -1, 2]]), "faces index outside vertices"),
    ],
)
def test_check_mesh_names_the_bad_argument(vertices, faces, message):
    with pytest.raises(ValueError, match=message):
        check_mesh(vertices, faces)


def test_check_mesh_accepts_valid_and_empty_faces():
    vertices, faces = grid_mesh(1, 1)
    check_mesh(vertices, faces)
    check_mesh(vertices, np.zeros((0, 3), dtype=np.int64))


def test_boundary_loops_open_chain_raises_value_error():
    """An open boundary chain (edge 0-1 has three faces: 012 plus the doubled 031 / 130) raises
    the documented ValueError. (Regression: the walk used to die with KeyError.)"""
    faces = np.array([[0, 1, 2], [0, 3, 1], [1, 3, 0]])
    assert not is_edge_manifold(faces)
    with pytest.raises(ValueError, match="open boundary chain"):
        boundary_loops(faces)


def test_vertex_normals_match_add_at_bit_for_bit():
    from service.geometry.mesh import face_normals, vertex_normals

    rng = np.random.default_rng(3)
    v, f = grid_mesh(7, 6)
    v = v + rng.normal(scale=0.05, size=v.shape)
    fn = face_normals(v, f, normalize=False)
    vn = np.zeros_like(v)
    for k in range(3):
        np.add.at(vn, f[:, k], fn)
    expected = vn / np.maximum(np.linalg.norm(vn, axis=1, keepdims=True), 1e-30)
    np.testing.assert_array_equal(vertex_normals(v, f), expected)
