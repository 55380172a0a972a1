"""Name an imported garment's openings (its boundary loops) by where they sit on the avatar.

Anny's frame: +x is the body's left, z up. A loop around the neck is ``neck``; one out on an arm
``sleeve_l`` / ``sleeve_r``; for a bottom the highest loop is the ``waist`` and loops below the
crotch off the midline ``leg_l`` / ``leg_r``; for a dress without a ``neck`` (strapless) the highest
loop around the midline, above its hem, is its ``top``; the lowest loop around the midline is the
``hem``; anything else, or a second loop for a name already taken, is ``opening_N``. The drape pins a
bottom's ``waist`` (``training.drape.dataset.PINNED_OPENINGS``), so a bottom must have one; a dress
must have a ``neck`` or a ``top``, and a ``hem`` (``pipeline.prepare``).
"""

from __future__ import annotations

import numpy as np

from service.geometry.mesh import boundary_loops

MIDLINE = 0.07  # m: a loop whose centre is this close to x = 0 goes around the torso


def name_openings(vertices: np.ndarray, faces: np.ndarray, category: str, joints: dict[str, np.ndarray]
                  ) -> dict[str, np.ndarray]:  # fmt: skip
    """Openings {name: (L,) int64 loop} of the garment ``vertices (V, 3)``, ``faces (F, 3)`` in Anny's
    frame; ``joints`` name -> (3,) of the mean body (``neck01``, ``upperarm01.L``, ``upperleg01.L``)."""
    loops = boundary_loops(faces)
    centres = np.array([vertices[loop].mean(0) for loop in loops])
    shoulder_z, shoulder_x = joints["upperarm01.L"][2], abs(joints["upperarm01.L"][0])
    neck_z, crotch_z = joints["neck01"][2], joints["upperleg01.L"][2] - 0.08
    names: list[str | None] = [None] * len(loops)
    for i, c in enumerate(centres):
        side = "l" if c[0] > 0 else "r"
        if abs(c[0]) < MIDLINE and c[2] > (shoulder_z + neck_z) / 2:
            names[i] = "neck"
        elif abs(c[0]) > shoulder_x and c[2] > crotch_z:
            names[i] = f"sleeve_{side}"
        elif abs(c[0]) >= MIDLINE and c[2] < crotch_z:
            names[i] = f"leg_{side}"
    around = [i for i, c in enumerate(centres) if names[i] is None and abs(c[0]) < MIDLINE]
    if category == "bottom" and around:
        names[max(around, key=lambda i: centres[i][2])] = "waist"
        around = [i for i in around if names[i] is None]
    if category == "dress" and "neck" not in names and len(around) > 1:  # one more below: the hem
        names[max(around, key=lambda i: centres[i][2])] = "top"
        around = [i for i in around if names[i] is None]
    if around:
        names[min(around, key=lambda i: centres[i][2])] = "hem"
    openings, n = {}, 0
    for i in np.argsort(-centres[:, 2]):  # top to bottom, so opening_N count downwards
        name = names[i]
        if name is None or name in openings:
            n += 1
            name = f"opening_{n}"
        openings[name] = np.asarray(loops[i], dtype=np.int64)
    return openings
