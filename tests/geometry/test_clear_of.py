"""``service.geometry.clear_of``: the proof that a triangle is clear of a mesh, against the reference
and against exact distances and crossing tests."""

from __future__ import annotations

import numpy as np

from service.geometry.clear_of import clear_of, clear_of_reference
from service.geometry.closest import ClosestPoint, closest_point_reference
from service.geometry.intersections import intersecting_pairs
from service.geometry.kept_queries import KeptQueries
from tests.meshes import sheet


def test_clear_of_is_the_reference_bit_for_bit():
    inner_v, inner_f = sheet(12, 0.4, lambda v: 0.0 * v[:, 0])
    outer_v, outer_f = sheet(16, 0.36, lambda v: 0.004 + 0.3 * (v[:, 0] + 0.18))
    kept = KeptQueries(ClosestPoint.build(inner_v, inner_f), len(outer_v))
    rng = np.random.default_rng(6)
    kept.at(outer_v, np.flatnonzero(rng.random(len(outer_v)) < 0.6))  # some never asked
    x = outer_v + rng.normal(size=outer_v.shape) * 0.002
    some = outer_f[rng.random(len(outer_f)) < 0.5]
    got = clear_of(x, some, kept)
    np.testing.assert_array_equal(got, clear_of_reference(x, some, kept))
    assert got.any() and not got.all()


def test_no_triangle_proved_clear_touches_the_inner_layer():
    # Loose triangles 0.5-3 cm across, from 1 cm inside a wavy sheet to 2 cm over it, some thin and
    # obtuse: every one the proof calls clear is farther from the sheet than 0 at every sample point,
    # and the three-ball rule proves some that one corner's ball does not.
    inner_v, inner_f = sheet(30, 0.4, lambda v: 0.01 * np.sin(25 * v[:, 0]))
    rng = np.random.default_rng(11)
    n = 3000
    centre = np.column_stack([rng.uniform(-0.12, 0.12, (n, 2)), rng.uniform(-0.01, 0.02, n)])
    size = rng.uniform(0.005, 0.03, n)[:, None, None]
    corners = centre[:, None] + size * rng.normal(size=(n, 3, 3)) * [1, 1, 0.3]
    x, faces = corners.reshape(-1, 3), np.arange(3 * n).reshape(n, 3)
    kept = KeptQueries(ClosestPoint.build(inner_v, inner_f), len(x))
    kept.at(x, np.arange(len(x)))
    clear = clear_of(x, faces, kept)
    np.testing.assert_array_equal(clear, clear_of_reference(x, faces, kept))
    w = rng.dirichlet([1, 1, 1], 64)  # samples of each proved triangle, corners included
    w = np.concatenate([np.eye(3), [[0.5, 0.5, 0], [0, 0.5, 0.5], [0.5, 0, 0.5]], w])
    samples = np.einsum("sk,tkd->tsd", w, corners[clear]).reshape(-1, 3)
    assert closest_point_reference(samples, inner_v, inner_f).distance.min() > 0
    assert len(intersecting_pairs(x, faces[clear], inner_v, inner_f)) == 0
    crossing = np.unique(intersecting_pairs(x, faces, inner_v, inner_f)[:, 0])
    assert len(crossing) > 100 and not clear[crossing].any()
    farthest = np.linalg.norm(corners[:, :, None] - corners[:, None], axis=3).max(axis=2)  # (n, 3)
    one_corner = (np.abs(kept.signed[faces]) > farthest).any(axis=1)
    assert (clear & ~one_corner).sum() > 100
