"""Quality measures of an outfit (DESIGN.md section 7), on world-space meshes, numpy only.

- penetration of garment j: the share of its vertices on the wrong side of an inner layer: inside the
  body (exact signed distance to the body mesh), or on an inner garment's body side, within
  ``PENETRATION_BAND`` of it, where that garment is active (its covariant field h < 0 at the vertex).
  A vertex whose closest point on the inner garment lies on its rim (a hem, an armhole) is past the
  garment's edge, on neither side: the sign there is only the rim face's orientation, and it had
  counted a T-shirt's sleeve leaving a tank top's armhole as inside the tank top;
- intersections: intersecting triangle pairs between every two layers (exact edge-triangle tests).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from service.geometry.closest import ClosestPoint
from service.geometry.intersections import intersecting_pairs

PENETRATION_BAND = 0.05  # m


@dataclass
class Layer:
    """One layer in world space: id, vertices (V, 3), faces (F, 3)."""

    id: str
    vertices: np.ndarray
    faces: np.ndarray


def penetration(layers: list[Layer], h_at: Callable[[int, int], np.ndarray]) -> dict[str, float]:
    """Share of each garment's vertices penetrating an inner layer; layers[0] is the body.

    ``h_at(inner, outer)`` gives the covariant field of layer ``inner`` at the vertices of layer
    ``outer`` ``(V_outer,)``."""
    closest = [ClosestPoint.build(layer.vertices, layer.faces) for layer in layers]
    out = {}
    for j in range(1, len(layers)):
        x = layers[j].vertices
        wrong = closest[0].query(x).signed < 0
        for i in range(1, j):
            q = closest[i].query(x)
            d = q.signed
            wrong |= (d < 0) & (d > -PENETRATION_BAND) & (h_at(i, j) < 0) & ~closest[i].on_boundary(q)
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
