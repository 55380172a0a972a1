"""``service.geometry.diffusion``: the compiled diffusion against scipy's product, bit for bit."""

from __future__ import annotations

import numpy as np

from service.geometry.diffusion import diffuse, diffuse_reference
from service.geometry.rings import dilate, vertex_neighbours
from tests.meshes import sheet


def test_diffusion_on_the_free_rows_is_the_whole_product_bit_for_bit():
    v, f = sheet(15, 0.3, lambda v: 0.0 * v[:, 0])
    adjacency = vertex_neighbours(f, len(v))
    rng = np.random.default_rng(0)
    held = rng.random(len(v)) < 0.05
    u = np.where(held[:, None], rng.normal(size=v.shape), 0.0)
    region = dilate(held, adjacency, 2)
    # The whole-matrix diffusion the row-restricted one replaces.
    degree = np.asarray(adjacency.sum(axis=1)).ravel()
    expected = u
    for _ in range(8):
        mean = (adjacency @ expected) / np.maximum(degree, 1)[:, None]
        expected = np.where((region & ~held)[:, None], mean, expected)
    np.testing.assert_array_equal(diffuse(u, held, region, adjacency, 8), expected)
    np.testing.assert_array_equal(diffuse_reference(u, held, region, adjacency, 8), expected)
    assert np.abs(expected - u).max() > 0.01  # it spread
