"""Green strain energy of a triangle mesh against a rest shape (paper eq. 12), numpy and a compiled loop.

E_strain(x) = sum_T || 1/2 (F_T^T F_T - I) ||_F^2 with F_T (3, 2) the deformation gradient of
triangle T from its rest shape, taken in an orthonormal 2-D frame of the rest triangle. The rest
shape is the explicit model's mesh, so the energy is 0 there and grows with any stretch or shear;
rigid motions cost nothing.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit


@dataclass(frozen=True)
class RestShape:
    """Per-triangle inverse rest edge matrices ``dm_inv (F, 2, 2)`` of ``faces (F, 3)``."""

    faces: np.ndarray
    dm_inv: np.ndarray

    @classmethod
    def build(cls, vertices: np.ndarray, faces: np.ndarray) -> RestShape:
        """From the rest mesh ``vertices (V, 3)``, ``faces (F, 3)``: ``build_reference`` bit for bit, in
        one compiled pass (``_rest_kernel``; every fit builds it for its garment's explicit mesh)."""
        v = np.ascontiguousarray(vertices, dtype=np.float64)
        faces = np.ascontiguousarray(faces, dtype=np.int64)
        dm_inv = np.zeros((len(faces), 2, 2))
        _rest_kernel(v, faces, dm_inv)
        return cls(faces, dm_inv)

    @classmethod
    def build_reference(cls, vertices: np.ndarray, faces: np.ndarray) -> RestShape:
        """``build`` with numpy arrays: the rest triangle in an orthonormal frame of its plane (e1 along its
        first edge), Dm = [[|e1|, e2 . u], [0, |w|]] with w the part of e2 across u, inverted."""
        v = np.asarray(vertices, dtype=np.float64)
        faces = np.asarray(faces, dtype=np.int64)
        e1 = v[faces[:, 1]] - v[faces[:, 0]]
        e2 = v[faces[:, 2]] - v[faces[:, 0]]
        n1 = np.linalg.norm(e1, axis=1)
        u = e1 / np.maximum(n1, 1e-300)[:, None]
        w = e2 - np.einsum("fd,fd->f", e2, u)[:, None] * u
        nw = np.linalg.norm(w, axis=1)
        # Dm = [[n1, p], [0, nw]] is upper triangular: its inverse written out (LAPACK's batched inverse
        # took 5 ms per garment).
        p = np.einsum("fd,fd->f", e2, u)
        # A degenerate rest triangle gets no strain term rather than an infinite one.
        ok = (n1 > 1e-12) & (nw > 1e-12)
        a, d = 1.0 / np.where(ok, n1, 1.0), 1.0 / np.where(ok, nw, 1.0)
        dm_inv = np.zeros((len(faces), 2, 2))
        dm_inv[:, 0, 0] = np.where(ok, a, 0.0)
        dm_inv[:, 0, 1] = np.where(ok, -p * a * d, 0.0)
        dm_inv[:, 1, 1] = np.where(ok, d, 0.0)
        return cls(faces, dm_inv)

    def subset(self, mask: np.ndarray) -> RestShape:
        """The triangles selected by ``mask (F,) bool`` (their energy, on the same vertices)."""
        return RestShape(self.faces[mask], self.dm_inv[mask])

    def compact(self, keep: np.ndarray) -> tuple[np.ndarray, RestShape]:
        """(sorted vertex ids ``(n,)``: those the triangles use and ``keep``, the same triangles
        numbered on those ``n`` vertices).

        The fit's strain term touches a few thousand of a garment's vertices: on the compact numbering
        every gradient is ``(n, 3)`` instead of ``(V, 3)`` (the same numbers, a third of the time).
        """
        keep = np.asarray(keep, dtype=np.int64)
        top = max(int(self.faces.max(initial=-1)), int(keep.max(initial=-1))) + 1
        mark = np.zeros(top, dtype=bool)
        mark[self.faces.ravel()] = True
        mark[keep] = True
        used = np.flatnonzero(mark)  # np.union1d's sorted ids, without its sort
        number = np.empty(top, dtype=np.int64)
        number[used] = np.arange(len(used))
        return used, RestShape(number[self.faces], self.dm_inv)

    def compact_reference(self, keep: np.ndarray) -> tuple[np.ndarray, RestShape]:
        """``compact`` by sorting (``np.union1d``, ``np.searchsorted``)."""
        used = np.union1d(self.faces.ravel(), keep)
        return used, RestShape(np.searchsorted(used, self.faces), self.dm_inv)


def strain_energy(x: np.ndarray, rest: RestShape) -> tuple[float, np.ndarray]:
    """(E_strain, gradient ``(V, 3)``) at vertices ``x (V, 3)``: ``strain_energy_reference`` in one
    compiled loop over the triangles (``_strain_kernel``), the 2 x 2 products written out and the
    gradient added straight into its vertices (numpy's batched matmul costs ~1 us per triangle and
    the scatter a pass of its own; the L-BFGS calls this ~12 times per garment). Same numbers to
    rounding (tests/pipeline/test_fit.py)."""
    x = np.ascontiguousarray(x, dtype=np.float64)
    grad = np.zeros_like(x)
    energy = _strain_kernel(x, rest.faces, rest.dm_inv, grad)
    return float(energy), grad


@njit(cache=True, nogil=True)
def _rest_kernel(v, faces, dm_inv):
    """``RestShape.build_reference``'s operations per triangle, in its order: np.linalg.norm sums the
    squares x, y, z; einsum's three-term dot product adds x and z first, then y."""
    for t in range(len(faces)):
        i, j, k = faces[t, 0], faces[t, 1], faces[t, 2]
        e1x, e1y, e1z = v[j, 0] - v[i, 0], v[j, 1] - v[i, 1], v[j, 2] - v[i, 2]
        e2x, e2y, e2z = v[k, 0] - v[i, 0], v[k, 1] - v[i, 1], v[k, 2] - v[i, 2]
        n1 = np.sqrt(e1x * e1x + e1y * e1y + e1z * e1z)
        scale = max(n1, 1e-300)
        ux, uy, uz = e1x / scale, e1y / scale, e1z / scale
        p = (e2x * ux + e2z * uz) + e2y * uy
        wx, wy, wz = e2x - p * ux, e2y - p * uy, e2z - p * uz
        nw = np.sqrt(wx * wx + wy * wy + wz * wz)
        if n1 > 1e-12 and nw > 1e-12:  # a degenerate rest triangle gets no strain term
            a, d = 1.0 / n1, 1.0 / nw
            dm_inv[t, 0, 0] = a
            dm_inv[t, 0, 1] = -p * a * d
            dm_inv[t, 1, 1] = d


@njit(cache=True, nogil=True, inline="always")
def _green_strain(x, faces, dm_inv, t):
    """Triangle t's deformation gradient F = Ds Dm^-1 by columns (p, q: 3 components each) and its
    Green strain E = (F^T F - I) / 2 (e00, e01, e11), as a flat tuple of 9."""
    i, j, k = faces[t, 0], faces[t, 1], faces[t, 2]
    m00, m01, m10, m11 = dm_inv[t, 0, 0], dm_inv[t, 0, 1], dm_inv[t, 1, 0], dm_inv[t, 1, 1]
    ax, ay, az = x[j, 0] - x[i, 0], x[j, 1] - x[i, 1], x[j, 2] - x[i, 2]  # the columns of Ds
    bx, by, bz = x[k, 0] - x[i, 0], x[k, 1] - x[i, 1], x[k, 2] - x[i, 2]
    p0, p1, p2 = ax * m00 + bx * m10, ay * m00 + by * m10, az * m00 + bz * m10
    q0, q1, q2 = ax * m01 + bx * m11, ay * m01 + by * m11, az * m01 + bz * m11
    e00 = 0.5 * (p0 * p0 + p1 * p1 + p2 * p2 - 1.0)
    e01 = 0.5 * (p0 * q0 + p1 * q1 + p2 * q2)
    e11 = 0.5 * (q0 * q0 + q1 * q1 + q2 * q2 - 1.0)
    return p0, p1, p2, q0, q1, q2, e00, e01, e11


@njit(cache=True, nogil=True)
def _strain_kernel(x, faces, dm_inv, grad):
    energy = 0.0
    for t in range(len(faces)):
        i, j, k = faces[t, 0], faces[t, 1], faces[t, 2]
        m00, m01, m10, m11 = dm_inv[t, 0, 0], dm_inv[t, 0, 1], dm_inv[t, 1, 0], dm_inv[t, 1, 1]
        p0, p1, p2, q0, q1, q2, e00, e01, e11 = _green_strain(x, faces, dm_inv, t)
        energy += e00 * e00 + 2.0 * e01 * e01 + e11 * e11
        # d||E||^2 / dDs = 2 F E Dm^-T: columns g0, g1 (E symmetric), per coordinate
        for d, fp, fq in ((0, p0, q0), (1, p1, q1), (2, p2, q2)):
            fe0 = 2.0 * (fp * e00 + fq * e01)
            fe1 = 2.0 * (fp * e01 + fq * e11)
            g0 = fe0 * m00 + fe1 * m01
            g1 = fe0 * m10 + fe1 * m11
            grad[j, d] += g0
            grad[k, d] += g1
            grad[i, d] -= g0 + g1
    return energy


def strain_energy_reference(x: np.ndarray, rest: RestShape) -> tuple[float, np.ndarray]:
    """``strain_energy`` with matrix products, as eq. 12 reads."""
    f = rest.faces
    ds = np.stack([x[f[:, 1]] - x[f[:, 0]], x[f[:, 2]] - x[f[:, 0]]], axis=2)  # (F, 3, 2)
    F = ds @ rest.dm_inv  # (F, 3, 2)
    E = 0.5 * (np.einsum("fdi,fdj->fij", F, F) - np.eye(2))  # (F, 2, 2)
    energy = float(np.einsum("fij,fij->", E, E))
    # d||E||^2 / dF = 2 F E; d / dDs = (2 F E) Dm^-T
    g = 2 * F @ E @ np.swapaxes(rest.dm_inv, 1, 2)  # (F, 3, 2)
    return energy, _scatter(f, g[:, :, 0], g[:, :, 1], len(x))


def _scatter(faces: np.ndarray, g0: np.ndarray, g1: np.ndarray, n: int) -> np.ndarray:
    """Vertex gradient ``(n, 3)`` from the gradients ``(F, 3)`` w.r.t. the edges v1 - v0 and v2 - v0."""
    # bincount, not np.add.at: an order of magnitude faster.
    corners = np.concatenate([faces[:, 1], faces[:, 2], faces[:, 0]])
    values = np.concatenate([g0, g1, -g0 - g1])  # (3F, 3)
    return np.stack([np.bincount(corners, values[:, d], minlength=n) for d in range(3)], 1)


def green_strain_norms(x: np.ndarray, rest: RestShape) -> np.ndarray:
    """|| E_T ||_F per triangle ``(F,)``: the deformation measure of the quality report, in one compiled
    loop (``green_strain_norms_reference`` to rounding; every request reports it per garment)."""
    out = np.empty(len(rest.faces))
    _norms_kernel(np.ascontiguousarray(x, dtype=np.float64), rest.faces, rest.dm_inv, out)
    return out


@njit(cache=True, nogil=True)
def _norms_kernel(x, faces, dm_inv, out):
    for t in range(len(faces)):
        e00, e01, e11 = _green_strain(x, faces, dm_inv, t)[6:]
        out[t] = np.sqrt(e00 * e00 + 2.0 * e01 * e01 + e11 * e11)


def green_strain_norms_reference(x: np.ndarray, rest: RestShape) -> np.ndarray:
    """``green_strain_norms`` with matrix products, as eq. 12 reads."""
    f = rest.faces
    ds = np.stack([x[f[:, 1]] - x[f[:, 0]], x[f[:, 2]] - x[f[:, 0]]], axis=2)
    F = ds @ rest.dm_inv
    E = 0.5 * (np.einsum("fdi,fdj->fij", F, F) - np.eye(2))
    return np.sqrt(np.einsum("fij,fij->f", E, E))
