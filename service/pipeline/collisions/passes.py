"""The squeeze then the exact repair of the fitted outfit in world space, pass after pass.

``resolve`` runs ``collisions.squeeze`` (inner garments pressed under the outer ones that cover them)
and ``collisions.repair`` (every layer lifted clear of its final inner layers, exact crossing tests) on
the world meshes the fit and the body map produced, and repeats both where faults remain, in each of
``CollisionSettings.ways`` in turn. Which vertices can be near a layer, and where it covers them, comes
from the fields at the fitted canonical vertices (``Fitted.field_at``).
"""

from __future__ import annotations

import time
from concurrent.futures import Future
from dataclasses import dataclass, field, fields, replace

import numpy as np

from service.geometry.closest import Closest, ClosestPoint
from service.geometry.fold_side import FoldSides
from service.geometry.kept_queries import KeptQueries, ask_ahead
from service.geometry.occupancy import Occupancy, triangle_boxes
from service.geometry.rings import dilate, vertex_neighbours
from service.pipeline.collisions.repair import Inner, RepairResult, repair_layer
from service.pipeline.collisions.settings import SETTINGS, CollisionSettings, Way
from service.pipeline.collisions.squeeze import Outer, squeeze_layer
from service.pipeline.collisions.stack import Fitted, Stack
from service.pipeline.quality import PENETRATION_BAND

ASK_AHEAD = True
"""Whether the squeeze and the repair ask closest points ahead, on a background thread (``ask_ahead``);
off, every query is asked when it is needed: the same meshes, bit for bit (tested)."""


@dataclass(frozen=True)
class Resolved:
    """The world meshes ``(V_i, 3)`` with the fewest faults found, inner to outer, and per garment what
    its repair left (``RepairResult``)."""

    meshes: list[np.ndarray]
    repairs: list[RepairResult]
    passes: int = 1  # squeeze-and-repair passes run to find them

    @property
    def faults(self) -> tuple[int, int]:
        return repair_faults(self.repairs)


def resolve(stack: Stack, body: ClosestPoint, explicit: list[np.ndarray], fitted: Fitted,
            world: list[np.ndarray], lowered: list[float] | None = None,
            settings: CollisionSettings = SETTINGS, pass_limit: int | None = None,
            deadline: float | None = None) -> Resolved:  # fmt: skip
    """The squeeze then the repair of the fitted world meshes ``world`` (per garment ``(V_i, 3)``, on the
    body mesh ``body``); where faults are left, again, up to ``settings.passes`` times in each of
    ``settings.ways``, a pass of each in turn, until one comes out clean. A way stops after
    ``settings.pass_patience`` passes without a new best of its own; only outfits with faults left run
    past the first pass.

    Returns the pass with the fewest crossings, then vertices inside (``repair_faults``). ``explicit``:
    the explicit canonical meshes the fields were learned on. ``lowered``: per garment, how far (m) its
    explicit mesh was let down from the one its fields know (``collisions.junctions``), which widens
    where the garments over it look for it. ``pass_limit``: at most this many passes (at least one),
    what is left of a request's ``settings.pass_budget``; ``deadline``: no pass after the first starts
    once ``time.perf_counter()`` has passed it (``settings.pass_seconds``)."""
    lowered = lowered or [0.0] * len(world)
    limit = max(1, pass_limit if pass_limit is not None else settings.pass_budget)
    best, run = None, 0
    chains = [_Chain(way, world, [np.full(len(x), settings.margin) for x in world]) for way in settings.ways]
    for _ in range(settings.passes):
        for chain in chains:
            if chain.stale >= settings.pass_patience:
                continue
            if run == limit or (run and deadline is not None and time.perf_counter() > deadline):
                return replace(best, passes=run)
            squeezed = _squeeze(stack, fitted, chain.start, body, chain.deep, chain.pressed, chain.way,
                                settings)  # fmt: skip
            out = _repair(stack, body, explicit, fitted, world, squeezed, settings, lowered)
            run += 1
            # Crossings first: a vertex left inside an inner layer is within the quality bound (0.1 %)
            # long before a crossing pair is.
            if best is None or out.faults < best.faults:
                best = out
            if out.faults == (0, 0):
                return replace(out, passes=run)
            chain.stale = 0 if out.faults < chain.fewest else chain.stale + 1
            chain.fewest = min(chain.fewest, out.faults)
            _deepen(out.repairs, stack.faces, chain.deep, chain.pressed, settings)
            chain.start = out.meshes if chain.way.from_repaired else world
    return replace(best, passes=run)


