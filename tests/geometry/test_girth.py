"""Tests of ``service/geometry/girth.py``: sections and tape girths of meshes whose answers are known
(elliptic cylinders against Ramanujan's perimeter, hulls against scipy's qhull)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import trimesh
from scipy.spatial import ConvexHull

from service.geometry.girth import (
    convex_hull,
    convex_perimeter,
    encloses,
    polyline_length,
    section_loops,
    signed_area,
    tape_edges,
    tape_girth,
    tape_girths,
    tape_girths_reference,
    tape_loop,
)


def stack(rings: np.ndarray, zs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Closed, outward-oriented mesh through horizontal rings ``(K, N, 2)`` (each counter-clockwise
    and star-shaped around its mean) at heights ``zs (K,)``, capped by fans: (vertices, faces)."""
    k, n = rings.shape[:2]
    side = np.concatenate([rings, np.broadcast_to(np.asarray(zs, float)[:, None, None], (k, n, 1))], axis=2)
    bottom = [*rings[0].mean(axis=0), zs[0]]
    top = [*rings[-1].mean(axis=0), zs[-1]]
    vertices = np.concatenate([side.reshape(-1, 3), [bottom, top]])
    idx = np.arange(k * n).reshape(k, n)
    a, b = idx[:-1], np.roll(idx, -1, axis=1)[:-1]
    c, d = np.roll(idx, -1, axis=1)[1:], idx[1:]
    walls = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)])
    i, j = idx[0], np.roll(idx[0], -1)
    bottom_fan = np.stack([np.full(n, k * n), j, i], 1)
    i, j = idx[-1], np.roll(idx[-1], -1)
    top_fan = np.stack([np.full(n, k * n + 1), i, j], 1)
    return vertices, np.concatenate([walls, bottom_fan, top_fan])


def ellipse(a: float, b: float, n: int, centre=(0.0, 0.0)) -> np.ndarray:
    t = 2 * np.pi * np.arange(n) / n
    return np.stack([centre[0] + a * np.cos(t), centre[1] + b * np.sin(t)], axis=1)


def ramanujan(a: float, b: float) -> float:
    """Ramanujan's second approximation of an ellipse's perimeter (relative error < 1e-9 here)."""
    h = ((a - b) / (a + b)) ** 2
    return math.pi * (a + b) * (1 + 3 * h / (10 + math.sqrt(4 - 3 * h)))


def elliptic_cylinder(a: float, b: float, n: int = 720, centre=(0.0, 0.0)) -> tuple[np.ndarray, np.ndarray]:
    return stack(np.stack([ellipse(a, b, n, centre)] * 3), np.array([-0.5, 0.0, 0.5]))


def test_stack_is_a_closed_outward_mesh():
    v, f = elliptic_cylinder(0.2, 0.1, 64)
    mesh = trimesh.Trimesh(v, f, process=False)
    assert mesh.is_watertight and mesh.is_winding_consistent and mesh.volume > 0


# ---------------------------------------------------------------- convex hull


@pytest.mark.parametrize("seed", range(5))
def test_convex_hull_matches_qhull(seed):
    rng = np.random.default_rng(seed)
    points = rng.normal(size=(300, 2)) * [1.0, 0.3]
    points = np.concatenate([points, points[:20], [[0.0, 0.0]]])  # repeats and an inner point
    hull = convex_hull(points)
    reference = ConvexHull(points)
    assert sorted(map(tuple, hull)) == sorted(map(tuple, points[reference.vertices]))
    assert signed_area(hull) == pytest.approx(reference.volume, rel=1e-12)  # counter-clockwise
    assert convex_perimeter(points) == pytest.approx(reference.area, rel=1e-12)


def test_convex_hull_drops_collinear_points():
    square = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], float)
    edge_points = np.array([[0.5, 0], [1, 0.25], [1, 0.5], [0.5, 1], [0, 0.5], [0.5, 0.5]])
    hull = convex_hull(np.concatenate([edge_points, square]))
    assert sorted(map(tuple, hull)) == sorted(map(tuple, square))
    assert convex_perimeter(np.concatenate([square, edge_points])) == pytest.approx(4.0)


