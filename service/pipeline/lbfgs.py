"""A small L-BFGS in numpy (Nocedal & Wright, algorithm 7.4 with an Armijo backtracking search).

Why not ``scipy.optimize.minimize(method="L-BFGS-B")``: on the fit's problems (10^3 - 10^4
variables, tens of iterations, no bounds) scipy spends ~6 ms per iteration in its driver on this
machine, more than the objective itself. This one spends microseconds. ``tests/pipeline/test_lbfgs.py``
compares it with scipy's on the same problems.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

Objective = Callable[[np.ndarray], tuple[float, np.ndarray]]


@dataclass
class LbfgsResult:
    x: np.ndarray
    fun: float
    nit: int
    converged: bool  # gradient below tolerance (False: iteration cap or a failed line search)


def minimize_lbfgs(
    fun: Objective,
    x0: np.ndarray,
    max_iterations: int = 100,
    memory: int = 8,
    gtol: float = 1e-8,
    first_step: float = 1e-3,
) -> LbfgsResult:
    """Minimise ``fun(x) -> (value, gradient)`` from ``x0 (n,)``.

    ``first_step`` bounds the largest coordinate change of the first (steepest-descent) step, in the
    units of x; later steps are scaled by the curvature pairs. Stops when max |gradient| <= ``gtol``.
    """
    x = np.asarray(x0, dtype=np.float64).copy()
    f, g = fun(x)
    pairs: list[tuple[np.ndarray, np.ndarray, float]] = []  # (s, y, 1 / y.s), oldest first
    for it in range(max_iterations):
        if np.abs(g).max() <= gtol:
            return LbfgsResult(x, f, it, True)
        p = -_two_loop(g, pairs, first_step)
        slope = float(g @ p)
        if slope >= 0:  # not a descent direction (round-off): restart from steepest descent
            pairs.clear()
            p = -_two_loop(g, pairs, first_step)
            slope = float(g @ p)
        t = 1.0
        while True:
            f_new, g_new = fun(x + t * p)
            if np.isfinite(f_new) and f_new <= f + 1e-4 * t * slope:
                break
            t *= 0.5
            if t < 1e-12:
                return LbfgsResult(x, f, it, False)
        s, y = t * p, g_new - g
        sy = float(s @ y)
        if sy > 1e-16 * float(y @ y):  # keep only pairs of positive curvature
            pairs.append((s, y, 1.0 / sy))
            if len(pairs) > memory:
                pairs.pop(0)
        x, f, g = x + s, f_new, g_new
    return LbfgsResult(x, f, max_iterations, bool(np.abs(g).max() <= gtol))


def _two_loop(g: np.ndarray, pairs, first_step: float) -> np.ndarray:
    """H g with H the L-BFGS inverse Hessian of ``pairs``."""
    q = g.copy()
    alphas = []
    for s, y, rho in reversed(pairs):
        a = rho * float(s @ q)
        q -= a * y
        alphas.append(a)
    if pairs:
        s, y, rho = pairs[-1]
        q *= 1.0 / (rho * float(y @ y))  # gamma = s.y / y.y
    else:
        q *= first_step / max(float(np.abs(g).max()), 1e-300)
    for (s, y, rho), a in zip(pairs, reversed(alphas), strict=True):
        b = rho * float(y @ q)
        q += (a - b) * s
    return q
