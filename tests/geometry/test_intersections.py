"""Tests of ``service/geometry/intersections.py``: the KD-tree and grid paths against the all-pairs reference
on random meshes and on touching and near-touching ones, and hand-made configurations whose answer is
known."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from service.geometry.intersections import (
    TriangleGrid,
    cross,
    crossing_triangles,
    intersecting_pairs,
    intersecting_pairs_reference,
    segments_cross_triangles,
    triangles_intersect,
)
from tests.meshes import grid_mesh

FLAT = np.array([[-1.0, -1.0, 0.0], [1.0, -1.0, 0.0], [0.0, 1.0, 0.0]])  # in z = 0
ONE_FACE = np.array([[0, 1, 2]])


def figure_eight_strip(n: int = 47) -> tuple[np.ndarray, np.ndarray]:
    """A strip whose centre line x = sin t, z = sin(2t) / 2 (t in [-0.5, pi + 0.5]) passes the
    origin twice in different directions, extruded along y in [0, 1]: it crosses itself along the
    y axis, between triangles far apart in the strip that share no vertex."""
    t = np.linspace(-0.5, np.pi + 0.5, n)  # no sample at t = 0 or pi: the crossing is transversal
    line = np.stack([np.sin(t), np.sin(2 * t) / 2], axis=1)
    vertices = np.concatenate(
        [np.stack([line[:, 0], np.full(n, y), line[:, 1]], axis=1) for y in (0.0, 0.5, 1.0)]
    )
    idx = np.arange(3 * n).reshape(3, n)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, 1:].ravel(), idx[1:, :-1].ravel()
    return vertices, np.concatenate([np.stack([a, b, c], axis=1), np.stack([a, c, d], axis=1)])


def pair_set(pairs: np.ndarray) -> set[tuple[int, int]]:
    return {(int(i), int(j)) for i, j in pairs}


def self_reference(vertices: np.ndarray, faces: np.ndarray) -> set[tuple[int, int]]:
    """Brute-force self-intersections: all pairs, i < j, no shared vertex."""
    pairs = pair_set(intersecting_pairs_reference(vertices, faces, vertices, faces))
    return {(i, j) for i, j in pairs if i < j and not set(faces[i]) & set(faces[j])}


def perturbed_sphere(rng: np.random.Generator, radius: float, center, noise: float):
    sphere = trimesh.creation.icosphere(subdivisions=1, radius=radius)
    vertices = np.asarray(sphere.vertices) + rng.normal(scale=noise, size=sphere.vertices.shape)
    return vertices + center, np.asarray(sphere.faces)


def perturbed_grid(rng: np.random.Generator, n: int, scale: float, noise: float):
    """A noisy square of side ``scale`` centred near the origin in a random orientation."""
    vertices, faces = grid_mesh(n)
    rotation = trimesh.transformations.random_rotation_matrix(rand=rng.random(3))[:3, :3]
    vertices = scale * (vertices - [0.5, 0.5, 0.0]) + rng.normal(scale=noise, size=vertices.shape)
    return vertices @ rotation.T + rng.uniform(-0.3, 0.3, size=3), faces


# ------------------------------------------------------------------ fast path vs reference


@pytest.mark.parametrize("seed", range(12))
def test_fast_matches_reference_on_random_spheres(seed: int):
    rng = np.random.default_rng(seed)
    # Second sphere from coincident to well apart, and of a different size (exercises both tree sides).
    va, fa = perturbed_sphere(rng, 1.0, np.zeros(3), noise=0.05)
    vb, fb = perturbed_sphere(rng, rng.uniform(0.3, 1.5), rng.uniform(-1.5, 1.5, size=3), noise=0.05)
    for args in ((va, fa, vb, fb), (vb, fb, va, fa)):
        assert pair_set(intersecting_pairs(*args)) == pair_set(intersecting_pairs_reference(*args))


@pytest.mark.parametrize("seed", range(12))
def test_fast_matches_reference_on_random_grids(seed: int):
    rng = np.random.default_rng(100 + seed)
    va, fa = perturbed_grid(rng, 6, 1.0, noise=0.03)
    vb, fb = perturbed_grid(rng, 3, rng.uniform(0.2, 3.0), noise=0.03)  # fewer, bigger or smaller triangles
    for args in ((va, fa, vb, fb), (vb, fb, va, fa)):
        assert pair_set(intersecting_pairs(*args)) == pair_set(intersecting_pairs_reference(*args))


def test_random_cases_include_intersections():
    """Guard against the comparisons above passing on empty sets only."""
    sphere_hits = grid_hits = 0
    for seed in range(12):
        rng = np.random.default_rng(seed)
        va, fa = perturbed_sphere(rng, 1.0, np.zeros(3), noise=0.05)
        vb, fb = perturbed_sphere(rng, rng.uniform(0.3, 1.5), rng.uniform(-1.5, 1.5, size=3), noise=0.05)
        sphere_hits += len(intersecting_pairs(va, fa, vb, fb)) > 0
        rng = np.random.default_rng(100 + seed)
        va, fa = perturbed_grid(rng, 6, 1.0, noise=0.03)
        vb, fb = perturbed_grid(rng, 3, rng.uniform(0.2, 3.0), noise=0.03)
        grid_hits += len(intersecting_pairs(va, fa, vb, fb)) > 0
    assert 3 <= sphere_hits <= 11 and 3 <= grid_hits <= 11


@pytest.mark.parametrize("seed", range(6))
def test_self_intersections_match_reference_on_crumpled_grid(seed: int):
    rng = np.random.default_rng(200 + seed)
    vertices, faces = grid_mesh(6)
    vertices = vertices + rng.normal(scale=0.12, size=vertices.shape)
    fast = pair_set(intersecting_pairs(vertices, faces))
    assert fast == self_reference(vertices, faces)
    assert all(i < j for i, j in fast)


# ------------------------------------------------------------------ hand-made configurations


def test_crossing_triangles_are_one_pair():
    # A vertical triangle in x = 0 wider than FLAT: FLAT's edges pass through it, like a cross.
    upright = np.array([[0.0, -3.0, -1.0], [0.0, 3.0, -1.0], [0.0, 0.0, 1.0]])
    pairs = intersecting_pairs(FLAT, ONE_FACE, upright, ONE_FACE)
    assert pair_set(pairs) == {(0, 0)}
    assert pair_set(intersecting_pairs(upright, ONE_FACE, FLAT, ONE_FACE)) == {(0, 0)}


def test_triangle_piercing_interior():
    # Both crossing edges of this narrow triangle pass through FLAT's interior; FLAT's edges miss it.
    spike = np.array([[0.0, 0.0, -1.0], [0.0, 0.5, 1.0], [0.0, -0.5, 1.0]])
    assert pair_set(intersecting_pairs(FLAT, ONE_FACE, spike, ONE_FACE)) == {(0, 0)}
    assert triangles_intersect(FLAT[None], spike[None]).tolist() == [True]
    assert triangles_intersect(spike[None], FLAT[None]).tolist() == [True]


def test_parallel_separated_triangles_do_not_intersect():
    above = FLAT + [0.0, 0.0, 0.1]
    assert len(intersecting_pairs(FLAT, ONE_FACE, above, ONE_FACE)) == 0
    assert triangles_intersect(FLAT[None], above[None]).tolist() == [False]


def test_triangle_beside_another_does_not_intersect():
    # Crosses FLAT's plane, but outside FLAT.
    beside = np.array([[3.0, 0.0, -1.0], [3.0, 0.5, 1.0], [3.0, -0.5, 1.0]])
    assert len(intersecting_pairs(FLAT, ONE_FACE, beside, ONE_FACE)) == 0


def test_touching_at_a_vertex_is_not_an_intersection():
    touching = np.array([[0.0, 0.0, 0.0], [0.0, 0.5, 1.0], [0.0, -0.5, 1.0]])
    assert len(intersecting_pairs(FLAT, ONE_FACE, touching, ONE_FACE)) == 0


def test_segments_cross_triangles_known_cases():
    a, b, c = np.array([0.0, 0.0, 0.0]), np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0])
    cases = [  # (p, q, crosses)
        ((0.2, 0.2, -1.0), (0.2, 0.2, 1.0), True),  # straight through the interior
        ((0.2, 0.2, 1.0), (0.2, 0.2, -1.0), True),  # either direction
        ((0.0, 0.0, -1.0), (0.6, 0.6, 1.0), True),  # slanted, through (0.3, 0.3, 0)
        ((2.0, 2.0, -1.0), (2.0, 2.0, 1.0), False),  # crosses the plane outside the triangle
        ((0.2, 0.2, 0.5), (0.2, 0.2, 1.0), False),  # stops short of the plane
        ((0.2, 0.2, 0.0), (0.2, 0.2, 1.0), False),  # touches the triangle
        ((-1.0, 0.2, 0.0), (1.0, 0.2, 0.0), False),  # coplanar
        ((0.5, 0.0, -1.0), (0.5, 0.0, 1.0), False),  # through an edge: touching
        ((0.0, 0.0, -1.0), (0.0, 0.0, 1.0), False),  # through a vertex: touching
    ]
    p = np.array([case[0] for case in cases])
    q = np.array([case[1] for case in cases])
    abc = [np.broadcast_to(x, p.shape) for x in (a, b, c)]
    result = segments_cross_triangles(p, q, *abc)
    assert result.dtype == bool and result.shape == (len(cases),)
    assert result.tolist() == [case[2] for case in cases]


def test_folded_strip_self_intersection_is_detected():
    vertices, faces = figure_eight_strip()
    pairs = intersecting_pairs(vertices, faces)
    assert len(pairs) > 0
    assert pair_set(pairs) == self_reference(vertices, faces)
    # Every reported pair straddles the crossing line x = z = 0.
    centroids = vertices[faces].mean(axis=1)
    assert np.all(np.abs(centroids[pairs][:, :, [0, 2]]) < 0.2)


@pytest.mark.parametrize("n", [1, 5])
def test_flat_grid_has_no_self_intersection(n: int):
    vertices, faces = grid_mesh(n)
    assert intersecting_pairs(vertices, faces).shape == (0, 2)


def test_closed_sphere_has_no_self_intersection():
    sphere = trimesh.creation.icosphere(subdivisions=2)
    assert len(intersecting_pairs(np.asarray(sphere.vertices), np.asarray(sphere.faces))) == 0


@pytest.mark.parametrize("seed", range(5))
def test_triangles_sharing_an_edge_are_never_reported(seed: int):
    # Pairs of triangles hinged on the edge a-b at random angles, folded flat ones included: as two
    # meshes (exact zeros of orient3d) and as one mesh (pairs sharing a vertex are skipped).
    rng = np.random.default_rng(300 + seed)
    n = 200
    a, b = rng.normal(size=(n, 3)), rng.normal(size=(n, 3))
    c, d = rng.normal(size=(n, 3)), rng.normal(size=(n, 3))
    d[:10] = c[:10] + 1e-9 * rng.normal(size=(10, 3))  # folded (almost) flat onto each other
    first = np.stack([a, b, c], axis=1)
    second = np.stack([b, a, d], axis=1)
    assert not triangles_intersect(first, second).any()
    assert not triangles_intersect(second, first).any()
    for k in range(n):
        vertices = np.stack([a[k], b[k], c[k], d[k]])
        faces = np.array([[0, 1, 2], [1, 0, 3]])
        assert len(intersecting_pairs(vertices, faces)) == 0
        assert len(intersecting_pairs(vertices, faces[:1], vertices, faces[1:])) == 0


def test_concentric_spheres_do_not_intersect_shifted_ones_do():
    inner = trimesh.creation.icosphere(subdivisions=3, radius=1.0)
    outer = trimesh.creation.icosphere(subdivisions=3, radius=1.1)
    vi, fi = np.asarray(inner.vertices), np.asarray(inner.faces)
    vo, fo = np.asarray(outer.vertices), np.asarray(outer.faces)
    assert intersecting_pairs(vi, fi, vo, fo).shape == (0, 2)
    shifted = intersecting_pairs(vi, fi, vi + [0.5, 0.0, 0.0], fi)
    assert len(shifted) > 0
    # The two unit spheres meet on the circle x = 0.25, radius sqrt(1 - 0.25^2).
    centroids = vi[fi[shifted[:, 0]]].mean(axis=1)
    assert np.all(np.abs(centroids[:, 0] - 0.25) < 0.1)


def test_input_shapes_are_checked():
    with pytest.raises(ValueError, match="vertices must be"):
        intersecting_pairs(FLAT[:, :2], ONE_FACE)
    with pytest.raises(ValueError, match="faces index outside vertices"):
        intersecting_pairs(FLAT, ONE_FACE, FLAT, np.array([[0, 1, 3]]))


def test_intersecting_pairs_on_a_mesh_without_faces():
    """A mesh with no faces has no intersecting pairs, like the reference says.
    (Regression: the largest-triangle radius was a reduction over an empty array.)"""
    none = np.zeros((0, 3), dtype=np.int64)
    for args in ((FLAT, none, FLAT, ONE_FACE), (FLAT, ONE_FACE, FLAT, none)):
        assert intersecting_pairs_reference(*args).shape == (0, 2)
        assert intersecting_pairs(*args).shape == (0, 2)
    assert intersecting_pairs(FLAT, none).shape == (0, 2)


# ------------------------------------------------------------------ the repair's grid path


@pytest.mark.parametrize("seed", range(8))
def test_grid_crossing_matches_intersecting_pairs(seed: int):
    rng = np.random.default_rng(300 + seed)
    va, fa = perturbed_sphere(rng, 1.0, np.zeros(3), noise=0.05)
    vb, fb = perturbed_sphere(rng, rng.uniform(0.3, 1.5), rng.uniform(-1.0, 1.0, size=3), noise=0.05)
    vg, fg = perturbed_grid(rng, 6, 1.0, noise=0.03)
    for (v1, f1), (v2, f2) in (((va, fa), (vb, fb)), ((vb, fb), (va, fa)), ((vg, fg), (va, fa))):
        for cell in (None, 0.05, 0.7):
            grid = TriangleGrid.build(v2, f2, cell)
            got = grid.crossing(v1, f1)
            assert len(got) == len(pair_set(got))  # each pair once
            assert pair_set(got) == pair_set(intersecting_pairs(v1, f1, v2, f2))


def test_grid_crossing_on_two_threads_is_the_one_thread_answer_in_order(monkeypatch):
    import service.geometry.intersections as intersections

    rng = np.random.default_rng(310)
    va, fa = perturbed_sphere(rng, 1.0, np.zeros(3), noise=0.05)
    vb, fb = perturbed_sphere(rng, 0.9, np.array([0.3, 0.0, 0.1]), noise=0.05)
    grid = TriangleGrid.build(vb, fb)
    monkeypatch.setattr(intersections, "CROSSING_SPLIT", 10**9)
    whole = grid.crossing(va, fa)
    assert len(whole) > 50 and len(fa) == 80
    monkeypatch.setattr(intersections, "CROSSING_SPLIT", 40)
    for threads in (2, 3):
        monkeypatch.setattr(intersections, "CROSSING_THREADS", threads)
        np.testing.assert_array_equal(grid.crossing(va, fa), whole)


def test_grid_crossing_finds_a_known_crossing_and_nothing_far_away():
    grid = TriangleGrid.build(FLAT, ONE_FACE)
    spike = np.array([[0.0, 0.0, -1.0], [0.1, 0.0, 1.0], [-0.1, 0.1, 1.0]])
    assert pair_set(grid.crossing(spike, ONE_FACE)) == {(0, 0)}
    assert grid.crossing(spike + [0.0, 0.0, 5.0], ONE_FACE).shape == (0, 2)
    assert grid.crossing(spike + 1e9, ONE_FACE).shape == (0, 2)  # beyond the cell keys


def test_crossing_triangles_is_triangles_intersect_bit_for_bit():
    rng = np.random.default_rng(7)
    ta = rng.normal(size=(4000, 3, 3))
    tb = ta + rng.normal(scale=0.7, size=ta.shape)
    # Shared corners, coplanar and touching cases, where the determinants are exactly zero.
    tb[:500, 0] = ta[:500, 0]
    tb[500:1000] = ta[500:1000][:, [1, 0, 2]]
    tb[1000:1500, :, 2] = ta[1000:1500, :, 2] = 0.0
    na = np.cross(ta[:, 1] - ta[:, 0], ta[:, 2] - ta[:, 0])
    nb = np.cross(tb[:, 1] - tb[:, 0], tb[:, 2] - tb[:, 0])
    fast = crossing_triangles(ta, tb, na, nb)
    np.testing.assert_array_equal(fast, triangles_intersect(ta, tb))
    assert 100 < fast.sum() < 3900


def test_cross_is_np_cross_bit_for_bit():
    rng = np.random.default_rng(11)
    u = rng.normal(size=(5000, 3)) * 10.0 ** rng.integers(-8, 9, size=(5000, 3))
    v = rng.normal(size=(5000, 3)) * 10.0 ** rng.integers(-8, 9, size=(5000, 3))
    u[:500] = 3 * v[:500]  # parallel
    u[500:1000, 2], v[500:1000, 2] = 0.0, -0.0  # signed zeros
    np.testing.assert_array_equal(cross(u, v).view(np.int64), np.cross(u, v).view(np.int64))


def _box_triangles(lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Triangles (vertices, faces) whose bounding boxes are exactly ``lo..hi (N, 3)``."""
    n = len(lo)
    vertices = np.concatenate([lo, hi, np.stack([lo[:, 0], hi[:, 1], lo[:, 2]], axis=1)])
    return vertices, np.arange(3 * n).reshape(3, n).T