def test_degenerate_point_sets():
    assert convex_perimeter(np.array([[0.3, 0.4]])) == 0.0
    assert convex_perimeter(np.array([[0.0, 0.0], [3.0, 4.0]])) == pytest.approx(10.0)  # there and back
    assert convex_perimeter(np.array([[0.0, 0.0], [1.0, 1.0], [3.0, 3.0]])) == pytest.approx(6 * math.sqrt(2))
    assert convex_perimeter(np.array([[1.0, 2.0]] * 4)) == 0.0
    with pytest.raises(ValueError):
        convex_hull(np.empty((0, 2)))
    with pytest.raises(ValueError):
        convex_hull(np.zeros((4, 3)))
    with pytest.raises(ValueError):
        convex_hull(np.array([[0.0, np.nan], [1, 1], [2, 0]]))


# ---------------------------------------------------------------- sections


@pytest.mark.parametrize(("a", "b"), [(0.15, 0.15), (0.18, 0.11), (0.2, 0.05)])
def test_tape_girth_of_an_elliptic_cylinder_is_its_perimeter(a, b):
    v, f = elliptic_cylinder(a, b)
    for z in (-0.3, 0.0, 0.21):  # through a ring of vertices and between rings
        girth = tape_girth(v, f, z, np.zeros(2))
        assert girth == pytest.approx(ramanujan(a, b), rel=2e-5)
        assert girth < ramanujan(a, b)  # an inscribed polygon is shorter than its ellipse


def test_section_loops_are_the_rings_counter_clockwise():
    rings = np.stack([ellipse(0.2, 0.1, 40), ellipse(0.3, 0.15, 40)])
    v, f = stack(rings, np.array([0.0, 1.0]))
    (loop,) = section_loops(v, f, 0.25)
    assert signed_area(loop) > 0
    # Each quad's vertical edge is crossed at the rings' interpolation, its diagonal in between.
    expected = 0.75 * rings[0] + 0.25 * rings[1]
    assert len(loop) == 80
    assert set(map(tuple, np.round(expected, 12))) <= set(map(tuple, np.round(loop, 12)))
    # Consecutive points are ring neighbours (the loop is in order, not just the right points).
    step = np.linalg.norm(np.diff(np.concatenate([loop, loop[:1]]), axis=0), axis=1)
    assert step.max() < 2 * np.linalg.norm(expected[1] - expected[0])
    assert section_loops(v, f, 2.0) == [] and section_loops(v, f, -1.0) == []


def test_a_tape_bridges_a_hollow():
    """A peanut section: the tape reads its hull's perimeter, shorter than the outline."""
    t = 2 * np.pi * np.arange(400) / 400
    r = 1.0 + 0.5 * np.cos(2 * t)
    peanut = np.stack([r * np.cos(t), r * np.sin(t)], axis=1)
    v, f = stack(np.stack([peanut] * 2), np.array([0.0, 1.0]))
    (loop,) = section_loops(v, f, 0.5)
    girth = tape_girth(v, f, 0.5, np.zeros(2))
    assert girth == pytest.approx(ConvexHull(peanut).area, rel=1e-12)
    assert girth < polyline_length(loop) - 0.1


