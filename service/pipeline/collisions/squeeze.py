"""Squeeze inner garments under the outer ones that cover them, in world space, before the repair.

The repair (``collisions.repair``) only ever moves a layer outwards, over its final inner layers. Where
an inner garment hangs loose beyond the one that covers it (a T-shirt tucked into tight pants: its
hem 2-4 cm off the body, the waistband on the skin) that means lifting the pants over the T-shirt's
hem: a ledge, and crossings left at the hem's rim that 24 rounds did not remove. Cloth does the
opposite: the tight outer layer presses the loose inner one against the body. The untangling
operator splits a violation between both layers too, but the fit moves a vertex at most ``trust``
(1 cm) in canonical space.

So, from the outermost garment inwards, every vertex of a garment that an outer garment covers (its
covariant field h < 0 at the vertex) and that lies outside that outer mesh, by less than ``PENETRATION_BAND``,
moves straight towards its closest body point until it is ``CollisionSettings.margin`` inside the outer mesh
(a walk in
steps of its signed distance), never closer to the body than ``floor``: the caller keeps one margin
per garment under it, so that a stack of squeezed layers does not collapse onto the skin, where the
repair would have to lift them apart again.

Towards the closest body point, not along the outer layer's normal: in a concave crease of the outer
layer (pants under a belly) the normal of the nearest face points through the other side of the
crease, and 118 of 768 crossings were left that way; along the garment's own normal the tucked
T-shirt kept 17 crossings. The displacement spreads over ``squeeze_ring`` rings (the diffusion of the
repair), so the garment folds in along the outer layer's edge instead of tearing there. The repair
then pushes whatever the squeeze put inside the body or an inner garment back out, and the outer
layers over it.

The covariant field only says "covered" near the outer garment's surface and inside its openings.
Cloth of the inner garment that hangs outside the outer one (a jacket's loose sleeve under a
long-sleeve shirt's narrower one, a jacket's low armhole under a T-shirt's armpit) is also under it:
the segment from the vertex's own body point (its ``BodyAnchors``, where the garment sits on the body,
not the closest point, which for a hanging sleeve can be the torso) to the vertex crosses the outer
mesh an odd number of times. Such vertices walk towards that body point, whatever their distance.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from service.geometry.closest import ClosestPoint
from service.geometry.diffusion import diffuse
from service.geometry.intersections import TriangleGrid, segment_crossings
from service.geometry.kept_queries import KeptQueries
from service.geometry.rings import dilate, vertex_neighbours
from service.pipeline.collisions.settings import SETTINGS, CollisionSettings
from service.pipeline.collisions.traits import tucked, worn_alike
from service.pipeline.quality import PENETRATION_BAND


@dataclass
class Outer:
    """An outer layer as one inner garment sees it."""

    mesh: ClosestPoint  # its world-space mesh
    near: np.ndarray  # (V,) bool: inner vertices that may be within band of it (others never move)
    covered: np.ndarray  # (V,) bool: inner vertices it covers (its h < 0 there)
    beyond: np.ndarray | None = None
    """(V,) bool: vertices found outside it by the segment test: covered and near, at any distance, and
    they walk to their anchors."""
    looser_under: bool = True
    """Whether the segment test is asked for the inner garment under this one (``asks_segment_test``).
    Worn the usual way, the field's cover is right, and the test's anchor walks cost time and left 9
    crossing pairs in four tops on a short, heavy body."""
    kept: KeptQueries | None = None
    """Closest points on ``mesh`` already asked for (of the inner garment's V vertices), or None: none
    yet (``service.pipeline.collisions.passes`` asks ahead)."""


def asks_segment_test(inner, outer, traits) -> bool:
    """Whether garment ``inner`` under ``outer`` (catalog ``Garment``s) gets the segment test: worn
    against the catalog's usual order (its ``layer_rank`` not below the outer one's), and either worn
    alike (``collisions.traits.worn_alike``: a looser top under a tighter one, a bottom in another) or
    tucked into a garment that goes around each leg (``traits.tucked`` and ``holds_legs_apart``: a top
    in pants, shorts), whose crotch the inner hem can hang below on a short body, as a looser top's
    armhole does below a fitted one's armpit. Not a top in a skirt: the test walked a jacket's hem
    inside a skirt on the shortest man into 12 crossing pairs where it had none. ``benchmarks.orders
    --pairs`` with tucked tops asked too: the long sleeve in pants on the shortest, lightest man 105 -> 6
    crossing pairs, in shorts 24 -> 0. ``traits(garment) -> GarmentTraits`` (``traits.traits_of``) is
    asked only against the usual order: usual orders never read the garments' slices."""
    if inner.layer_rank < outer.layer_rank:
        return False
    a, b = traits(inner), traits(outer)
    return worn_alike(a, b) or (tucked(a, b) and b.holds_legs_apart)