@pytest.mark.parametrize("cell", [None, 0.25, 0.1, 1e-9])
def test_grid_candidates_are_the_overlapping_boxes_each_once(cell: float | None):
    # Boxes on a lattice of 1/8: with cells of 1/4 their sides fall on cell and step boundaries and
    # many touch exactly. Some span many cells, some are flat, some queries lie outside the grid or
    # straddle its side, and some end one float below a grid box (the steps tie, the floats decide).
    rng = np.random.default_rng(5)

    def boxes(n: int, size: int) -> tuple[np.ndarray, np.ndarray]:
        lo = rng.integers(-2, 9, size=(n, 3)) / 8
        return lo, lo + rng.integers(0, size, size=(n, 3)) / 8

    grid_lo, grid_hi = boxes(300, 4)
    grid_lo[:20], grid_hi[:20] = boxes(20, 12)
    lo, hi = boxes(400, 4)
    lo[:30] += 3.0
    hi[:30] += 3.0
    lo[30:60] -= 0.5
    below = rng.integers(0, 300, size=40)
    hi[60:100] = np.nextafter(grid_lo[below], -np.inf)
    lo[60:100] = hi[60:100] - 0.2
    grid = TriangleGrid.build(*_box_triangles(grid_lo, grid_hi), cell)
    i, j = grid.candidates(lo, hi)
    expected = np.all((lo[:, None] <= grid_hi[None]) & (grid_lo[None] <= hi[:, None]), axis=2)
    assert len(i) == len(pair_set(np.stack([i, j], axis=1)))  # each pair once
    assert pair_set(np.stack([i, j], axis=1)) == pair_set(np.argwhere(expected))
    assert expected.sum() > 1000