def test_tape_goes_round_the_selected_loop_only():
    """A torso with an arm beside it: the tape round the torso leaves the arm out."""
    torso, arm = elliptic_cylinder(0.15, 0.1), elliptic_cylinder(0.04, 0.04, centre=(0.3, 0.0))
    v = np.concatenate([torso[0], arm[0]])
    f = np.concatenate([torso[1], arm[1] + len(torso[0])])
    assert len(section_loops(v, f, 0.1)) == 2
    assert tape_girth(v, f, 0.1, (0.0, 0.0)) == pytest.approx(ramanujan(0.15, 0.1), rel=2e-5)
    assert tape_girth(v, f, 0.1, (0.3, 0.0)) == pytest.approx(2 * math.pi * 0.04, rel=2e-5)
    hull = tape_loop(v, f, 0.1, (0.0, 0.0))
    assert hull[:, 0].max() < 0.16
    with pytest.raises(ValueError, match="goes around"):
        tape_girth(v, f, 0.1, (0.2, 0.0))
    girths, hulls = tape_girths(v, f, np.array([0.1, 0.2, 0.7]), (0.0, 0.0))
    assert girths[0] == tape_girth(v, f, 0.1, (0.0, 0.0)) and girths[1] == girths[0]
    assert np.isnan(girths[2]) and hulls[2].shape == (0, 2)  # above the mesh


def test_tape_goes_round_the_outside_of_a_tube():
    """A point in a tube's bore is inside the outer wall's loop and the inner one's: the tape goes
    round the outer wall; the bore's loop runs clockwise."""
    mesh = trimesh.creation.annulus(r_min=0.1, r_max=0.2, height=0.5, sections=256)
    assert mesh.is_watertight and mesh.volume > 0
    loops = section_loops(mesh.vertices, mesh.faces, 0.05)
    assert sorted(np.sign([signed_area(loop) for loop in loops])) == [-1, 1]
    assert all(encloses(loop, (0.0, 0.0)) for loop in loops)
    assert tape_girth(mesh.vertices, mesh.faces, 0.05, (0.0, 0.0)) == pytest.approx(
        2 * math.pi * 0.2, rel=1e-4
    )


def test_open_and_bad_meshes_raise():
    v, f = elliptic_cylinder(0.2, 0.1, 32)
    wall = f[: 2 * 2 * 32]  # the side walls without their caps: open at the bottom and the top
    assert len(section_loops(v, wall, 0.1)) == 1  # between the rims the section is still closed
    kept = np.ones(len(f), bool)
    kept[5] = False  # a hole in the wall
    with pytest.raises(ValueError, match="open"):
        section_loops(v, f[kept], -0.3)
    flipped = f.copy()
    flipped[5] = flipped[5, ::-1]
    with pytest.raises(ValueError):
        section_loops(v, flipped, -0.3)
    with pytest.raises(ValueError):
        section_loops(v[:, :2], f, 0.0)
    with pytest.raises(ValueError):
        section_loops(v, f, float("nan"))
    with pytest.raises(ValueError):
        tape_girths(v, f, np.array([0.0, 0.1]), np.zeros((3, 2)))


def test_a_plane_through_vertices():
    """A section exactly through a ring of vertices is that ring (a vertex on the plane is below)."""
    ring = ellipse(0.2, 0.1, 24)
    v, f = stack(np.stack([ring * 0.5, ring, ring * 0.5]), np.array([0.0, 1.0, 2.0]))
    (loop,) = section_loops(v, f, 1.0)  # each ring vertex twice: its vertical and diagonal edges up
    assert sorted(set(map(tuple, np.round(loop, 12)))) == sorted(map(tuple, np.round(ring, 12)))
    assert tape_girth(v, f, 1.0, (0, 0)) == pytest.approx(polyline_length(ring), rel=1e-12)


