"""Room for cloth where a body's parts touch: a pressed body's contacts opened to a gap.

A heavy body's inner thighs are pressed into contact (``self_contact``), and a pair of trousers cannot
pass between two surfaces a millimetre apart: each leg's inner cloth ends up inside the other thigh.
Clothed flesh gives way to the cloth. ``open_contacts`` makes that room: the mesh is blown up by half
the ``gap`` along its normals, pressed (wherever two parts now come within ``gap`` of each other they
cross and are pressed apart), and shrunk back by as much. Parts that were more than ``gap`` apart do not
move; parts in contact end up ``gap`` apart, each giving way by half.
"""

from __future__ import annotations

import numpy as np

from service.geometry.mesh import vertex_normals
from service.geometry.self_contact import press_contacts


def open_contacts(
    vertices: np.ndarray, faces: np.ndarray, gap: float, ignore: np.ndarray | None = None
) -> np.ndarray:
    """``vertices (V, 3)`` of a closed mesh ``faces (F, 3)`` that does not cross itself, with every
    contact opened to ``gap`` (m; module docstring). ``ignore (F,) bool``: faces left out of the
    pressing (``BodyModel.template_crossings``)."""
    blown = vertices + 0.5 * gap * vertex_normals(vertices, faces)
    shrunk = vertices + (press_contacts(blown, faces, 0.0, ignore).vertices - blown)  # exact where unmoved
    # Shrunk back, a fold the relaxation smoothed on the blown-up mesh can cross again (the armpits of
    # the heaviest women: 8 pairs): pressed once more.
    return press_contacts(shrunk, faces, 0.0, ignore).vertices
