"""An outer garment let down where an inner one's junction hangs lower (issue 21).

A junction is where a garment's cloth passes between two body parts: the armpit of a top (between
arm and torso), the crotch of pants. Where the inner garment's junction hangs below the outer one's
(a jacket's deep armhole under a T-shirt: 15 cm on the mean body's drapes; a long sleeve under a tank
top; shorts under pants), the inner cloth between the parts lies outside the outer garment over that
height, and no push towards the body or along a normal takes it in: the outer garment has to come
down around it. ``lowering`` moves the outer garment's cloth at its junction down, below the inner
one's, in canonical space (the same for every body shape), as a smooth bump: full at the outer
junction's saddle point, fading over ``RADIUS`` times the drop, and fading out over ``GATE`` above the
saddle (the shoulders and the waistband stay where they are). The stretch that adds is the outer
garment's, as cloth pulled over a bulkier one stretches; ``benchmarks.orders`` reports it.

The run is ``service.pipeline.layering.junction_run`` on the two garments' drapes on the mean body
(the explicit models at the default shape: a drape's armhole hangs lower than its template's). It is
measured on both sides of the body at once, so the drop is the deeper side's, applied to each saddle
(the garments are near symmetric). Pure functions of the two meshes: ``OutfitModels.lowering`` makes
and keeps one per ordered pair, imported garments included.
"""

from __future__ import annotations

import numpy as np

from service.pipeline.layering import STEP, BodySlices, GarmentProfile, junction_run

EXTRA = 0.04
"""m: how far below the inner garment's junction the outer one's comes down (room for both cloths; 2
cm left the jacket under the T-shirt crossing on one of ``benchmarks.orders --pairs``' three bodies)."""
RADIUS = 1.5
"""The bump's radius per metre of drop (at least ``MIN_RADIUS``): the cloth around the saddle comes
down with it, so the drop spreads over the sleeve and the side instead of pulling one vertex."""
MIN_RADIUS = 0.06  # m
GATE = 0.10
"""m above the saddle over which the drop fades to nothing: the top of the sleeve and the shoulder
seam, on the body, stay (moved down they would go into the shoulder). 5 cm left the jacket under the
tank top at 24-133 crossing pairs, 10 cm at 0-36."""


def saddles(parts: frozenset[int], centres: np.ndarray, names: list[str]) -> list[np.ndarray]:
    """Horizontal positions ``(2,)`` between the parts a junction passes between: the torso and each
    arm, or two legs (``centres (P, 2)`` and ``names`` of one level of ``BodySlices``)."""
    idx = sorted(parts)
    torso = [i for i in idx if names[i] == "torso"]
    if torso:
        return [0.5 * (centres[torso[0]] + centres[i]) for i in idx if i != torso[0]]
    return [0.5 * (centres[a] + centres[b]) for a, b in zip(idx, idx[1:], strict=False)]


def lowering(inner: GarmentProfile, outer: GarmentProfile, body: BodySlices, outer_vertices: np.ndarray):
    """``(V, 3)`` displacement of the outer garment's canonical ``outer_vertices (V, 3)`` (its drape on
    the mean body, of which ``outer`` is the profile) that brings its junctions ``EXTRA`` below the
    inner garment's (``inner``'s profile), or None where the inner one's hangs no lower."""
    run = junction_run(inner, outer, body)
    if run is None:
        return None
    length, k, parts = run
    drop = length * STEP + EXTRA
    z_saddle = body.levels[k] + STEP  # the first level where the outer garment joins the parts
    radius = max(RADIUS * drop, MIN_RADIUS)
    out = np.zeros_like(outer_vertices)
    for xy in saddles(parts, body.centres[k], body.names[k]):
        target = np.array([xy[0], xy[1], z_saddle])
        saddle = outer_vertices[np.argmin(np.linalg.norm(outer_vertices - target, axis=1))]
        r = np.linalg.norm(outer_vertices - saddle, axis=1)
        w = np.clip(1 - (r / radius) ** 2, 0.0, None) ** 2
        w *= np.clip((saddle[2] + GATE - outer_vertices[:, 2]) / GATE, 0.0, 1.0)
        out[:, 2] = np.minimum(out[:, 2], -drop * w)  # two saddles' bumps overlap: the deeper one
    return out


def combined(drops: list[np.ndarray]) -> np.ndarray | None:
    """One garment's lowerings for several inner garments (each ``(V, 3)``, down only): the deepest at
    each vertex, or None for none."""
    if not drops:
        return None
    return np.minimum.reduce(drops)
