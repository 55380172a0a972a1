"""An outer garment let down where an inner one's junction hangs lower, or a tucked top gathered up
(issue 21).

A junction is where a garment's cloth passes between two body parts: the armpit of a top (between
arm and torso), the crotch of pants. Where the inner garment's junction hangs below the outer one's
(a jacket's deep armhole under a T-shirt: 15 cm on the mean body's drapes; a long sleeve under a tank
top; shorts under pants), the inner cloth between the parts lies outside the outer garment over that
height, and no push towards the body or along a normal takes it in: the outer garment has to come
down around it. ``lowering`` moves the outer garment's cloth at its junction down, below the inner one's,
in canonical space, as a smooth bump: full at the outer junction's saddle point, fading over
``CollisionSettings.bump_radius`` times the drop, and fading out over ``gate`` above the saddle (the
shoulders and the waistband stay where they are). How far is read on the body the garments are worn on
(``body_run``: their explicit meshes there, which hang lower or higher on it than on the mean body). The
stretch that adds is the outer garment's, as cloth pulled over a bulkier one stretches;
``benchmarks.orders`` reports it.

Which pairs are let down, and where the bump sits, come from ``collisions.layering.junction_run``
on the two garments' drapes on the mean body (the explicit models at the default shape: a drape's
armhole hangs lower than its template's); the drop's depth from the same run on the body's explicit
meshes, sliced near the drapes' run. It is measured on both sides of the body at once, so the drop is
the deeper side's, applied to each saddle (the garments are near symmetric). Pure functions of the
meshes: ``PairCaches.lowering`` keeps the drapes' part per ordered pair, imported garments included.

A top tucked into a bottom whose crotch is above its hem is the exception: the top's hem is gathered
up above the crotch instead (``raising``, ``PairCaches.raising``), since it is hidden under the
bottom and a bottom's dropped crotch shows. Its extent is made once per pair; the crotch height it
ends at is read on each body.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from service.pipeline.collisions.layering import BodySlices, GarmentProfile, junction_run, slice_loops
from service.pipeline.collisions.settings import SETTINGS


def saddles(parts: frozenset[int], centres: np.ndarray, names: list[str]) -> list[np.ndarray]:
    """Horizontal positions ``(2,)`` between the parts a junction passes between: the torso and each
    arm, or two legs (``centres (P, 2)`` and ``names`` of one level of ``BodySlices``)."""
    idx = sorted(parts)
    torso = [i for i in idx if names[i] == "torso"]
    if torso:
        return [0.5 * (centres[torso[0]] + centres[i]) for i in idx if i != torso[0]]
    return [0.5 * (centres[a] + centres[b]) for a, b in zip(idx, idx[1:], strict=False)]


def lowering(inner: GarmentProfile, outer: GarmentProfile, body: BodySlices, outer_vertices: np.ndarray,
             between: int = 0, length: int | None = None, extra: float = SETTINGS.extra):  # fmt: skip
    """``(V, 3)`` displacement of the outer garment's canonical ``outer_vertices (V, 3)`` (its drape on
    the mean body, of which ``outer`` is the profile) that brings its junctions ``extra`` below the
    inner garment's (``inner``'s profile), or None where the inner one's hangs no lower. ``between``:
    garments between the two that were let down around the inner one too; each of their junctions
    takes its own ``extra`` below it, and this one comes down below all of them. ``length``: the run
    (levels) on the body the garments are worn on (``body_run``) instead of the drapes' own; the bump
    stays where the drapes put it. ``extra``: the room in place of ``extra`` (``rooms``)."""
    run = junction_run(inner, outer, body)
    if run is None:
        return None
    drapes_length, k, parts = run
    drop = (drapes_length if length is None else length) * SETTINGS.slice_step + extra * (1 + between)
    z_saddle = body.levels[k] + SETTINGS.slice_step  # the first level where the outer garment joins the parts
    radius = max(SETTINGS.bump_radius * drop, SETTINGS.min_bump_radius)
    out = np.zeros_like(outer_vertices)
    for xy in saddles(parts, body.centres[k], body.names[k]):
        target = np.array([xy[0], xy[1], z_saddle])
        saddle = outer_vertices[np.argmin(np.linalg.norm(outer_vertices - target, axis=1))]
        r = np.linalg.norm(outer_vertices - saddle, axis=1)
        w = np.clip(1 - (r / radius) ** 2, 0.0, None) ** 2
        w *= np.clip((saddle[2] + SETTINGS.gate - outer_vertices[:, 2]) / SETTINGS.gate, 0.0, 1.0)
        out[:, 2] = np.minimum(out[:, 2], -drop * w)  # two saddles' bumps overlap: the deeper one
    return out


def body_run(inner: GarmentProfile, outer: GarmentProfile, body: BodySlices, inner_vertices: np.ndarray,
             inner_faces: np.ndarray, outer_vertices: np.ndarray,
             outer_faces: np.ndarray) -> int:  # fmt: skip
    """The length (levels) of the junction run of the two garments on one body: their explicit meshes
    there (canonical ``inner_vertices (V, 3)``, ``outer_vertices (W, 3)``), sliced only within ``run_band``
    of the run of their drapes on the mean body (``inner``, ``outer``: those drapes' profiles), which
    must have one; 0 where the body's has none.

    Each garment is graded to the body it is worn on, and in canonical space its armhole sits lower or
    higher with the body: the jacket's below the tank top's by 16-21 cm on the corners of the supported
    box and held-out bodies, 18 on the mean body. A drop made for 18 left 1-2 cm of room on the bodies
    at 20-21, and those were the ones that crossed (4 of 10: 42-80 pairs, the others clean)."""
    length, k, _ = junction_run(inner, outer, body)
    pad = round(SETTINGS.run_band / SETTINGS.slice_step)
    levels = range(max(k - length - pad, 0), min(k + pad + 1, len(body.levels)))
    meshes = ((inner, inner_vertices, inner_faces), (outer, outer_vertices, outer_faces))
    here = [GarmentProfile.build(p.garment_id, v, f, body, levels) for p, v, f in meshes]
    run = junction_run(*here, body)
    return 0 if run is None else run[0]


@dataclass(frozen=True)
class Gathering:
    """How a top tucked into a bottom is gathered up above the bottom's crotch (``raising``): per inner
    vertex its weight ``(V,)`` (1 across its hem's width, 0 beside it), and the outer garment's
    vertices at its crotch ``(K,)``, whose height on each body is where the gathering ends."""

    weight: np.ndarray
    crotch: np.ndarray

    def shift(self, inner_vertices: np.ndarray, outer_vertices: np.ndarray) -> np.ndarray | None:
        """``(V, 3)`` displacement (up) of the top's canonical ``inner_vertices (V, 3)`` for the bottom's
        ``outer_vertices`` on the same body, or None where it hangs no lower. Read per body: against the
        shorts' crotch, the jacket's hem hangs 2 cm lower on the mean body's drapes, 5.5 cm on a
        held-out body and 10.5 cm on the shortest man (their explicit meshes, canonical)."""
        target = float(outer_vertices[self.crotch, 2].max()) + SETTINGS.extra
        z = inner_vertices[:, 2]
        hanging = (self.weight > 0) & (z < target)
        if not hanging.any():
            return None
        low = z[hanging].min()
        top = target + max(SETTINGS.gate, target - low)  # gathered at most two to one
        region = (self.weight > 0) & (z < top)
        gathered = top - (top - z) * (top - target) / (top - low)
        out = np.zeros_like(inner_vertices)
        out[:, 2] = np.where(region, self.weight * (gathered - z), 0.0)
        return out


def raising(inner: GarmentProfile, outer: GarmentProfile, body: BodySlices, inner_vertices: np.ndarray,
            inner_faces: np.ndarray, outer_vertices: np.ndarray) -> Gathering | None:  # fmt: skip
    """The ``Gathering`` of a top (canonical drape on the mean body ``inner_vertices (V, 3)``, of which
    ``inner`` is the profile) tucked into a bottom (``outer_vertices (W, 3)``, ``outer``) whose crotch
    is above its hem, or None.

    A top tucked into pants whose hem hangs below their crotch (a jacket: 6 cm on the mean body's
    drapes) wraps both legs in one piece where the pants go around each. Letting the pants' crotch down
    around it (``lowering``) showed: a crotch dropped 10 cm, and the jacket's hem still crossed it
    (195-294 pairs on ``benchmarks.orders --pairs``' bodies). The top's hem is under the pants, where
    nobody sees it, so the top gives way instead, as a tucked shirt's tail bunches up: across the
    width of its loop around both legs (plus ``gather_pad``, fading out over another), every vertex below
    ``gate`` above the target height (or more, so that the cloth is gathered at most two to one) is
    pressed up, its height mapped linearly so that the lowest one ends ``extra`` above the outer
    garment's crotch and those at the top stay: cloth gathered, never folded over itself. Across the
    whole hem, not only between the legs: gathered there alone, the hem rose in a V from each thigh's
    front to the crotch, and its slopes at the thighs crossed the pants (41-49 pairs on two bodies)."""
    run = junction_run(inner, outer, body)
    if run is None:
        return None
    _, k, parts = run
    if len(parts) != 2 or any(body.names[k][i] != "leg" for i in parts):
        return None
    a, b = sorted(parts)
    ca, cb = body.centres[k][a], body.centres[k][b]
    axis = (cb - ca) / np.linalg.norm(cb - ca)  # from one leg to the other
    mid = 0.5 * (ca + cb)
    # Across the inner garment's loop around both legs at the run's top (not its sleeves, whose cuffs
    # can hang as low beside the hips).
    loops = [lp for lp in slice_loops(inner_vertices, inner_faces, body.levels[k]) if lp.closed]
    around = [lp for lp in loops if lp.contains(mid[None])[0]]
    if not around:
        return None
    full = max(float(np.abs((lp.points - mid) @ axis).max()) for lp in around) + SETTINGS.gather_pad
    pad = SETTINGS.gather_pad
    w = np.clip((full + pad - np.abs((inner_vertices[:, :2] - mid) @ axis)) / pad, 0.0, 1.0)
    # The outer garment's crotch: its vertices nearest the saddle, a level above the run's top.
    saddle = np.array([*mid, body.levels[k] + SETTINGS.slice_step])
    crotch = np.argsort(np.linalg.norm(outer_vertices - saddle, axis=1))[:SETTINGS.crotch_vertices]
    return Gathering(w * w * (3 - 2 * w), crotch)


def combined(shifts: list[np.ndarray]) -> np.ndarray | None:
    """One garment's lowerings for its inner garments and raisings for its outer ones (each ``(V, 3)``,
    vertical): the deepest drop plus the highest rise at each vertex, or None for none."""
    if not shifts:
        return None
    zero = np.zeros_like(shifts[0])
    return np.minimum.reduce([zero, *shifts]) + np.maximum.reduce([zero, *shifts])
