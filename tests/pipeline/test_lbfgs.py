"""service.pipeline.lbfgs against scipy's L-BFGS-B (the reference) on problems with known minima."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import minimize, rosen, rosen_der

from service.pipeline.lbfgs import minimize_lbfgs


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
