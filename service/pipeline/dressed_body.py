"""The body garments are fitted to: a shopper's built body with room for cloth where its parts touch.

A heavy body served bare has its crossing parts pressed into contact (``body_build.pressed_body``); a
trouser leg cannot pass between two thighs a millimetre apart. Dressed, those contacts are opened to
``CLOTH_GAP_M`` (``service.geometry.contact_gap``), near the vertices the pressing moved only (blown up
everywhere, fingers and toes would cross too). A body that was not pressed is dressed as it is.
"""

from __future__ import annotations

import numpy as np

from service.geometry.contact_gap import open_contacts
from service.geometry.rings import dilate, vertex_neighbours
from service.pipeline.body import BodyModel
from service.pipeline.body_build import BuiltBody

CLOTH_GAP_M = 0.01
"""m between the parts of a dressed body that touch: two layers of cloth, each kept a few millimetres
off the skin. Pants on the three heaviest held-out NHANES women (BMI 59-65): 22, 0 and 9 triangle pairs
crossing the body with the pressed 1 mm contact, none with 1 cm."""
OPEN_RINGS = 3
"""Rings around the pressed vertices where contacts are opened (the pressing spreads its moves over two)."""


def dressed_vertices(model: BodyModel, built: BuiltBody) -> np.ndarray:
    """``(V, 3)``: ``built.vertices`` with the contacts it was pressed at opened to ``CLOTH_GAP_M``."""
    if built.pressed is None:
        return built.vertices
    return open_contacts(built.vertices, model.faces, CLOTH_GAP_M, ~opened_faces(model, built))


def opened_faces(model: BodyModel, built: BuiltBody) -> np.ndarray:
    """``(F,) bool``: the faces whose contacts ``dressed_vertices`` opens: within ``OPEN_RINGS`` of a
    vertex the pressing moved, Anny's own crossings (``template_crossings``) left out."""
    moved = np.any(model.shape_vertices(built.shape) != built.vertices, axis=1)
    near = dilate(moved, vertex_neighbours(model.faces, len(moved)), OPEN_RINGS)
    return near[model.faces].all(axis=1) & ~model.template_crossings