def test_tape_edges_are_the_tape_with_its_mesh_edges():
    """Each hull corner of ``tape_edges`` is the point ``a + t (b - a)`` of its mesh edge at the level, and
    the hull is ``tape_loop``'s (a torso with an arm beside it: the arm's loop is left out)."""
    torso, arm = elliptic_cylinder(0.15, 0.1, n=90), elliptic_cylinder(0.04, 0.04, n=30, centre=(0.3, 0.0))
    v = np.concatenate([torso[0], arm[0]])
    v[:, :2] *= 1.0 + 0.1 * np.sin(7.0 * v[:, 2:3])  # not a prism: the edges are slanted
    f = np.concatenate([torso[1], arm[1] + len(torso[0])])
    for z, tape in zip((0.13, 0.31), tape_edges(v, f, np.array([0.13, 0.31]), (0.0, 0.0)), strict=True):
        np.testing.assert_array_equal(tape.points, tape_loop(v, f, z, (0.0, 0.0)))
        a, b = v[tape.a], v[tape.b]
        np.testing.assert_allclose(a + tape.t[:, None] * (b - a), np.column_stack(
            [tape.points, np.full(len(tape.points), z)]), atol=1e-12)
        assert tape.girth == pytest.approx(tape_girth(v, f, z, (0.0, 0.0)), rel=1e-12)
    with pytest.raises(ValueError, match="goes around"):
        tape_edges(v, f, np.array([0.1]), (0.2, 0.0))


def _wavy_torso_and_arms():
    """A wavy torso with two arms beside it and a tube, rings of 97 points (odd, and ties in x where
    the rings repeat): several loops at most heights."""
    rng = np.random.default_rng(5)
    zs = np.linspace(0.0, 1.0, 21)
    t = 2 * np.pi * np.arange(97) / 97
    radius = 0.15 + 0.02 * np.sin(5 * t)[None] + 0.01 * rng.random((21, 1))
    rings = np.stack([np.stack([r * np.cos(t), 0.7 * r * np.sin(t)], 1) for r in radius])
    torso = stack(rings, zs)
    parts = [torso, elliptic_cylinder(0.04, 0.03, 97, centre=(0.3, 0.0)),
             elliptic_cylinder(0.04, 0.03, 97, centre=(-0.3, 0.01))]  # fmt: skip
    tube = trimesh.creation.annulus(r_min=0.05, r_max=0.08, height=0.4, sections=64)
    parts.append((np.asarray(tube.vertices) + [0.0, 0.5, 0.3], np.asarray(tube.faces)))
    offsets = np.cumsum([0] + [len(v) for v, _ in parts])
    return (np.concatenate([v for v, _ in parts]),
            np.concatenate([f + o for (_, f), o in zip(parts, offsets, strict=False)]))  # fmt: skip


def test_the_compiled_sections_are_the_numpy_path_bit_for_bit():
    """Many heights (compiled past FEW_LEVELS) through loops of several parts, one point for all and
    one per height (some in a tube's bore, some around nothing, some above the mesh): the same hulls
    and girths as height by height in numpy."""
    v, f = _wavy_torso_and_arms()
    zs = np.concatenate([np.linspace(-0.1, 1.1, 97), [0.5, 0.35]])  # 0.5 and 0.35: through ring vertices
    rng = np.random.default_rng(6)
    points = rng.choice([0.0, 0.3, -0.3, 0.5, 0.2], size=len(zs))[:, None] * [1.0, 0.0] + [0.0, 0.0]
    points[::7] = [0.0, 0.5]  # in the tube's bore
    for select in ((0.0, 0.0), points):
        girths, hulls = tape_girths(v, f, zs, select)
        ref_girths, ref_hulls = tape_girths_reference(v, f, zs, select)
        np.testing.assert_array_equal(girths, ref_girths)
        assert all(np.array_equal(a, b) for a, b in zip(hulls, ref_hulls, strict=True))
        assert np.isfinite(girths).sum() > 20 and np.isnan(girths).sum() > 5


def test_the_compiled_sections_raise_as_the_numpy_path():
    v, f = elliptic_cylinder(0.2, 0.1, 32)
    zs = np.linspace(-0.4, 0.4, 40)
    kept = np.ones(len(f), bool)
    kept[5] = False
    flipped = np.concatenate([f[:5], f[5:6, ::-1], f[6:]])
    for faces, match in ((f[kept], "open"), (flipped, "not a set of loops")):
        for path in (tape_girths, tape_girths_reference):
            with pytest.raises(ValueError, match=match):
                path(v, faces, zs, (0.0, 0.0))
