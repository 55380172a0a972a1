"""The fabric's stretch on the shopper, as a tension map (issue 56): how far a worn garment is stretched
beyond its rest shape, the cut it was sewn to.

The rest shape is the garment's cut: for a size, the style's pattern on that size's chart body
(``training.garments.grading``, ``models/garments/size_charts.json``); for the one-size garment, the
pattern graded ``ONE_SIZE_GRADING`` of the way to the wearer (``service.pipeline.size_model``).

The stretch of a triangle is the mean of its two principal stretches minus 1 (0.03: 3 % longer than
cut on average over directions; negative: slack). Per vertex, the mean over its triangles, then
smoothed over the mesh ((I + ``SMOOTHING`` L) s, L the graph Laplacian): a garment the models predict
is a few mm off its drape everywhere, which on 1 cm triangles reads as +-10 % of strain that the cloth
does not have; smoothed over a few centimetres, the served T-shirt in S, M, L and XL on a man of chest
102 cm reads 3.8, 0.7, -1.4 and -3.6 % at the median, in the order of its simulated drapes (1.3, 0.0,
-0.1 and -0.2 %; the largest principal stretch, unsmoothed, read 10.7, 3.8, 2.3 and 4.8 %: noise;
docs/fit.md). The map colours each vertex white at rest or slack, through yellow to red at
``MAP_STRETCH``, as design tools (CLO, Browzwear) show strain.
"""

from __future__ import annotations

import json
import threading
from pathlib import Path

import numpy as np

from service.geometry.mesh import graph_laplacian
from service.pipeline.ease import principal_strain
from service.pipeline.size_model import ONE_SIZE_GRADING
from service.pipeline.strain import RestShape

MAP_STRETCH = 0.05
"""The map's full red: 5 % stretched on average over directions, a size under the wearer's (the served
T-shirt a size under a man's chest reads 3.8 % at the median)."""
RAMP = ((0.0, (0.95, 0.95, 0.95)), (0.33, (0.98, 0.85, 0.2)), (1.0, (0.8, 0.05, 0.05)))  # white, yellow, red
STRETCHED = 0.02  # a vertex this much beyond its cut counts as stretched (the report's share)
SMOOTHING = 30.0  # lambda of the smoothing, vertex steps squared: a few cm on the garments' ~1 cm edges


def tension_colors(stretch: np.ndarray) -> np.ndarray:
    """``(N, 3)`` RGB in 0..1 of ``stretch (N,)``: white at 0 or less, yellow at a third of
    ``MAP_STRETCH``, red at it and more."""
    t = np.clip(np.asarray(stretch, dtype=np.float64) / MAP_STRETCH, 0.0, 1.0)
    stops = np.array([s for s, _ in RAMP])
    colors = np.array([c for _, c in RAMP])
    return np.stack([np.interp(t, stops, colors[:, k]) for k in range(3)], axis=1)


def mean_stretch(x: np.ndarray, rest: RestShape) -> np.ndarray:
    """Per triangle ``(F,)``: the mean of the two principal stretches of ``x (V, 3)`` against ``rest``,
    minus 1 (``service.pipeline.ease.principal_strain`` gives the largest alone)."""
    f = rest.faces
    ds = np.stack([x[f[:, 1]] - x[f[:, 0]], x[f[:, 2]] - x[f[:, 0]]], axis=2)  # (F, 3, 2)
    F = ds @ rest.dm_inv
    C = np.einsum("fki,fkj->fij", F, F)
    a, b, d = C[:, 0, 0], C[:, 0, 1], C[:, 1, 1]
    r = np.sqrt(0.25 * (a - d) ** 2 + b * b)
    return 0.5 * (np.sqrt(0.5 * (a + d) + r) + np.sqrt(np.maximum(0.5 * (a + d) - r, 0.0))) - 1.0


