"""Quality measures of an outfit (docs/design.md section 7), on world-space meshes, numpy only.

- penetration of garment j: the share of its vertices on the wrong side of an inner layer: inside the
  body (exact signed distance to the body mesh), or on an inner garment's body side, within
  ``PENETRATION_BAND`` of it, where that garment is active (its covariant field h < 0 at the vertex).
  A vertex whose closest point on the inner garment lies on its rim (a hem, an armhole) is past the
  garment's edge, on neither side: the sign there is only the rim face's orientation, and it had
  counted a T-shirt's sleeve leaving a tank top's armhole as inside the tank top. Where the closest
  face of the inner garment faces the body (``reversed_at``: a fold's middle sheet, whose normal says
  "inside" above it), the sign is not read from it: the vertex is inside when the segment from its
  closest body point to it crosses the inner garment an even number of times (every sheet of a fold
  it passed is one crossing). Over a jacket's fold under shorts all 38 vertices the plain sign put
  inside crossed 1 or 3 of its sheets;
- intersections: intersecting triangle pairs between every two layers (exact edge-triangle tests).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from service.geometry.closest import ClosestPoint
from service.geometry.fold_side import inside_by_parity
from service.geometry.intersections import TriangleGrid, intersecting_pairs

PENETRATION_BAND = 0.05  # m


@dataclass
class Layer:
    """One layer in world space: id, vertices (V, 3), faces (F, 3)."""

    id: str
    vertices: np.ndarray
    faces: np.ndarray


def penetration(layers: list[Layer], h_at: Callable[[int, int], np.ndarray],
                reversed_at: Callable[[int], np.ndarray] | None = None) -> dict[str, float]:  # fmt: skip
    """Share of each garment's vertices penetrating an inner layer; layers[0] is the body.

    ``h_at(inner, outer)`` gives the covariant field of layer ``inner`` at the vertices of layer
    ``outer`` ``(V_outer,)``; ``reversed_at(inner)`` the ``(F_inner,)`` bool faces of garment ``inner``
    that face the body (None: none do)."""
    closest = [ClosestPoint.build(layer.vertices, layer.faces) for layer in layers]
    out = {}
    for j in range(1, len(layers)):
        x = layers[j].vertices
        on_body = closest[0].query(x)
        wrong = on_body.signed < 0
        for i in range(1, j):
            q = closest[i].query(x)
            inside = q.signed < 0
            if reversed_at is not None:
                turned = np.flatnonzero(reversed_at(i)[q.face] & (q.distance < PENETRATION_BAND))
                if len(turned):
                    grid = TriangleGrid.build(layers[i].vertices, layers[i].faces)
                    inside[turned] = inside_by_parity(grid, on_body.point[turned], x[turned])
            wrong |= inside & (q.distance < PENETRATION_BAND) & (h_at(i, j) < 0) & ~closest[i].on_boundary(q)
        out[layers[j].id] = float(wrong.mean())
    return out


def intersections(layers: list[Layer]) -> dict[str, int]:
    """Intersecting triangle pairs per pair of layers, keyed ``"inner/outer"``."""
    out = {}
    for i in range(len(layers)):
        for j in range(i + 1, len(layers)):
            a, b = layers[i], layers[j]
            out[f"{a.id}/{b.id}"] = int(len(intersecting_pairs(a.vertices, a.faces, b.vertices, b.faces)))
    return out