def repair_faults(results) -> tuple[int, int]:
    """(crossing pairs, vertices inside) left by an outfit's ``RepairResult``s: compared as a tuple,
    crossings first."""
    return (sum(r.crossing_pairs for r in results), sum(r.inside for r in results))


@dataclass
class _Chain:
    """One ``Way``'s passes: where its next squeeze starts, its per-vertex depths (``_deepen``), the
    fewest faults it reached and the passes since."""

    way: Way
    start: list[np.ndarray]
    deep: list[np.ndarray]
    pressed: dict = field(default_factory=dict)
    fewest: tuple = (np.inf, np.inf)
    stale: int = 0


def _deepen(results, faces, deep: list[np.ndarray], pressed: dict,
            settings: CollisionSettings = SETTINGS) -> None:  # fmt: skip
    """Where the repair left layer i crossing (or inside) garment k, the next squeeze presses k deeper
    under i: ``settings.deepen`` more margin (``deep[k] (V_k,)``, m, up to ``settings.deepest``) on the
    faults' vertices of k and ``settings.deepen_ring`` rings around them, and those vertices count as
    under i (``pressed[(k, i)] (V_k,)`` bool) whatever i's fields say."""
    for i, r in enumerate(results):
        for n, at in enumerate(r.faults[1:]):  # the first inner layer is the body
            if not len(at):
                continue
            mask = np.zeros(len(deep[n]), dtype=bool)
            mask[at] = True
            mask = dilate(mask, vertex_neighbours(faces[n], len(mask)), settings.deepen_ring)
            deep[n][mask] = np.minimum(deep[n][mask] + settings.deepen, settings.deepest)
            pressed[(n, i)] = pressed.get((n, i), np.zeros(len(mask), dtype=bool)) | mask


def _squeeze(stack: Stack, fitted: Fitted, world: list[np.ndarray], body: ClosestPoint,
             deep: list[np.ndarray], pressed: dict, way: Way,
             settings: CollisionSettings) -> list[np.ndarray]:  # fmt: skip
    """World meshes with every garment pulled inside the outer ones that cover it
    (``collisions.squeeze``), from the outermost inwards. Where an outer garment covers a vertex and how
    far it is comes from the outer garment's fields at the vertex's fitted canonical position, as in
    ``_repair``, and from ``_deepen``'s ``pressed``; how far inside it goes, from its ``deep``.

    Garment i's mesh is final once its own squeeze is done (the outermost's from the start): the first
    closest points of the garments two or more layers under it are asked ahead then (``ask_ahead``),
    while the garments between are squeezed."""
    out = list(world)
    meshes: dict[int, ClosestPoint] = {}
    # (j, i): garment j's vertices near outer garment i and covered by it, where any are
    masks = {}
    for j in range(len(out) - 1):
        for i in range(j + 1, len(out)):
            f, h = fitted.field_at(stack.fields, i + 1, j)
            near, covered = np.abs(f) < settings.reach, h < 0
            if (j, i) in pressed:
                near, covered = near | pressed[(j, i)], covered | pressed[(j, i)]
            if (near & covered).any():
                masks[(j, i)] = (near, covered)
    asked: dict[tuple[int, int], tuple[KeptQueries, Future]] = {}

    def mesh(i: int) -> ClosestPoint:
        if i not in meshes:
            meshes[i] = ClosestPoint.build(out[i], stack.faces[i])
        return meshes[i]

    def ahead(i: int) -> None:
        """Garment i's mesh is final: ask it about the garments two or more under it, nearest first."""
        for j in range(i - 2, -1, -1) if ASK_AHEAD else ():
            if (j, i) in masks:
                near, covered = masks[(j, i)]
                kept = KeptQueries(mesh(i), len(out[j]))
                asked[(j, i)] = (kept, ask_ahead(kept, out[j], np.flatnonzero(near & covered)))

    ahead(len(out) - 1)
    for j in range(len(out) - 2, -1, -1):
        outer = []
        for i in range(j + 1, len(out)):
            if (j, i) not in masks:
                continue
            kept = None
            if (j, i) in asked:
                kept, future = asked.pop((j, i))
                future.result()
            looser = stack.segment_test(j, i)
            outer.append(Outer(mesh(i), *masks[(j, i)], looser_under=looser, kept=kept))
        if outer:
            floor = (j + 1) * settings.margin  # room for the garments under this one
            looser = any(o.looser_under for o in outer)  # else the segment test is never asked
            anchors = stack.anchors[j].on(body.vertices, body.faces) if looser else None
            r = squeeze_layer(out[j], stack.faces[j], outer, body, floor, settings, anchors, deep[j],
                              way.past_rim)  # fmt: skip
            out[j] = r.vertices if np.all(np.isfinite(r.vertices)) else out[j]
        ahead(j)
    return out