def beyond(x: np.ndarray, anchors: np.ndarray, outer: Outer, kept: KeptQueries) -> np.ndarray:
    """``(V,)`` bool: vertices of ``x (V, 3)`` whose segment from their anchor ``(V, 3)`` crosses the
    outer mesh an odd number of times, at any distance from it. Asked only where the squeeze may move a
    vertex: those the field does not count as covered, and covered ones outside the outer mesh
    (``kept``: closest points on it, which the squeeze's first round then reuses). Covered vertices
    already under the outer layer, nearly all of a garment worn in the usual order, are not asked.

    Not only the vertices ``outer.near`` (the fields' distance within ``CollisionSettings.reach``): a
    jacket's sleeve
    hangs up to 7 cm below a long sleeve's along the forearm, where the fields (read at the mesh before
    the long sleeve was let down) put it farther, and nothing pulled it in: 29-412 crossing pairs on
    ``benchmarks.orders --pairs``' three bodies, 0 with every vertex asked. The caller adds those
    found to ``near``."""
    covered = np.flatnonzero(outer.covered)
    far = covered[kept.signed_at(x, covered)[0] > 0] if len(covered) else covered
    ask = np.union1d(np.flatnonzero(~outer.covered), far)
    out = np.zeros(len(x), dtype=bool)
    if len(ask):
        grid = TriangleGrid.build(outer.mesh.vertices, outer.mesh.faces)
        out[ask] = segment_crossings(grid, anchors[ask], x[ask]) % 2 == 1
    return out


@dataclass
class SqueezeResult:
    vertices: np.ndarray  # (V, 3)
    moved: np.ndarray  # (V,) bool
    outside: int  # covered vertices still outside an outer layer (within band) at the end


def _pulls(x: np.ndarray, outer: Outer, kept: KeptQueries, body: KeptQueries, floor: float,
           settings: CollisionSettings, margin: np.ndarray, anchors: np.ndarray | None = None,
           past_rim: bool = False):  # fmt: skip
    """Vertices of ``x (V, 3)`` outside ``outer`` where it covers them (by less than ``margin (V,)``
    inside it), and their targets: (indices (K,), targets (K, 3)). ``kept`` and ``body`` keep the
    closest points on the outer layer and on the body of the vertices that did not move since the last
    round; ``anchors (V, 3)``: the body points the ``outer.beyond`` vertices walk to."""
    cand = np.flatnonzero(outer.near & outer.covered)
    if not len(cand):
        return cand, np.zeros((0, 3))
    signed_out, rim = kept.signed_at(x, cand)
    far = outer.beyond[cand] if outer.beyond is not None else np.zeros(len(cand), dtype=bool)
    under = signed_out < PENETRATION_BAND
    if past_rim:
        under &= ~rim
    # 10 % slack, as in the repair: a vertex pulled to the margin lands a rounding error short of it.
    bad = (signed_out > -settings.short_of_margin * margin[cand]) & (under | far)
    idx = cand[bad]
    if not len(idx):
        return idx, np.zeros((0, 3))
    signed_body, point_body = body.at(x, idx)[:2]
    keep = signed_body > 0  # a vertex inside the body is the repair's to move, outwards
    idx, p, c = idx[keep], x[idx[keep]], point_body[keep]
    to_anchor = np.zeros(len(idx), dtype=bool) if outer.beyond is None else outer.beyond[idx]
    if to_anchor.any():
        c[to_anchor] = anchors[idx[to_anchor]]
    if not len(idx):
        return idx, np.zeros((0, 3))
    span = np.maximum(np.linalg.norm(p - c, axis=1), 1e-12)
    m = margin[idx]
    # Walk the kept fraction s of the distance to the body down from 1: the signed distance changes at
    # most as fast as the point moves, so a step of (distance + margin) never passes the margin inside
    # the outer layer, and meets it exactly where the walk is along the outer layer's normal; obliquely
    # it takes a few steps. Never below floor / distance (the outer layer is then on the skin there
    # and the repair lifts it over this one).
    low = floor / span  # above 1 where the vertex is already under the floor: out to it
    s = np.ones(len(idx))
    signed = signed_out[bad][keep]
    walking = np.arange(len(idx))
    for _ in range(settings.squeeze_steps):
        s[walking] = np.maximum(low[walking], s[walking] - (signed + m[walking]) / span[walking])
        walking = walking[s[walking] > low[walking]]
        if not len(walking):
            break
        signed = outer.mesh.query(c[walking] + s[walking, None] * (p - c)[walking]).signed
        keep = signed > -settings.short_of_margin * m[walking]
        walking, signed = walking[keep], signed[keep]
        if not len(walking):
            break
    # The straight way to an anchor can pass the body elsewhere (a sleeve's anchor on the arm seen from
    # under the armpit): back off halfway, up to three times, while the target is under the floor.
    back = np.flatnonzero(to_anchor & (s < 1))
    for _ in range(settings.squeeze_backoffs):
        if not len(back):
            break
        under = body.mesh.query(c[back] + s[back, None] * (p - c)[back]).signed < floor
        back = back[under]
        s[back] = 0.5 * (1 + s[back])
    s[back] = 1.0  # still under it: this vertex waits (the repair lifts what is left)
    return idx, c + s[:, None] * (p - c)


