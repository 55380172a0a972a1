"""``service.geometry.rings``: the kept adjacency and ring dilation against their references."""

from __future__ import annotations

import numpy as np

from service.geometry.rings import dilate, dilate_reference, vertex_neighbours, vertex_neighbours_reference
from tests.meshes import grid_mesh


def test_kept_adjacency_equals_a_fresh_one():
    _, f = grid_mesh(6)
    n = int(f.max()) + 1
    first, again = vertex_neighbours(f, n), vertex_neighbours(f.copy(), n)
    assert again is first  # same faces by content: the kept matrix
    assert (first != vertex_neighbours_reference(f, n)).nnz == 0
    other = f[:, ::-1].copy()  # other faces (orientation flipped): its own entry, same edges
    assert vertex_neighbours(other, n) is not first
    assert vertex_neighbours(f, n + 1).shape == (n + 1, n + 1)


def test_dilation_by_sparse_products_is_the_breadth_first_walk():
    _, f = grid_mesh(9)
    n = int(f.max()) + 1
    rng = np.random.default_rng(2)
    mask = rng.random(n) < 0.03
    adjacency = vertex_neighbours(f, n)
    for rings in range(4):
        np.testing.assert_array_equal(dilate(mask, adjacency, rings), dilate_reference(mask, f, rings))
    assert dilate(mask, adjacency, 2).sum() > dilate(mask, adjacency, 1).sum() > mask.sum()
