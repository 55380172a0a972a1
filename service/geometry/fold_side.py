"""Which side of an open sheet (a garment) a point is on, where the sheet's closest face faces the body.

A garment is open: its faces' winding says "outside" only where the cloth lies the usual way. Over a
fold's middle sheet the winding points at the body, and where the cloth bends hard (the underside of a
sleeve at the armpit) the body-normal test that finds such faces (``BodyAnchors.reversed_faces``) flags
faces that lie the usual way. There the side is read from the sheets between the point and the body:
the point is inside (on the body's side) when the segment from its closest body point to it crosses the
garment an even number of times, every sheet of a fold it passes being one crossing.

One notion for both the measure (``service.pipeline.quality.penetration``) and the repair's closest-point
queries (``KeptQueries``' ``sides``): with the repair turning every flagged face over instead, 47
long-sleeve vertices under a let-down T-shirt's armpit (``benchmarks.orders --stacks 100 --seed 7``,
skirt < jacket < T-shirt < long sleeve) had no T-shirt between them and the body, the measure counted
them inside (0.52 % with the others), and the repair, reading "outside", never moved them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from service.geometry.closest import ClosestPoint
from service.geometry.intersections import TriangleGrid, segment_crossings


def inside_by_parity(grid: TriangleGrid, body_points: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``(K,)`` bool: points ``x (K, 3)`` on the body's side of the sheet in ``grid``: the segments from
    their closest body points ``body_points (K, 3)`` cross it an even number of times."""
    return segment_crossings(grid, body_points, x) % 2 == 0


@dataclass(frozen=True)
class FoldSides:
    """A garment's side test for the points whose closest face on it faces the body."""

    grid: TriangleGrid  # the garment's triangles
    body: ClosestPoint  # the body under it
    band: float
    """m: points farther than this from the garment are not asked (no measure or push reads their side)."""

    @classmethod
    def build(cls, vertices: np.ndarray, faces: np.ndarray, body: ClosestPoint, band: float) -> FoldSides:
        """The garment ``vertices (V, 3)``, ``faces (F, 3)`` over ``body``."""
        return cls(TriangleGrid.build(vertices, faces), body, band)

    def inside(self, x: np.ndarray) -> np.ndarray:
        """``(K,)`` bool: points ``x (K, 3)`` on the body's side (``inside_by_parity``)."""
        if not len(x):
            return np.zeros(0, dtype=bool)
        return inside_by_parity(self.grid, self.body.query(x).point, x)
