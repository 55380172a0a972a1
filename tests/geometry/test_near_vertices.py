"""``NeighbourCells`` against scipy's KD-tree: the same k nearest, bit for bit, near the points,
far from them (the tree's fallback) and outside the grid; ties in distance ordered by index."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from service.geometry.near_vertices import NeighbourCells


def _surface(n: int = 60, seed: int = 0) -> np.ndarray:
    """A bumpy closed-ish sheet of points (a cylinder 0.5 m tall, radius 0.15 m), a body's scale."""
    rng = np.random.default_rng(seed)
    theta, z = rng.uniform(0, 2 * np.pi, n * n), rng.uniform(0, 0.5, n * n)
    r = 0.15 + 0.01 * np.sin(5 * theta) * np.cos(9 * z)
    return np.stack([r * np.cos(theta), r * np.sin(theta), z], axis=1)


@pytest.mark.parametrize("k", [1, 6, 32])
def test_the_k_nearest_are_the_trees(k):
    points = _surface()
    tree = cKDTree(points)
    cells = NeighbourCells.build(points, k, tree)
    rng = np.random.default_rng(1)
    near = points[rng.integers(0, len(points), 3000)] + rng.normal(0, 0.02, (3000, 3))
    far = rng.normal(0, 0.5, (300, 3))  # most beyond REACH (no list: the tree answers), some outside the grid
    queries = np.concatenate([near, far, points[:50]])
    d, j = cells.query(queries)
    d_ref, j_ref = tree.query(queries, k=k)
    d_ref, j_ref = d_ref.reshape(len(queries), k), j_ref.reshape(len(queries), k)
    np.testing.assert_array_equal(d, d_ref)
    np.testing.assert_array_equal(j, j_ref)
    assert np.diff(cells.start).max() >= k  # lists were used, not only the fallback


def test_ties_are_ordered_by_index():
    """A regular grid of points (1/64 m apart: exact in binary) and queries at its squares' centres:
    four neighbours at exactly the same distance each."""
    i, j = np.meshgrid(np.arange(11), np.arange(11), indexing="ij")
    v = np.stack([i.ravel(), j.ravel(), np.zeros(i.size)], axis=1) / 64
    cells = NeighbourCells.build(v, 4)
    inner = (i.ravel() < 10) & (j.ravel() < 10)
    queries = v[inner] + [1 / 128, 1 / 128, 0.0]
    d, j = cells.query(queries)
    assert np.all(d == d[:, :1])  # four at the same distance
    assert np.all(np.diff(j, axis=1) > 0)