def _sheet(n: int, angle: float, shift) -> tuple[np.ndarray, np.ndarray]:
    """``grid_mesh(n)`` centred on the origin, turned by ``angle`` about x, then moved by ``shift``."""
    vertices, faces = grid_mesh(n)
    vertices = vertices - [0.5, 0.5, 0.0]
    c, s = np.cos(angle), np.sin(angle)
    return vertices @ np.array([[1, 0, 0], [0, c, s], [0, -s, c]]) + shift, faces


@pytest.mark.parametrize("cell", [None, 1 / 8, 0.03])
def test_grid_crossing_matches_reference_on_touching_and_near_touching_sheets(cell: float | None):
    inner_v, inner_f = _sheet(8, 0.0, [0.5, 0.5, 0.0])  # z = 0, vertices every 1/8
    cases = {  # name: (mesh, crossings expected)
        "tilted through": (_sheet(5, 0.4, [0.5, 0.5, 0.0]), True),
        "upright, through its triangles": (_sheet(4, np.pi / 2, [0.5, 0.5 + 1 / 16, 1 / 16]), True),
        "upright, along its edges": (_sheet(4, np.pi / 2, [0.5, 0.5, 1 / 16]), False),  # touching only
        "upright, an edge row in its plane": (_sheet(4, np.pi / 2, [0.5, 0.5, 0.0]), False),
        "upright, standing on it": (_sheet(4, np.pi / 2, [0.5, 0.5, 0.5]), False),
        "itself": ((inner_v, inner_f), False),
        "1e-15 above": ((inner_v + [0.0, 0.0, 1e-15], inner_f), False),
        "denormal above": ((inner_v + [0.0, 0.0, 5e-324], inner_f), False),
        "beside it": (_sheet(4, 0.4, [1.5 + 2**-50, 0.5, 0.0]), False),
    }
    grid = TriangleGrid.build(inner_v, inner_f, cell)
    for name, ((v, f), crosses) in cases.items():
        got = pair_set(grid.crossing(v, f))
        assert got == pair_set(intersecting_pairs_reference(v, f, inner_v, inner_f)), name
        assert bool(got) == crosses, name


