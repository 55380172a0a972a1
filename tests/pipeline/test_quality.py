"""Quality measures (service.pipeline.quality) and rim detection (ClosestPoint.on_boundary) with known
answers."""

from __future__ import annotations

import numpy as np
import trimesh

from service.geometry.closest import ClosestPoint
from service.pipeline.quality import Layer, penetration
from tests.meshes import grid_mesh


def _patch(size: float = 0.2):
    v, f = grid_mesh(10)
    return (v - [0.5, 0.5, 0]) * [size, size, 0], f


def test_closest_points_past_a_sheets_edge_or_corner_are_on_its_boundary():
    v, f = _patch()
    mesh = ClosestPoint.build(v, f)
    points = np.array([
        [0.0, 0.0, -0.01],  # under the middle
        [0.05, -0.03, 0.02],  # over the middle
        [0.15, 0.0, -0.01],  # past the x = 0.1 edge
        [0.0, -0.14, 0.0],  # past the y = -0.1 edge, in the sheet's plane
        [0.13, 0.12, -0.02],  # past a corner
    ])  # fmt: skip
    np.testing.assert_array_equal(mesh.on_boundary(mesh.query(points)), [False, False, True, True, True])
    # A closed mesh has no boundary.
    sphere = trimesh.creation.icosphere(subdivisions=2, radius=0.1)
    closed = ClosestPoint.build(sphere.vertices, sphere.faces)
    assert not closed.on_boundary(closed.query(points)).any()


def test_penetration_counts_the_body_side_of_an_inner_garment_but_not_past_its_rim():
    sphere = trimesh.creation.icosphere(subdivisions=3, radius=0.05)
    body = Layer("body", sphere.vertices - [0, 0, 0.1], sphere.faces)  # well under the patch
    v, f = _patch()
    inner = Layer("inner", v, f)
    outer_points = np.array([
        [0.0, 0.0, -0.01],  # under the inner patch's middle: on its body side
        [0.05, 0.02, 0.01],  # above it
        [0.15, 0.0, -0.01],  # under the plane but past the rim: on neither side
        [0.0, 0.0, -0.1],  # inside the body
    ])  # fmt: skip
    # An outer "garment" of four tiny triangles, one at each point.
    tri = np.array([[0, 0, 0], [1e-4, 0, 0], [0, 1e-4, 0]])
    ov = (outer_points[:, None] + tri[None]).reshape(-1, 3)
    of = np.arange(len(ov)).reshape(-1, 3)
    outer = Layer("outer", ov, of)

    def h_at(i, j):
        return np.full(len(ov), -1.0)  # the inner garment covers everything

    wrong = penetration([body, inner, outer], h_at)["outer"]
    # Vertices of the first and the last triangle: 6 of 12.
    assert wrong == 0.5
