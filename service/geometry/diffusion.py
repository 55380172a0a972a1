"""Displacement diffusion over a mesh's vertex rings: a push or a pull spreads over a patch.

The squeeze and the repair move a few vertices exactly and let their neighbours follow: Jacobi
iterations of the neighbour mean over a region (``service.geometry.rings.dilate``), the moved ones held.
"""

from __future__ import annotations

import numpy as np
from numba import njit


def diffuse(u: np.ndarray, held: np.ndarray, region: np.ndarray, adjacency, iterations: int) -> np.ndarray:
    """Spread displacements ``u (V, 3)`` from ``held`` into ``region`` (both (V,) bool): Jacobi iterations
    of the weighted neighbour mean on the free rows. ``diffuse_reference`` bit for bit (each row's sum in
    the CSR order, as scipy's product adds it), one compiled loop (``_diffuse_kernel``): the squeeze and the
    repair call it every round, and scipy's row slicing was most of it."""
    free = np.flatnonzero(region & ~held)
    if not len(free):
        return u
    out = np.array(u, dtype=np.float64, order="C")
    _diffuse_kernel(adjacency.indptr, adjacency.indices, adjacency.data, free, iterations, out)
    return out


@njit(cache=True, nogil=True)
def _diffuse_kernel(indptr, indices, data, free, iterations, u):
    degree = np.empty(len(free))
    for k in range(len(free)):
        total = 0.0
        for j in range(indptr[free[k]], indptr[free[k] + 1]):
            total += data[j]
        degree[k] = max(total, 1.0)
    new = np.empty((len(free), 3))
    for _ in range(iterations):
        for k in range(len(free)):
            s0, s1, s2 = 0.0, 0.0, 0.0
            for j in range(indptr[free[k]], indptr[free[k] + 1]):
                c, w = indices[j], data[j]
                s0 += w * u[c, 0]
                s1 += w * u[c, 1]
                s2 += w * u[c, 2]
            new[k, 0], new[k, 1], new[k, 2] = s0 / degree[k], s1 / degree[k], s2 / degree[k]
        for k in range(len(free)):
            u[free[k], 0], u[free[k], 1], u[free[k], 2] = new[k, 0], new[k, 1], new[k, 2]


def diffuse_reference(u: np.ndarray, held: np.ndarray, region: np.ndarray, adjacency, iterations: int):
    """``diffuse`` with scipy: only the free rows change, and their rows of the adjacency give the same sums
    as the whole product."""
    free = np.flatnonzero(region & ~held)
    if not len(free):
        return u
    rows = adjacency[free]
    degree = np.maximum(np.asarray(rows.sum(axis=1)).ravel(), 1)[:, None]
    u = u.copy()
    for _ in range(iterations):
        u[free] = (rows @ u) / degree
    return u