@dataclass
class _FinalLayer:
    """A layer the repair is done with, as the layers over it see it."""

    mesh: ClosestPoint
    closed: bool
    """The body: inside is inside, at any depth."""
    moved: float
    """m: how far, at most, it is from the explicit mesh whose fields the outer layers read."""
    turned: np.ndarray | None = None
    """(F,) bool: its faces that may face the body (``BodyAnchors.reversed_faces``)."""
    sides: FoldSides | None = None
    """Its side test where those faces are closest (``service.geometry.fold_side``)."""

    occupied: dict[float, Occupancy] = field(default_factory=dict, repr=False)

    def occupancy(self, pad: float) -> Occupancy:
        """The cells within ``pad`` of it (``near_in_world``), built once for each pad."""
        if pad not in self.occupied:
            self.occupied[pad] = Occupancy.build(self.mesh.vertices, self.mesh.faces, pad)
        return self.occupied[pad]


def _repair(stack: Stack, body: ClosestPoint, explicit: list[np.ndarray], fitted: Fitted,
            fit_world: list[np.ndarray], world: list[np.ndarray], settings: CollisionSettings,
            lowered: list[float]) -> Resolved:  # fmt: skip
    """Repaired world meshes and their ``RepairResult``s, each layer against the final inner ones.

    Which vertices can be near an inner layer, and where it covers them, comes from the fields at the
    layer's fitted canonical vertices (``Fitted.field_at``: those the fit left, values only). The
    fields are those of the explicit meshes: an inner garment that its fit and repair moved by up to
    s is looked for within ``settings.reach`` + s. The fields were read where the fit left a vertex:
    one the squeeze (or an earlier pass) moved by d since is looked for within d more, so that the
    crossings left that the repair counts are never fewer than the returned meshes have (a loose
    sleeve walked 5 cm to its anchor can end inside the arm)."""
    inner = [_FinalLayer(body, True, 0.0)]
    out, results = [], []
    # The body never moves, and every layer's first pushes ask it about the layer's vertices where
    # the squeeze left them: those queries go in one batch, which the query's blocks spread over both
    # cores (a layer's own batch is often below a block); the same answers, kept for each layer.
    masks = []
    # m per vertex: how far the squeeze (and an earlier pass) moved it from where the fit left it.
    own = [np.linalg.norm(x - x0, axis=1) for x, x0 in zip(world, fit_world, strict=True)]
    for i in range(len(world)):
        # The body's distance is exact (canonical, a grid): only vertices it puts within
        # max_margin + body_query_pad can be within a margin of the body in world space, less how far
        # they moved since the fit: a jacket's sleeve walked 5 cm to its anchor on the arm can be
        # inside the arm.
        f_body = fitted.field_at(stack.fields, 0, i)[0] - own[i]
        # The canonical distance is not the world's where the body map squeezes space (a heavy body's
        # armpit): the triangles the world puts within reach are near whatever the field says.
        near = near_in_world(world[i], stack.faces[i], inner[0], f_body < settings.reach, settings.reach)
        seen = near & (f_body >= settings.reach)
        masks.append((near, (f_body < settings.max_margin + settings.body_query_pad) | seen))
    kept_body = _asked_together(body, world, [np.flatnonzero(near & query) for near, query in masks])
    # (i, k): garment i's Inner for inner layer k (a garment), asked ahead (``ask_ahead``) once layer k
    # was final, while the garments between were repaired, and the future its first answers come from.
    asked: dict[tuple[int, int], tuple[Inner, Future]] = {}

    def garment_inner(i: int, k: int) -> Inner:
        """Layer k (a garment under garment i, final) as garment i's repair sees it."""
        layer = inner[k]
        f_k, h_k = fitted.field_at(stack.fields, k, i)
        near = np.abs(f_k) < settings.reach + layer.moved + own[i]
        seen = np.flatnonzero(near_in_world(world[i], stack.faces[i], layer, near, settings.reach) & ~near)
        if len(seen):
            # Near in the world only: the fit may have left them the bound and an inactive h, as far from
            # the layer (``fit.FAR_FIELD``); where the layer covers them is asked again.
            near = near.copy()
            near[seen] = True
            h_k = h_k.copy()
            h_k[seen] = stack.fields(k, fitted.vertices[i][seen])[1]
        return Inner(layer.mesh, False, near, h_k < 0, reversed_faces=layer.turned, sides=layer.sides)

    for i, (x, f) in enumerate(zip(world, stack.faces, strict=True)):
        layers = []
        for k, layer in enumerate(inner):
            if layer.closed:
                near, query = masks[i]
                layers.append(Inner(layer.mesh, True, near, np.ones(len(x), dtype=bool), query, kept_body[i]))
            elif (i, k) in asked:
                found, future = asked.pop((i, k))
                future.result()
                layers.append(found)
            else:
                layers.append(garment_inner(i, k))
        r = repair_layer(x, f, layers, settings)
        out.append(r.vertices if np.all(np.isfinite(r.vertices)) else x)
        results.append(r)
        # How far this layer now is from its explicit mesh, whose fields the outer layers see: the fit
        # moved it in canonical space (times the body map's stretch), the squeeze and the repair in
        # world space.
        stretch = settings.body_map_stretch
        fit_move = float(np.linalg.norm(fitted.vertices[i] - explicit[i], axis=1).max())
        moved = stretch * fit_move + float(np.linalg.norm(out[-1] - fit_world[i], axis=1).max())
        moved += stretch * lowered[i]  # its fields are of the mesh before it was let down
        if i == len(world) - 1:
            break  # no layer over it
        # Its faces turned against the body, the same for every layer over it.
        turned = stack.anchors[i].reversed_faces(out[-1], f, body.vertices, body.faces, body.fn)
        # Their side where those faces are closest is the measure's crossing parity (``fold_side``).
        sides = FoldSides.build(out[-1], f, body, PENETRATION_BAND)
        inner.append(_FinalLayer(ClosestPoint.build(out[-1], f), False, moved, turned, sides))
        # Its closest points for the garments two or more over it, nearest first, while the ones between
        # are repaired: their first round asks every near vertex, where the squeeze left it.
        k = len(inner) - 1
        for later in range(i + 2, len(world)) if ASK_AHEAD else ():
            layer = garment_inner(later, k)
            layer.kept = KeptQueries(layer.mesh, len(world[later]), layer.reversed_faces, layer.sides)
            asked[(later, k)] = (layer, ask_ahead(layer.kept, world[later], np.flatnonzero(layer.near)))
    return Resolved(out, results)


