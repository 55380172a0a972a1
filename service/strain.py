"""Green strain energy of a triangle mesh against a rest shape (paper eq. 12), numpy only.

E_strain(x) = sum_T || 1/2 (F_T^T F_T - I) ||_F^2 with F_T (3, 2) the deformation gradient of
triangle T from its rest shape, taken in an orthonormal 2-D frame of the rest triangle. The rest
shape is the explicit model's mesh, so the energy is 0 there and grows with any stretch or shear;
rigid motions cost nothing.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class RestShape:
    """Per-triangle inverse rest edge matrices ``dm_inv (F, 2, 2)`` of ``faces (F, 3)``."""

    faces: np.ndarray
    dm_inv: np.ndarray

    @classmethod
    def build(cls, vertices: np.ndarray, faces: np.ndarray) -> RestShape:
        v = np.asarray(vertices, dtype=np.float64)
        faces = np.asarray(faces, dtype=np.int64)
        e1 = v[faces[:, 1]] - v[faces[:, 0]]
        e2 = v[faces[:, 2]] - v[faces[:, 0]]
        n1 = np.linalg.norm(e1, axis=1)
        u = e1 / np.maximum(n1, 1e-300)[:, None]
        w = e2 - np.einsum("fd,fd->f", e2, u)[:, None] * u
        nw = np.linalg.norm(w, axis=1)
        dm = np.zeros((len(faces), 2, 2))
        dm[:, 0, 0] = n1
        dm[:, 0, 1] = np.einsum("fd,fd->f", e2, u)
        dm[:, 1, 1] = nw
        # A degenerate rest triangle gets no strain term rather than an infinite one.
        ok = (n1 > 1e-12) & (nw > 1e-12)
        dm_inv = np.zeros_like(dm)
        dm_inv[ok] = np.linalg.inv(dm[ok])
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
        used = np.union1d(self.faces.ravel(), keep)
        return used, RestShape(np.searchsorted(used, self.faces), self.dm_inv)


def strain_energy(x: np.ndarray, rest: RestShape) -> tuple[float, np.ndarray]:
    """(E_strain, gradient ``(V, 3)``) at vertices ``x (V, 3)``."""
    f = rest.faces
    ds = np.stack([x[f[:, 1]] - x[f[:, 0]], x[f[:, 2]] - x[f[:, 0]]], axis=2)  # (F, 3, 2)
    F = ds @ rest.dm_inv  # (F, 3, 2)
    E = 0.5 * (np.einsum("fdi,fdj->fij", F, F) - np.eye(2))  # (F, 2, 2)
    energy = float(np.einsum("fij,fij->", E, E))
    # d||E||^2 / dF = 2 F E; d / dDs = (2 F E) Dm^-T
    g = 2 * F @ E @ np.swapaxes(rest.dm_inv, 1, 2)  # (F, 3, 2)
    # Scatter the corner gradients with bincount (np.add.at is an order of magnitude slower).
    corners = np.concatenate([f[:, 1], f[:, 2], f[:, 0]])
    values = np.concatenate([g[:, :, 0], g[:, :, 1], -g[:, :, 0] - g[:, :, 1]])  # (3F, 3)
    grad = np.stack([np.bincount(corners, values[:, d], minlength=len(x)) for d in range(3)], 1)
    return energy, grad


def green_strain_norms(x: np.ndarray, rest: RestShape) -> np.ndarray:
    """|| E_T ||_F per triangle ``(F,)``: the deformation measure of the quality report."""
    f = rest.faces
    ds = np.stack([x[f[:, 1]] - x[f[:, 0]], x[f[:, 2]] - x[f[:, 0]]], axis=2)
    F = ds @ rest.dm_inv
    E = 0.5 * (np.einsum("fdi,fdj->fij", F, F) - np.eye(2))
    return np.sqrt(np.einsum("fij,fij->f", E, E))
