"""The fit's L-BFGS in one compiled loop (numba): ``service.pipeline.lbfgs.minimize_lbfgs`` on the fit's
objective (``service.pipeline.fit._minimise``), without the interpreter between its vector operations.

The objective is the linearised misfit plus the strain term (eq. 10):

    E(y) = sum_v (r0_v + g_v . (y_v - y0_v))^2 + omega * E_strain(x with y at the fitted vertices)

Per garment the numpy loop makes ~12 objective calls and ~10 two-loop recursions on vectors of
10^3 - 10^4 entries: each numpy call costs microseconds of dispatch, and every one of them holds the
GIL, so the four garments fitted side by side queue for it. Here the whole run releases the GIL.
The iterates are ``minimize_lbfgs``'s to rounding (its dot products are BLAS's, summed in another order;
``tests/pipeline/test_lbfgs.py`` compares both on the same fit problems).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from service.pipeline.strain import _strain_kernel


@njit(cache=True, nogil=True)
def _objective(flat, y0, r0, g, xl, slot, faces, dm_inv, omega, grad):
    """E at ``flat (3 n,)`` (the fitted vertices' positions, flattened); its gradient into ``grad (3 n,)``."""
    n = len(r0)
    misfit = 0.0
    for v in range(n):
        # g . (y - y0) summed x, y, z, then added to r0, as the numpy objective's einsum does
        r = r0[v] + (g[v, 0] * (flat[3 * v] - y0[v, 0]) + g[v, 1] * (flat[3 * v + 1] - y0[v, 1])
                     + g[v, 2] * (flat[3 * v + 2] - y0[v, 2]))  # fmt: skip
        for d in range(3):
            xl[slot[v], d] = flat[3 * v + d]
        misfit += r * r
        for d in range(3):
            grad[3 * v + d] = 2.0 * r * g[v, d]
    gs = np.zeros_like(xl)
    es = _strain_kernel(xl, faces, dm_inv, gs)
    for v in range(n):
        for d in range(3):
            grad[3 * v + d] += omega * gs[slot[v], d]
    return misfit + omega * es


@njit(cache=True, nogil=True, inline="always")
def _dot(a, b):
    s = 0.0
    for i in range(len(a)):
        s += a[i] * b[i]
    return s


@njit(cache=True, nogil=True)
def _max_abs(a):
    m = 0.0
    for i in range(len(a)):
        m = max(m, abs(a[i]))
    return m


@njit(cache=True, nogil=True)
def _two_loop(grad, S, Y, rho, order, count, first_step, out):
    """``lbfgs._two_loop``: H grad into ``out``, the pairs ``S, Y, rho`` in rows ``order[:count]``
    (oldest first). Loops, not array expressions: the same arithmetic, compiled in a fraction of the time."""
    size = len(grad)
    for i in range(size):
        out[i] = grad[i]
    alphas = np.empty(max(count, 1))
    for c in range(count - 1, -1, -1):
        k = order[c]
        a = rho[k] * _dot(S[k], out)
        for i in range(size):
            out[i] -= a * Y[k, i]
        alphas[c] = a
    if count:
        k = order[count - 1]
        scale = 1.0 / (rho[k] * _dot(Y[k], Y[k]))
    else:
        scale = first_step / max(_max_abs(grad), 1e-300)
    for i in range(size):
        out[i] *= scale
    for c in range(count):
        k = order[c]
        b = rho[k] * _dot(Y[k], out)
        for i in range(size):
            out[i] += (alphas[c] - b) * S[k, i]


@njit(cache=True, nogil=True)
def minimize_fit(x0, y0, r0, g, xl, slot, faces, dm_inv, omega, max_iterations, memory, gtol, first_step):
    """``minimize_lbfgs(objective, x0, max_iterations, memory, gtol, first_step)`` of the fit's objective
    (module docstring): ``x0 (3 n,)`` the start, ``y0 (n, 3)`` the linearisation points, ``r0 (n,)`` and
    ``g (n, 3)`` the misfit's values and gradients there, ``xl (m, 3)`` the strain term's vertices on
    the compact numbering (overwritten), ``slot (n,)`` the fitted vertices' rows in it, ``faces (T, 3)``
    and ``dm_inv (T, 2, 2)`` its triangles. Returns (x (3 n,), iterations, converged)."""
    size = len(x0)
    x = x0.copy()
    grad = np.empty(size)
    f = _objective(x, y0, r0, g, xl, slot, faces, dm_inv, omega, grad)
    S, Y = np.empty((memory, size)), np.empty((memory, size))
    rho = np.empty(memory)
    order = np.empty(memory, dtype=np.int64)  # rows of the kept pairs, oldest first
    count = 0
    p, trial, grad_new = np.empty(size), np.empty(size), np.empty(size)
    s, y = np.empty(size), np.empty(size)
    for it in range(max_iterations):
        if _max_abs(grad) <= gtol:
            return x, it, True
        _two_loop(grad, S, Y, rho, order, count, first_step, p)
        for i in range(size):
            p[i] = -p[i]
        slope = _dot(grad, p)
        if slope >= 0:  # not a descent direction (round-off): restart from steepest descent
            count = 0
            _two_loop(grad, S, Y, rho, order, count, first_step, p)
            for i in range(size):
                p[i] = -p[i]
            slope = _dot(grad, p)
        t = 1.0
        while True:
            for i in range(size):
                trial[i] = x[i] + t * p[i]
            f_new = _objective(trial, y0, r0, g, xl, slot, faces, dm_inv, omega, grad_new)
            if np.isfinite(f_new) and f_new <= f + 1e-4 * t * slope:
                break
            t *= 0.5
            if t < 1e-12:
                return x, it, False
        for i in range(size):
            s[i] = t * p[i]
            y[i] = grad_new[i] - grad[i]
        sy = _dot(s, y)
        if sy > 1e-16 * _dot(y, y):  # keep only pairs of positive curvature, in the oldest one's row
            row = count if count < memory else order[0]
            for i in range(size):
                S[row, i], Y[row, i] = s[i], y[i]
            rho[row] = 1.0 / sy
            if count < memory:
                order[count] = row
                count += 1
            else:
                for c in range(memory - 1):
                    order[c] = order[c + 1]
                order[memory - 1] = row
        for i in range(size):
            x[i] += s[i]
        f = f_new
        for i in range(size):
            grad[i] = grad_new[i]
    return x, max_iterations, _max_abs(grad) <= gtol