def vertex_strain(face_strain: np.ndarray, faces: np.ndarray, n_vertices: int) -> np.ndarray:
    """``(V,)`` mean of ``face_strain (F,)`` over each vertex's triangles ``faces (F, 3)`` (0 where none)."""
    total = np.zeros(n_vertices)
    count = np.zeros(n_vertices)
    for k in range(3):
        np.add.at(total, faces[:, k], face_strain)
        np.add.at(count, faces[:, k], 1.0)
    return total / np.maximum(count, 1.0)


def strain_summary(stretch: np.ndarray) -> dict:
    """What the report says of one garment's map ``stretch (V,)``: median, 95th percentile, largest, and
    the share of vertices stretched more than ``STRETCHED``."""
    return {
        "stretch_p50": round(float(np.median(stretch)), 4),
        "stretch_p95": round(float(np.percentile(stretch, 95)), 4),
        "stretch_max": round(float(np.max(stretch)), 4),
        "stretched_share": round(float(np.mean(stretch > STRETCHED)), 4),
    }


class CutShapes:
    """Each garment's rest shape on a wearer (module docstring), the chart bodies built once per process.

    ``models``: ``OutfitModels`` (its catalog, canonical space, body builder and size models)."""

    def __init__(self, models, charts_path: Path | None = None):
        from service.process.paths import models_dir

        self.models = models
        path = charts_path or models_dir() / "garments" / "size_charts.json"
        self.charts = json.loads(Path(path).read_text()) if Path(path).is_file() else {}
        self._chart_rests: dict[tuple[str, str], RestShape] = {}
        self._smoothers: dict[str, object] = {}
        self._lock = threading.Lock()

    def rest(self, garment_id: str, size: str | None, wearer: np.ndarray) -> RestShape:
        """The rest shape of ``garment_id`` cut in ``size`` (None: the one-size cut for ``wearer (B, 3)``)."""
        garment = self.models.catalog[garment_id]
        space = self.models.space
        if size is None:
            carried = space.to_body(garment.vertices, wearer)
            graded = garment.vertices + ONE_SIZE_GRADING * (carried - garment.vertices)
            return RestShape.build(graded, garment.faces)
        key = (garment_id, size)
        with self._lock:
            rest = self._chart_rests.get(key)
        if rest is None:
            from service.pipeline.body_build import BodyRequest

            request = BodyRequest(**self.charts[f"{self.models.sizes[garment_id].run}/{size}"]["request"])
            chart_body = self.models.bodies.build(request).vertices
            rest = RestShape.build(space.to_body(garment.vertices, chart_body), garment.faces)
            with self._lock:
                self._chart_rests[key] = rest
        return rest

    def strain(self, garment_id: str, size: str | None, wearer: np.ndarray, worn: np.ndarray) -> np.ndarray:
        """``(F,)`` largest principal strain of the worn garment ``worn (V, 3)`` against its cut."""
        return principal_strain(worn, self.rest(garment_id, size, wearer))

    def stretch(self, garment_id: str, size: str | None, wearer: np.ndarray, worn: np.ndarray) -> np.ndarray:
        """``(V,)`` the map's stretch (module docstring) of ``worn (V, 3)`` against its cut."""
        faces = np.asarray(self.models.catalog[garment_id].faces)
        per_vertex = vertex_strain(mean_stretch(worn, self.rest(garment_id, size, wearer)), faces, len(worn))
        return self._smoother(garment_id, faces, len(worn))(per_vertex)

    def _smoother(self, garment_id: str, faces: np.ndarray, n_vertices: int):
        with self._lock:
            solve = self._smoothers.get(garment_id)
        if solve is None:
            import scipy.sparse as sp
            import scipy.sparse.linalg as spl

            matrix = sp.identity(n_vertices) + SMOOTHING * graph_laplacian(faces, n_vertices)
            solve = spl.factorized(matrix.tocsc())
            with self._lock:
                self._smoothers[garment_id] = solve
        return solve