def near_in_world(x: np.ndarray, faces: np.ndarray, inner: _FinalLayer, near: np.ndarray,
                  reach: float) -> np.ndarray:  # fmt: skip
    """``near (V,)`` and the corners of every other triangle of ``faces (F, 3)`` over ``x (V, 3)`` that
    comes within ``reach`` of the ``inner`` layer in world space or may cross it: one of its corners is
    within ``reach`` or within its longest edge of the inner mesh (or inside the body). A crossing
    triangle's corners are all within its longest edge of the crossing point, so the crossing tests
    of the triangles with a near corner see every crossing. Only the triangles that touch the inner
    layer's cells (``Occupancy``) are measured, at their corners.

    Why: the repair tests only the vertices the canonical fields put near an inner layer, and the
    body map can squeeze space by more than its stretch allows. On the BMI 52-65 held-out women a
    jacket crossed the body and the T-shirt at the armpits in 7-461 pairs that no test saw, and the
    report called the outfit clean (``benchmarks.population --outfits``)."""
    other = np.flatnonzero(~near[faces].any(axis=1))
    lo, hi = triangle_boxes(x, faces[other])
    other = other[inner.occupancy(reach).touching(lo, hi)]
    if not len(other):
        return near
    corners, back = np.unique(faces[other], return_inverse=True)
    found = inner.mesh.query(x[corners])
    tri = x[faces[other]]
    longest = np.linalg.norm(tri - tri[:, [1, 2, 0]], axis=2).max(axis=1)
    close = found.distance[back].reshape(-1, 3).min(axis=1) <= np.maximum(reach, longest)
    if inner.closed:
        close |= (found.signed[back].reshape(-1, 3) < 0).any(axis=1)
    out = near.copy()
    out[faces[other[close]].ravel()] = True
    return out


def _asked_together(
    mesh: ClosestPoint, point_sets: list[np.ndarray], asked: list[np.ndarray]
) -> list[KeptQueries]:
    """``KeptQueries`` of ``mesh`` for each of ``point_sets (V_i, 3)`` holding the answers for its points
    ``asked[i] (K_i,)``, all asked in one query."""
    kept = [KeptQueries(mesh, len(x)) for x in point_sets]
    total = sum(len(a) for a in asked)
    if not total:
        return kept
    q = mesh.query(np.concatenate([x[a] for x, a in zip(point_sets, asked, strict=True)]))
    start = 0
    for x, a, k in zip(point_sets, asked, kept, strict=True):
        part = slice(start, start + len(a))
        k.store(x, a, Closest(*(getattr(q, name.name)[part] for name in fields(Closest))))
        start += len(a)
    return kept