def squeeze_layer(
    vertices: np.ndarray,
    faces: np.ndarray,
    outer: list[Outer],
    body: ClosestPoint,
    floor: float,
    settings: CollisionSettings = SETTINGS,
    anchors: np.ndarray | None = None,
    margin: np.ndarray | None = None,
    past_rim: bool = False,
) -> SqueezeResult:
    """Pull garment ``vertices (V, 3)``, ``faces (F, 3)`` towards the ``body`` mesh, inside the
    ``outer`` layers that cover it, but no closer to the body than ``floor`` (m). With ``anchors``
    (``(V, 3)``, ``BodyAnchors.on`` this body) vertices under an outer layer by the segment test are
    pulled too (``beyond``). ``margin (V,)``: how far inside the outer layers each vertex goes (m;
    default ``settings.margin`` everywhere). ``past_rim``: a vertex whose closest point on an outer
    layer is on its rim is past its opening, not under it (``Way.past_rim``)."""
    x0 = np.asarray(vertices, dtype=np.float64)
    margin = np.full(len(x0), settings.margin) if margin is None else np.asarray(margin, dtype=np.float64)
    x = x0.copy()
    kept = [KeptQueries(layer.mesh, len(x)) if layer.kept is None else layer.kept for layer in outer]
    if anchors is not None:  # the caller's layers stay as they were
        outer = [
            replace(layer, beyond=(b := beyond(x0, anchors, layer, queries)),
                    covered=layer.covered | b, near=layer.near | b)
            if layer.looser_under else layer
            for layer, queries in zip(outer, kept, strict=True)
        ]  # fmt: skip
    adjacency = vertex_neighbours(np.asarray(faces), len(x))
    on_body = KeptQueries(body, len(x))
    outside, last, final = 0, None, False
    rounds = settings.squeeze_rounds
    if anchors is None:
        rounds = min(rounds, settings.squeeze_usual_rounds)
    for round_ in range(rounds + 1):
        u = np.zeros_like(x)
        held = np.zeros(len(x), dtype=bool)
        for layer, queries in zip(outer, kept, strict=True):
            idx, target = _pulls(x + u, layer, queries, on_body, floor, settings, margin, anchors, past_rim)
            u[idx] = target - x[idx]
            held[idx] = True
        outside = int(held.sum())
        if not outside or round_ == rounds or final:
            break
        # A handful of vertices the walk cannot bring in (blocked at the floor) would keep every
        # round busy: once the count stops falling, one last round puts the pulled ones in place.
        final = round_ == rounds - 1 or (round_ >= settings.squeeze_stall_after and outside >= last)
        last = outside
        region = dilate(held, adjacency, settings.squeeze_ring)
        u = diffuse(u, held, region, adjacency, settings.squeeze_smoothing)
        if not final:  # the last round puts the pulled vertices where they belong
            u = diffuse(u, np.zeros_like(held), region, adjacency, settings.squeeze_relax)
        x += u
    return SqueezeResult(x, np.any(x != x0, axis=1), outside)