def test_grid_cells_hold_boxes_whose_sides_fall_on_cell_boundaries_after_rounding():
    """Regression: sheets of decimal sizes (cells of 0.04, 0.03, ...) whose highest corner divided by
    the cell rounds just below a whole number while its quantised steps reach it; the grid counted
    one cell too few and listing its boxes failed."""
    for n, size in ((10, 0.4), (8, 0.36), (12, 0.3), (9, 0.27)):
        vertices, faces = grid_mesh(n)
        vertices = (vertices - [0.5, 0.5, 0.0]) * [size, size, 0.0]
        corner_x = vertices[faces][:, :, 0]
        for a in range(n):  # every window of columns, as the repair passes the faces near a layer
            for b in range(a + 1, n + 1):
                near = (corner_x.min(axis=1) >= (a / n - 0.5) * size - 1e-12) & (
                    corner_x.max(axis=1) <= (b / n - 0.5) * size + 1e-12
                )
                grid = TriangleGrid.build(vertices, faces[near])
                spike = np.array([[0.0, 0.0, -1.0], [0.01, 0.0, 1.0], [-0.01, 0.01, 1.0]]) * size
                expected = intersecting_pairs_reference(spike, ONE_FACE, vertices, faces[near])
                assert pair_set(grid.crossing(spike, ONE_FACE)) == pair_set(expected)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_segment_crossings_match_reference_and_count_a_sphere_once(seed: int):
    from service.geometry.intersections import segment_crossings, segment_crossings_reference

    sphere = trimesh.creation.icosphere(subdivisions=2, radius=0.1)
    v, f = np.asarray(sphere.vertices), np.asarray(sphere.faces, dtype=np.int64)
    rng = np.random.default_rng(seed)
    p = rng.normal(0, 0.02, (300, 3))  # inside
    q = p + rng.normal(0, 0.12, (300, 3))  # inside or outside
    counts = segment_crossings(TriangleGrid.build(v, f), p, q)
    np.testing.assert_array_equal(counts, segment_crossings_reference(v, f, p, q))
    # Clearly inside the faceted sphere (within its inscribed radius) or clearly outside it.
    r = np.linalg.norm(q, axis=1)
    inside, outside = r < 0.095, r > 0.1
    assert inside.sum() > 20 and outside.sum() > 20
    assert np.all(counts[inside] == 0) and np.all(counts[outside] == 1)
