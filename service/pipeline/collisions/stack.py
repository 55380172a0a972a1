"""What the world-space stages know of an outfit: its garments, their fields and where the fit left them.

``Stack`` is the stages' whole view of the models (no callback into the loaded models: the caller,
``service.pipeline.outfit``, builds it per request); ``Fitted`` carries the fit's canonical meshes and
the field values it left at them, so that the stages read "where is layer k at garment i's vertices"
without evaluating the networks again where the fit already did.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from service.geometry.anchors import BodyAnchors


class LayerFields(Protocol):
    def __call__(self, layer: int, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(f (P,), h (P,)) of layer ``layer`` (0 = the body, k = the k-th garment, inner to outer) at
        canonical points ``x (P, 3)``, values only."""
        ...


@dataclass(frozen=True)
class Stack:
    """An outfit's garments, inner to outer, as the squeeze and the repair see them."""

    faces: list[np.ndarray]
    """Per garment ``(F_i, 3)`` int64."""
    anchors: list[BodyAnchors]
    """Per garment, where its vertices sit on the body (``service.geometry.anchors``)."""
    segment_test: Callable[[int, int], bool]
    """``(j, i) -> bool``: whether garment j under garment i asks the segment test
    (``collisions.squeeze.asks_segment_test``); asked only where i covers some of j."""
    fields: LayerFields
    """Every layer's fields at canonical points (the body is layer 0)."""


@dataclass(frozen=True)
class Fitted:
    """The fit's result per garment: canonical vertices ``(V_i, 3)`` and, where the fit left them, every
    layer's field values there (``FitResult.values``: f, h ``(V_i, N)``; None: evaluate again)."""

    vertices: list[np.ndarray]
    values: list[tuple[np.ndarray, np.ndarray] | None]

    def field_at(self, fields: LayerFields, k: int, i: int) -> tuple[np.ndarray, np.ndarray]:
        """Layer ``k``'s (f, h) ``(V_i,)`` at garment ``i``'s fitted canonical vertices: from the fit's
        values where it left them, else evaluated (values only)."""
        if self.values[i] is not None:
            return self.values[i][0][:, k], self.values[i][1][:, k]
        return fields(k, self.vertices[i])
