"""Point-triangle closest points from precomputed per-triangle scalars (numpy only).

The transfer of ``service.canonical`` tests every garment vertex against ~24 triangles per request.
``service.closest.closest_on_triangles`` (the reference, Ericson's Voronoi regions) works on
``(M, 3)`` arrays throughout; here each triangle's corner, edge vectors and Gram matrix are stored
once, so a pair costs three dot products and then scalar work on ``(M,)`` arrays: the closest point
is the plane projection when it falls inside the triangle, otherwise the closest of the three edge
points (a projection outside the triangle has its closest point on the boundary).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


def _segment(q: np.ndarray, b: np.ndarray, length2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(t in [0, 1], squared distance) of the closest point u + t e of a segment to p, from
    q = |p - u|^2, b = (p - u) . e and length2 = |e|^2, all ``(M,)``."""
    t = np.clip(b / np.maximum(length2, 1e-300), 0.0, 1.0)
    return t, q - t * (2 * b - t * length2)


@dataclass
class TriangleTable:
    data: np.ndarray  # (F, 12) float64 per triangle abc: a, b - a, c - a, |e0|^2, e0 . e1, |e1|^2

    @classmethod
    def build(cls, vertices: np.ndarray, faces: np.ndarray) -> TriangleTable:
        """From a mesh ``vertices (V, 3)``, ``faces (F, 3)``."""
        a, b, c = (np.asarray(vertices, dtype=np.float64)[np.asarray(faces)[:, k]] for k in range(3))
        e0, e1 = b - a, c - a
        gram = [np.einsum("fd,fd->f", u, w)[:, None] for u, w in ((e0, e0), (e0, e1), (e1, e1))]
        return cls(np.concatenate([a, e0, e1, *gram], axis=1))

    def closest(self, points: np.ndarray, face: np.ndarray, bary: bool = True):
        """Closest point of triangle ``face (M,)`` to ``points (M, 3)``: (barycentric coordinates
        (M, 3), squared distance (M,)), or only the squared distance without ``bary``. Degenerate
        triangles fall back to their edges."""
        t = self.data[face]  # (M, 12)
        ap = points - t[:, 0:3]
        g00, g01, g11 = t[:, 9], t[:, 10], t[:, 11]
        q = np.einsum("md,md->m", ap, ap)
        b0, b1 = np.einsum("md,md->m", ap, t[:, 3:6]), np.einsum("md,md->m", ap, t[:, 6:9])
        # Plane projection a + s e0 + u e1 by the normal equations; its squared distance q - s b0 - u b1.
        det = g00 * g11 - g01 * g01
        ok = det > 1e-12 * g00 * g11
        det = np.where(ok, det, 1.0)
        s, u = (g11 * b0 - g01 * b1) / det, (g00 * b1 - g01 * b0) / det
        inside = ok & (s >= 0) & (u >= 0) & (s + u <= 1)
        t_ab, d_ab = _segment(q, b0, g00)
        t_ac, d_ac = _segment(q, b1, g11)
        # Edge bc from b: p - b = ap - e0 along e1 - e0.
        t_bc, d_bc = _segment(q - 2 * b0 + g00, b1 - b0 - g01 + g00, g00 - 2 * g01 + g11)
        d_edge = np.minimum(np.minimum(d_ab, d_ac), d_bc)
        d2 = np.maximum(np.where(inside, q - s * b0 - u * b1, d_edge), 0.0)
        if not bary:
            return d2
        zero = np.zeros_like(q)
        w = np.where((d_bc == d_edge)[:, None], np.stack([zero, 1 - t_bc, t_bc], 1), 0.0)
        w = np.where((d_ac == d_edge)[:, None], np.stack([1 - t_ac, zero, t_ac], 1), w)
        w = np.where((d_ab == d_edge)[:, None], np.stack([1 - t_ab, t_ab, zero], 1), w)
        w = np.where(inside[:, None], np.stack([1 - s - u, s, u], 1), w)
        return w, d2
