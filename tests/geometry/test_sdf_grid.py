"""service.geometry.sdf_grid: the body's grid distance against the exact one it replaces."""

from __future__ import annotations

import numpy as np
import pytest

from service.geometry.sdf_grid import SdfGrid

R = 0.1


def sphere(x):
    n = np.linalg.norm(x, axis=1)
    return n - R, x / n[:, None]


@pytest.fixture(scope="module")
def grid():
    return SdfGrid.sample(sphere, np.full(3, -0.2), np.full(3, 0.2), 0.006, clip=0.05)


def test_interpolates_a_sphere_within_the_curvature_bound(grid):
    rng = np.random.default_rng(0)
    d = rng.normal(size=(5000, 3))
    x = d / np.linalg.norm(d, axis=1, keepdims=True) * rng.uniform(R - 0.02, R + 0.02, (5000, 1))
    value, gradient = grid(x, sphere)
    exact, normal = sphere(x)
    # Trilinear error ~ h^2 / (8 R) per axis: 0.045 mm here; allow the three axes.
    assert np.abs(value - exact).max() < 3 * 0.006**2 / (8 * (R - 0.02))
    assert np.einsum("pd,pd->p", gradient, normal).min() > 0.95


def test_gradient_is_the_interpolants_own(grid):
    rng = np.random.default_rng(1)
    x = rng.uniform(-0.15, 0.15, (200, 3))
    _, g = grid(x, sphere)
    eps = 1e-6
    for axis in range(3):
        step = np.zeros(3)
        step[axis] = eps
        fd = (grid(x + step, sphere)[0] - grid(x - step, sphere)[0]) / (2 * eps)
        np.testing.assert_allclose(g[:, axis], fd, atol=1e-6)


def test_outside_the_grid_and_deep_inside_ask_the_exact_query(grid):
    x = np.array([[0.5, 0.0, 0.0], [0.0, 0.0, 0.01]])  # beyond the box; 9 cm deep (clip is 5 cm)
    value, gradient = grid(x, sphere)
    np.testing.assert_allclose(value, sphere(x)[0])
    np.testing.assert_allclose(gradient, sphere(x)[1])


def test_round_trips_through_its_file(grid, tmp_path):
    grid.save(tmp_path / "g.npz")
    back = SdfGrid.load(tmp_path / "g.npz")
    assert back.spacing == grid.spacing and back.clip == grid.clip
    np.testing.assert_allclose(back.values, grid.values, atol=1e-4)  # float16 on disk


def test_committed_body_grid_matches_the_exact_distance_where_garments_are():
    from export.body_sdf import FILE, TOLERANCE_MM, check
    from service.pipeline.body import DEFAULT_BETA, BodyModel
    from service.pipeline.canonical import CanonicalSpace
    from service.process.paths import models_dir

    body = BodyModel.load(models_dir() / "body" / "anny_shape.npz")
    space = CanonicalSpace.build(body.vertices(np.asarray(DEFAULT_BETA)), body.faces)
    err = check(SdfGrid.load(models_dir() / FILE), space)
    assert err["points"] > 10_000
    assert err["p99"] <= TOLERANCE_MM and err["mean"] < 0.1


def test_compiled_lookup_equals_the_numpy_reference_bit_for_bit(grid):
    # Inside, on cell faces and corners, outside the box, deep inside (clipped), and NaN: all through
    # both, the same arrays.
    rng = np.random.default_rng(2)
    x = np.concatenate([
        rng.uniform(-0.25, 0.25, (20_000, 3)),
        np.round(rng.uniform(-0.2, 0.2, (2000, 3)) / 0.006) * 0.006 - 0.2 % 0.006,  # on grid planes
        [[0.0, 0.0, 0.001], [0.2, 0.2, 0.2], [-0.2, -0.2, -0.2], [np.nan, 0.0, 0.0]],
    ])  # fmt: skip

    def fallback(p):
        return np.where(np.isnan(p[:, 0]), 7.0, sphere(np.nan_to_num(p, nan=0.1))[0]), sphere(
            np.nan_to_num(p, nan=0.1)
        )[1]

    value, gradient = grid(x, fallback)
    with np.errstate(invalid="ignore"):  # the NaN point's cell index
        ref_value, ref_gradient = grid.call_reference(x, fallback)
    np.testing.assert_array_equal(value, ref_value)
    np.testing.assert_array_equal(gradient, ref_gradient)
    assert value[-1] == 7.0
