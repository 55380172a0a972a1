"""service.pipeline.lbfgs against scipy's L-BFGS-B (the reference) on problems with known minima, and
the fit's compiled L-BFGS (service.pipeline.lbfgs_kernel) against it."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import minimize, rosen, rosen_der

from service.pipeline.fit import FitSettings, _minimise
from service.pipeline.lbfgs import minimize_lbfgs
from service.pipeline.strain import RestShape


def test_quadratic_reaches_the_linear_solve():
    rng = np.random.default_rng(0)
    a = rng.normal(size=(40, 40))
    h = a @ a.T + 40 * np.eye(40)
    b = rng.normal(size=40)

    def fun(x):
        return 0.5 * x @ h @ x - b @ x, h @ x - b

    # |x - x*| <= |g| / lambda_min = 2.5e-10 at gtol 1e-8 (the gradient, ~6 in size, stalls near 1e-9)
    r = minimize_lbfgs(fun, np.zeros(40), max_iterations=200, gtol=1e-8, first_step=1.0)
    assert r.converged
    np.testing.assert_allclose(r.x, np.linalg.solve(h, b), atol=1e-9)


def test_rosenbrock_matches_scipy():
    x0 = np.full(10, -1.2)
    ours = minimize_lbfgs(
        lambda x: (rosen(x), rosen_der(x)), x0, max_iterations=2000, gtol=1e-8, first_step=0.1
    )
    ref = minimize(rosen, x0, jac=rosen_der, method="L-BFGS-B", options={"gtol": 1e-10, "maxiter": 2000})
    assert ours.converged
    np.testing.assert_allclose(ours.x, ref.x, atol=1e-5)
    np.testing.assert_allclose(ours.x, np.ones(10), atol=1e-5)
    assert ours.fun == pytest.approx(0.0, abs=1e-10)


def test_an_objective_that_only_gives_nan_stops_at_the_start():
    def fun(x):
        if np.any(x != 0):
            return np.nan, np.full_like(x, np.nan)
        return 1.0, np.ones_like(x)

    r = minimize_lbfgs(fun, np.zeros(3))
    assert not r.converged
    np.testing.assert_array_equal(r.x, np.zeros(3))


def _fit_problem(seed: int, n: int = 12):
    """A fit's L-BFGS problem (``fit._minimise``): a crumpled sheet's vertices off their targets, the
    misfit linearised with gradients of all directions, the strain against irregular rest triangles."""
    from tests.meshes import grid_mesh

    rng = np.random.default_rng(seed)
    v, f = grid_mesh(n)
    rest_v = v * [0.2, 0.2, 0] + rng.normal(scale=0.002, size=v.shape)
    x = rest_v + rng.normal(scale=0.003, size=v.shape)
    idx = np.flatnonzero(rng.random(len(v)) < 0.6)  # the optimised vertices
    g = rng.normal(size=(len(idx), 3))
    r0 = rng.normal(scale=0.004, size=len(idx))
    return x, idx, r0, g, RestShape.build(rest_v, f)


@pytest.mark.parametrize("inner", [3, 10, 40])  # 40: past the 8 pairs kept, the oldest dropped
def test_the_compiled_fit_lbfgs_gives_the_numpy_iterates(inner):
    for seed in range(4):
        x, idx, r0, g, rest = _fit_problem(seed)
        runs = {}
        for optimiser in ("numpy", "compiled"):
            settings = FitSettings(optimiser=optimiser, inner=inner)
            runs[optimiser] = _minimise(x, idx, r0, g, rest, settings)
        (y_ref, nit_ref, ok_ref), (y, nit, ok) = runs["numpy"], runs["compiled"]
        assert ok and ok_ref and nit == nit_ref
        assert np.abs(y - x[idx]).max() > 1e-4  # the run moved the vertices
        # the same iterates but for the order of the dot products' sums (BLAS's against a loop)
        np.testing.assert_allclose(y, y_ref, rtol=0, atol=1e-12)


def test_the_compiled_fit_lbfgs_stops_where_the_numpy_one_does_on_a_nan():
    x, idx, r0, g, rest = _fit_problem(0)
    r0[3] = np.nan
    for optimiser in ("numpy", "compiled"):
        y, nit, ok = _minimise(x, idx, r0, g, rest, FitSettings(optimiser=optimiser))
        assert nit == 0
        np.testing.assert_array_equal(np.isfinite(y), True)
